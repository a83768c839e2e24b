"""Perception-aware solve of one perching QP: FoV rows (8)-(9), SQP steps, fallback (16).

Policy (:func:`solve_with_fov`), at fixed segment durations:

* **Replanning** (a ``previous`` plan is given): linearise the cone (7) at ``n_p`` points of the
  previous plan (mapped by the fraction of the remaining time, which is the same absolute time when
  the final time did not change), solve the QP with the FoV rows; if that is incompatible (16),
  solve again without them.
* **First plan** (no previous plan): solve without FoV rows, linearise around that solution and
  solve again (an SQP step); repeat, at most ``fov.sqp_iterations`` times, while the visibility
  (:func:`avp.metrics.visibility` on a 200-sample grid, time + path fraction) improves; a step
  that does not improve it is discarded (so FoV on never lowers the visibility of a first plan). If the first FoV step is incompatible,
  the FoV-free solution is returned and the result says the rows were dropped.

Incompatibility (16) is declared when the back-end reports no solution, raises, or returns a point
whose KKT residuals are out of tolerance: primal violation above
:data:`avp.solve.FEASIBILITY_TOL` (checked by :func:`~avp.solve.solve_perching_qp`), or dual
residual / duality gap of the returned ``qpsolvers.Solution`` above :data:`KKT_TOL`
(:func:`avp.solve.incompatibility`, next to the back-end table :data:`avp.solve.BACKENDS`). For
the FoV attempts iterative back-ends (proxqp, osqp) get ``max_iter = fov.fallback_max_iter`` so
an infeasible problem is declared quickly (docs/perception.md has the measurements).
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from ._typing import Array
from .config import PlannerConfig
from .errors import InfeasibleError, SolverError
from .metrics import visibility_many
from .qp.assemble import ConstraintBlock, PerchingQp, build_perching_qp
from .qp.fov import FovLinearisation, fov_blocks, fov_times
from .solve import (
    ITERATIVE_SOLVERS,
    KKT_TOL,
    QpOutcome,
    backend,
    incompatibility,
    solve_perching_qp,
)
from .trajectory import Trajectory
from .types import PerchTarget, State

__all__ = ["ITERATIVE_SOLVERS", "KKT_TOL", "FovSolve", "incompatibility", "linearise_on", "solve_with_fov"]

_SCORE_GRID = 200
"""Samples of the coarse visibility grid used to accept an SQP step."""


@dataclass(frozen=True)
class FovSolve:
    """Result of :func:`solve_with_fov` (the planner wraps it in its attempt record)."""

    outcome: QpOutcome | None
    trajectory: Trajectory | None
    fov_dropped: bool
    build: float
    solve: float
    sqp_steps: int = 0
    linearisation: FovLinearisation | None = None


def _trajectory(qp: PerchingQp, outcome: QpOutcome, g: float) -> Trajectory | None:
    if not outcome.ok or outcome.c_hat is None:
        return None
    return qp.trajectory(outcome.c_hat, g)


def linearise_on(
    qp: PerchingQp, reference: Trajectory, target: PerchTarget, cfg: PlannerConfig
) -> FovLinearisation:
    """FoV blocks for ``qp`` linearised on ``reference`` at the ``n_p`` gated times.

    The relative time ``t`` of the new plan (final time ``tf``) maps to the reference's
    ``t0_new + t (tf_ref - t0_new)/tf``: the same absolute time when both plans end together.
    """
    knots = qp.knots_rel
    tf = float(knots[-1])
    times = fov_times(0.0, tf, cfg.fov)
    if times.size == 0:
        return fov_blocks(qp.layout, knots, times, np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3)),
                          target.point, cfg.fov, cfg.g)
    start = max(qp.t0, reference.t0)
    t_ref = np.clip(qp.t0 + times * (reference.tf - start) / tf, reference.t0, reference.tf)
    d = reference.derivatives(t_ref, (0, 2))
    return fov_blocks(qp.layout, knots, times, d[0, :, :3], d[0, :, 3], d[1, :, :3],
                      target.point, cfg.fov, cfg.g)


def _fov_config(cfg: PlannerConfig) -> PlannerConfig:
    cap = cfg.fov.fallback_max_iter
    if cap is None or not backend(cfg.solver).iterative:
        return cfg
    return replace(cfg, solver_options=(("max_iter", int(cap)),) + tuple(cfg.solver_options))


def _scores(trajs: tuple[Trajectory, ...], target: PerchTarget, cfg: PlannerConfig) -> list[float]:
    """Visibility time + path fraction of plans on the same knots, in one vectorised pass."""
    vis = visibility_many(trajs, target, cfg.fov.camera, dt=trajs[0].duration / _SCORE_GRID)
    return [v.time_fraction + v.path_fraction for v in vis]


def solve_with_fov(
    state: State,
    target: PerchTarget,
    cfg: PlannerConfig,
    T: Array,
    log: list[str],
    previous: Trajectory | None = None,
    initvals: Array | None = None,
    extra: tuple[ConstraintBlock, ...] = (),
    *,
    first: tuple[PerchingQp, QpOutcome, Trajectory] | None = None,
    worth_fov: Callable[[Trajectory], bool] | None = None,
) -> FovSolve:
    """Solve the perching QP at durations ``T`` with FoV rows (8)-(9) and the fallback (16).

    Appends one line per QP to ``log``. ``fov_dropped`` is ``True`` when the returned plan was
    solved without FoV rows because the rows were incompatible (16). ``initvals`` (normalised
    coefficients) warm-start every solve of back-ends that take a guess. ``extra`` inequality
    blocks (the workspace rows of :mod:`avp.safety`) are part of every QP, with or without FoV.
    ``first``: this QP without FoV rows (``extra`` included) and its solution, when the caller
    already has them (the planner's time search at these durations); a first plan's SQP then
    starts from them instead of building and solving that QP again. ``worth_fov``: a test of
    a first plan's FoV-free solution; when it returns ``False`` (the planner: a sampled bound
    is already violated, so a search over durations follows) no SQP step is taken and that
    solution is returned (the rows are not dropped, they were not tried).

    Raises
    ------
    SolverError
        The back-end is missing or failed on the FoV-free QP.
    """
    t0 = time.perf_counter()
    if first is not None and previous is None:
        base = first[0]
    else:
        base = build_perching_qp(state, target, cfg, T)
        if extra:
            base = base.with_inequalities(*extra)
    build = time.perf_counter() - t0
    solve = 0.0
    fov_cfg = _fov_config(cfg)

    def run(qp: PerchingQp, c: PlannerConfig, label: str, strict: bool) -> tuple[QpOutcome | None, str | None]:
        nonlocal build, solve
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always" if not strict else "default")
                out = solve_perching_qp(qp, c, initvals)
            if not strict:  # expected on an incompatible FoV QP (16): log, do not warn
                log.extend(f"{label}: {w.category.__name__}: {w.message}" for w in caught)
            else:
                for w in caught:
                    warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        except InfeasibleError as exc:
            log.append(f"{label}: {exc}")
            return None, str(exc)
        except SolverError as exc:
            if strict:
                raise
            log.append(f"{label}: {exc}")
            return None, str(exc)
        build += out.build_time
        solve += out.solve_time
        return out, None

    def plain(label: str) -> tuple[QpOutcome | None, Trajectory | None]:
        out, _err = run(base, cfg, label, True)
        if out is None:
            return None, None
        log.append(f"{label} {cfg.solver}: {out.status.value} (max violation {out.max_violation:.1e})")
        return out, _trajectory(base, out, cfg.g)

    def with_rows(reference: Trajectory, label: str) -> tuple[QpOutcome | None, Trajectory | None, str | None, FovLinearisation]:
        nonlocal build
        tb = time.perf_counter()
        lin = linearise_on(base, reference, target, cfg)
        qp = base.with_inequalities(*lin.blocks)
        build += time.perf_counter() - tb
        n_vis = int(np.sum(lin.h0 <= 0.0))
        desc = (f"{label}: {int(lin.placed.sum())}/{lin.times.size} FoV points placed "
                f"({int(lin.progress.sum())} progress-only, {n_vis} visible at linearisation)")
        out, err = run(qp, fov_cfg, label, False)
        why = err if out is None else incompatibility(out)
        if why is not None or out is None:
            log.append(f"{desc}; incompatible (16): {why}")
            return out, None, why, lin
        log.append(f"{desc}; {fov_cfg.solver}: solved (max violation {out.max_violation:.1e})")
        return out, _trajectory(qp, out, cfg.g), None, lin

    if previous is not None:
        probe = fov_times(0.0, float(np.sum(T)), cfg.fov)
        if probe.size == 0:
            out, traj = plain("QP (no FoV rows: inside the gate)")
            return FovSolve(out, traj, False, build, solve)
        out, traj, why, lin = with_rows(previous, "QP + FoV (linearised on the previous plan)")
        if why is None:
            return FovSolve(out, traj, False, build, solve, 1, lin)
        out, traj = plain("QP without FoV rows (fallback (16))")
        return FovSolve(out, traj, True, build, solve, 1, lin)

    out0: QpOutcome | None
    traj0: Trajectory | None
    if first is not None:
        _qp, out0, traj0 = first
        log.append("QP (first plan, before FoV): the search step's solution at these durations")
    else:
        out0, traj0 = plain("QP (first plan, before FoV)")
    if traj0 is None or out0 is None:
        return FovSolve(out0, None, False, build, solve)
    if fov_times(0.0, float(np.sum(T)), cfg.fov).size == 0:
        log.append("no FoV points: the gate covers the whole plan")
        return FovSolve(out0, traj0, False, build, solve)
    if worth_fov is not None and not worth_fov(traj0):
        log.append("no SQP step: the plan without FoV rows already violates a vehicle limit")
        return FovSolve(out0, traj0, False, build, solve)
    best_out, best_traj = out0, traj0
    best_score: float | None = None  # scored with the first step's plan, in one pass
    best_lin: FovLinearisation | None = None
    steps = 0
    for k in range(cfg.fov.sqp_iterations):
        out, traj, why, lin = with_rows(best_traj, f"SQP step {k + 1}")
        if why is not None or traj is None or out is None:
            if k == 0:
                log.append("FoV rows dropped (16): returning the plan without them")
                return FovSolve(out0, traj0, True, build, solve, 0, lin)
            break
        if best_score is None:
            best_score, score = _scores((traj0, traj), target, cfg)
        else:
            (score,) = _scores((traj,), target, cfg)
        log.append(f"SQP step {k + 1}: visibility time+path {score / 2:.3f} (was {best_score / 2:.3f})")
        if score <= best_score + 1e-4:
            if k == 0 and score < best_score - 1e-4:
                log.append("SQP step 1 lowered the visibility: keeping the first solution")
            break
        best_out, best_traj, best_score, best_lin, steps = out, traj, score, lin, k + 1
    return FovSolve(best_out, best_traj, False, build, solve, steps, best_lin)
