"""Closed-form cost (4): ``sum_i int_0^{T_i} |d^j p_i / dt^j|^2 dt`` per flat output.

In normalised time ``u = t/T_i`` the integral is ``T_i^(1 - 2j) c_hat^T G_j c_hat`` with the Gram
matrix ``G_j[k, l] = k!/(k-j)! l!/(l-j)! / (k + l - 2j + 1)``; no quadrature.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from .._typing import Array
from .layout import N_AXES, YAW, DecisionLayout, layout_for


@lru_cache(maxsize=64)
def gram(degree: int, order: int) -> Array:
    """``int_0^1 (d^j/du^j u^k)(d^j/du^j u^l) du`` for ``k, l <= degree`` (read-only)."""
    n = degree + 1
    G = np.zeros((n, n))
    for k in range(order, n):
        for m in range(order, n):
            fk = np.prod(np.arange(k - order + 1, k + 1, dtype=float))
            fm = np.prod(np.arange(m - order + 1, m + 1, dtype=float))
            G[k, m] = fk * fm / (k + m - 2 * order + 1)
    G.setflags(write=False)
    return G


def cost_matrix(layout: DecisionLayout, durations: Array, position_order: int, yaw_order: int) -> Array:
    """Block-diagonal Hessian ``P`` with ``c_hat^T P c_hat`` proportional to the cost (4).

    Each axis block is scaled by ``T_total^(2j - 1)`` and the whole matrix to a unit largest
    diagonal entry, so entries stay O(1) whatever the durations; the minimiser is unchanged (the
    axes are separate sums). It depends on ``total / T_i`` only: cached per (layout, durations
    over the longest, orders), read-only.
    """
    T = np.ascontiguousarray(durations, dtype=float)
    ratios = T / T.max()  # scale-free (the matrix depends on total / T_i only): exactly 1 for equal T
    return _cost_matrix(layout.n_segments, layout.degree, ratios.tobytes(), position_order, yaw_order)


@lru_cache(maxsize=256)
def _cost_matrix(n_segments: int, degree: int, durations: bytes, position_order: int, yaw_order: int) -> Array:
    layout = layout_for(n_segments, degree)
    S, n = layout.n_segments, layout.n_coeffs
    T = np.frombuffer(durations, dtype=float)
    total = float(T.sum())
    P = np.zeros((layout.n_variables, layout.n_variables))
    for axis in range(N_AXES):
        j = yaw_order if axis == YAW else position_order
        G = gram(layout.degree, j)
        w = (total / T) ** (2 * j - 1)
        for seg in range(S):
            s = layout.start(axis, seg)
            P[s : s + n, s : s + n] = w[seg] * G
    P /= float(np.max(np.diag(P)))
    P.setflags(write=False)
    return P
