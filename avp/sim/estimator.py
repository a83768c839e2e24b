"""Target (perch pad) estimator: inverse-variance fusion of camera detections.

The pad is static, so the best linear unbiased estimate of its centre from independent detections
with per-axis stds ``sigma_i`` (the camera's ``sigma_p(d_i)``, Fig. 9) is the weighted mean with
weights ``w_i = 1 / sigma_i^2``; its per-axis std is ``(sum w_i)^-1/2``. Far, noisy detections
therefore fade as soon as close ones arrive, which is what AVP's replanning exploits (Sec. IV).

The rotation is the weighted chordal L2 mean: ``M = sum_i u_i R_i`` with ``u_i = 1/sigma_ang_i^2``,
projected onto SO(3) (polar factor, det +1). For small, isotropic errors this is the maximum
likelihood rotation to first order. Running sums make every update O(1).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..frames import Array, project_so3
from .camera import CameraMeasurement

__all__ = ["TargetEstimate", "TargetEstimator"]


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
    """Fuses :class:`~avp.sim.camera.CameraMeasurement` objects into one pad pose estimate."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """Drop every measurement."""
        self._w_pos = 0.0
        self._wp = np.zeros(3)
        self._w_ang = 0.0
        self._wR = np.zeros((3, 3))
        self._n = 0
        self._t_last = float("nan")

    @property
    def n_measurements(self) -> int:
        """Number of fused detections."""
        return self._n

    def update(self, meas: CameraMeasurement) -> None:
        """Fuse one detection, weighted by the inverse variances it carries."""
        w_p = 1.0 / max(meas.sigma_pos, 1e-9) ** 2
        w_a = 1.0 / max(meas.sigma_ang, 1e-9) ** 2
        self._w_pos += w_p
        self._wp += w_p * np.asarray(meas.p_W, dtype=float)
        self._w_ang += w_a
        self._wR += w_a * np.asarray(meas.R_WS, dtype=float)
        self._n += 1
        self._t_last = float(meas.t)

    def estimate(self) -> TargetEstimate | None:
        """The current fused pad pose, or None before the first detection."""
        if self._n == 0:
            return None
        return TargetEstimate(
            p_W=self._wp / self._w_pos,
            R_WS=project_so3(self._wR / self._w_ang),
            sigma_pos=float(self._w_pos**-0.5),
            sigma_ang=float(self._w_ang**-0.5),
            n_measurements=self._n,
            t_last=self._t_last,
        )
