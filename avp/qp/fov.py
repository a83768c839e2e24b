"""Field-of-view rows: the one-sided cone (7), its linearisation (8) and the trust region (9).

With ``n_d = s - x`` and the camera's optical axis ``e_c = R_WB(a, psi) R_BC e3`` given by the
flatness map (11), (13), the target is visible when

    h(x, psi, a) = cos(half_fov) |n_d| - n_d . e_c <= 0.                                  (7)

This is the one-sided form of the paper's (7): ``|n_d - n_proj| <= tan(half_fov) |n_proj|`` with
an unsigned ``|n_proj|`` also admits a target behind the camera. Around an anticipated
point ``z0 = (x0, psi0, a0)`` the row (8) is ``h(z0) + grad h(z0) . (z - z0) <= 0``, divided by
``|n_d(z0)|`` so that every row is dimensionless (``h/|n_d|`` is ``cos(half_fov)`` minus the cosine
of the angle off the optical axis). ``x``, ``psi`` and ``a`` at the linearisation times are linear
in the decision vector through :func:`~avp.qp.rows.point_rows`, so (8) and the box trust region (9)
are linear rows on the QP. All blocks are named ``"fov ..."`` so ``qp.without("fov")`` drops them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ..camera import Camera, FovConfig, FovPointPolicy
from ..frames import GRAVITY
from .assemble import ConstraintBlock
from .layout import YAW, DecisionLayout
from .rows import point_rows

Array = npt.NDArray[np.float64]

__all__ = [
    "FOV_PREFIX",
    "FovGradient",
    "FovLinearisation",
    "fov_blocks",
    "fov_gradient",
    "fov_h",
    "fov_times",
]

FOV_PREFIX = "fov"
"""Name prefix of every FoV block (``qp.without(FOV_PREFIX)``)."""

E3 = np.array([0.0, 0.0, 1.0])


def _skew(w: Array) -> Array:
    """``hat(w)`` for ``w`` of shape ``(..., 3)`` -> ``(..., 3, 3)`` with ``hat(w) u = w x u``."""
    z = np.zeros(w.shape[:-1])
    return np.stack([
        np.stack([z, -w[..., 2], w[..., 1]], -1),
        np.stack([w[..., 2], z, -w[..., 0]], -1),
        np.stack([-w[..., 1], w[..., 0], z], -1),
    ], -2)


@dataclass(frozen=True)
class FovGradient:
    """``h`` of (7) and its partial derivatives at a batch of points (leading shape ``(m,)``)."""

    h: Array  # (m,)
    d_x: Array  # (m, 3)
    d_psi: Array  # (m,)
    d_a: Array  # (m, 3)
    distance: Array  # (m,) |n_d|


def _axis_and_jacobians(psi: Array, a: Array, axis_B: Array, g: float) -> tuple[Array, Array, Array]:
    """``e_c``, ``d e_c / d psi`` (m, 3) and ``d e_c / d a`` (m, 3, 3) for the construction (13)."""
    f = a + g * E3
    fn = np.linalg.norm(f, axis=-1, keepdims=True)
    b3 = f / fn
    eye = np.eye(3)
    J_b3 = (eye - b3[..., :, None] * b3[..., None, :]) / fn[..., None]  # d b3 / d a
    b2d = np.stack([-np.sin(psi), np.cos(psi), np.zeros_like(psi)], -1)
    b2d_psi = np.stack([-np.cos(psi), -np.sin(psi), np.zeros_like(psi)], -1)
    v = np.cross(b2d, b3)
    vn = np.linalg.norm(v, axis=-1, keepdims=True)
    b1 = v / vn
    b2 = np.cross(b3, b1)
    P1 = (eye - b1[..., :, None] * b1[..., None, :]) / vn[..., None]  # d b1 / d v
    dv_a = _skew(b2d) @ J_b3
    dv_psi = np.cross(b2d_psi, b3)
    J_b1_a = P1 @ dv_a
    J_b1_psi = np.einsum("mij,mj->mi", P1, dv_psi)
    # b2 = b3 x b1: d b2 = hat(b3) d b1 - hat(b1) d b3
    J_b2_a = _skew(b3) @ J_b1_a - _skew(b1) @ J_b3
    J_b2_psi = np.cross(b3, J_b1_psi)
    d1, d2, d3 = axis_B
    e_c = d1 * b1 + d2 * b2 + d3 * b3
    de_psi = d1 * J_b1_psi + d2 * J_b2_psi
    de_a = d1 * J_b1_a + d2 * J_b2_a + d3 * J_b3
    return e_c, de_psi, de_a


def fov_h(
    x: npt.ArrayLike, psi: npt.ArrayLike, a: npt.ArrayLike, s: npt.ArrayLike,
    camera: Camera, g: float = GRAVITY,
) -> Array:
    """``h(x, psi, a) = cos(half_fov) |n_d| - n_d . e_c`` of (7); ``<= 0`` means visible.

    Vectorised: ``x, a`` of shape ``(m, 3)`` (or ``(3,)``), ``psi`` of shape ``(m,)``.
    """
    return fov_gradient(x, psi, a, s, camera, g).h


def fov_gradient(
    x: npt.ArrayLike, psi: npt.ArrayLike, a: npt.ArrayLike, s: npt.ArrayLike,
    camera: Camera, g: float = GRAVITY,
) -> FovGradient:
    """``h`` of (7) and its analytic gradient with respect to ``(x, psi, a)``, the terms of (8).

    ``d h / d x = e_c - cos(half_fov) n_d / |n_d|``; ``d h / d (psi, a) = -n_d^T d e_c / d (psi, a)``
    with ``e_c`` differentiated through ``b3 = (a + g e3)/|.|``, ``b1 = (b2_des x b3)/|.|`` and
    ``b2 = b3 x b1`` (11), (13). Singular where the thrust vanishes or ``b3 || b2_des``.
    """
    xx = np.atleast_2d(np.asarray(x, dtype=float))
    aa = np.atleast_2d(np.asarray(a, dtype=float))
    pp = np.atleast_1d(np.asarray(psi, dtype=float))
    n_d = np.asarray(s, dtype=float) - xx
    dist = np.linalg.norm(n_d, axis=-1)
    e_c, de_psi, de_a = _axis_and_jacobians(pp, aa, camera.axis_B, g)
    c = math.cos(camera.half_fov)
    h = c * dist - np.sum(n_d * e_c, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        unit = n_d / dist[:, None]
    d_x = e_c - c * unit
    d_psi = -np.sum(n_d * de_psi, axis=-1)
    d_a = -np.einsum("mi,mij->mj", n_d, de_a)
    return FovGradient(h=h, d_x=d_x, d_psi=d_psi, d_a=d_a, distance=dist)


def fov_times(start: float, end: float, fov: FovConfig) -> Array:
    """The ``n_p`` linearisation times (relative), equally spaced over ``(start, end - gate]``.

    The start itself is excluded (the state there is fixed by the initial conditions). Empty when
    the gate covers the whole remaining plan.
    """
    last = end - fov.gate
    if last <= start + 1e-9:
        return np.zeros(0)
    k = np.arange(1, fov.n_points + 1)
    return start + (last - start) * k / fov.n_points


@dataclass(frozen=True)
class FovLinearisation:
    """The FoV blocks of one QP and what happened to each linearisation point."""

    blocks: tuple[ConstraintBlock, ...]
    times: Array  # relative times of the points
    h0: Array  # h/|n_d| at the linearisation points (<= 0: visible there)
    reachable: Array  # smallest h/|n_d| the linearised row reaches inside the box (9)
    placed: Array  # bool: a FoV row was placed
    progress: Array  # bool: the row asks for progress only (PROGRESS policy)

    @property
    def n_rows(self) -> int:
        return int(sum(b.n_rows for b in self.blocks))


def fov_blocks(
    layout: DecisionLayout,
    knots_rel: Array,
    times: Array,
    x0: Array,
    psi0: Array,
    a0: Array,
    target_point: Array,
    fov: FovConfig,
    g: float = GRAVITY,
) -> FovLinearisation:
    """FoV rows (8) and box trust region (9) linearised at ``(x0, psi0, a0)`` at ``times``.

    Parameters
    ----------
    layout, knots_rel:
        Decision layout and knots (relative to the plan start) of the QP.
    times:
        Relative times of the ``n_p`` points (:func:`fov_times`).
    x0, psi0, a0:
        Linearisation point at each time (shapes ``(m, 3)``, ``(m,)``, ``(m, 3)``), from the
        previous plan (anticipation (6)) or the previous SQP iterate.
    target_point:
        ``s`` (W).
    fov:
        :class:`~avp.camera.FovConfig` (trust region, policy, camera).

    Returns
    -------
    FovLinearisation
        Blocks ``"fov rows (8)"`` and ``"fov trust region (9) x|a|yaw"``.
    """
    t = np.asarray(times, dtype=float)
    m = t.size
    empty = np.zeros(0)
    if m == 0:
        return FovLinearisation((), t, empty, empty, np.zeros(0, bool), np.zeros(0, bool))
    grad = fov_gradient(x0, psi0, a0, target_point, fov.camera, g)
    Rx = point_rows(layout, knots_rel, 0, t, (0, 1, 2))  # (m, 3, n)
    Ra = point_rows(layout, knots_rel, 2, t, (0, 1, 2))
    Rpsi = point_rows(layout, knots_rel, 0, t, (YAW,))[:, 0, :]  # (m, n)
    ok = np.isfinite(grad.h) & np.all(np.isfinite(grad.d_a), axis=1) & np.isfinite(grad.d_psi) & (grad.distance > 1e-6)
    dist = np.where(ok, grad.distance, 1.0)
    gx = np.where(ok[:, None], grad.d_x, 0.0) / dist[:, None]
    ga = np.where(ok[:, None], grad.d_a, 0.0) / dist[:, None]
    gp = np.where(ok, grad.d_psi, 0.0) / dist
    h0 = np.where(ok, grad.h, np.inf) / dist
    # Largest linearised decrease inside the box (9): sum |grad_i| r_i.
    decrease = (np.abs(gx).sum(1) * fov.trust_position + np.abs(ga).sum(1) * fov.trust_acceleration
                + np.abs(gp) * fov.trust_yaw)
    reachable = h0 - decrease
    # Row: grad.z <= grad.z0 - h0 - margin, i.e. h0 + grad.(z - z0) <= -margin.
    G = np.einsum("mi,min->mn", gx, Rx) + np.einsum("mi,min->mn", ga, Ra) + gp[:, None] * Rpsi
    lin0 = np.sum(gx * x0, 1) + np.sum(ga * a0, 1) + gp * psi0
    rhs = lin0 - h0 - fov.margin
    placed = ok.copy()
    progress = np.zeros(m, bool)
    # A row needing more than reach_fraction of the box's decrease is treated as out of reach:
    # a thin feasible set makes first-order back-ends (proxqp, osqp) declare infeasibility.
    hopeless = ok & (h0 - fov.reach_fraction * decrease > -fov.margin)
    if fov.point_policy is FovPointPolicy.SKIP:
        placed &= ~hopeless
    elif fov.point_policy is FovPointPolicy.PROGRESS:
        # Ask for a fraction of the reachable decrease: h0 + grad.(z - z0) <= h0 - f * decrease.
        rhs = np.where(hopeless, lin0 - fov.progress_fraction * decrease, rhs)
        progress = hopeless.copy()
    blocks = []
    if placed.any():
        blocks.append(ConstraintBlock(
            f"{FOV_PREFIX} rows (8)", G[placed], np.full(int(placed.sum()), -np.inf), rhs[placed]))
        sel = placed
        for label, R, z0, r in (
            ("x", Rx[sel].reshape(-1, layout.n_variables), np.asarray(x0)[sel].reshape(-1), fov.trust_position),
            ("a", Ra[sel].reshape(-1, layout.n_variables), np.asarray(a0)[sel].reshape(-1), fov.trust_acceleration),
            ("yaw", Rpsi[sel], np.asarray(psi0)[sel], fov.trust_yaw),
        ):
            if math.isfinite(r):
                blocks.append(ConstraintBlock(f"{FOV_PREFIX} trust region (9) {label}", R, z0 - r, z0 + r))
    return FovLinearisation(tuple(blocks), t, h0, reachable, placed, progress)
