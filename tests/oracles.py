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


def attitude_zyx(acc: np.ndarray, yaw: np.ndarray, g: float = 9.81) -> np.ndarray:
    """``R_WB`` with thrust axis along ``a + g e3`` and the ZYX yaw ``yaw``, built as
    ``Rz(yaw) Ry(pitch) Rx(roll)`` (``|roll| <= pi/2``) by scipy from Euler angles: an independent
    construction of the attitude (13) (not ``avp.frames``)."""
    from scipy.spatial.transform import Rotation

    f = np.asarray(acc, dtype=float) + [0.0, 0.0, g]
    c, s = np.cos(yaw), np.sin(yaw)
    fx = c * f[:, 0] + s * f[:, 1]  # f in the yaw-rotated frame: Rz(-yaw) f
    fy = -s * f[:, 0] + c * f[:, 1]
    pitch = np.arctan2(fx, f[:, 2])
    roll = np.arctan2(-fy, np.hypot(fx, f[:, 2]))
    return Rotation.from_euler("ZYX", np.column_stack([yaw, pitch, roll])).as_matrix()


def body_rate_norm_numeric(traj, dt: float = 5e-4) -> tuple[np.ndarray, np.ndarray]:
    """``|omega|`` on a grid of step ``dt`` by differentiating :func:`attitude_zyx` numerically:
    ``|log(R_k^T R_{k+1})| / dt`` at the midpoints (second-order accurate). Returns
    ``(t_mid, |omega|)``; ``traj`` needs ``sample``, ``evaluate``."""
    from scipy.spatial.transform import Rotation

    t = traj.sample(dt)
    acc = traj.evaluate(t, 2)[:, :3]
    yaw = traj.evaluate(t, 0)[:, 3]
    R = attitude_zyx(acc, yaw, traj.g)
    rel = np.einsum("kji,kjl->kil", R[:-1], R[1:])
    w = np.linalg.norm(Rotation.from_matrix(rel).as_rotvec(), axis=1) / np.diff(t)
    return 0.5 * (t[1:] + t[:-1]), w


def roll_zyx(acc: np.ndarray, yaw: np.ndarray, g: float = 9.81) -> np.ndarray:
    """ZYX roll (rad) of the attitude with thrust along ``a + g e3`` and yaw ``yaw``."""
    f = np.asarray(acc, dtype=float) + [0.0, 0.0, g]
    fy = -np.sin(yaw) * f[:, 0] + np.cos(yaw) * f[:, 1]
    return np.arcsin(np.clip(-fy / np.linalg.norm(f, axis=1), -1.0, 1.0))
