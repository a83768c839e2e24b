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

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property, lru_cache

import numpy as np
import numpy.typing as npt

from .. import _avp_rust
from .. import _validate as v
from .._typing import Array
from ..camera import Camera
from ..config import FovConfig
from ..errors import ConfigError
from ..frames import GRAVITY
from .assemble import ConstraintBlock, _read_only
from .layout import DecisionLayout

__all__ = [
    "FOV_PREFIX",
    "FovGradient",
    "FovLinearisation",
    "FovRowInputs",
    "fov_blocks",
    "fov_gradient",
    "fov_h",
    "fov_rows",
    "fov_times",
    "linearise_on_spline",
]

FOV_PREFIX = "fov"
"""Name prefix of every FoV block (``qp.without(FOV_PREFIX)``)."""


@dataclass(frozen=True)
class FovGradient:
    """``h`` of (7) and its partial derivatives at a batch of points (leading shape ``(m,)``)."""

    h: Array  # (m,)
    d_x: Array  # (m, 3)
    d_psi: Array  # (m,)
    d_a: Array  # (m, 3)
    distance: Array  # (m,) |n_d|


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
    Computed in Rust (``avp._avp_rust.fov_gradient``) for all points in one call; the inputs
    broadcast over the points.
    """
    xx = np.atleast_2d(np.asarray(x, dtype=float))
    aa = np.atleast_2d(np.asarray(a, dtype=float))
    pp = np.atleast_1d(np.asarray(psi, dtype=float))
    m = max(xx.shape[0], aa.shape[0], pp.shape[0])

    def rows(v: Array, shape: tuple[int, ...]) -> Array:
        return np.ascontiguousarray(v if v.shape == shape else np.broadcast_to(v, shape))

    h, d_x, d_psi, d_a, dist = _avp_rust.fov_gradient(
        rows(xx, (m, 3)),
        rows(pp, (m,)),
        rows(aa, (m, 3)),
        np.ascontiguousarray(s, dtype=float),
        camera.axis_B,
        math.cos(camera.half_fov),
        float(g),
    )
    return FovGradient(h=h, d_x=d_x, d_psi=d_psi, d_a=d_a, distance=dist)


def fov_times(start: float, end: float, fov: FovConfig) -> Array:
    """The ``n_p`` linearisation times (relative), equally spaced over ``(start, end - gate]``.

    The start itself is excluded (the state there is fixed by the initial conditions). Empty when
    the gate covers the whole remaining plan. Read-only: the times of the last few requests are
    kept (a plan asks for the same ones at every SQP step).
    """
    return _equally_spaced(float(start), float(end) - fov.gate, fov.n_points)


@lru_cache(maxsize=64)
def _equally_spaced(start: float, last: float, n: int) -> Array:
    if last <= start + 1e-9:
        return _read_only(np.zeros(0))
    k = np.arange(1, n + 1)
    return _read_only(start + (last - start) * k / n)


@dataclass(frozen=True, eq=False)
class FovRowInputs:
    """What the FoV rows of the placed points are built from (:func:`fov_rows`)."""

    layout: DecisionLayout
    knots_rel: Array  # (S + 1,) knots of the QP, relative to its start
    times: Array  # (k,) relative times of the placed points
    gx: Array  # (k, 3) row (8) gradient in x, over |n_d|
    ga: Array  # (k, 3) ... in a
    gp: Array  # (k,) ... in yaw
    rhs: Array  # (k,) right-hand side of row (8)
    x0: Array  # (k, 3) linearisation point
    a0: Array  # (k, 3)
    psi0: Array  # (k,)
    fov: FovConfig
    rotor_drag: float = 0.0  # 1/s: the rows' acceleration variable is a + d v (fov_blocks)


@lru_cache(maxsize=64)
def _point_basis(layout: DecisionLayout, knots_rel: bytes, times: bytes,
                 rotor_drag: float) -> tuple[npt.NDArray[np.int64], Array, Array]:
    """``(segment, position basis, acceleration basis)`` of the points at ``times`` (relative,
    as bytes) on ``knots_rel`` (bytes), read-only and row-major (:func:`fov_rows`). The SQP steps
    of one plan place their rows at the same times on the same knots: computed once for them."""
    knots = np.frombuffer(knots_rel, dtype=float)
    t = np.frombuffer(times, dtype=float)
    seg, u = layout.locate(knots, t)
    T = knots[seg + 1] - knots[seg]
    p0 = layout.basis(0, u)  # (k, C) position basis
    p2 = layout.basis(2, u) / (T**2)[:, None]  # (k, C) acceleration basis
    if rotor_drag:  # the basis of a + d v (fov_blocks)
        p2 = p2 + rotor_drag * layout.basis(1, u) / T[:, None]
    out = (np.ascontiguousarray(seg, dtype=np.int64), np.ascontiguousarray(p0), np.ascontiguousarray(p2))
    for arr in out:
        arr.setflags(write=False)
    return out


def fov_rows(inp: FovRowInputs) -> tuple[ConstraintBlock, ...]:
    """Blocks ``"fov rows (8)"`` and ``"fov trust region (9) x|a|yaw"`` of the placed points.

    Every row of a point touches only its segment's columns (``layout.columns(axis, seg)``):
    row (8) ``grad.z <= grad.z0 - h0 - margin`` (i.e. ``h0 + grad.(z - z0) <= -margin``) has x/a
    columns ``gx_j b0 + ga_j b2`` and yaw columns ``gp b0``; the trust region (9) rows are ``b0``
    (x, yaw) and ``b2`` (a) on one axis each. The basis rows are evaluated here, the dense
    matrices filled by the Rust kernel ``avp._avp_rust.fov_row_matrices``.
    """
    k = inp.times.size
    if k == 0:
        return ()
    fov, layout = inp.fov, inp.layout
    as_key = functools.partial(np.ascontiguousarray, dtype=np.float64)  # the cache's keys are float64 bytes
    seg, p0, p2 = _point_basis(layout, as_key(inp.knots_rel).tobytes(), as_key(inp.times).tobytes(),
                               float(inp.rotor_drag))
    row8, Rx, Ra, Ryaw = _avp_rust.fov_row_matrices(
        layout.n_segments, seg, p0, p2,
        np.ascontiguousarray(inp.gx), np.ascontiguousarray(inp.ga), np.ascontiguousarray(inp.gp),
    )
    trust = []
    for R, z0, r in ((Rx, inp.x0.reshape(-1), fov.trust_position), (Ra, inp.a0.reshape(-1), fov.trust_acceleration),
                     (Ryaw, inp.psi0, fov.trust_yaw)):
        trust.append((R, z0 - r, z0 + r))
    return _assembled(fov, inp.rhs, row8, trust)


_ROW8 = f"{FOV_PREFIX} rows (8)"
_TRUST = tuple(f"{FOV_PREFIX} trust region (9) {label}" for label in ("x", "a", "yaw"))


_NO_LOWER = _read_only(np.full(256, -np.inf))
"""The rows (8)'s lower bounds (none): read-only views of it (more points than this get a
read-only array of their own)."""


def _assembled(fov: FovConfig, rhs: Array, row8: Array,
               trust: Sequence[tuple[Array, Array, Array]]) -> tuple[ConstraintBlock, ...]:
    """The FoV blocks of the placed points from their matrices: the rows (8) ``row8 <= rhs`` and
    the trust region (9) ``(matrix, lower, upper)`` in position, acceleration and yaw (``trust``,
    in that order), each only when its radius is finite. No block without a placed point."""
    if rhs.size == 0:
        return ()
    k = rhs.size
    no_lower = _NO_LOWER[:k] if k <= _NO_LOWER.size else _read_only(np.full(k, -np.inf))
    blocks = [ConstraintBlock(_ROW8, row8, no_lower, rhs)]
    radii = (fov.trust_position, fov.trust_acceleration, fov.trust_yaw)
    for name, r, (R, lo, hi) in zip(_TRUST, radii, trust, strict=True):
        if math.isfinite(r):
            blocks.append(ConstraintBlock(name, R, lo, hi))
    return tuple(blocks)


@dataclass(frozen=True, eq=False)
class FovLinearisation:
    """The FoV blocks of one QP and what happened to each linearisation point.

    ``blocks`` are built on first access (:func:`fov_rows`): a caller that only needs to know
    whether the rows hold at the linearisation point itself (:attr:`hold_at_linearisation`)
    never builds them. :func:`linearise_on_spline` builds them with the terms when asked
    (``build_blocks``), in the same kernel call: the same blocks. The arrays are read-only.
    """

    times: Array  # relative times of the points
    h0: Array  # h/|n_d| at the linearisation points (<= 0: visible there)
    reachable: Array  # smallest h/|n_d| the linearised row reaches inside the box (9)
    placed: npt.NDArray[np.bool_]  # a FoV row was placed
    progress: npt.NDArray[np.bool_]  # the row asks for progress only (PROGRESS policy)
    hold_at_linearisation: bool
    """Every placed row holds at the linearisation point: row (8) reads ``h0 <= -margin`` there
    (to 1e-9 relative to its right-hand side, as the rows are checked elsewhere), the trust
    region (9) is centred on it, and no row asks for progress (those need a decrease)."""
    rows: FovRowInputs | None = field(default=None, repr=False)

    @cached_property
    def blocks(self) -> tuple[ConstraintBlock, ...]:
        """Blocks ``"fov rows (8)"`` and ``"fov trust region (9) x|a|yaw"`` (built once)."""
        return fov_rows(self.rows) if self.rows is not None else ()

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
    rotor_drag: float = 0.0,
) -> FovLinearisation:
    """FoV rows (8) and box trust region (9) linearised at ``(x0, psi0, a0)`` at ``times``.

    Parameters
    ----------
    layout, knots_rel:
        Decision layout and knots (relative to the plan start) of the QP.
    times:
        Relative times of the ``n_p`` points (:func:`fov_times`).
    x0, psi0, a0:
        Linearisation point at each time (shapes ``(m, 3)``, ``(m,)``, ``(m, 3)``): the QP's
        FoV-free solution or the previous SQP iterate (:mod:`avp.attempt`).
    target_point:
        ``s`` (W).
    fov:
        :class:`~avp.camera.FovConfig` (trust region, policy, camera).
    rotor_drag:
        Mass-normalised rotor drag ``d`` (1/s, :class:`~avp.config.VehicleLimits`). With drag the
        thrust axis is ``b3 || a + g e3 + d v`` (Faessler et al.), so the attitude (11), (13) and
        the rows are taken in ``a + d v``: ``a0`` is that sum at the points, the rows' acceleration
        columns carry ``b2 + d b1`` and the trust region (9) in ``a`` bounds it. 0: ``a`` alone.

    Returns
    -------
    FovLinearisation
        Blocks ``"fov rows (8)"`` and ``"fov trust region (9) x|a|yaw"``.
    """
    t = np.array(times, dtype=float)  # a copy: it is returned read-only
    drag = v.nonnegative_float("limits.rotor_drag", rotor_drag)
    m = t.size
    if m == 0:
        return _no_points(t)
    # row-major copies, kept by the rows: the caller's arrays may be views it reuses
    x0 = np.array(x0, dtype=float, order="C")
    a0 = np.array(a0, dtype=float, order="C")
    psi0 = np.array(psi0, dtype=float, order="C")
    # Rust: the gradient, the largest linearised decrease inside the box (9) (sum |grad_i| r_i),
    # the rows' right-hand sides and the point policy: a point whose row needs more than
    # reach_fraction of that decrease is out of reach (a thin feasible set makes first-order
    # back-ends, proxqp and osqp, declare infeasibility)
    h0, reachable, gx, ga, gp, rhs, placed, progress, hold = _avp_rust.fov_linearise(
        x0, psi0, a0, np.ascontiguousarray(target_point, dtype=float), fov.camera.axis_B,
        math.cos(fov.camera.half_fov), float(g), (fov.trust_position, fov.trust_acceleration, fov.trust_yaw),
        fov.margin, fov.reach_fraction, fov.progress_fraction, fov.point_policy.name.lower(),
    )
    # the rows themselves are built by fov_rows, on first access to the blocks
    knots = np.array(knots_rel, dtype=float)
    if placed.all():  # every point placed: the arrays as they are
        rows = FovRowInputs(layout, knots, t, gx, ga, gp, rhs, x0, a0, psi0, fov, drag)
    else:
        rows = FovRowInputs(layout, knots, t[placed], gx[placed], ga[placed], gp[placed], rhs[placed],
                            x0[placed], a0[placed], psi0[placed], fov, drag)
    for arr in (t, h0, reachable, placed, progress):
        arr.setflags(write=False)
    return FovLinearisation(t, h0, reachable, placed, progress, hold, rows)


_NO_BASIS = (np.zeros(0, dtype=np.int64), np.zeros((0, 0)), np.zeros((0, 0)))


def _no_points(times: Array) -> FovLinearisation:
    """The linearisation at no point: no row, and the rows (none) hold."""
    empty = np.zeros(0)
    return FovLinearisation(times, empty, empty, np.zeros(0, bool), np.zeros(0, bool), True)


def linearise_on_spline(
    layout: DecisionLayout,
    knots_rel: Array,
    times: Array,
    coefficients: Array,
    spline_knots_rel: Array,
    tau: Array,
    target_point: Array,
    fov: FovConfig,
    g: float = GRAVITY,
    rotor_drag: float = 0.0,
    *,
    build_blocks: bool = True,
) -> FovLinearisation:
    """:func:`fov_blocks` at the points of a reference spline (``coefficients`` on
    ``spline_knots_rel``, at its relative times ``tau``, one per entry of ``times``): its
    position, yaw and acceleration (``a + rotor_drag v``) there, with the blocks built at once
    when ``build_blocks`` (otherwise on first access, by :func:`fov_rows`, as
    :func:`fov_blocks` does). One kernel call (``avp._avp_rust.fov_step_rows``) evaluates the
    points, computes the row terms and fills the rows, with the kernels :func:`fov_blocks` and
    :func:`fov_rows` call, in the same order of operations: the result is the same bits as
    theirs on the evaluated points. ``rotor_drag`` is taken as validated (the planner's
    configuration)."""
    t = np.array(times, dtype=float)
    tau = np.ascontiguousarray(tau, dtype=float)
    if t.ndim != 1 or tau.shape != t.shape:
        raise ConfigError("tau", f"one relative time of the reference per entry of times: expected shape {t.shape}, "
                                 f"got {tau.shape}")
    if t.size == 0:
        return _no_points(t)
    if build_blocks:
        seg, p0, p2 = _point_basis(layout, np.ascontiguousarray(knots_rel, dtype=np.float64).tobytes(), t.tobytes(),
                                   float(rotor_drag))
    else:  # no rows to fill: no basis (fov_rows evaluates the placed points' if the blocks are asked for)
        seg, p0, p2 = _NO_BASIS
    cam = fov.camera
    point, inputs, mats = _avp_rust.fov_step_rows(
        coefficients, spline_knots_rel, tau, float(rotor_drag), np.ascontiguousarray(target_point, dtype=float),
        cam.axis_B, math.cos(cam.half_fov), float(g), (fov.trust_position, fov.trust_acceleration, fov.trust_yaw),
        fov.margin, fov.reach_fraction, fov.progress_fraction, fov.point_policy.name.lower(), layout.n_segments,
        seg, p0, p2, build_blocks)
    h0, reachable, placed, progress, hold = point
    gx, ga, gp, rhs, x0, a0, psi0 = inputs
    k = rhs.size
    knots = np.array(knots_rel, dtype=float)
    rows = FovRowInputs(layout, knots, t if k == t.size else t[placed], gx, ga, gp, rhs, x0, a0, psi0, fov,
                        float(rotor_drag))
    for arr in (t, h0, reachable, placed, progress):
        arr.setflags(write=False)
    lin = FovLinearisation(t, h0, reachable, placed, progress, hold, rows)
    if mats is not None:  # the blocks, built: what the cached property would build from the rows
        row8, Rx, x_lo, x_hi, Ra, a_lo, a_hi, Ryaw, y_lo, y_hi = mats
        lin.__dict__["blocks"] = _assembled(fov, rhs, row8, ((Rx, x_lo, x_hi), (Ra, a_lo, a_hi), (Ryaw, y_lo, y_hi)))
    return lin
