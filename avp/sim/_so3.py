"""Small SO(3) helpers shared by the simulator modules (hat/vee, exponential map, projection)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

from ..errors import ConfigError

Array = npt.NDArray[np.float64]

ROTATION_TOL = 1e-6
"""Tolerance on ``max|R^T R - I|`` and ``|det R - 1|`` for rotation inputs."""


def hat(w: Array) -> Array:
    """Skew matrix with ``hat(w) @ b == cross(w, b)``."""
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def cross(a: Array, b: Array) -> Array:
    """``a x b`` for two 3-vectors (much faster than ``np.cross`` on single vectors)."""
    return np.array(
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    )


def vee(S: Array) -> Array:
    """Inverse of :func:`hat` for a skew-symmetric ``S``."""
    return np.array([S[2, 1], S[0, 2], S[1, 0]])


def expm_so3(phi: Array) -> Array:
    """Rodrigues' formula: ``exp(hat(phi))`` for a rotation vector ``phi`` (rad)."""
    theta = math.sqrt(float(phi @ phi))
    K = hat(phi)
    if theta < 1e-8:
        return np.eye(3) + K + 0.5 * K @ K
    return np.eye(3) + (math.sin(theta) / theta) * K + ((1.0 - math.cos(theta)) / theta**2) * K @ K


def project_so3(M: Array) -> Array:
    """Nearest rotation to ``M`` in the Frobenius norm (polar factor via SVD, det forced to +1)."""
    U, _, Vt = np.linalg.svd(M)
    D = np.diag([1.0, 1.0, float(np.sign(np.linalg.det(U @ Vt))) or 1.0])
    return U @ D @ Vt


def as_vector(field: str, value: Any, size: int = 3) -> Array:
    """``value`` as a finite float vector of length ``size`` (a scalar is broadcast)."""
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ConfigError(field, f"expected {size} numbers, got {value!r}") from exc
    if arr.ndim == 0:
        arr = np.full(size, float(arr))
    if arr.shape != (size,):
        raise ConfigError(field, f"expected shape ({size},), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ConfigError(field, "contains NaN or inf; pass finite values")
    return arr


def as_rotation(field: str, value: Any) -> Array:
    """``value`` as a 3x3 rotation matrix (checked orthonormal with det +1)."""
    try:
        R = np.array(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ConfigError(field, f"expected a 3x3 rotation, got {value!r}") from exc
    if R.shape != (3, 3) or not np.all(np.isfinite(R)):
        raise ConfigError(field, f"expected a finite 3x3 rotation, got shape {R.shape}")
    err = max(float(np.max(np.abs(R.T @ R - np.eye(3)))), abs(float(np.linalg.det(R)) - 1.0))
    if err > ROTATION_TOL:
        raise ConfigError(field, "is not a rotation (R^T R != I or det != +1); orthonormalise it")
    return R
