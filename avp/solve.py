"""Solve a :class:`~avp.qp.PerchingQp` through qpsolvers and judge the answer.

Back-end exceptions are re-raised as :class:`~avp.errors.SolverError`; "no solution" is an
outcome, not an exception, so the planner can drop the FoV rows and retry (16). A returned point
is accepted only if it is finite and its KKT residuals are within tolerance.

Everything avp knows about a back-end lives in one table, :data:`BACKENDS` (settings, warm
start, iterative or not, iteration cap), next to the acceptance tests that use it: the primal
check :data:`FEASIBILITY_TOL` and the KKT compatibility check (16), :func:`incompatibility`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from enum import Enum
from types import MappingProxyType
from typing import Any

import numpy as np
import qpsolvers
import scipy.sparse

from ._typing import Array
from .config import PlannerConfig, QpForm
from .errors import SolverError
from .qp.assemble import PerchingQp

__all__ = [
    "BACKENDS",
    "FEASIBILITY_TOL",
    "ITERATIVE_SOLVERS",
    "KKT_TOL",
    "SOLVER_DEFAULTS",
    "WARM_START_SOLVERS",
    "Backend",
    "QpOutcome",
    "QpStatus",
    "available_solvers",
    "backend",
    "incompatibility",
    "solve_perching_qp",
]


@dataclass(frozen=True)
class Backend:
    """What avp knows about one qpsolvers back-end.

    Attributes
    ----------
    name:
        qpsolvers name.
    defaults:
        Settings avp passes unless ``config.solver_options`` overrides them.
    warm_start:
        Uses an initial guess (``initvals``); DAQP, an active-set method, ignores it.
    iterative:
        Accepts ``max_iter`` and may iterate up to its cap on an infeasible QP, so the FoV
        attempts (16) cap it (``FovConfig.fallback_max_iter``).
    max_iter:
        The iteration cap avp sets by default (``None``: the back-end's own).
    """

    name: str
    defaults: MappingProxyType[str, Any] = field(default_factory=lambda: MappingProxyType({}))
    warm_start: bool = False
    iterative: bool = False
    max_iter: int | None = None


def _backend(name: str, defaults: dict[str, Any] | None = None, **facts: Any) -> Backend:
    d = dict(defaults or {})
    return Backend(name, MappingProxyType(d), max_iter=d.get("max_iter"), **facts)


BACKENDS: MappingProxyType[str, Backend] = MappingProxyType({b.name: b for b in (
    _backend("daqp"),
    # Tight tolerances: at ProxQP's/OSQP's defaults (1e-3) coefficient errors reach 3.5e-2, far
    # too coarse for contact.
    _backend("proxqp", {"eps_abs": 1e-9, "eps_rel": 0.0}, warm_start=True, iterative=True),
    _backend("osqp", {"eps_abs": 1e-9, "eps_rel": 1e-9, "polishing": True, "max_iter": 200_000,
                      "raise_error": False}, warm_start=True, iterative=True),
    _backend("piqp", warm_start=True),
    _backend("qpalm", warm_start=True),
    _backend("scs", iterative=True),
    _backend("clarabel", iterative=True),
)})
"""The one table of back-end facts (other back-ends qpsolvers offers run with their defaults)."""


def backend(name: str) -> Backend:
    """The facts of back-end ``name`` (an unknown one: no settings, no warm start, direct)."""
    return BACKENDS.get(name) or Backend(name)


SOLVER_DEFAULTS: dict[str, dict[str, Any]] = {b.name: dict(b.defaults) for b in BACKENDS.values() if b.defaults or b.name == "daqp"}
"""Per-back-end settings (a view of :data:`BACKENDS`, kept for compatibility)."""

WARM_START_SOLVERS = frozenset(b.name for b in BACKENDS.values() if b.warm_start)
"""Back-ends that use an initial guess (a view of :data:`BACKENDS`)."""

ITERATIVE_SOLVERS = tuple(b.name for b in BACKENDS.values() if b.iterative)
"""Back-ends that accept ``max_iter`` and may iterate to their cap (a view of :data:`BACKENDS`)."""

FEASIBILITY_TOL = 1e-6
"""Largest accepted inequality violation, relative to ``max(1, |bound|)``."""

KKT_TOL = 1e-5
"""Largest accepted dual residual and duality gap (of the unit-diagonal scaled reduced QP)."""


class QpStatus(Enum):
    SOLVED = "solved"
    NO_SOLUTION = "no solution: the back-end reported failure or infeasibility"
    INACCURATE = "inaccurate: the returned point violates the constraints beyond tolerance"


@dataclass(frozen=True, kw_only=True)
class QpOutcome:
    """What one QP solve produced."""

    status: QpStatus
    c_hat: Array | None
    solver: str
    build_time: float
    solve_time: float
    max_violation: float
    solution: qpsolvers.Solution | None

    @property
    def ok(self) -> bool:
        return self.status is QpStatus.SOLVED


def available_solvers() -> list[str]:
    """qpsolvers back-ends installed here."""
    return list(qpsolvers.available_solvers)


def _one_sided(G: Array, lower: Array, upper: Array) -> tuple[Array | None, Array | None]:
    up = np.isfinite(upper)
    lo = np.isfinite(lower)
    if not (up.any() or lo.any()):
        return None, None
    return np.vstack([G[up], -G[lo]]), np.concatenate([upper[up], -lower[lo]])


def _options(config: PlannerConfig) -> dict[str, Any]:
    opts = dict(backend(config.solver).defaults)
    opts.update(dict(config.solver_options))
    return opts


def _writable(M: Any) -> Any:
    """``M``, or a copy when it is a read-only array (cached factors; some back-ends need a
    writable buffer)."""
    return M.copy() if isinstance(M, np.ndarray) and not M.flags.writeable else M


def incompatibility(outcome: QpOutcome | None) -> str | None:
    """Why a FoV-constrained solve counts as incompatible (16), or ``None`` if it is accepted:
    no solution, a primal violation above :data:`FEASIBILITY_TOL`, or a dual residual / duality
    gap of the returned ``qpsolvers.Solution`` above :data:`KKT_TOL`."""
    if outcome is None:
        return "no outcome"
    if not outcome.ok:
        return f"{outcome.status.value} (max violation {outcome.max_violation:.1e})"
    sol = outcome.solution
    if sol is None:
        return None
    for name in ("dual_residual", "duality_gap"):
        try:
            val = float(getattr(sol, name)())
        except (ValueError, TypeError, AttributeError):  # no multipliers: the primal check stands
            continue
        if math.isfinite(val) and val > KKT_TOL:
            return f"KKT {name.replace('_', ' ')} {val:.1e} > {KKT_TOL:.0e}"
    return None


def solve_perching_qp(qp: PerchingQp, config: PlannerConfig, initvals: Array | None = None) -> QpOutcome:
    """Solve ``qp`` with ``config.solver`` in ``config.qp_form``.

    Raises
    ------
    SolverError
        The back-end is not installed, or raised.
    InfeasibleError
        The equality constraints alone are inconsistent.
    """
    if config.solver not in qpsolvers.available_solvers:
        raise SolverError(
            f"config.solver: QP back-end '{config.solver}' is not installed here; choose one of "
            f"{sorted(qpsolvers.available_solvers)} or `pip install qpsolvers[{config.solver}]`"
        )
    t_build = time.perf_counter()
    G_full, lo_full, hi_full = qp.stacked_inequalities()
    if config.qp_form is QpForm.REDUCED:
        red = qp.reduce()
        Gs, hs = _one_sided(red.G, red.lower, red.upper)
        problem = qpsolvers.Problem(P=_writable(red.H), q=red.g, G=Gs, h=hs)
        init = None
        if initvals is not None and initvals.shape == red.c_p.shape:
            init = red.Z.T @ (initvals - red.c_p)
    else:
        red = None
        A, b = qp.stacked_equalities()
        Gs, hs = _one_sided(G_full, lo_full, hi_full)
        problem = qpsolvers.Problem(P=_writable(qp.P), q=np.zeros(qp.layout.n_variables), G=Gs, h=hs,
                                    A=_writable(A), b=_writable(b))
        init = initvals
    if config.solver not in qpsolvers.dense_solvers:  # sparse-only back-ends (OSQP...)
        problem = qpsolvers.Problem(*[  # type: ignore[arg-type]
            scipy.sparse.csc_matrix(m) if isinstance(m, np.ndarray) and m.ndim == 2 else m
            for m in problem.unpack()
        ])
    build_time = time.perf_counter() - t_build
    t_solve = time.perf_counter()
    try:
        solution = qpsolvers.solve_problem(problem, solver=config.solver, initvals=init, **_options(config))
    except Exception as exc:  # qpsolvers/back-end errors must not leak (one hierarchy)
        raise SolverError(f"QP back-end '{config.solver}' failed: {exc}") from exc
    solve_time = time.perf_counter() - t_solve
    x = solution.x if solution.found else None
    if x is None or not np.all(np.isfinite(x)):
        return QpOutcome(status=QpStatus.NO_SOLUTION, c_hat=None, solver=config.solver, build_time=build_time, solve_time=solve_time, max_violation=np.inf, solution=solution)
    c_hat = red.lift(x) if red is not None else np.asarray(x, dtype=float)
    violation = _max_violation(qp, c_hat, G_full, lo_full, hi_full)
    status = QpStatus.SOLVED if violation <= FEASIBILITY_TOL else QpStatus.INACCURATE
    return QpOutcome(status=status, c_hat=c_hat, solver=config.solver, build_time=build_time, solve_time=solve_time, max_violation=violation, solution=solution)


def _max_violation(qp: PerchingQp, c_hat: Array, G: Array, lo: Array, hi: Array) -> float:
    """Largest relative violation of the equalities and inequalities at ``c_hat``."""
    A, b = qp.stacked_equalities()
    viol = [np.abs(A @ c_hat - b) / np.maximum(1.0, np.abs(b))]
    if G.shape[0]:
        Gc = G @ c_hat
        with np.errstate(invalid="ignore"):
            viol.append(np.where(np.isfinite(hi), (Gc - hi) / np.maximum(1.0, np.abs(hi)), 0.0))
            viol.append(np.where(np.isfinite(lo), (lo - Gc) / np.maximum(1.0, np.abs(lo)), 0.0))
    return float(max(0.0, max(float(np.max(v)) if v.size else 0.0 for v in viol)))
