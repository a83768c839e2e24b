"""Target (perch pad) filter on the user side: what a user of avp would write around a tag detector.

This is **not** part of the planner; it is the kind of filter a user puts between an AprilTag
detector and :meth:`avp.replan.Replanner.step`, written the way a user would: a static pad, so
fuse the detections with inverse-variance weights ``w_i = 1 / var_i`` (the best linear unbiased
estimate for independent errors), with two user-side safeguards for a detector whose errors grow
with range:

- ``scale_error``: the user's guess of the detector's scale error (fraction of range, e.g. a
  slightly wrong tag size). It adds ``(scale_error d_i)^2`` to the variance of a detection at
  range ``d_i``, so far detections, whose bias is largest, fade faster.
- ``range_ratio``: only detections taken within ``range_ratio`` times the closest range seen so
  far are fused (older, farther ones are dropped once the vehicle is much closer).

- ``estimate_scale``: a user who suspects a scale error (wrong tag size or focal length) can
  estimate it from the approach itself: a detection from camera position ``c_i`` is
  ``p_i = c_i + (1 + b)(p - c_i) + noise``, i.e. ``p_i = q - b c_i`` with ``q = (1 + b) p``, linear
  in ``(q, b)``. The filter solves that weighted least-squares problem with the prior
  ``b ~ N(0, scale_error^2)`` (so a hover-only start, where ``b`` is unobservable, gives the plain
  fusion) and returns ``p = q / (1 + b)``. Detections taken from different ranges along the line
  of sight make ``b`` observable, which an approach provides. This fit weights each detection by
  ``1 / sigma_i^2`` alone: ``b`` is a parameter here, and inflating the variances by
  ``(scale_error d_i)^2`` as well counts the scale error twice and discards the far detections
  that make ``b`` observable (measured in the realistic simulator, 20 seeds each, AVP on a wall
  at 4.5 m: 4/20 perches with the inflated weights, 13/20 without; on a 60 deg slope 18/20).

``var_i = sigma_i^2 + (scale_error d_i)^2`` with ``sigma_i`` the detector's per-axis std at range
``d_i`` (the camera's ``sigma_p(d)``, Fig. 9). Its per-axis std is ``(sum w_i)^-1/2`` (noise only;
a bias common to all detections is not averaged away). The rotation is the weighted chordal L2
mean ``M = sum_i u_i R_i`` with ``u_i = 1/sigma_ang_i^2``, projected onto SO(3) (polar factor,
det +1): for small, isotropic errors the maximum-likelihood rotation to first order. With the
defaults (0, None) it is the plain inverse-variance fusion of every detection.
"""

from __future__ import annotations

import operator
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize_scalar

from ..errors import ConfigError
from ..frames import Array, project_so3
from ..platform import MotionModel, MovingTarget, rot_z
from .camera import CameraMeasurement

__all__ = ["PlatformEstimator", "TargetEstimate", "TargetEstimator"]


POSE_SIGMA = 0.003
"""Floor (m) on a detection's per-axis position std. A detection reaches W through the camera pose
the robot believes, whose own error is a few millimetres (the odometry's white noise), so no
detection is better than that, however good the detector. Without the floor a noise-free detector
got weights of 1e18: with a scale fit, millimetres of pose noise between hover detections were
explained by a scale error of order one and the first estimate of a wall 4.5 m away was 18 m off."""


@dataclass(frozen=True, eq=False)
class TargetEstimate:
    """Fused pad pose: centre ``p_W`` (m), ``R_WS``, per-axis stds, count and last time (s)."""

    p_W: Array
    R_WS: Array
    sigma_pos: float
    sigma_ang: float
    n_measurements: int
    t_last: float


class TargetEstimator:
    """Fuses :class:`~avp.sim.camera.CameraMeasurement` objects into one pad pose estimate.

    Parameters
    ----------
    scale_error:
        Assumed range-proportional error of the detector (fraction), added to each variance.
    range_ratio:
        Fuse only detections within this factor of the closest range so far (``None``: all).
    estimate_scale:
        Estimate the detector's scale error along with the pad centre (module docstring; needs
        ``scale_error > 0`` as the prior's std).
    pose_sigma:
        Floor (m) on a detection's position std: :data:`POSE_SIGMA`.
    """

    def __init__(self, scale_error: float = 0.0, range_ratio: float | None = None,
                 estimate_scale: bool = False, pose_sigma: float = POSE_SIGMA) -> None:
        if not (np.isfinite(scale_error) and scale_error >= 0):
            raise ConfigError("estimator.scale_error", f"must be a fraction >= 0, got {scale_error}")
        if range_ratio is not None and not (np.isfinite(range_ratio) and range_ratio >= 1.0):
            raise ConfigError("estimator.range_ratio", f"must be >= 1 or None, got {range_ratio}")
        if not (np.isfinite(pose_sigma) and pose_sigma > 0):
            raise ConfigError("estimator.pose_sigma", f"must be a positive length (m), got {pose_sigma}")
        self.pose_sigma = float(pose_sigma)
        self.scale_error = float(scale_error)
        self.range_ratio = range_ratio
        self.estimate_scale = bool(estimate_scale) and self.scale_error > 0
        self.reset()

    def _position_std(self, m: CameraMeasurement) -> float:
        """Per-axis position std (m) of detection ``m``, floored at :attr:`pose_sigma`."""
        return max(m.sigma_pos, self.pose_sigma)

    def reset(self) -> None:
        """Drop every measurement."""
        self._meas: list[CameraMeasurement] = []
        self._n = 0
        self._t_last = float("nan")

    @property
    def n_measurements(self) -> int:
        """Number of detections received."""
        return self._n

    def update(self, meas: CameraMeasurement) -> None:
        """Add one detection."""
        self._meas.append(meas)
        self._n += 1
        self._t_last = float(meas.t)

    def estimate(self) -> TargetEstimate | None:
        """The current fused pad pose, or None before the first detection."""
        if self._n == 0:
            return None
        ms = self._meas
        if self.range_ratio is not None:
            d_min = min(m.distance for m in ms)
            ms = [m for m in ms if m.distance <= self.range_ratio * d_min]
        w_pos = np.array([1.0 / (self._position_std(m) ** 2 + (self.scale_error * m.distance) ** 2) for m in ms])
        w_ang = np.array([1.0 / max(m.sigma_ang, 1e-9) ** 2 for m in ms])
        P = np.array([m.p_W for m in ms], dtype=float)
        Rs = np.array([m.R_WS for m in ms], dtype=float)
        p_W = (w_pos @ P) / w_pos.sum()
        if self.estimate_scale and all(m.p_cam_W is not None for m in ms):
            # the scale error is a parameter of this fit, not noise: weight by the detector's
            # noise alone (inflating by (scale_error d)^2 as well would count it twice)
            w_noise = np.array([1.0 / self._position_std(m) ** 2 for m in ms])
            p_W = self._scale_corrected(ms, w_noise, P)
        return TargetEstimate(
            p_W=p_W,
            R_WS=project_so3(np.einsum("i,ijk->jk", w_ang, Rs) / w_ang.sum()),
            sigma_pos=float(w_pos.sum() ** -0.5),
            sigma_ang=float(w_ang.sum() ** -0.5),
            n_measurements=self._n,
            t_last=self._t_last,
        )

    def _scale_corrected(self, ms: list[CameraMeasurement], w: np.ndarray, P: np.ndarray) -> Array:
        """Weighted least squares for ``(q, b)`` in ``p_i = q - b c_i`` with the prior
        ``b ~ N(0, scale_error^2)``; returns ``q / (1 + b)``."""
        C = np.array([m.p_cam_W for m in ms], dtype=float)
        A = np.zeros((len(ms), 3, 4))
        A[:, :, :3] = np.eye(3)
        A[:, :, 3] = -C  # p_i = A_i [q; b]
        x = _whitened_lstsq(A, P, w, 3, self.scale_error)
        return x[:3] / (1.0 + x[3])


def _whitened_lstsq(A: np.ndarray, P: np.ndarray, w: np.ndarray, prior_index: int, prior_std: float) -> Array:
    """``argmin_x sum_i w_i |A_i x - p_i|^2 + x_k^2 / prior_std^2`` (``k = prior_index``).

    Solved on the whitened rows by an orthogonal factorisation (``numpy.linalg.lstsq``), not by
    the normal equations: with precise detections (weights up to ``1e18`` for a noise-free
    camera) and a parameter the data leave unobservable (the scale error while hovering, or
    while tracking a platform at a constant offset), the normal equations' condition number is
    the square of this one and their solution was metres off.
    """
    n, _, k = A.shape
    root = np.sqrt(w)[:, None, None]
    rows = (root * A).reshape(n * 3, k)
    rhs = (np.sqrt(w)[:, None] * P).reshape(n * 3)
    prior = np.zeros((1, k))
    prior[0, prior_index] = 1.0 / prior_std
    sol, *_ = np.linalg.lstsq(np.vstack([rows, prior]), np.concatenate([rhs, [0.0]]), rcond=None)
    return np.asarray(sol)


class PlatformEstimator(TargetEstimator):
    """Fuses detections of a pad on a *moving* platform into a platform-state estimate.

    What a user would put between the tag detector and :class:`~avp.moving.MovingReplanner`:
    over the detections captured in the last ``window`` s, a weighted least-squares fit of
    ``p_i = p + M(t_i - t_ref) v``, the CTRV displacement for a turn rate ``omega`` (``M = dt I``
    for a straight line; ``t_ref`` the latest capture time, weights ``1 / (sigma_i^2 +
    (scale_error d_i)^2)`` as :class:`TargetEstimator`). For ``turn_rate=True`` (the CTRV model)
    ``omega`` minimises that fit's squared residual plus the residual of a straight-line fit of
    the pad's yaw (the direction of ``s2 = e3 x h``) against time: a one-dimensional search
    (bounded Brent) around the yaw-only slope. The track's curvature pins the turn far better
    than a few degrees of normal noise per detection do (3 times better rms at 3 mm / 2 deg,
    ``test_platform_turn_rate_uses_the_track_not_only_the_noisy_yaw``). The rotation is the chordal mean of the detections turned back
    to ``t_ref`` by that rate. :meth:`target` returns an :class:`avp.platform.MovingTarget` at
    ``t_ref`` (heading along the fitted horizontal velocity), which the replanner predicts to
    the contact time; fewer than two detections in the window give zero velocity. With
    ``estimate_scale`` the detector's scale error ``b`` is fitted too, as in
    :class:`TargetEstimator` (``p_i = (1 + b) p(t_i) - b c_i``, linear in ``((1 + b) p,
    (1 + b) v, b)``, prior ``b ~ N(0, scale_error^2)``, weights without the ``scale_error``
    term; observable once the range changes other than linearly in time, as when braking).

    The window forgets by time, but never below the newest ``min_detections`` detections: when
    the pad leaves the camera's view (on a long approach it can be out of view for seconds), the
    first detection after the gap is fitted with the last ones before it, through the motion
    model, instead of alone (one detection alone gives no velocity, and a few give a turn rate
    that is all noise: on a turning 1.5 rad plane that made the late replans chase a pad at
    rest, 17-27 cm off).
    """

    def __init__(self, window: float = 1.0, scale_error: float = 0.0, turn_rate: bool = False,
                 estimate_scale: bool = False, min_detections: int = 10) -> None:
        if not (np.isfinite(window) and window > 0):
            raise ConfigError("estimator.window", f"must be a positive time (s), got {window}")
        try:
            count = None if isinstance(min_detections, bool) else operator.index(min_detections)
        except TypeError:
            count = None
        if count is None or count < 2:
            raise ConfigError("estimator.min_detections", f"must be an integer >= 2, got {min_detections!r}")
        super().__init__(scale_error, None, estimate_scale)
        self.window = float(window)
        self.turn_rate = bool(turn_rate)
        self.min_detections = count

    def update(self, meas: CameraMeasurement) -> None:
        """Add one detection (those captured more than ``window`` before the newest are dropped,
        except the newest ``min_detections``)."""
        super().update(meas)
        ms = sorted(self._meas, key=lambda m: m.t)
        t_new = ms[-1].t
        keep = max(sum(m.t >= t_new - self.window - 1e-9 for m in ms), self.min_detections)
        self._meas = ms[-keep:]

    def _fit(self) -> tuple[Array, Array, Array, float, float, np.ndarray] | None:
        if not self._meas:
            return None
        ms = self._meas
        t_ref = max(m.t for m in ms)
        dt = np.array([m.t - t_ref for m in ms])
        scale = self.estimate_scale and all(m.p_cam_W is not None for m in ms)
        inflate = 0.0 if scale else self.scale_error  # a fitted scale error is modelled, not noise
        w = np.array([1.0 / (self._position_std(m) ** 2 + (inflate * m.distance) ** 2) for m in ms])
        P = np.array([m.p_W for m in ms], dtype=float)
        Rs = np.array([m.R_WS for m in ms], dtype=float)
        u = np.array([1.0 / max(m.sigma_ang, 1e-9) ** 2 for m in ms])
        spread = len(ms) >= 2 and np.ptp(dt) > 1e-6
        C = np.array([m.p_cam_W for m in ms], dtype=float) if scale else None

        def position_fit(omega: float) -> tuple[Array, float]:
            # p_i = p + M(dt_i) v: the CTRV displacement, linear in (p, v) for a given omega
            # (M = dt I for omega = 0); v is the velocity at t_ref.
            # With estimate_scale, as TargetEstimator: p_i = (1 + b) p(t_i) - b c_i, linear in
            # (q, u, b) = ((1 + b) p, (1 + b) v, b) with the prior b ~ N(0, scale_error^2).
            # Returns the parameters and the weighted squared residual (prior included).
            A = np.zeros((len(ms), 3, 7 if scale else 6))
            A[:, :, :3] = np.eye(3)
            x = omega * dt
            s_ = np.sin(x) / omega if abs(omega) > 1e-9 else dt
            c_ = (1.0 - np.cos(x)) / omega if abs(omega) > 1e-9 else np.zeros_like(dt)
            A[:, 0, 3], A[:, 0, 4], A[:, 1, 3], A[:, 1, 4], A[:, 2, 5] = s_, -c_, c_, s_, dt
            if C is not None:
                A[:, :, 6] = -C
                X = _whitened_lstsq(A, P, w, 6, self.scale_error)
                prior = float(X[6] / self.scale_error) ** 2
            else:
                X = np.linalg.solve(np.einsum("i,ija,ijb->ab", w, A, A), np.einsum("i,ija,ij->a", w, A, P))
                prior = 0.0
            r = np.einsum("ija,a->ij", A, X) - P
            return X, float(np.einsum("i,ij,ij->", w, r, r)) + prior

        omega = 0.0
        if self.turn_rate and spread:
            # omega from both the pad's yaw (the direction of s2 = e3 x h, a straight line in
            # time) and the curvature of its track: minimise the yaw fit's squared residual
            # (a parabola in omega about the yaw-only slope) plus the position fit's, over
            # omega. The track pins a turn far better than a few degrees of normal noise do.
            yaw = np.unwrap(np.arctan2(-Rs[:, 0, 1], Rs[:, 1, 1]))
            A = np.column_stack([np.ones_like(dt), dt])
            N = A.T @ (u[:, None] * A)
            omega_yaw = float(np.linalg.solve(N, A.T @ (u * yaw))[1])
            curvature = N[1, 1] - N[0, 1] ** 2 / N[0, 0]  # 1 / var(omega_yaw)
            sd = curvature ** -0.5 if curvature > 0 else 1.0

            def cost(om: float) -> float:
                return position_fit(om)[1] + curvature * (om - omega_yaw) ** 2

            span = max(8.0 * sd, 0.05)
            res = minimize_scalar(cost, bounds=(omega_yaw - span, omega_yaw + span), method="bounded",
                                  options={"xatol": 1e-6})
            omega = float(res.x)
        if spread:
            X, _ = position_fit(omega)
            k = 1.0 / (1.0 + X[6]) if scale else 1.0
            p, vel = k * X[:3], k * X[3:6]
        else:
            p, vel = (w @ P) / w.sum(), np.zeros(3)
        turned = np.array([rot_z(-omega * d) @ Ri for d, Ri in zip(dt, Rs, strict=True)])  # each at t_ref
        R = project_so3(np.einsum("i,ijk->jk", u, turned) / u.sum())
        return p, vel, R, float(t_ref), omega, w

    def estimate(self) -> TargetEstimate | None:
        """The pad pose at the latest capture time (as :meth:`TargetEstimator.estimate`)."""
        fit = self._fit()
        if fit is None:
            return None
        p, _, R, t_ref, _, w = fit
        return TargetEstimate(p_W=p, R_WS=R, sigma_pos=float(w.sum() ** -0.5), sigma_ang=float("nan"),
                              n_measurements=self._n, t_last=t_ref)

    def target(self, model: MotionModel) -> MovingTarget | None:
        """The fused platform as an :class:`avp.platform.MovingTarget` with ``model``, or None."""
        fit = self._fit()
        if fit is None:
            return None
        p, vel, R, t_ref, omega, _ = fit
        return MovingTarget(point=p, R_WS=R, heading=float(np.arctan2(vel[1], vel[0])),
                            speed=float(np.hypot(vel[0], vel[1])), turn_rate=omega,
                            vertical_speed=float(vel[2]), time=t_ref, model=model)

