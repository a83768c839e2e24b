"""Evaluation metrics of a plan: target visibility in time and along the path (Tables I, III)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from . import _avp_rust, frames
from . import _validate as v
from ._typing import Array
from .camera import Camera
from .errors import ConfigError
from .trajectory import Trajectory
from .types import PerchTarget

__all__ = ["Visibility", "visibility", "visibility_many"]


@dataclass(frozen=True)
class Visibility:
    """Fractions (0..1) of the manoeuvre with the target inside the camera's FoV.

    Attributes
    ----------
    time_fraction:
        Share of the duration (the paper's "percent of the time", Tables I, III).
    path_fraction:
        Share of the path length (arc length) travelled while visible ("percent of distance").
    first_loss:
        Time (s, absolute) the target first leaves the FoV, or ``None`` if it never does before
        contact.
    """

    time_fraction: float
    path_fraction: float
    first_loss: float | None = None

    def __str__(self) -> str:
        return f"{100 * self.time_fraction:.1f}%/{100 * self.path_fraction:.1f}%"


def visibility(
    trajectory: Trajectory,
    target: PerchTarget,
    camera: Camera | None = None,
    dt: float = 1e-3,
    *,
    rotor_drag: float = 0.0,
) -> Visibility:
    """Fraction of time and of path length with the target point inside ``camera``'s FoV.

    The plan is sampled every ``dt`` (s); the target is visible at a sample when it is inside the
    one-sided cone (7) (and the image rectangle and range, if the camera sets them) from the
    position and attitude (11), (13) there. Each interval between samples counts with the mean of
    its two end flags (trapezoid), weighted by its duration or by its chord length. The contact
    instant itself (``|n_d| = 0``) is not visible.

    Parameters
    ----------
    trajectory:
        The plan.
    target:
        Perch pad; its ``point`` is what the camera must see.
    camera:
        :class:`~avp.camera.Camera` (default: front camera, 35 deg half-angle).
    dt:
        Sampling step (s).
    rotor_drag:
        Mass-normalised rotor drag ``d`` (1/s): the attitude is the one of the thrust
        ``a + g e3 + d v`` (0: the drag-free map (11)). Pass the planner's
        ``config.limits.rotor_drag`` to get the figures its SQP step scores.
    """
    if not isinstance(trajectory, Trajectory):
        raise ConfigError("trajectory", f"expected avp.Trajectory, got {type(trajectory).__name__}")
    return visibility_many((trajectory,), target, camera, dt, rotor_drag=rotor_drag)[0]


def visibility_many(
    trajectories: Sequence[Trajectory],
    target: PerchTarget,
    camera: Camera | None = None,
    dt: float = 1e-3,
    *,
    rotor_drag: float = 0.0,
) -> list[Visibility]:
    """:func:`visibility` of several plans in one pass.

    Plans on the same knots (the candidates of one SQP, say) are evaluated by one kernel call on
    their stacked coefficients and one vectorised camera test; the result equals calling
    :func:`visibility` on each. Plans on different knots are evaluated one after the other.
    ``trajectories`` is any sequence or iterable of :class:`~avp.Trajectory` (a lone plan is
    refused: wrap it, ``(trajectory,)``).
    """
    trajectories = v.sequence("trajectories", trajectories, "avp.Trajectory", (Trajectory,))
    if camera is not None and not isinstance(camera, Camera):
        raise ConfigError("camera", f"expected avp.Camera or None, got {type(camera).__name__}")
    if not isinstance(target, PerchTarget):
        raise ConfigError("target", f"expected avp.PerchTarget (a pad; a line has no single point to see), got "
                          f"{type(target).__name__}")
    for i, tr in enumerate(trajectories):
        if not isinstance(tr, Trajectory):
            raise ConfigError(f"trajectories[{i}]", f"expected avp.Trajectory, got {type(tr).__name__}")
    cam = Camera() if camera is None else camera
    step = v.positive_float("dt", dt)
    drag = v.nonnegative_float("limits.rotor_drag", rotor_drag)
    return _visibility_checked(trajectories, target, cam, step, drag)


def _cone_only(cam: Camera) -> bool:
    """The camera's FoV is its cone (7) alone: no rectangular limits, an unlimited range."""
    return cam.horizontal_fov is None and cam.vertical_fov is None and not math.isfinite(cam.range)


def _cone_fractions(coeffs: Array, first: Trajectory, t: Array, target: PerchTarget, cam: Camera,
                    drag: float) -> tuple[Array, Array, Array]:
    """``(time fractions, path fractions, relative time of the first loss or NaN)`` of the plans
    whose coefficients are stacked along the axes in ``coeffs``, on ``first``'s knots, sampled at
    its relative times ``t`` (two at least), for a camera whose FoV is its cone
    (:func:`_cone_only`): h <= 0 with the Rust FoV kernel's own arithmetic (the same test as
    ``Camera.sees``; a degenerate attitude gives a NaN h: not seen), and the trapezoid sums, in
    one call for all samples of all plans, which it evaluates (position, yaw and the thrust's
    a + d v, ``VehicleLimits.rotor_drag``)."""
    return _avp_rust.spline_visibility(
        coeffs, first.knots_rel, t, float(drag), np.ascontiguousarray(target.point, dtype=float), cam.axis_B,
        math.cos(cam.half_fov), first.g)


def _visibility_checked(trajectories: Sequence[Trajectory], target: PerchTarget, cam: Camera, step: float,
                        drag: float) -> list[Visibility]:
    """:func:`visibility_many` of arguments it has checked (the planner's SQP score calls it
    directly with its own plans and validated configuration)."""
    if not trajectories:
        return []
    first = trajectories[0]
    if any(not np.array_equal(tr.knots_rel, first.knots_rel) or tr.t0 != first.t0 or tr.g != first.g
           for tr in trajectories[1:]):
        return [_visibility_checked((tr,), target, cam, step, drag)[0] for tr in trajectories]
    k = len(trajectories)
    t = first._sample_rel(step)  # since the plans' start: exact durations at any clock value
    t0 = first.t0
    coeffs = first.coefficients if k == 1 else np.concatenate([tr.coefficients for tr in trajectories], axis=1)
    if _cone_only(cam) and t.size >= 2:
        tf, pf, lost_at = _cone_fractions(coeffs, first, t, target, cam, drag)
        return [Visibility(float(a), float(b), None if math.isnan(c) else t0 + float(c))
                for a, b, c in zip(tf, pf, lost_at, strict=True)]
    if drag:  # position and the thrust's a + d v (VehicleLimits.rotor_drag)
        pva = _avp_rust.eval_spline(coeffs, first.knots_rel, t, [0, 1, 2]).reshape(3, t.size, k, 4)
        pva[2, :, :, :3] = frames.drag_acceleration(pva[2, :, :, :3], pva[1, :, :, :3], drag)
        ev = np.ascontiguousarray(pva[[0, 2]])
    else:
        ev = _avp_rust.eval_spline(coeffs, first.knots_rel, t, [0, 2]).reshape(2, t.size, k, 4)
    x = ev[0, :, :, :3]  # (n, k, 3)
    R = frames.attitude(ev[1, :, :, :3], ev[0, :, :, 3], first.g)  # (n, k, 3, 3), (11), (13)
    flags = cam.sees(x, R, target.point).astype(float)
    flags[~np.all(np.isfinite(R.reshape(t.size, k, -1)), axis=2)] = 0.0
    dtimes = t[1:] - t[:-1]
    total_t = float(dtimes.sum())
    # per plan, contiguous rows: the same arithmetic whatever the batch (one plan or several)
    w = np.ascontiguousarray((0.5 * (flags[1:] + flags[:-1])).T)  # (k, n - 1) trapezoid weights
    dx = x[1:] - x[:-1]
    ds = np.ascontiguousarray(np.sqrt(np.einsum("nki,nki->kn", dx, dx)))  # (k, n - 1) chords
    lost = flags[:-1] < 0.5
    first_lost = lost.argmax(axis=0)
    out = []
    for j in range(k):
        total_s = float(ds[j].sum())
        tf_j = float(w[j] @ dtimes / total_t) if total_t > 0 else 0.0
        pf_j = float(w[j] @ ds[j] / total_s) if total_s > 0 else tf_j
        out.append(Visibility(tf_j, pf_j, t0 + float(t[first_lost[j]]) if lost[first_lost[j], j] else None))
    return out
