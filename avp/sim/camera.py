"""Front camera that localises the perch pad, with a distance-dependent error (Sec. VI-B, Fig. 9).

Geometry. The camera frame C has its optical axis along ``c3``; it is mounted with rotation
``R_BC`` and offset ``p_B`` (from the centre of mass, in B). The default ``R_BC`` looks along
``b1`` (front camera) with image x along ``-b2`` and image y along ``-b3``. The pad centre ``s`` is
visible when it lies inside the one-sided FoV cone (7) of half-angle ``half_fov`` (35 deg, the
paper's 70 deg front camera)::

    cos(half_fov) |n_d| <= n_d . e_c,   n_d = s - p_cam_W,   e_c = R_WB R_BC e3

and within ``[min_range, max_range]``; optionally (``max_incidence``) the pad's face must be
turned towards the camera, ``-n_d . s3 >= cos(max_incidence) |n_d|``.

Timing. Frames arrive at ``rate_hz`` (10 Hz, as in the paper) at times ``phase + k / rate_hz``;
a frame is consumed whether or not the pad is visible.

Noise model. Fig. 9 shows the AprilTag localisation error growing roughly exponentially with
distance: a few centimetres at 1-2 m, tens of centimetres at 7-8 m. We use isotropic, per-axis
Gaussian errors in C with::

    sigma_p(d)   = 0.012 m   * exp(d / 2.6 m)     (1.8 cm at 1 m, 2.6 cm at 2 m, 21 cm at 7.5 m)
    sigma_ang(d) = 0.5 deg   * exp(d / 2.6 m)     (0.7 deg at 1 m, 9 deg at 7.5 m)

so the mean norm of the position error (about 1.6 sigma_p) is 3-4 cm at 1-2 m and 34 cm at
7.5 m. The ten-fold growth between 1.5 m and 7.5 m sets ``d0 = 6 m / ln 10 = 2.6 m``. The paper
gives no angular curve; the angular model reuses ``d0`` with a scale typical of a large tag.
Rotation noise is a right perturbation ``R_CS exp(hat(delta))``. The measured relative pose is
composed with the vehicle pose the robot believes (odometry), so odometry errors enter the
world-frame measurement as they would on the robot.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from ..errors import ConfigError
from ._so3 import Array, as_rotation, as_vector, expm_so3
from .vehicle import RigidBodyState

__all__ = ["FRONT_CAMERA_R_BC", "Camera", "CameraMeasurement", "CameraParams", "in_fov"]

FRONT_CAMERA_R_BC = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
"""Default mounting: ``c3 = b1`` (optical axis forward), ``c1 = -b2``, ``c2 = -b3``."""


@dataclass(frozen=True, eq=False)
class CameraParams:
    """Mounting, field of view, frame rate and noise model (module docstring) of the camera."""

    R_BC: Any = field(default_factory=lambda: FRONT_CAMERA_R_BC.copy())
    p_B: Any = (0.0, 0.0, 0.0)
    half_fov: float = float(np.deg2rad(35.0))
    min_range: float = 0.05
    max_range: float = 10.0
    max_incidence: float | None = None
    rate_hz: float = 10.0
    phase: float = 0.0
    sigma0_pos: float = 0.012
    d0_pos: float = 2.6
    sigma0_ang: float = float(np.deg2rad(0.5))
    d0_ang: float = 2.6

    def __post_init__(self) -> None:
        object.__setattr__(self, "R_BC", as_rotation("camera.R_BC", self.R_BC))
        object.__setattr__(self, "p_B", as_vector("camera.p_B", self.p_B))
        if not 0.0 < self.half_fov < np.pi / 2:
            raise ConfigError("camera.half_fov", "must be in (0, pi/2) rad")
        if not 0.0 <= self.min_range < self.max_range:
            raise ConfigError("camera.max_range", "need 0 <= min_range < max_range (m)")
        for name in ("rate_hz", "d0_pos", "d0_ang"):
            if not (np.isfinite(getattr(self, name)) and getattr(self, name) > 0):
                raise ConfigError(f"camera.{name}", "must be a positive finite number")
        for name in ("sigma0_pos", "sigma0_ang"):
            if not (np.isfinite(getattr(self, name)) and getattr(self, name) >= 0):
                raise ConfigError(f"camera.{name}", "must be a finite std >= 0")

    def sigma_position(self, distance: npt.ArrayLike) -> Array:
        """Per-axis position std (m) at ``distance`` (m): ``sigma0_pos exp(d / d0_pos)``."""
        return self.sigma0_pos * np.exp(np.asarray(distance, dtype=float) / self.d0_pos)

    def sigma_angle(self, distance: npt.ArrayLike) -> Array:
        """Per-axis rotation std (rad) at ``distance`` (m): ``sigma0_ang exp(d / d0_ang)``."""
        return self.sigma0_ang * np.exp(np.asarray(distance, dtype=float) / self.d0_ang)

    def pose_W(self, p_W: Array, R_WB: Array) -> tuple[Array, Array]:
        """Camera position and rotation ``(p_cam_W, R_WC)`` for the vehicle pose ``(p_W, R_WB)``."""
        return p_W + R_WB @ self.p_B, R_WB @ self.R_BC


@dataclass(frozen=True, eq=False)
class CameraMeasurement:
    """One detection of the pad at time ``t`` (s).

    ``p_C, R_CS`` is the noisy relative pose in C; ``p_W, R_WS`` the same composed with the
    vehicle pose used at measurement time. ``sigma_pos`` (m) and ``sigma_ang`` (rad) are the
    per-axis stds of the model at the true ``distance`` (m), for the estimator's weights.
    """

    t: float
    p_W: Array
    R_WS: Array
    p_C: Array
    R_CS: Array
    distance: float
    sigma_pos: float
    sigma_ang: float


def in_fov(
    target_W: npt.ArrayLike,
    p_cam_W: npt.ArrayLike,
    e_c_W: npt.ArrayLike,
    half_fov: float,
) -> npt.NDArray[np.bool_]:
    """One-sided FoV cone test ``cos(half_fov) |n_d| <= n_d . e_c``, ``n_d = target - p_cam``.

    Vectorised over leading axes; ``e_c_W`` must be a unit vector.
    """
    n_d = np.asarray(target_W, dtype=float) - np.asarray(p_cam_W, dtype=float)
    along = np.sum(n_d * np.asarray(e_c_W, dtype=float), axis=-1)
    return np.cos(half_fov) * np.linalg.norm(n_d, axis=-1) <= along


class Camera:
    """A camera producing pad detections at ``rate_hz`` while the pad is visible."""

    def __init__(self, params: CameraParams | None = None) -> None:
        self.params = params if params is not None else CameraParams()
        self._next_frame: float | None = None

    def reset(self) -> None:
        """Forget the frame schedule (the next call to :meth:`measure` starts it again)."""
        self._next_frame = None

    def visible(self, state: RigidBodyState, target_p_W: Array, target_R_WS: Array) -> bool:
        """Whether the pad centre is in the FoV cone and in range (and optionally faces us)."""
        cp = self.params
        p_cam, R_WC = cp.pose_W(state.p_W, state.R_WB)
        n_d = np.asarray(target_p_W, dtype=float) - p_cam
        d = float(np.linalg.norm(n_d))
        if not cp.min_range <= d <= cp.max_range:
            return False
        if not bool(in_fov(target_p_W, p_cam, R_WC[:, 2], cp.half_fov)):
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
        """A detection at time ``t`` if a frame is due and the pad is visible, else None.

        Parameters
        ----------
        t:
            Current time (s); call at least once per frame period (e.g. every control step).
        state:
            True vehicle state (sets visibility and the true relative pose).
        target_p_W, target_R_WS:
            True pad centre (m) and rotation ``[s1 s2 s3]``.
        rng:
            Source of the measurement noise (6 normals per detection).
        believed:
            Vehicle state the robot believes (odometry), used to express the detection in W;
            the true state when omitted.
        """
        if not self._frame_due(t):
            return None
        p_S = np.asarray(target_p_W, dtype=float)
        R_WS = np.asarray(target_R_WS, dtype=float)
        if not self.visible(state, p_S, R_WS):
            return None
        cp = self.params
        p_cam, R_WC = cp.pose_W(state.p_W, state.R_WB)
        d = float(np.linalg.norm(p_S - p_cam))
        sp, sa = float(cp.sigma_position(d)), float(cp.sigma_angle(d))
        n = rng.standard_normal(6)
        p_C = R_WC.T @ (p_S - p_cam) + sp * n[:3]
        R_CS = R_WC.T @ R_WS @ expm_so3(sa * n[3:])
        b = believed if believed is not None else state
        p_cam_b, R_WC_b = cp.pose_W(b.p_W, b.R_WB)
        return CameraMeasurement(
            t=float(t),
            p_W=p_cam_b + R_WC_b @ p_C,
            R_WS=R_WC_b @ R_CS,
            p_C=p_C,
            R_CS=R_CS,
            distance=d,
            sigma_pos=sp,
            sigma_ang=sa,
        )
