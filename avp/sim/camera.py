"""The camera sensor that localises the perch pad (Sec. VI-B, Fig. 9), built on :class:`avp.Camera`.

One camera. :class:`CameraParams` *holds* the planner's :class:`avp.Camera` (mounting ``R_BC``,
FoV cone (7), range) and adds only what the sensor needs: an offset from the centre of mass, a
frame rate, latency, dropouts and the error model. Visibility is :meth:`avp.Camera.sees` (the
planner's own test) plus a minimum range and an optional incidence limit; there is no second FoV
test. :func:`avp.sim.run.simulate` hands the same :class:`avp.Camera` object to the planner.

Timing. Frames are captured at ``rate_hz`` (10 Hz, as in the paper) at ``phase + k / rate_hz``;
a frame is consumed whether or not the pad is visible, is lost with probability ``dropout`` and
is delivered ``latency`` s after capture (composed with the pose the robot believed at capture).

Error model (each term can be set to 0):

- Noise growing with range. Fig. 9 shows the AprilTag localisation error growing roughly
  exponentially with distance: a few centimetres at 1-2 m, tens of centimetres at 7-8 m::

      sigma_p(d)   = 0.012 m * exp(d / 2.6 m)     (1.8 cm at 1 m, 2.6 cm at 2 m, 21 cm at 7.5 m)
      sigma_ang(d) = 0.5 deg * exp(d / 2.6 m)     (0.7 deg at 1 m, 9 deg at 7.5 m)

  per axis in C; rotation noise is a right perturbation ``R_CS exp(hat(delta))``.
- Scale error: the measured relative position is ``(1 + b) p_C``, ``b = bias_sign * scale_bias``,
  a bias proportional to range along the line of sight (a wrong tag size or focal length does
  exactly this). The sign is drawn per run unless ``bias_sign`` fixes it.
- Tilted normal: the measured pad rotation is ``exp(normal_tilt hat(u)) R_WS`` for a unit axis
  ``u`` in the pad plane drawn per run (a constant error of the normal).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from .. import _validate as v
from ..camera import FRONT_CAMERA_R_BC, Camera
from ..errors import ConfigError
from ..frames import Array, expm_so3
from .vehicle import RigidBodyState

__all__ = ["FRONT_CAMERA_R_BC", "CameraMeasurement", "CameraParams", "CameraSensor"]


def _default_camera() -> Camera:
    return Camera(range=10.0)


@v.typed_keywords("camera")
@dataclass(frozen=True, eq=False)
class CameraParams:
    """The planner's :class:`avp.Camera` plus timing and the error model (module docstring).

    Parameters
    ----------
    camera:
        :class:`avp.Camera` (mounting, FoV cone, range; default: front camera, 35 deg, 10 m).
    p_B:
        Camera offset from the centre of mass in B (m).
    min_range:
        Closer than this (m) the tag is not detected.
    max_incidence:
        Optional: the pad's face must be turned towards the camera within this angle (rad).
    rate_hz, phase:
        Frame rate (Hz) and time of frame 0 (s).
    latency:
        Capture-to-delivery delay (s).
    dropout:
        Probability that a due frame with the pad in view gives no detection.
    sigma0_pos, d0_pos, sigma0_ang, d0_ang:
        Range-growing noise ``sigma0 exp(d / d0)`` (m, m, rad, m).
    scale_bias:
        Range-proportional bias (fraction of the range, along the line of sight).
    bias_sign:
        +1 (ranges too long), -1 (too short) or None (drawn per run).
    normal_tilt:
        Constant tilt of the measured pad normal (rad), about a per-run axis in the pad plane.
    """

    camera: Camera = field(default_factory=_default_camera)
    p_B: Any = (0.0, 0.0, 0.0)
    min_range: float = 0.05
    max_incidence: float | None = None
    rate_hz: float = 10.0
    phase: float = 0.0
    latency: float = 0.0
    dropout: float = 0.0
    sigma0_pos: float = 0.012
    d0_pos: float = 2.6
    sigma0_ang: float = float(np.deg2rad(0.5))
    d0_ang: float = 2.6
    scale_bias: float = 0.0
    bias_sign: float | None = None
    normal_tilt: float = 0.0

    def __post_init__(self) -> None:
        if not isinstance(self.camera, Camera):
            raise ConfigError("camera.camera", f"must be an avp.Camera, got {type(self.camera).__name__}")
        object.__setattr__(self, "p_B", v.vector("camera.p_B", self.p_B))
        for name in ("rate_hz", "d0_pos", "d0_ang"):
            object.__setattr__(self, name, v.positive_float(f"camera.{name}", getattr(self, name)))
        for name in ("min_range", "sigma0_pos", "sigma0_ang", "latency", "scale_bias", "normal_tilt", "dropout"):
            object.__setattr__(self, name, v.nonnegative_float(f"camera.{name}", getattr(self, name)))
        if not self.min_range < self.camera.range:
            raise ConfigError("camera.min_range", "need 0 <= min_range < camera.range (m)")
        if not self.dropout < 1.0:
            raise ConfigError("camera.dropout", f"must be a probability in [0, 1), got {self.dropout}")
        if self.bias_sign not in (None, 1, -1, 1.0, -1.0) or isinstance(self.bias_sign, (bool, np.bool_)):
            raise ConfigError("camera.bias_sign", "must be +1, -1 or None (random per run)")

    @property
    def R_BC(self) -> Array:
        """Mounting rotation of :attr:`camera`."""
        return np.asarray(self.camera.R_BC)

    @property
    def half_fov(self) -> float:
        """FoV half-angle of :attr:`camera` (rad)."""
        return float(self.camera.half_fov)

    @property
    def max_range(self) -> float:
        """Detection range of :attr:`camera` (m)."""
        return float(self.camera.range)

    def ideal(self) -> CameraParams:
        """The same camera without noise, bias, latency or dropouts."""
        return CameraParams(camera=self.camera, p_B=self.p_B, min_range=self.min_range,
                            max_incidence=self.max_incidence, rate_hz=self.rate_hz, phase=self.phase,
                            sigma0_pos=0.0, sigma0_ang=0.0)

    def sigma_position(self, distance: npt.ArrayLike) -> Array:
        """Per-axis position std (m) at ``distance`` (m): ``sigma0_pos exp(d / d0_pos)``."""
        return self.sigma0_pos * np.exp(np.asarray(distance, dtype=float) / self.d0_pos)

    def sigma_angle(self, distance: npt.ArrayLike) -> Array:
        """Per-axis rotation std (rad) at ``distance`` (m): ``sigma0_ang exp(d / d0_ang)``."""
        return self.sigma0_ang * np.exp(np.asarray(distance, dtype=float) / self.d0_ang)

    def pose_W(self, p_W: Array, R_WB: Array) -> tuple[Array, Array]:
        """Camera position and rotation ``(p_cam_W, R_WC)`` for the vehicle pose ``(p_W, R_WB)``."""
        return p_W + R_WB @ self.p_B, self.camera.R_WC(R_WB)


@dataclass(frozen=True, eq=False)
class CameraMeasurement:
    """One detection of the pad captured at time ``t`` (s).

    ``p_C, R_CS`` is the measured relative pose in C; ``p_W, R_WS`` the same composed with the
    vehicle pose believed at capture. ``sigma_pos`` (m) and ``sigma_ang`` (rad) are the per-axis
    stds of the model at the true ``distance`` (m), for the estimator's weights; ``t_delivered``
    is when the robot gets it (``t + latency``); ``p_cam_W`` the camera position the robot
    believed at capture.
    """

    t: float
    p_W: Array
    R_WS: Array
    p_C: Array
    R_CS: Array
    distance: float
    sigma_pos: float
    sigma_ang: float
    t_delivered: float = float("nan")
    p_cam_W: Array | None = None


class CameraSensor:
    """Produces pad detections at ``rate_hz`` while the pad is visible (module docstring).

    Parameters
    ----------
    params:
        :class:`CameraParams`.
    rng:
        Draws the per-run bias sign and tilt axis (when random) at construction.
    """

    def __init__(self, params: CameraParams | None = None, rng: np.random.Generator | None = None) -> None:
        self.params = params if params is not None else CameraParams()
        draws = (rng if rng is not None else np.random.default_rng(0)).random(2)
        sign = self.params.bias_sign if self.params.bias_sign is not None else (1.0 if draws[0] < 0.5 else -1.0)
        self.scale = float(sign) * self.params.scale_bias
        self.tilt_phase = float(2.0 * math.pi * draws[1])
        self._next_frame: float | None = None
        self._queue: deque[CameraMeasurement] = deque()

    def reset(self) -> None:
        """Forget the frame schedule and any detection in flight."""
        self._next_frame = None
        self._queue.clear()

    def visible(self, state: RigidBodyState, target_p_W: Array, target_R_WS: Array) -> bool:
        """Whether the pad centre is seen (:meth:`avp.Camera.sees`, at least ``min_range``
        away, optionally facing the camera)."""
        cp = self.params
        p_cam = state.p_W + state.R_WB @ cp.p_B
        if not bool(cp.camera.sees(p_cam, state.R_WB, target_p_W)):
            return False
        n_d = np.asarray(target_p_W, dtype=float) - p_cam
        d = float(np.linalg.norm(n_d))
        if d < cp.min_range:
            return False
        if cp.max_incidence is not None:
            return float(-n_d @ np.asarray(target_R_WS)[:, 2]) >= np.cos(cp.max_incidence) * d
        return True

    def _frame_due(self, t: float) -> bool:
        period = 1.0 / self.params.rate_hz
        if self._next_frame is None:
            k = np.ceil((t - self.params.phase) / period - 1e-9)
            self._next_frame = self.params.phase + k * period
        if t + 1e-9 < self._next_frame:
            return False
        k = np.floor((t - self.params.phase) / period + 1e-9) + 1
        self._next_frame = self.params.phase + k * period
        return True

    def measure(
        self,
        t: float,
        state: RigidBodyState,
        target_p_W: npt.ArrayLike,
        target_R_WS: npt.ArrayLike,
        rng: np.random.Generator,
        believed: RigidBodyState | None = None,
    ) -> CameraMeasurement | None:
        """A detection captured at ``t`` if a frame is due, the pad visible and the frame not
        dropped, else None (ignores the latency: see :meth:`poll`).

        Parameters
        ----------
        t:
            Current time (s); call at least once per frame period (e.g. every control step).
        state:
            True vehicle state (sets visibility and the true relative pose).
        target_p_W, target_R_WS:
            True pad centre (m) and rotation ``[s1 s2 s3]``.
        rng:
            Source of the measurement noise (7 uniforms/normals per due frame with the pad seen).
        believed:
            Vehicle state the robot believes (odometry) at capture, used to express the detection
            in W; the true state when omitted.
        """
        if not self._frame_due(t):
            return None
        p_S = np.asarray(target_p_W, dtype=float)
        R_WS = np.asarray(target_R_WS, dtype=float)
        if not self.visible(state, p_S, R_WS):
            return None
        cp = self.params
        n = rng.standard_normal(6)
        if rng.random() < cp.dropout:
            return None
        p_cam, R_WC = cp.pose_W(state.p_W, state.R_WB)
        d = float(np.linalg.norm(p_S - p_cam))
        sp, sa = float(cp.sigma_position(d)), float(cp.sigma_angle(d))
        p_C = (1.0 + self.scale) * (R_WC.T @ (p_S - p_cam)) + sp * n[:3]
        R_meas = R_WS
        if cp.normal_tilt > 0.0:
            u = math.cos(self.tilt_phase) * R_WS[:, 0] + math.sin(self.tilt_phase) * R_WS[:, 1]
            R_meas = expm_so3(cp.normal_tilt * u) @ R_WS
        R_CS = R_WC.T @ R_meas @ expm_so3(sa * n[3:])
        b = believed if believed is not None else state
        p_cam_b, R_WC_b = cp.pose_W(b.p_W, b.R_WB)
        return CameraMeasurement(
            t=float(t), p_W=p_cam_b + R_WC_b @ p_C, R_WS=R_WC_b @ R_CS, p_C=p_C, R_CS=R_CS,
            distance=d, sigma_pos=sp, sigma_ang=sa, t_delivered=float(t) + cp.latency, p_cam_W=p_cam_b,
        )

    def poll(
        self,
        t: float,
        state: RigidBodyState,
        target_p_W: npt.ArrayLike,
        target_R_WS: npt.ArrayLike,
        rng: np.random.Generator,
        believed: RigidBodyState | None = None,
    ) -> list[CameraMeasurement]:
        """Capture (as :meth:`measure`) and return every detection delivered by ``t`` (latency)."""
        m = self.measure(t, state, target_p_W, target_R_WS, rng, believed)
        if m is not None:
            self._queue.append(m)
        out = []
        while self._queue and self._queue[0].t_delivered <= t + 1e-9:
            out.append(self._queue.popleft())
        return out
