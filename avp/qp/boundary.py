"""Initial-state and knot-continuity equalities of the QP (5)."""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from .._typing import Array
from ..types import State
from .layout import N_AXES, YAW, DecisionLayout, layout_for


def initial_state_rows(
    layout: DecisionLayout, durations: Array, state: State, t_scale: float
) -> tuple[Array, Array]:
    """Position, velocity, acceleration, jerk of x, y, z, then yaw and yaw rate, at ``t0``.

    Row of order ``r`` is multiplied by ``t_scale^r`` (conditioning only). The matrix depends on
    ``T_0 / t_scale`` alone (unchanged by a uniform time scale): cached per that ratio (exact
    float key; read-only).
    """
    rows = _initial_matrix(layout.n_segments, layout.degree, float(durations[0]) / t_scale)
    values = np.concatenate((state.position, state.velocity, state.acceleration, state.jerk,
                             (state.yaw, state.yaw_rate)))
    return rows, values * t_scale ** _INITIAL_ORDERS


_INITIAL_ORDERS = np.array([r for r in range(4) for _ in range(3)] + [0, 1], dtype=float)
_INITIAL_AXES = [a for _ in range(4) for a in range(3)] + [YAW, YAW]


@lru_cache(maxsize=256)
def _initial_matrix(n_segments: int, degree: int, T0_over_scale: float) -> Array:
    layout = layout_for(n_segments, degree)
    B0, _ = layout.endpoint_basis
    n = layout.n_coeffs
    rows = np.zeros((_INITIAL_ORDERS.size, layout.n_variables))
    for i, (r, a) in enumerate(zip(_INITIAL_ORDERS.astype(int), _INITIAL_AXES, strict=True)):
        s = layout.start(a, 0)
        rows[i, s : s + n] = B0[r] * (1.0 / T0_over_scale) ** r
    rows.setflags(write=False)
    return rows


def continuity_rows(layout: DecisionLayout, durations: Array, max_order: int, t_scale: float) -> Array:
    """``p_i^(r)(t_{i+1}) = p_{i+1}^(r)(t_{i+1})`` for ``r <= max_order`` at every interior knot, all axes.

    Depends on ``durations / t_scale`` alone (unchanged by a uniform time scale): cached per
    those ratios (exact float keys; read-only)."""
    if layout.n_segments == 1:
        return np.zeros((0, layout.n_variables))
    ratios = tuple(float(T) / t_scale for T in np.asarray(durations, dtype=float))
    return _continuity_matrix(layout.n_segments, layout.degree, max_order, ratios)


@lru_cache(maxsize=256)
def _continuity_matrix(n_segments: int, degree: int, max_order: int, ratios: tuple[float, ...]) -> Array:
    layout = layout_for(n_segments, degree)
    S, n = layout.n_segments, layout.n_coeffs
    T = np.asarray(ratios)  # durations in units of t_scale
    B0, B1 = layout.endpoint_basis
    R = max_order + 1
    rows = np.zeros(((S - 1) * N_AXES * R, layout.n_variables))
    r = np.arange(R)
    i = 0
    for knot in range(S - 1):
        left = B1[:R] * ((1.0 / T[knot]) ** r)[:, None]
        right = -B0[:R] * ((1.0 / T[knot + 1]) ** r)[:, None]
        for axis in range(N_AXES):
            a, b = layout.start(axis, knot), layout.start(axis, knot + 1)
            rows[i : i + R, a : a + n] = left
            rows[i : i + R, b : b + n] = right
            i += R
    rows.setflags(write=False)
    return rows
