"""Linear rows that evaluate a derivative of the flat outputs at given times.

A row ``r`` with ``r @ c_hat = d^order p_axis / dt^order (t)`` (times relative to the plan start).
Every constraint family (boundary, perching, field of view) is built from these.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .._typing import Array
from .layout import DecisionLayout


def point_rows(
    layout: DecisionLayout,
    knots_rel: Array,
    order: int,
    times: Array | float,
    axes: Sequence[int] = (0, 1, 2),
) -> Array:
    """Rows of shape ``(len(times), len(axes), n_variables)`` for derivative ``order``."""
    t = np.atleast_1d(np.asarray(times, dtype=float))
    seg, u = layout.locate(knots_rel, t)
    T = knots_rel[seg + 1] - knots_rel[seg]
    local = layout.basis(order, u) / (T**order)[:, None]  # (m, C)
    ax = np.asarray(axes)
    rows = np.zeros((t.size, ax.size, layout.n_variables))
    cols = layout.columns(ax[None, :], seg[:, None])  # (m, A, C)
    m_idx = np.arange(t.size)[:, None, None]
    a_idx = np.arange(ax.size)[None, :, None]
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
