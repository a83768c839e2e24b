"""Pure-NumPy references used only as test oracles for the Rust kernels (never at run time)."""

from __future__ import annotations

import numpy as np
from numpy.polynomial import polynomial as P


def eval_spline_reference(coeffs: np.ndarray, knots: np.ndarray, times: np.ndarray, order: int) -> np.ndarray:
    """``order``-th derivative of every axis, shape ``(len(times), axes)``, with numpy.polynomial
    (ascending powers; ``np.polyval`` would be descending and is never used)."""
    S = coeffs.shape[0]
    out = np.empty((times.size, coeffs.shape[1]))
    for i, t in enumerate(times):
        seg = min(max(int(np.searchsorted(knots, t, side="right")) - 1, 0), S - 1)
        tau = t - knots[seg]
        for a in range(coeffs.shape[1]):
            c = P.polyder(coeffs[seg, a], order) if order else coeffs[seg, a]
            out[i, a] = P.polyval(tau, c)
    return out
