"""The one exception hierarchy of avp.

Every error the library raises on purpose is an :class:`AvpError`. Messages name the field that
is wrong and say what to change (qpsolvers style). Solver-library exceptions are caught and
re-raised as :class:`SolverError` so that they do not leak through the abstraction.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # pragma: no cover
    from .planner import PlanResult

__all__ = [
    "AvpError",
    "BoundsNotCertifiedError",
    "ConfigError",
    "InfeasibleError",
    "PlanningError",
    "RelaxedPlanError",
    "SolverError",
    "WorkerError",
    "WorkspaceNotCertifiedError",
]


class AvpError(Exception):
    """Base class of every error raised by avp."""


class ConfigError(AvpError, ValueError):
    """Bad input: wrong shape, NaN/inf, non-orthonormal rotation, impossible limits...

    Attributes
    ----------
    field:
        Name of the offending argument or field (``"target.R_WS"``, ``"limits.thrust_min"``).
    message:
        What is wrong and what to do, without the field name.
    """

    def __init__(self, field: str, message: str) -> None:
        self.field = field
        self.message = message
        super().__init__(f"{field}: {message}")

    def __reduce__(self) -> tuple[Any, ...]:
        # pickled by its two arguments, so that it crosses a process boundary: the campaign's
        # process pool and Ray workers hand a trial's error back to the caller by pickle. By
        # ``args`` (the one formatted string) unpickling called ``ConfigError(text)``, a
        # TypeError, and the pool reported a BrokenProcessPool instead of the field.
        return (type(self), (self.field, self.message), self.__dict__)


class PlanningError(AvpError):
    """Planning produced no trajectory; ``result`` holds the diagnostics (a ``PlanResult``)."""

    def __init__(self, message: str, result: PlanResult | Any | None = None) -> None:
        self.result = result
        super().__init__(message)


class InfeasibleError(PlanningError):
    """The perching constraints admit no trajectory (even after dropping the FoV rows)."""


class SolverError(PlanningError):
    """The QP back-end is missing, or failed without an infeasibility certificate."""


class BoundsNotCertifiedError(PlanningError):
    """Actuator bounds could not be certified within the allowed duration changes."""


class WorkspaceNotCertifiedError(PlanningError):
    """No trajectory keeps the workspace limits (perch-plane clearance, ground, speed,
    half-spaces, spheres) certified; ``result.safety`` and ``result.log`` say which."""


class RelaxedPlanError(PlanningError):
    """A certified trajectory exists only with soft constraints relaxed (``result.relaxations``);
    :func:`avp.plan` returns it only with ``allow_relaxed=True``."""


class WorkerError(AvpError):
    """The planning worker of :class:`avp.BackgroundReplanner` died, was closed, did not answer
    in time or hosts another replanner now; or the hosted replanner raised an exception that is
    not an ``AvpError`` and does not cross the process boundary (the message has its traceback).
    The message says which, and whether the worker was closed (then start a new
    :class:`avp.PlanningWorker`)."""
