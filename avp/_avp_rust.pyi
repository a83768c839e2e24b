"""Stubs for the compiled kernels (avp_rust). Coefficients are in ascending powers."""

import numpy as np
import numpy.typing as npt

__version__: str

def eval_spline(
    coeffs: npt.NDArray[np.float64],
    knots: npt.NDArray[np.float64],
    times: npt.NDArray[np.float64],
    orders: list[int],
) -> npt.NDArray[np.float64]:
    """Spline derivatives, shape ``(len(orders), len(times), axes)``.

    ``coeffs`` has shape ``(segments, axes, coeffs)`` in powers of ``t - knots[i]``; times outside
    ``[knots[0], knots[-1]]`` extrapolate the first/last segment. Raises ``ValueError`` on bad
    shapes, non-finite values or non-increasing knots.
    """
