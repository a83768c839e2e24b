"""Perception-aware planning: the field-of-view rows (8)-(9) of one QP, linearised on a
reference plan, and the visibility score that accepts an SQP step.

The policy that uses them (first plan: SQP steps while the visibility improves; replanning:
one SQP step; the fallback (16)) is the FoV stage of the planner's one
attempt path, :mod:`avp.attempt`. Incompatibility (16) is declared when the back-end reports no
solution, raises, or returns a point whose KKT residuals are out of tolerance: primal violation
above :data:`avp.solve.FEASIBILITY_TOL` (checked by :func:`~avp.solve.solve_perching_qp`), or
dual residual / duality gap of the returned ``qpsolvers.Solution`` above :data:`KKT_TOL`
(:func:`avp.solve.incompatibility`, next to the back-end table :data:`avp.solve.BACKENDS`). For
the FoV attempts iterative back-ends (proxqp, osqp) get ``max_iter = fov.fallback_max_iter`` so
an infeasible problem is declared quickly (docs/perception.md has the measurements).
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from ._typing import Array
from .config import PlannerConfig
from .metrics import _cone_fractions, _cone_only, _visibility_checked
from .qp.assemble import ConstraintBlock, PerchingQp
from .qp.fov import FovLinearisation, fov_times, linearise_on_spline
from .solve import ITERATIVE_SOLVERS, KKT_TOL, backend, incompatibility
from .trajectory import Trajectory
from .types import PerchTarget, State

if TYPE_CHECKING:
    from .attempt import Attempt

__all__ = ["ITERATIVE_SOLVERS", "KKT_TOL", "incompatibility", "linearise_on", "solve_with_fov"]

_SCORE_GRID = 200
"""Samples of the coarse visibility grid used to accept an SQP step."""


def __getattr__(name: str) -> Any:
    if name == "FovSolve":  # the former result record: an attempt of the one attempt path
        from .attempt import Attempt
        return Attempt
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def linearise_on(
    qp: PerchingQp, reference: Trajectory, target: PerchTarget, cfg: PlannerConfig, *, build_blocks: bool = True,
) -> FovLinearisation:
    """FoV blocks for ``qp`` linearised on ``reference`` at the ``n_p`` gated times.

    The relative time ``t`` of the new plan (final time ``tf``) maps to the reference's
    ``t0_new + t (tf_ref - t0_new)/tf``: the same absolute time when both plans end together.
    With ``cfg.limits.rotor_drag = d`` the attitude is the one of the thrust ``a + g e3 + d v``
    (the rows' acceleration variable is ``a + d v``: :func:`~avp.qp.fov.fov_blocks`).
    ``build_blocks``: build the blocks with the terms, in the same kernel call; ``False`` for a
    caller that may only ask whether the rows hold at the reference (they are then built on
    first access).
    """
    knots = qp.knots_rel
    tf = float(knots[-1])
    times = fov_times(0.0, tf, cfg.fov)  # none when the gate covers the plan: no row (linearise_on_spline)
    t0, ref_t0, ref_tf = qp.t0, reference.t0, reference.tf
    span = ref_tf - max(t0, ref_t0)
    # within the reference (clipped): Trajectory.derivatives' times, unchecked; in Python floats
    # (a handful of points: fewer calls than array operations, the same values)
    tau = np.array(reference._relative_floats([min(ref_tf, max(ref_t0, t0 + t * span / tf)) for t in times.tolist()]))
    # the reference's points and their rows in one kernel call; with rotor drag the attitude is
    # the one of the thrust a + g e3 + d v (VehicleLimits.rotor_drag)
    return linearise_on_spline(qp.layout, knots, times, reference.coefficients, reference.knots_rel, tau,
                               target.point, cfg.fov, cfg.g, rotor_drag=cfg.limits.rotor_drag,
                               build_blocks=build_blocks)


def _fov_config(cfg: PlannerConfig) -> PlannerConfig:
    cap = cfg.fov.fallback_max_iter
    if cap is None or not backend(cfg.solver).iterative:
        return cfg
    return replace(cfg, solver_options=(("max_iter", int(cap)),) + tuple(cfg.solver_options))


def _scores(trajs: tuple[Trajectory, ...], target: PerchTarget, cfg: PlannerConfig) -> list[float]:
    """Visibility time + path fraction of plans on the same knots, in one vectorised pass, in
    the cone the FoV rows ask for (:attr:`~avp.config.FovConfig.score_camera`: the camera's
    cone narrowed by ``fov.margin``)."""
    camera = cfg.fov.score_camera
    if camera is None:  # no direction meets the rows: nothing to gain
        return [0.0] * len(trajs)
    first = trajs[0]
    step = first.duration / _SCORE_GRID
    if _cone_only(camera) and all(tr.knots_rel is first.knots_rel and tr.t0 == first.t0 and tr.g == first.g
                                  for tr in trajs[1:]):
        # the plans of one QP's copies (the same knots object, a shortcut of _visibility_checked's
        # test by value): the fractions alone, summed
        coeffs = first.coefficients if len(trajs) == 1 else np.concatenate([tr.coefficients for tr in trajs], axis=1)
        tf, pf, _ = _cone_fractions(coeffs, first, first._sample_rel(step), target, camera, cfg.limits.rotor_drag)
        return (tf + pf).tolist()  # type: ignore[no-any-return]
    vis = _visibility_checked(trajs, target, camera, step, cfg.limits.rotor_drag)
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
) -> Attempt:
    """The FoV stage of :mod:`avp.attempt` at durations ``T`` (kept for callers of this
    module): :func:`avp.attempt.solve_fov`, with its log lines appended to ``log``."""
    from .attempt import solve_fov

    attempt = solve_fov(state, target, cfg, T, extra, previous=previous, initvals=initvals)
    log.extend(attempt.log)
    return attempt
