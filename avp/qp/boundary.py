"""Initial-state and knot-continuity equalities of the QP (5)."""

from __future__ import annotations

import numpy as np

from .._typing import Array
from ..types import State
from .layout import N_AXES, YAW, DecisionLayout


def initial_state_rows(
    layout: DecisionLayout, durations: Array, state: State, t_scale: float
) -> tuple[Array, Array]:
    """Position, velocity, acceleration, jerk of x, y, z, then yaw and yaw rate, at ``t0``.

    Row of order ``r`` is multiplied by ``t_scale^r`` (conditioning only).
    """
    B0, _ = layout.endpoint_basis
    n = layout.n_coeffs
    T0 = float(durations[0])
    orders = [r for r in range(4) for _ in range(3)] + [0, 1]
    axes = [a for _ in range(4) for a in range(3)] + [YAW, YAW]
    rows = np.zeros((len(orders), layout.n_variables))
    derivs = state.derivatives()
    rhs = np.empty(len(orders))
    for i, (r, a) in enumerate(zip(orders, axes, strict=True)):
        s = layout.start(a, 0)
        w = (t_scale / T0) ** r
        rows[i, s : s + n] = B0[r] * w
        value = derivs[r, a] if a != YAW else (state.yaw if r == 0 else state.yaw_rate)
        rhs[i] = value * t_scale**r
    return rows, rhs


def continuity_rows(layout: DecisionLayout, durations: Array, max_order: int, t_scale: float) -> Array:
    """``p_i^(r)(t_{i+1}) = p_{i+1}^(r)(t_{i+1})`` for ``r <= max_order`` at every interior knot, all axes."""
    S, n = layout.n_segments, layout.n_coeffs
    if S == 1:
        return np.zeros((0, layout.n_variables))
    T = np.asarray(durations, dtype=float)
    B0, B1 = layout.endpoint_basis
    R = max_order + 1
    rows = np.zeros(((S - 1) * N_AXES * R, layout.n_variables))
    r = np.arange(R)
    i = 0
    for knot in range(S - 1):
        left = B1[:R] * ((t_scale / T[knot]) ** r)[:, None]
        right = -B0[:R] * ((t_scale / T[knot + 1]) ** r)[:, None]
        for axis in range(N_AXES):
            a, b = layout.start(axis, knot), layout.start(axis, knot + 1)
            rows[i : i + R, a : a + n] = left
            rows[i : i + R, b : b + n] = right
            i += R
    return rows
