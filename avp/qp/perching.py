"""Perching constraints: terminal position, acceleration (12), contact velocity in S, terminal
yaw (13), and the pre-impact band (14) in the paper's componentwise form or as a tilt cone."""

from __future__ import annotations

import math
from functools import lru_cache
from typing import Any

import numpy as np

from .._typing import Array
from ..config import PlannerConfig, PreImpactMode
from ..types import PerchTarget
from .layout import YAW, DecisionLayout, layout_for
from .rows import point_rows, vector_rows

E3 = np.array([0.0, 0.0, 1.0])


def terminal_acceleration(target: PerchTarget, alpha: float, g: float) -> Array:
    """``c0 = alpha s3 - g e3``, eq. (12): the acceleration that makes ``b3 = s3`` at contact."""
    return alpha * target.s3 - g * E3


def terminal_yaw(target: PerchTarget, near: float) -> float:
    """Yaw (13) whose attitude with ``b3 = s3`` is exactly ``R_WS`` (:func:`avp.frames.contact_yaw`),
    unwrapped to within pi of ``near``. For a contact attitude the construction cannot represent,
    the yaw of the closest one with ``b3 = s3``."""
    psi = target._contact_yaw
    return psi + 2.0 * math.pi * round((near - psi) / (2.0 * math.pi))


TerminalRows = tuple[Array, Array, list[str]]
"""Rows, right-hand side and a name per row."""


def terminal_rows(
    layout: DecisionLayout,
    knots_rel: Array,
    target: PerchTarget,
    config: PlannerConfig,
    yaw_start: float,
    t_scale: float,
    T_last: float | None = None,
) -> TerminalRows:
    """Equalities at ``t_f`` (:func:`terminal_parts`) as one block: the fixed rows, then the
    pad's."""
    (A1, b1, n1), (A2, b2, n2) = terminal_parts(layout, knots_rel, target, config, yaw_start, t_scale, T_last)
    if not n2:
        return A1, b1, n1
    return np.concatenate([A1, A2]), np.concatenate([b1, b2]), n1 + n2


def terminal_parts(
    layout: DecisionLayout,
    knots_rel: Array,
    target: PerchTarget,
    config: PlannerConfig,
    yaw_start: float,
    t_scale: float,
    T_last: float | None = None,
) -> tuple[TerminalRows, TerminalRows]:
    """Equalities at ``t_f``: position, acceleration (12), requested velocity components in S,
    yaw (13), in two parts.

    The **fixed** rows (position, yaw, the acceleration (12) when ``alpha_range`` is not set,
    the whole contact velocity as world rows ``v(t_f) = R_WS v_S`` when every component is
    given) form a read-only matrix that depends on ``T_last / t_scale`` alone (cached): every pad
    and every time left of the replans share it, and with it the equality elimination of the
    QP's fixed rows (:mod:`avp.qp.assemble`). The **pad's** rows are the others: (12) with
    ``alpha_range`` (no ``s1``, ``s2`` component of the thrust), the given components ``s_i . v``
    of a partly free contact velocity, and (12) on ``a + d v`` with a rotor drag ``d`` and such
    a velocity (its row depends on ``t_scale``); empty with the default settings.

    With a rotor drag ``d`` (12) is on ``a + d v``; when the whole contact velocity is given and
    ``alpha_range`` is not, it is written ``a = c0 - d v_W`` (the same condition, fixed rows).
    ``T_last``: the last segment's duration (default from the knots; pass the duration itself to
    keep its exact bits).
    """
    # position, t_scale * velocity, t_scale^2 * acceleration and yaw rows at t_f: they depend on
    # T_last / t_scale alone (cached)
    if T_last is None:
        T_last = float(knots_rel[-1] - knots_rel[-2])
    ratio = float(T_last) / t_scale
    _, V, A, _ = _end_rows(layout.n_segments, layout.degree, ratio)
    drag = config.limits.rotor_drag
    v_S = config.contact_velocity.components(target.incline)
    v_W = target._velocity_W(v_S) if all(value is not None for value in v_S) else None  # type: ignore[arg-type]
    fixed_accel = config.alpha_range is None and (not drag or v_W is not None)
    rhs: list[float] = []
    names: list[str] = []
    pad_rows: list[Array] = []
    pad_rhs: list[float] = []
    pad_names: list[str] = []
    p_contact = target.point + config.workspace.body_offset * target.s3  # centre of mass at contact
    rhs.extend(float(x) for x in p_contact)
    names.extend(f"terminal position {'xyz'[axis]}" for axis in range(3))
    if config.alpha_range is None:
        c0 = terminal_acceleration(target, config.contact_alpha(target.incline), config.g)
        if fixed_accel:
            # The thrust direction is a + g e3 + d v (VehicleLimits.rotor_drag). With the whole
            # contact velocity given, v(t_f) = v_W is an equality of its own, so (12) is
            # a(t_f) = c0 - d v_W: the same condition with rows free of d and of t_scale.
            if drag:
                assert v_W is not None
                c0 = c0 - drag * v_W
            rhs.extend(float(c) * t_scale**2 for c in c0)
            names.extend(f"terminal acceleration (12) {'xyz'[axis]}" for axis in range(3))
        else:  # drag, and a partly free velocity: rows on a + (d t_scale) v
            pad_rows.extend(A + (drag * t_scale) * V)
            pad_rhs.extend(float(c) * t_scale**2 for c in c0)
            pad_names.extend(f"terminal acceleration (12) {'xyz'[axis]}" for axis in range(3))
    else:  # (12) with alpha free: a(tf) + d v(tf) + g e3 has no component along s1, s2
        F = A + (drag * t_scale) * V if drag else A
        for label, direction in (("s1", target.s1), ("s2", target.s2)):
            pad_rows.append(direction @ F)
            pad_rhs.append(-config.g * direction[2] * t_scale**2)
            pad_names.append(f"terminal thrust along s3 (12): no {label} component")
    if v_W is not None:
        # the whole velocity is given: the same condition as world rows, v(t_f) = R_WS v_S, whose
        # matrix does not depend on the pad's frame
        rhs.extend(float(v) * t_scale for v in v_W)
        names.extend(f"contact velocity {'xyz'[axis]} (R_WS v_S)" for axis in range(3))
    else:
        for label, direction, value in zip(("s1", "s2", "s3"), target.R_WS.T, v_S, strict=True):
            if value is None:
                continue
            pad_rows.append(direction @ V)
            pad_rhs.append(value * t_scale)
            pad_names.append(f"contact velocity v.{label}")
    rhs.append(terminal_yaw(target, yaw_start))
    names.append("terminal yaw (13)")
    fixed = _terminal_matrix(layout.n_segments, layout.degree, ratio, fixed_accel, v_W is not None)
    n = layout.n_variables
    pad = np.array(pad_rows) if pad_rows else np.zeros((0, n))
    return (fixed, np.array(rhs), names), (pad, np.array(pad_rhs), pad_names)


@lru_cache(maxsize=256)
def _terminal_matrix(n_segments: int, degree: int, T_last_over_scale: float, acceleration: bool,
                     world_velocity: bool) -> Array:
    """:func:`terminal_parts`' fixed rows: position, acceleration (when ``acceleration``),
    velocity as world rows (when ``world_velocity``), yaw; read-only. Shared by every QP with
    these durations and settings, so the equality elimination finds it by identity
    (``qp.assemble``)."""
    P, V, A, Y = _end_rows(n_segments, degree, T_last_over_scale)
    matrix = np.array([*P, *(A if acceleration else ()), *(V if world_velocity else ()), Y])
    matrix.setflags(write=False)
    return matrix


@lru_cache(maxsize=256)
def _end_rows(n_segments: int, degree: int, T_last_over_scale: float) -> tuple[Array, Array, Array, Array]:
    """Rows at the end of the plan in units of ``t_scale``: position (3, n), velocity x
    ``t_scale`` (3, n), acceleration x ``t_scale^2`` (3, n) and yaw (n,), read-only."""
    layout = layout_for(n_segments, degree)
    _, B1 = layout.endpoint_basis
    n_c = layout.n_coeffs
    out = np.zeros((3, 3, layout.n_variables))
    for order in range(3):
        local = B1[order] / T_last_over_scale**order
        for axis in range(3):
            start = layout.start(axis, n_segments - 1)
            out[order, axis, start:start + n_c] = local
    Y = np.zeros(layout.n_variables)
    start = layout.start(YAW, n_segments - 1)
    Y[start:start + n_c] = B1[0]
    for arr in (out, Y):
        arr.setflags(write=False)
    return out[0], out[1], out[2], Y


def terminal_thrust_rows(
    layout: DecisionLayout, knots_rel: Array, target: PerchTarget, config: PlannerConfig
) -> tuple[Array, Array, Array]:
    """With ``alpha_range = (lo, hi)``: ``lo <= s3 . (a(t_f) + d v(t_f) + g e3) <= hi`` (empty
    otherwise; ``d`` the rotor drag, :func:`thrust_rows`)."""
    if config.alpha_range is None:
        n = layout.n_variables
        return np.zeros((0, n)), np.zeros(0), np.zeros(0)
    A = thrust_rows(layout, knots_rel, float(knots_rel[-1]), config)[0]
    lo, hi = config.alpha_range
    gs3 = config.g * target.s3[2]
    return (target.s3 @ A)[None, :], np.array([lo - gs3]), np.array([hi - gs3])


def thrust_rows(layout: DecisionLayout, knots_rel: Array, times: Any, config: PlannerConfig) -> Array:
    """Rows of ``a + d v`` at ``times`` (``(m, 3, n)``): the thrust direction minus ``g e3`` with
    the rotor drag ``d = config.limits.rotor_drag`` (``b3 || a + g e3 + d v``,
    :class:`~avp.config.VehicleLimits`); the acceleration rows when ``d = 0``."""
    return _thrust_rows(layout, knots_rel, times, config.limits.rotor_drag)


def _thrust_rows(layout: DecisionLayout, knots_rel: Array, times: Any, drag: float) -> Array:
    # a + d v in one pass (point_rows' plus): the same values as adding the velocity rows
    return point_rows(layout, knots_rel, 2, times, plus=(1, drag)) if drag else vector_rows(layout, knots_rel, 2, times)


def is_overhang(target: PerchTarget, config: PlannerConfig) -> bool:
    """The pad is an overhang for :class:`~avp.config.OverhangFlip` (incline above its minimum)."""
    return config.flip.enabled and target.incline > config.flip.min_incline


def flip_time(target: PerchTarget, config: PlannerConfig, tf: float) -> float | None:
    """Time (relative, s) of the overhang's horizontal-thrust waypoint, or ``None`` when the
    pad is not an overhang for ``config.flip`` or the plan is too short to hold it."""
    if not is_overhang(target, config):
        return None
    t_w = tf - config.t_k - (target.incline - 0.5 * math.pi) / config.flip.rate(config.limits)
    return t_w if t_w > 0.05 * tf else None


def flip_rows(
    layout: DecisionLayout, knots_rel: Array, target: PerchTarget, config: PlannerConfig
) -> tuple[Array, Array, Array]:
    """Overhang (:class:`~avp.config.OverhangFlip`): at ``t_w`` the thrust ``a + g e3`` is
    horizontal, along the horizontal part ``u`` of ``s1`` and at least ``flip.thrust``:
    ``a_z = -g``, ``a . (e3 x u) = 0``, ``a . u >= thrust`` (rows ``lower <= G c_hat <= upper``)."""
    n = layout.n_variables
    t_w = flip_time(target, config, float(knots_rel[-1]))
    if t_w is None:
        return np.zeros((0, n)), np.zeros(0), np.zeros(0)
    s1h = np.array([target.s1[0], target.s1[1], 0.0])
    u = s1h / np.linalg.norm(s1h)  # nonzero: s1 is vertical only when s3 is horizontal
    side = np.cross(E3, u)
    A = thrust_rows(layout, knots_rel, t_w, config)[0]
    G = np.vstack([A[2], side @ A, u @ A])
    thrust = config.flip.horizontal_thrust(config.limits)
    return G, np.array([-config.g, 0.0, thrust]), np.array([-config.g, 0.0, np.inf])


def band_times(config: PlannerConfig, tf: float) -> Array:
    """Sample times ``t_f - t_k + j dt``, ``0 <= j < round(t_k/dt)``, of (14), clipped to ``t >= 0``."""
    return _band_times(tf, config.t_k, config.dt, config.band_samples)


def _band_times(tf: float, t_k: float, dt: float, samples: int) -> Array:
    t = tf - t_k + dt * np.arange(samples)
    return np.asarray(t[t >= 0.0], dtype=np.float64)


@lru_cache(maxsize=16)
def _band_thrust_rows(n_segments: int, degree: int, knots_rel: bytes, t_k: float, dt: float, samples: int,
                      drag: float) -> Array:
    """Rows of ``a + d v`` at the band's sample times (:func:`band_times`), ``(m, 3, n)``,
    read-only. They depend on the knots and the band's timing, not on the pad: the fractions of
    one replan step (same start, same durations) and a plan's relaxations share them."""
    layout = layout_for(n_segments, degree)
    knots = np.frombuffer(knots_rel, dtype=float)
    times = _band_times(float(knots[-1]), t_k, dt, samples)
    A = _thrust_rows(layout, knots, times, drag) if times.size else np.zeros((0, 3, layout.n_variables))
    A.setflags(write=False)
    return A


def _tile(v: Array, times: int) -> Array:
    """``v`` repeated ``times`` times (``np.tile`` without its Python-level dispatch)."""
    out = np.empty((times, v.shape[0]))
    out[:] = v
    return out.reshape(-1)


def pre_impact_rows(
    layout: DecisionLayout,
    knots_rel: Array,
    target: PerchTarget,
    config: PlannerConfig,
) -> tuple[Array, Array, Array]:
    """Pre-impact band (14): rows ``G`` with ``lower <= G c_hat <= upper``.

    PAPER: per component, ``a_i(t)`` between ``c0_i`` and ``(1+q) c0_i`` (min/max, since a
    negative component flips the order), widened symmetrically to ``band_min_width``. With an
    ``alpha_range`` the box spans ``c0(lo)`` to ``(1+q) c0(hi)``.
    CONE: ``f = a + g e3`` has ``alpha <= f.s3 <= (1+q) alpha`` and lies in a polyhedral cone
    of half-angle ``cone_half_angle`` about ``s3`` (inner approximation with ``cone_facets``
    faces, so the true tilt never exceeds the angle).
    """
    n = layout.n_variables
    mode = config.pre_impact
    if mode is PreImpactMode.PAPER and config.flip.cone_band and is_overhang(target, config):
        mode = PreImpactMode.CONE  # OverhangFlip.cone_band: the box blocks overhangs
    if mode is PreImpactMode.OFF:
        return np.zeros((0, n)), np.zeros(0), np.zeros(0)
    A = _band_thrust_rows(layout.n_segments, layout.degree, np.asarray(knots_rel, dtype=float).tobytes(),
                          config.t_k, config.dt, config.band_samples, config.limits.rotor_drag)  # (m, 3, n)
    if A.shape[0] == 0:
        return np.zeros((0, n)), np.zeros(0), np.zeros(0)
    times = A.shape[0]  # the number of samples (the tiles below)
    alpha = config.contact_alpha(target.incline)
    alpha_lo, alpha_hi = config.alpha_range if config.alpha_range is not None else (alpha, alpha)
    if mode is PreImpactMode.PAPER:
        c_lo = terminal_acceleration(target, alpha_lo, config.g)
        c_hi = (1.0 + config.q) * terminal_acceleration(target, alpha_hi, config.g)
        lo = np.minimum(c_lo, c_hi)
        hi = np.maximum(c_lo, c_hi)
        pad = np.maximum(0.0, config.band_min_width - (hi - lo)) / 2.0
        lo, hi = lo - pad, hi + pad
        G = A.reshape(-1, n)
        return G, _tile(lo, times), _tile(hi, times)
    # CONE mode
    s1, s2, s3 = target.s1, target.s2, target.s3
    gz = config.g * E3
    kappa = math.tan(config.cone_half_angle) * math.cos(math.pi / config.cone_facets)
    dirs = [math.cos(th) * s1 + math.sin(th) * s2
            for th in 2 * math.pi * np.arange(config.cone_facets) / config.cone_facets]
    # per sample: the thrust row along s3, then one facet row per direction (the order of the
    # rows is sample-major, as the diagnostics read them)
    W = np.vstack([s3[None, :], np.asarray(dirs) - kappa * s3[None, :]])  # (1 + facets, 3)
    G = np.einsum("fi,kin->kfn", W, A).reshape(-1, n)
    lower_k = np.full(W.shape[0], -np.inf)
    lower_k[0] = alpha_lo - s3 @ gz
    upper_k = -(W @ gz)
    upper_k[0] = (1.0 + config.q) * alpha_hi - s3 @ gz
    return G, _tile(lower_k, times), _tile(upper_k, times)
