"""Solve a :class:`~avp.qp.PerchingQp` through qpsolvers and judge the answer.

Back-end exceptions are re-raised as :class:`~avp.errors.SolverError`; "no solution" is an
outcome, not an exception, so the planner can drop the FoV rows and retry (16). A returned point
is accepted only if it is finite and meets every row within :data:`FEASIBILITY_TOL`; a solve
with FoV rows must also meet the KKT residuals (:func:`incompatibility`). Optimality rests on
the back-end: the reduced form is positive definite, and back-ends that miss the full form's
optimum are refused with it (:attr:`Backend.full_form`).

Everything avp knows about a back-end lives in one table, :data:`BACKENDS` (settings, warm
start, iterative or not, iteration cap), next to the acceptance tests that use it: the primal
check :data:`FEASIBILITY_TOL` and the KKT compatibility check (16), :func:`incompatibility`.
"""

from __future__ import annotations

import functools
import math
import operator
import re
import time
from dataclasses import dataclass, field
from enum import Enum
from types import MappingProxyType
from typing import Any

import numpy as np
import qpsolvers
import scipy.sparse

from . import _avp_rust
from ._typing import Array
from .config import PlannerConfig, QpForm
from .errors import AvpError, ConfigError, SolverError
from .qp.assemble import LeastDistanceQp, PerchingQp, ReducedQp, _read_only

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
    "known_solvers",
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
    two_sided:
        avp calls the back-end's own API on the reduced QP with two-sided rows
        ``lower <= G z <= upper`` (no one-sided stacking, no qpsolvers dispatch; DAQP's
        ``daqp.solve``); the returned solution computes the same KKT residuals as the one-sided
        problem qpsolvers would have built (:class:`TwoSidedSolution`).
    full_form:
        Solves :attr:`QpForm.FULL <avp.config.QpForm.FULL>` to its optimum. That form's Hessian
        is singular (the cost (4) weighs only the highest derivatives, not the lowest
        coefficients) and its equalities are passed as rows. DAQP (a dual active-set method
        that factors the Hessian) and OSQP (at avp's 1e-9 tolerances, polished) returned
        feasible plans far from the optimum there and are refused with it (``ConfigError`` on
        ``config.qp_form``): on a 4.5 m wall without FoV rows, DAQP's snap cost was 2.3 times
        the reduced form's at 12 segments of degree 9 (1.23 at 8), OSQP's 1.46 times at 12
        segments of degree 7; ProxQP's agreed within 0.02 %.
    """

    name: str
    defaults: MappingProxyType[str, Any] = field(default_factory=lambda: MappingProxyType({}))
    warm_start: bool = False
    iterative: bool = False
    max_iter: int | None = None
    two_sided: bool = False
    full_form: bool = True


def _backend(name: str, defaults: dict[str, Any] | None = None, **facts: Any) -> Backend:
    d = dict(defaults or {})
    return Backend(name, MappingProxyType(d), max_iter=d.get("max_iter"), **facts)


BACKENDS: MappingProxyType[str, Backend] = MappingProxyType({b.name: b for b in (
    _backend("daqp", two_sided=True, full_form=False),
    # Tight tolerances: at ProxQP's/OSQP's defaults (1e-3) coefficient errors reach 3.5e-2, far
    # too coarse for contact.
    _backend("proxqp", {"eps_abs": 1e-9, "eps_rel": 0.0}, warm_start=True, iterative=True),
    _backend("osqp", {"eps_abs": 1e-9, "eps_rel": 1e-9, "polishing": True, "max_iter": 200_000,
                      "raise_error": False}, warm_start=True, iterative=True, full_form=False),
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


@functools.cache
def known_solvers() -> tuple[str, ...]:
    """Every back-end name the installed qpsolvers knows, installed here or not: the names of its
    ``qpsolvers.solvers.<name>_solve_qp`` entry points (:class:`~avp.config.PlannerConfig` refuses
    any other ``solver``)."""
    import qpsolvers.solvers

    return tuple(sorted(n.removesuffix("_solve_qp") for n in dir(qpsolvers.solvers) if n.endswith("_solve_qp")))


_INF = 1e30
"""DAQP's infinity for a missing bound."""

_VARIABLE_OPTIONS = frozenset({"primal_start", "eps_prox"})
"""DAQP settings whose meaning depends on the variables (a primal guess, a proximal term): with
one of them in ``config.solver_options`` DAQP is given the reduced QP in ``z`` as asked, not its
least-distance form."""


@dataclass(frozen=False)
class TwoSidedSolution(qpsolvers.Solution):
    """A ``qpsolvers.Solution`` of ``min 1/2 x^T P x + q^T x`` s.t. ``lower <= G x <= upper``
    solved through a back-end's own two-sided API. ``problem`` holds the cost only; the rows and
    the signed multipliers ``lam`` (``> 0``: upper bound active, ``< 0``: lower) are kept here,
    and the residuals equal those of the one-sided problem ``[G; -G] x <= [upper; -lower]``
    with ``z = [lam^+; lam^-]``."""

    G: Array | None = None
    lower: Array | None = None
    upper: Array | None = None
    lam: Array | None = None

    def __post_init__(self) -> None:
        if self.__dict__.get("_z", 0) is None:  # the constructor's default: not set, computed when read
            del self.__dict__["_z"]

    @property  # type: ignore[misc]
    def z(self) -> Array | None:
        """The multipliers of the one-sided stacking, ``[lam^+; lam^-]``, computed from ``lam``
        when first read (nothing in avp reads them; qpsolvers' ``Solution`` has them) unless set
        (``None`` included)."""
        d = self.__dict__
        if "_z" not in d:
            if self.lam is None:
                return None
            d["_z"] = np.concatenate([np.maximum(self.lam, 0.0), -np.minimum(self.lam, 0.0)])
        return d["_z"]  # type: ignore[no-any-return]

    @z.setter
    def z(self, value: Array | None) -> None:
        self.__dict__["_z"] = value

    def primal_residual(self) -> float:
        if not self.found or self.x is None or self.G is None or self.lower is None or self.upper is None:
            return math.inf
        if not self.G.shape[0]:
            return 0.0
        Gx = self.G @ self.x
        return float(max(0.0, float(np.max(Gx - self.upper)), float(np.max(self.lower - Gx))))

    def _kkt(self) -> tuple[float, float]:
        """``(dual residual, duality gap)`` by the Rust kernel, computed once per set of array
        objects it reads (nothing writes them in place: a new ``x`` is a new array). Missing
        bounds read as infinite: only the gap needs them, and it is not asked for then."""
        x, lam, G = self.x, self.lam, self.G
        assert x is not None and lam is not None and G is not None  # the callers check
        inputs = (self.problem.P, self.problem.q, G, x, lam, self.lower, self.upper)
        cached = self.__dict__.get("_kkt_cache")
        if cached is None or not all(map(operator.is_, cached[0], inputs)):  # the same 7 objects
            m = lam.shape[0]
            lower = self.lower if self.lower is not None else np.full(m, -np.inf)
            upper = self.upper if self.upper is not None else np.full(m, np.inf)
            residuals = _avp_rust.kkt_residuals(self.problem.P, self.problem.q, G, x, lam, lower, upper)  # any layout
            cached = (inputs, residuals)
            self.__dict__["_kkt_cache"] = cached
        return cached[1]

    def dual_residual(self) -> float:
        """``max |P x + q + G^T lam|`` (0 for an empty ``x``)."""
        if not self.found or self.x is None or self.lam is None or self.G is None:
            return math.inf
        return self._kkt()[0]

    def duality_gap(self) -> float:
        """``|x^T P x + q^T x + upper^T lam^+ + lower^T lam^-|``: only active sides carry
        multipliers, so an infinite bound never multiplies a nonzero one."""
        if not self.found or self.x is None or self.lam is None or self.G is None or self.lower is None \
                or self.upper is None:
            return math.inf
        return self._kkt()[1]


@functools.cache
def _read_only_identity(n: int) -> Array:
    return _read_only(np.eye(n))


def _identity(n: int) -> Array:
    """A new ``(n, n)`` identity (DAQP takes a writable Hessian): a copy of a cached one, which
    costs less than building it."""
    return _read_only_identity(n).copy()


_last_cost: tuple[Array, Array, qpsolvers.Problem] | None = None
"""The last :func:`_cost` (the QPs of a plan's SQP steps share their cost arrays)."""


def _cost(H: Array, g: Array) -> qpsolvers.Problem:
    """``qpsolvers.Problem(P=H, q=g)``: the same object again for the same array objects as the
    last call (a plan's SQP steps). Nothing in avp writes a solution's problem or these arrays."""
    global _last_cost
    last = _last_cost  # one read: another thread may replace it
    if last is not None and last[0] is H and last[1] is g:
        return last[2]
    problem = qpsolvers.Problem(P=H, q=g)
    _last_cost = (H, g, problem)
    return problem


def _solve_two_sided(H: Array, g: Array, G: Array, lower: Array, upper: Array,
                     options: dict[str, Any], ldp: LeastDistanceQp | None = None) -> TwoSidedSolution:
    """``min 1/2 z^T H z + g^T z`` s.t. ``lower <= G z <= upper`` by ``daqp.solve`` directly.

    ``ldp``: the same QP as a least-distance problem (:meth:`PerchingQp.least_distance`), which
    DAQP is then given (an identity Hessian: it skips the factorisation and row transformation
    it would otherwise do at every call); the solution is mapped back, ``z = R^-1 u``, and
    judged in ``z`` as always. The multipliers are those of the same rows. A DAQP setting that
    lives in the variables' space (:data:`_VARIABLE_OPTIONS`) sends the QP in ``z`` instead."""
    import daqp  # type: ignore[import-not-found]

    if "verbose" in options:  # a qpsolvers keyword
        options = {k: v for k, v in options.items() if k != "verbose"}
    # DAQP's infinities for missing bounds (an upper bound of -inf, no request anyone makes, stays
    # one: DAQP then finds the rows infeasible)
    bu, bl = np.minimum(_INF, upper), np.maximum(-_INF, lower)
    sense = np.zeros(G.shape[0], dtype=np.intc)
    t0 = time.perf_counter()
    if ldp is not None and not _VARIABLE_OPTIONS.isdisjoint(options):
        ldp = None  # a primal start or proximal term is given in z: DAQP gets the QP in z
    if ldp is not None:
        x, obj, exitflag, info = daqp.solve(_identity(H.shape[0]), ldp.v, ldp.M, bu, bl, sense, **options)
    else:
        x, obj, exitflag, info = daqp.solve(np.array(H), g, np.ascontiguousarray(G), bu, bl, sense, **options)
    solution = TwoSidedSolution(_cost(H, g), G=G, lower=lower, upper=upper)
    solution.found = exitflag > 0
    if solution.found:
        solution.x, solution.obj = (ldp.reduced(x) if ldp is not None else x), obj
        solution.lam = info["lam"]  # and z = [lam^+; lam^-] when read
    solution.solve_time = time.perf_counter() - t0
    solution.extras = {"exitflag": exitflag, "iterations": info.get("iterations")}
    return solution


def _backend_error(config: PlannerConfig, exc: Exception) -> AvpError:
    """The typed error of a back-end call that raised: one whose message names a setting of the
    user's ``config.solver_options`` as a word ("unexpected keyword argument 'x'", OSQP's
    "Unrecognized settings ['x']", ProxQP's "kwargs = { x: int }") is a ``ConfigError`` naming it;
    anything else a ``SolverError`` (a refusal that does not name the setting cannot be told from
    a back-end failure)."""
    text = str(exc)
    named = [k for k, _ in config.solver_options if re.search(rf"(?<![\w.]){re.escape(k)}(?!\w)", text)]
    if named:  # ProxQP lists every setting it was given: then it is one of them
        which = named[0] if len(named) == 1 else f"one of {', '.join(named)}"
        return ConfigError("config.solver_options", f"back-end '{config.solver}' refused {which}: {text}; "
                                                    "check its documentation for the names and types of its settings")
    return SolverError(f"QP back-end '{config.solver}' failed: {text}")


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
    gap of the returned ``qpsolvers.Solution`` above :data:`KKT_TOL`, NaN or infinite. From a
    qpsolvers back-end an infinite one is qpsolvers' "not defined" (no multipliers returned): the
    primal check stands; a :class:`TwoSidedSolution` always has its multipliers."""
    if outcome is None:
        return "no outcome"
    if not outcome.ok:
        return f"{outcome.status.value} (max violation {outcome.max_violation:.1e})"
    sol = outcome.solution
    if sol is None:
        return None
    inf_undefined = not isinstance(sol, TwoSidedSolution)  # qpsolvers' inf: no multipliers returned
    for name in ("dual_residual", "duality_gap"):
        try:
            val = float(getattr(sol, name)())
        except (ValueError, TypeError, AttributeError):  # no multipliers: the primal check stands
            continue
        if val == math.inf and inf_undefined:
            continue
        if not val <= KKT_TOL:  # above the tolerance, NaN, or an overflow of the direct path
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
    facts = backend(config.solver)
    if config.qp_form is QpForm.REDUCED and facts.two_sided:
        two = qp.reduce()
        ldp = qp.least_distance()
        build_time = time.perf_counter() - t_build
        t_solve = time.perf_counter()
        try:
            solution: qpsolvers.Solution = _solve_two_sided(two.H, two.g, two.G, two.lower, two.upper, _options(config), ldp)
        except Exception as exc:  # back-end errors must not leak (one hierarchy)
            raise _backend_error(config, exc) from exc
        solve_time = time.perf_counter() - t_solve
        return _outcome(qp, config, two, solution, G_full, lo_full, hi_full, build_time, solve_time)
    red: ReducedQp | None = None
    if config.qp_form is QpForm.REDUCED:
        red = qp.reduce()
        Gs, hs = _one_sided(red.G, red.lower, red.upper)
        problem = qpsolvers.Problem(P=_writable(red.H), q=red.g, G=Gs, h=hs)
        init = None
        if initvals is not None and initvals.shape == red.c_p.shape:
            init = red.Z.T @ (initvals - red.c_p)
    else:
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
        raise _backend_error(config, exc) from exc
    solve_time = time.perf_counter() - t_solve
    return _outcome(qp, config, red, solution, G_full, lo_full, hi_full, build_time, solve_time)


def _outcome(qp: PerchingQp, config: PlannerConfig, red: ReducedQp | None, solution: qpsolvers.Solution,
             G_full: Array, lo_full: Array, hi_full: Array, build_time: float, solve_time: float) -> QpOutcome:
    """Judge a back-end's answer: finite, lifted to the coefficients, within the tolerances."""
    x = solution.x if solution.found else None
    if x is None or not np.isfinite(x).all():
        return QpOutcome(status=QpStatus.NO_SOLUTION, c_hat=None, solver=config.solver, build_time=build_time, solve_time=solve_time, max_violation=np.inf, solution=solution)
    c_hat = red.lift(x) if red is not None else np.asarray(x, dtype=float)
    violation = _max_violation(qp, c_hat, G_full, lo_full, hi_full)
    status = QpStatus.SOLVED if violation <= FEASIBILITY_TOL else QpStatus.INACCURATE
    return QpOutcome(status=status, c_hat=c_hat, solver=config.solver, build_time=build_time, solve_time=solve_time, max_violation=violation, solution=solution)


def _max_violation(qp: PerchingQp, c_hat: Array, G: Array, lo: Array, hi: Array) -> float:
    """Largest relative violation of the equalities and inequalities at ``c_hat`` (each row's
    residual over ``max(1, |bound|)``; an infinite bound is never violated), by the Rust kernel:
    NaN when a residual is NaN (then not SOLVED)."""
    A, b = qp.stacked_equalities()
    return float(_avp_rust.max_violation(c_hat, A, b, G, lo, hi))  # reads any layout and float dtype
