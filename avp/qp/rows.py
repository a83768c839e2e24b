"""Linear rows that evaluate a derivative of the flat outputs at given times.

A row ``r`` with ``r @ c_hat = d^order p_axis / dt^order (t)`` (times relative to the plan start).
Every constraint family (boundary, perching, field of view) is built from these.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .._typing import Array
from .layout import DecisionLayout

_LOOP_ROWS = 24
"""Up to this many rows are filled by slices, more by one fancy-index assignment."""


def point_rows(
    layout: DecisionLayout,
    knots_rel: Array,
    order: int,
    times: Array | float,
    axes: Sequence[int] = (0, 1, 2),
    plus: tuple[int, float] | None = None,
) -> Array:
    """Rows of shape ``(len(times), len(axes), n_variables)`` for derivative ``order``.

    ``plus = (order2, w)``: rows of ``d^order p + w d^order2 p`` in one pass (the same values
    as adding ``w`` times the ``order2`` rows, without building them)."""
    t = np.atleast_1d(np.asarray(times, dtype=float))
    if t.size == 1 and float(t[0]) == float(knots_rel[-1]):  # the end of the plan: u = 1
        seg = np.array([layout.n_segments - 1])
        T_end = float(knots_rel[-1] - knots_rel[-2])
        B1 = layout.endpoint_basis[1]
        local = (B1[order] / T_end**order)[None, :]
        if plus is not None:
            local = local + plus[1] * (B1[plus[0]] / T_end ** plus[0])[None, :]
    else:
        seg, u = layout.locate(knots_rel, t)
        T = knots_rel[seg + 1] - knots_rel[seg]
        local = layout.basis(order, u) / (T**order)[:, None]  # (m, C)
        if plus is not None:
            local = local + plus[1] * (layout.basis(plus[0], u) / (T ** plus[0])[:, None])
    ax = tuple(int(a) for a in axes)
    m, n_c, n_s = t.size, layout.n_coeffs, layout.n_segments
    rows = np.zeros((m, len(ax), layout.n_variables))
    if m * len(ax) <= _LOOP_ROWS:  # a few rows: slices beat the fancy-index machinery
        for i, s in enumerate(seg.tolist()):
            for j, a in enumerate(ax):
                start = (a * n_s + s) * n_c
                rows[i, j, start:start + n_c] = local[i]
        return rows
    if (seg == seg[0]).all():  # one segment (e.g. the band (14)): a slice per axis
        for j, a in enumerate(ax):
            start = (a * n_s + int(seg[0])) * n_c
            rows[:, j, start:start + n_c] = local
        return rows
    cols = layout.columns(np.asarray(ax)[None, :], seg[:, None])  # (m, A, C)
    m_idx = np.arange(m)[:, None, None]
    a_idx = np.arange(len(ax))[None, :, None]
    rows[m_idx, a_idx, cols] = local[:, None, :]
    return rows


def derivative_rows(
    layout: DecisionLayout, knots_rel: Array, axis: int, order: int, times: Array | float
) -> Array:
    """Rows of shape ``(len(times), n_variables)`` for one axis."""
    return point_rows(layout, knots_rel, order, times, (axis,))[:, 0, :]


def vector_rows(layout: DecisionLayout, knots_rel: Array, order: int, times: Array | float) -> Array:
    """Rows for the position vector's derivative: shape ``(len(times), 3, n_variables)``."""
    return point_rows(layout, knots_rel, order, times)

