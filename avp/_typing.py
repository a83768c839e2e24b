"""Type aliases shared by the package (one home)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]
"""A float64 NumPy array (SI units; shapes in each function's docstring)."""
