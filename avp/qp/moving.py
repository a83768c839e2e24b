"""Terminal map for a moving pad at a fixed arrival time (Gao et al., "Adaptive Tracking and
Perching for Quadrotor in Dynamic Scenarios", T-RO 2023, Sec. V-D, eqs. (43)-(51)).

For a fixed duration ``T`` the pad's predicted state at ``t_f = t_0 + T`` is known, and every
terminal condition is linear in the spline coefficients:

* position ``p(t_f) = rho(t_f) + l s3(t_f)`` (their (43), ``l`` the landing-gear offset along the
  outward normal);
* thrust axis along ``s3(t_f)``: ``a(t_f) + g e3 = alpha s3`` (their (49)-(50), our (12)), with
  ``alpha`` fixed or free in ``config.alpha_range`` (their ``tau_e`` in ``[tau_min, tau_max]``);
* velocity ``v(t_f) = v_pad(t_f) - v_n s3 + nu_x s1 + nu_y s2`` (their (45)-(46)): the normal
  component is an equality, the tangential slip ``nu`` is free within ``|nu_i| <= slip_max``
  and costs ``w |nu|^2`` (their (47), Fig. 7); ``slip_max = 0`` makes it an equality;
* optionally zero jerk ``p'''(t_f) = 0`` (their Sec. V-D), so the body rate vanishes at contact;
* yaw ``psi(t_f) = theta(t_f)`` (their (44)) or the static rule (13) on the predicted pad.

The slip cost ``w |S_t^T (V c - v_pad)|^2`` has a constant ``v_pad``; the QP of
:mod:`avp.qp.assemble` has no linear cost term, so the constant is homogenised with a linear form
``l`` that equals 1 on the feasible set (``l = A^T b / |b|^2`` over the equalities ``A c = b``):
``w |S_t^T (V - v_pad l^T) c|^2`` is a quadratic form that agrees with the slip cost wherever
``A c = b``, which is the only place the QP looks (exact, not an approximation).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from enum import Enum
from functools import lru_cache

import numpy as np
import scipy.linalg

from .._typing import Array
from ..config import PlannerConfig
from ..errors import ConfigError
from ..platform import MovingTarget
from ..safety import workspace_blocks
from ..types import PerchTarget, State
from .assemble import RANK_TOL, ConstraintBlock, PerchingQp, eliminate_within
from .boundary import continuity_rows, initial_state_rows
from .cost import cost_matrix, gram
from .layout import YAW, layout_for
from .perching import pre_impact_rows, terminal_yaw
from .rows import derivative_rows, vector_rows

__all__ = ["MovingQpBuilder", "TerminalYaw", "contact_point", "moving_perching_qp", "objective"]



class TerminalYaw(Enum):
    """Yaw at contact on a moving pad."""

    HEADING = "heading: psi(t_f) = theta(t_f), the platform's predicted heading (Gao et al. (44))"
    PAD = "pad: b2 parallel to s2 of the predicted pad, the static rule (13)"


def contact_point(pad: PerchTarget, body_offset: float) -> Array:
    """The CoM at contact: ``rho + l s3`` (Gao et al. (43))."""
    return np.asarray(pad.point + body_offset * pad.s3, dtype=np.float64)


def _physical_scale(durations: Array, degree: int, config: PlannerConfig) -> float:
    """``k`` with ``sum_i int |d^j p / dt^j|^2 dt = k c_hat^T P c_hat`` on the position columns:
    :func:`avp.qp.cost.cost_matrix` scales axis blocks by ``T_total^(2j - 1)`` and divides the
    whole matrix by its largest diagonal entry (position or yaw block)."""
    T = np.asarray(durations, dtype=float)
    ratio = float(np.max(T.sum() / T))
    peak = max(float(np.max(np.diag(gram(degree, j)))) * ratio ** (2 * j - 1)
               for j in (config.position_cost_order, config.yaw_cost_order))
    return peak * float(T.sum()) ** (1 - 2 * config.position_cost_order)


def objective(qp: PerchingQp, c_hat: Array, config: PlannerConfig) -> float:
    """The QP objective ``c_hat^T P c_hat`` in physical units of the position cost (4): the snap
    integral ``sum_i int |d^j p / dt^j|^2 dt`` (m^2 s^(1-2j)) plus the slip cost ``w |nu|^2`` and
    the yaw cost on the same scale."""
    return float(c_hat @ qp.P @ c_hat) * _physical_scale(qp.durations, qp.layout.degree, config)


def _tangents(pad: PerchTarget) -> tuple[Array, Array, Array]:
    """``(t1, t2, s3)``: an orthonormal frame with ``t1`` along ``s1``. The thrust rows ask
    ``f . t1 = f . t2 = 0``, which makes ``f`` parallel to ``s3`` exactly even when ``R_WS`` is
    orthonormal only to its validation tolerance (1e-6)."""
    s3 = pad.s3 / np.linalg.norm(pad.s3)
    t1 = pad.s1 - (pad.s1 @ s3) * s3
    t1 = t1 / np.linalg.norm(t1)
    return t1, np.cross(s3, t1), s3


@lru_cache(maxsize=16)
def _fixed_parts(
    S: int, degree: int, position_order: int, yaw_order: int, continuity_order: int
) -> tuple[Array, ConstraintBlock, list[Array], Array, Array, Array, Array]:
    """The T-invariant parts of a moving-pad QP with ``S`` equal segments (read-only): cost
    matrix, continuity rows, endpoint rows (position..jerk, yaw) at ``t_f`` for unit segments,
    the null space ``Z0`` of the initial-state and continuity rows, the map ``L0`` from the
    initial right-hand side to a particular solution, and ``Z0^T P Z0``. With equal segments the
    initial-state and continuity matrices do not depend on ``T`` (only the right-hand side)."""
    layout = layout_for(S, degree)
    ones = np.ones(S)
    P = cost_matrix(layout, ones, position_order, yaw_order)
    Ac = continuity_rows(layout, ones, continuity_order, 1.0)
    continuity = ConstraintBlock("continuity", Ac, np.zeros(Ac.shape[0]), np.zeros(Ac.shape[0]))
    knots = np.arange(S + 1, dtype=float)
    end = [vector_rows(layout, knots, r, float(S))[0] for r in range(4)]  # / T_S^r: physical
    end_yaw = derivative_rows(layout, knots, YAW, 0, float(S))[0]
    A0, _ = initial_state_rows(layout, ones, State.hover(np.zeros(3)), 1.0)
    A_fix = np.vstack([A0, Ac])
    Q, R, piv = scipy.linalg.qr(A_fix.T, pivoting=True, check_finite=False)
    diag = np.abs(np.diag(R))
    rank = int(np.sum(diag > RANK_TOL * max(float(diag[0]), 1.0)))
    if rank < A_fix.shape[0]:  # pragma: no cover - the initial/continuity rows are independent
        raise ConfigError("config", "initial-state and continuity rows are dependent; raise config.degree")
    Z0 = Q[:, rank:]
    # c0 = L b_fix solves A_fix c = b_fix = [b0; 0]; only the b0 columns are needed.
    L = Q[:, :rank] @ scipy.linalg.solve_triangular(R[:rank, :rank], np.eye(rank), trans="T", check_finite=False)
    L0 = np.zeros((Q.shape[0], A0.shape[0]))
    for col, row in enumerate(piv[:rank]):
        if row < A0.shape[0]:
            L0[:, row] = L[:, col]
    G0 = Z0.T @ P @ Z0
    for arr in (P, Z0, L0, G0, end_yaw, *end):
        arr.setflags(write=False)
    return P, continuity, end, end_yaw, Z0, L0, G0


@dataclass
class MovingQpBuilder:
    """Builds :func:`moving_perching_qp` for many durations of one start state: with equal
    segments the cost (4), the continuity rows and the endpoint rows in normalised coefficients
    do not depend on ``T`` (``c_hat_k = c_k T_i^k``), so they are computed once and only the
    right-hand sides and the pad-dependent rows change per ``T``."""

    state: State
    config: PlannerConfig
    normal_speed: float
    slip_max: float
    slip_weight: float
    zero_jerk: bool
    yaw: TerminalYaw
    body_offset: float

    def __post_init__(self) -> None:
        cfg = self.config
        self.layout = layout_for(cfg.n_segments, cfg.degree)
        fixed = _fixed_parts(cfg.n_segments, cfg.degree, cfg.position_cost_order, cfg.yaw_cost_order,
                             cfg.continuity_order)
        self.P, self.continuity, self.end, self.end_yaw, self.Z0, self.L0, self.G0 = fixed
        self.peak = _physical_scale(np.ones(cfg.n_segments), cfg.degree, cfg) * float(cfg.n_segments) ** (
            2 * cfg.position_cost_order - 1)  # largest raw diagonal of the cost matrix
        self.static_config = replace(cfg, workspace=replace(cfg.workspace, perch_clearance=False))
        """``config`` without the perch plane (it moves): the static workspace limits."""
        self._plane_rows: tuple[ConstraintBlock, ...] | None = None

    def build(self, pad: MovingTarget, total: float) -> PerchingQp:
        """The QP for duration ``total`` toward ``pad`` predicted at ``state.time + total``."""
        cfg, st = self.config, self.state
        S = cfg.n_segments
        Ti = total / S
        T = np.full(S, Ti)
        A0, b0 = initial_state_rows(self.layout, T, st, Ti)
        P_, V_, A_, J_ = self.end  # scaled by Ti^r: rows in normalised units
        drag = cfg.limits.rotor_drag
        F_ = A_ + (drag * Ti) * V_ if drag else A_  # a + d v: the thrust direction minus g e3
        s1, s2, s3 = _tangents(pad)
        v_pad = pad.velocity
        R: list[Array] = list(P_)
        b: list[float] = list(contact_point(pad, self.body_offset))  # (43)
        if cfg.alpha_range is None:
            R.extend(F_)
            b.extend((cfg.contact_alpha(pad.incline) * s3 - np.array([0.0, 0.0, cfg.g])) * Ti**2)
        else:  # (12) with alpha free: no s1, s2 component of the thrust a + d v + g e3
            R.extend([s1 @ F_, s2 @ F_])
            b.extend([-cfg.g * s1[2] * Ti**2, -cfg.g * s2[2] * Ti**2])
        R.append(s3 @ V_)
        b.append((float(s3 @ v_pad) - self.normal_speed) * Ti)
        S_t = np.stack([s1, s2])
        if self.slip_max == 0.0:
            R.extend(S_t @ V_)
            b.extend(S_t @ v_pad * Ti)
        if self.zero_jerk:
            R.extend(J_)
            b.extend([0.0, 0.0, 0.0])
        R.append(self.end_yaw)
        if self.yaw is TerminalYaw.HEADING:
            target_yaw = pad.heading + 2.0 * math.pi * round((st.yaw - pad.heading) / (2.0 * math.pi))
        else:
            target_yaw = terminal_yaw(pad, st.yaw)
        b.append(target_yaw)
        A_t, b_t = np.array(R), np.array(b)
        eq = (ConstraintBlock("initial state", A0, b0, b0), self.continuity,
              ConstraintBlock("terminal (moving pad, Gao et al. (43)-(51))", A_t, b_t, b_t))
        ineq: tuple[ConstraintBlock, ...] = ()
        knots_rel = np.concatenate([[0.0], np.cumsum(T)])
        G, lo, hi = pre_impact_rows(self.layout, knots_rel, pad, cfg)
        if G.shape[0]:
            ineq += (ConstraintBlock("pre-impact band (14)", G, lo, hi),)
        if cfg.alpha_range is not None:
            a_lo, a_hi = cfg.alpha_range
            gs3 = cfg.g * s3[2]
            ineq += (ConstraintBlock("contact thrust range (12)", (s3 @ F_)[None, :] / Ti**2,
                                     np.array([a_lo - gs3]), np.array([a_hi - gs3])),)
        ineq += self._workspace_blocks(pad, knots_rel)
        P = self.P
        M: Array | None = None  # slip cost P = P0 + M^T M
        if self.slip_max > 0.0:
            slip = S_t @ V_ / Ti  # physical m/s
            d = S_t @ v_pad
            ineq += (ConstraintBlock("tangential slip (Gao et al. (46))", slip, d - self.slip_max, d + self.slip_max),)
            if self.slip_weight > 0.0:
                A_all = np.vstack([blk.matrix for blk in eq])
                b_all = np.concatenate([blk.lower for blk in eq])
                ell = A_all.T @ b_all / float(b_all @ b_all)  # ell . c = 1 wherever A c = b
                weight = self.slip_weight * total ** (2 * cfg.position_cost_order - 1) / self.peak
                M = math.sqrt(weight) * (slip - np.outer(d, ell))
                P = P + M.T @ M
        qp = PerchingQp(layout=self.layout, durations=T, t0=st.time, P=P, equalities=eq, inequalities=ineq)
        qp.__dict__["elimination"] = self._eliminate(b0, A_t, b_t, M)  # as _same_equalities does
        return qp

    def _workspace_blocks(self, pad: MovingTarget, knots_rel: Array) -> tuple[ConstraintBlock, ...]:
        """Rows of the static limits of ``config.workspace`` (ground, half-spaces, spheres) on
        its samples, as for a static pad (:func:`avp.safety.workspace_blocks`). The perch plane
        moves: it gets no rows here and is certified on the plan
        (:func:`avp.moving_clearance.certify_moving_clearance`); rows for it, measured on the
        moving grid, changed no outcome and cost 0.7 ms per plan."""
        static_cfg = self.static_config
        if not static_cfg.workspace.active:
            return ()
        if static_cfg.workspace.spheres:  # linearised on the line to the contact point: per pad
            return workspace_blocks(self.layout, knots_rel, self.state, pad.static(), static_cfg)
        if self._plane_rows is None:  # half-spaces on the sample grid: the same normalised rows for every T
            self._plane_rows = workspace_blocks(self.layout, knots_rel, self.state, pad.static(), static_cfg)
        return self._plane_rows

    def _eliminate(self, b0: Array, A_t: Array, b_t: Array, M: Array | None) -> tuple[Array, Array, Array, Array]:
        """:attr:`PerchingQp.elimination` (same contract: ``c = c_p + Z z`` spans the solutions of
        every equality, and the cost in ``z`` scaled to a unit largest Hessian diagonal) in two
        stages: the precomputed null space ``Z0`` of the T-invariant rows, then the terminal rows
        inside it (:func:`~avp.qp.assemble.eliminate_within`: a QR of a matrix of about 13 x 42
        instead of 64 x 96; not cached, the pad moves). ``P = P0 + M^T M``."""
        return eliminate_within(self.Z0, self.L0 @ b0, self.G0, self.P, A_t, b_t, M, cache=False)


def moving_perching_qp(
    state: State,
    pad: MovingTarget,
    config: PlannerConfig,
    durations: Array,
    *,
    normal_speed: float,
    slip_max: float,
    slip_weight: float,
    zero_jerk: bool,
    yaw: TerminalYaw,
    body_offset: float,
) -> PerchingQp:
    """The perching QP toward ``pad`` (already predicted at ``t_f = state.time + sum(durations)``)
    with equal segments (``durations`` must be equal; the arrival-time search only scales them).

    ``config`` supplies the cost, continuity, pre-impact band (14) and the contact thrust
    (``alpha`` or ``alpha_range``); its ``contact_velocity`` and FoV settings are not used.
    """
    T = np.asarray(durations, dtype=float)
    if T.shape != (config.n_segments,) or np.ptp(T) > 1e-12 * float(T.max()):
        raise ConfigError("durations", f"expected {config.n_segments} equal segment durations, got {T.tolist()}")
    builder = MovingQpBuilder(state, config, normal_speed, slip_max, slip_weight, zero_jerk, yaw, body_offset)
    return builder.build(pad, float(T.sum()))
