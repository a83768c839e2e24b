"""Frames and the differential-flatness map (10), (11), (13) and (22).

Everything here is vectorised over a leading time axis: inputs of shape ``(..., 3)`` (and
``(...,)`` for yaw) give outputs with the same leading shape. World frame W is z-up, gravity
``g`` along ``-e3``; body frame B has ``b3`` along the thrust; the attitude follows the paper's
construction (13): ``b2_des = [-sin psi, cos psi, 0]``, ``b1 = (b2_des x b3)/|.|``,
``b2 = b3 x b1``. No QP code lives here.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from ._typing import Array

__all__ = [
    "GRAVITY",
    "MAX_CONTACT_ROLL",
    "attitude",
    "body_rates",
    "contact_yaw",
    "cross",
    "drag_acceleration",
    "expm_so3",
    "hat",
    "project_so3",
    "rotation_error_angle",
    "thrust_magnitude",
    "thrust_vector",
    "vee",
    "yaw_from_b2",
]

GRAVITY = 9.81
"""Standard gravity used throughout (m/s^2), as in the paper."""

E3 = np.array([0.0, 0.0, 1.0])



def thrust_vector(acc: npt.ArrayLike, g: float = GRAVITY) -> Array:
    """Mass-normalised thrust vector ``f = a + g e3`` (m/s^2), from (1)."""
    a = np.asarray(acc, dtype=float)
    return a + g * E3


def drag_acceleration(acc: Array, vel: Array, rotor_drag: float) -> Array:
    """``a + d v``: the acceleration whose flatness map (11), (13) gives the attitude of a vehicle
    with mass-normalised rotor drag ``d`` (:class:`avp.VehicleLimits` ``rotor_drag``; after
    Faessler, Franchi and Scaramuzza, the thrust axis is ``b3 || a + g e3 + d v``). Shapes
    ``(..., 3)``."""
    return acc + rotor_drag * vel


def thrust_magnitude(acc: npt.ArrayLike, g: float = GRAVITY) -> Array:
    """Mass-normalised thrust ``|a + g e3|`` (m/s^2), eq. (10) divided by the mass."""
    return np.linalg.norm(thrust_vector(acc, g), axis=-1)


def _cross(u: Array, v: Array) -> Array:
    """``u x v`` over the last axis (np.cross costs ~30 us per call on single vectors)."""
    u0, u1, u2 = u[..., 0], u[..., 1], u[..., 2]
    v0, v1, v2 = v[..., 0], v[..., 1], v[..., 2]
    return np.stack([u1 * v2 - u2 * v1, u2 * v0 - u0 * v2, u0 * v1 - u1 * v0], axis=-1)


def _b2_des(yaw: Array) -> Array:
    return np.stack([-np.sin(yaw), np.cos(yaw), np.zeros_like(yaw)], axis=-1)


def attitude(acc: npt.ArrayLike, yaw: npt.ArrayLike, g: float = GRAVITY) -> Array:
    """Attitude ``R_WB`` (columns ``b1, b2, b3``) from acceleration and yaw, eqs. (11), (13).

    Shape ``(..., 3, 3)``. Singular where the thrust vanishes (free fall) or ``b3`` is parallel
    to ``b2_des`` (roll of +-90 deg); there the result holds NaN, which callers must check.
    """
    f = thrust_vector(acc, g)
    yaw_arr = np.asarray(yaw, dtype=float)
    b3 = f / np.linalg.norm(f, axis=-1, keepdims=True)
    v = _cross(_b2_des(yaw_arr), b3)
    b1 = v / np.linalg.norm(v, axis=-1, keepdims=True)
    b2 = _cross(b3, b1)
    return np.stack([b1, b2, b3], axis=-1)


def body_rates(
    acc: npt.ArrayLike,
    jerk: npt.ArrayLike,
    yaw: npt.ArrayLike,
    yaw_rate: npt.ArrayLike,
    g: float = GRAVITY,
) -> Array:
    """Body angular velocity ``Omega`` (rad/s, body frame) with ``hat(Omega) = R^T dR/dt``.

    ``w1 = -b2.j/|f|`` and ``w2 = b1.j/|f|`` are (22); ``w3 = b2 . d(b1)/dt`` is the exact
    yaw term of the construction (13) (the paper's (24) in Z-Y-X Euler angles).
    """
    a = np.asarray(acc, dtype=float)
    j = np.asarray(jerk, dtype=float)
    yaw_arr = np.asarray(yaw, dtype=float)
    yaw_rate_arr = np.asarray(yaw_rate, dtype=float)
    f = thrust_vector(a, g)
    fn = np.linalg.norm(f, axis=-1, keepdims=True)
    b3 = f / fn
    b3_dot = (j - np.sum(b3 * j, axis=-1, keepdims=True) * b3) / fn
    b2d = _b2_des(yaw_arr)
    b2d_dot = yaw_rate_arr[..., None] * np.stack(
        [-np.cos(yaw_arr), -np.sin(yaw_arr), np.zeros_like(yaw_arr)], axis=-1
    )
    v = _cross(b2d, b3)
    vn = np.linalg.norm(v, axis=-1, keepdims=True)
    b1 = v / vn
    b2 = _cross(b3, b1)
    v_dot = _cross(b2d_dot, b3) + _cross(b2d, b3_dot)
    w1 = -np.sum(b2 * j, axis=-1) / fn[..., 0]
    w2 = np.sum(b1 * j, axis=-1) / fn[..., 0]
    w3 = np.sum(b2 * v_dot, axis=-1) / vn[..., 0]
    return np.stack([w1, w2, w3], axis=-1)


def yaw_from_b2(b2: npt.ArrayLike) -> float:
    """Yaw ``psi`` whose ``b2_des = [-sin psi, cos psi, 0]`` points along ``b2``'s horizontal part.

    Used for the terminal yaw (13): ``b2_des`` parallel to ``s2`` makes ``R_WB(t_f) = R_WS``.
    """
    v = np.asarray(b2, dtype=float)
    return float(np.arctan2(-v[0], v[1]))


MAX_CONTACT_ROLL = math.asin(math.sqrt(0.9375))
"""Largest roll (rad, about 75.5 deg) of a contact attitude reached exactly: the top roll
level ``sin^2 phi < 15/16`` of the body-rate certificate (docs/bounds.md). The construction (13)
is singular at 90 deg; near it the yaw term of the body rate grows as ``1/cos phi``."""


def _exact_b2_des(R: Array) -> tuple[Array, float]:
    """``b2_des`` that makes the construction (13) reproduce ``R`` exactly, and the (unsigned)
    roll of that attitude (see :func:`contact_yaw`)."""
    s2, s3 = R[:, 1], R[:, 2]
    wn = float(np.hypot(s2[2], s3[2]))
    if wn < 1e-12:  # s1 vertical: any horizontal b2_des along s2 works, phi = 0
        return np.array([s2[0], s2[1], 0.0]), 0.0
    return math.copysign(1.0, s3[2]) * (s3[2] * s2 - s2[2] * s3) / wn, math.atan2(abs(s2[2]), abs(s3[2]))


def contact_yaw(R_WS: npt.ArrayLike) -> tuple[float, float]:
    """Yaw ``psi`` for which the construction (13) with ``b3 = s3`` gives exactly
    ``R_WB = R_WS`` when that is representable, and the roll ``phi`` (rad) of the attitude it gives.

    The construction is ``R_WB = Rz(psi) Ry(theta) Rx(phi)`` with ``cos phi > 0``; it gives
    ``b1 = s1`` iff ``b2_des`` is horizontal, orthogonal to ``s1`` and has ``b2_des . s2 > 0``:
    ``b2_des = sign(s3z) (s3z s2 - s2z s3) / sqrt(s2z^2 + s3z^2)``, with ``cos phi =
    |s3z| / sqrt(s2z^2 + s3z^2)``. When ``s1`` is vertical (``s2z = s3z = 0``, a wall in its
    natural frame) ``b2_des = s2`` and ``phi = 0``.

    A frame whose roll exceeds :data:`MAX_CONTACT_ROLL` (``s3z`` small against ``s2z``: a wall
    with a tilted or vertical ``s2``, e.g. an estimate of a wall's frame rotated by noise) is not
    represented exactly, and near 90 deg the exact yaw is singular. Then ``b2_des`` is the
    horizontal direction closest to ``s2`` (``e3 x s3`` if ``s2`` is vertical): the plan still
    ends with ``b3 = s3`` exactly, and the rotation about ``s3`` differs from ``R_WS`` by
    :func:`contact_frame_error`.
    """
    R = np.asarray(R_WS, dtype=float)
    s2, s3 = R[:, 1], R[:, 2]
    b2d, roll = _exact_b2_des(R)
    if roll > MAX_CONTACT_ROLL:  # not representable: the horizontal direction closest to s2
        h = np.array([s2[0], s2[1], 0.0])
        if float(np.linalg.norm(h)) < 1e-9:
            h = np.cross([0.0, 0.0, 1.0], s3)
        b2d = h / float(np.linalg.norm(h))
        return float(math.atan2(-b2d[0], b2d[1])), float(math.asin(max(-1.0, min(1.0, -float(b2d @ s3)))))
    return float(math.atan2(-b2d[0], b2d[1])), math.copysign(roll, -float(b2d @ s3)) if roll else 0.0


def contact_frame_error(R_WS: npt.ArrayLike, g: float = GRAVITY) -> float:
    """Angle (rad) of the rotation about ``s3`` between ``R_WS`` and the contact attitude the
    planner reaches with :func:`contact_yaw`: 0 when the roll is at most :data:`MAX_CONTACT_ROLL`
    (the construction reproduces ``R_WS`` exactly, nothing to compute on the planner's path)."""
    R = np.asarray(R_WS, dtype=float)
    if _exact_b2_des(R)[1] <= MAX_CONTACT_ROLL:
        return 0.0
    psi, _ = contact_yaw(R)
    a_f = 4.0 * R[:, 2] - g * np.array([0.0, 0.0, 1.0])  # any contact thrust along s3
    return float(rotation_error_angle(attitude(a_f, psi), R))


def rotation_error_angle(R_a: npt.ArrayLike, R_b: npt.ArrayLike) -> Array:
    """Geodesic angle (rad) between rotations: with ``M = R_a^T R_b``, ``atan2(|vee(M - M^T)| / 2,
    (tr(M) - 1) / 2)``, the sine and cosine of the angle. Accurate to rounding at every angle;
    ``arccos((tr - 1)/2)`` alone loses half the digits near 0 and pi (an error of about 1e-8
    rad)."""
    Ra = np.asarray(R_a, dtype=float)
    Rb = np.asarray(R_b, dtype=float)
    M = np.einsum("...ji,...jk->...ik", Ra, Rb)
    cos = (np.einsum("...ii->...", M) - 1.0) / 2.0
    skew = np.stack([M[..., 2, 1] - M[..., 1, 2], M[..., 0, 2] - M[..., 2, 0], M[..., 1, 0] - M[..., 0, 1]], axis=-1)
    sin = 0.5 * np.linalg.norm(skew, axis=-1)
    return np.arctan2(sin, cos)


# -- SO(3) helpers (the single home of hat/vee/exp/projection for the planner and avp.sim) ------


def hat(w: Array) -> Array:
    """Skew matrix with ``hat(w) @ b == cross(w, b)`` for one 3-vector."""
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def vee(S: Array) -> Array:
    """Inverse of :func:`hat` for a skew-symmetric ``S``."""
    return np.array([S[2, 1], S[0, 2], S[1, 0]])


def cross(a: Array, b: Array) -> Array:
    """``a x b`` for two single 3-vectors (much faster than ``np.cross`` on one pair)."""
    return np.array(
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    )


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
