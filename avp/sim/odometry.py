"""Odometry noise: what the controller and the camera believe about the vehicle's own state.

The paper localises the vehicle with VIO upsampled to 300 Hz (Sec. VI-A) and studies injected
zero-mean Gaussian noise on the state estimate (Sec. VI-C, Fig. 10). We model exactly that:
independent white Gaussian noise on each odometry sample, drawn from an explicit
``np.random.Generator`` (no drift; a random walk is easy to add on top if a study needs it).
Defaults (1 cm, 2 cm/s, 0.5 deg, 0.01 rad/s per axis) are of the order of a good VIO.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ConfigError
from ._so3 import expm_so3
from .vehicle import RigidBodyState

__all__ = ["OdometryNoise", "noisy_odometry"]


@dataclass(frozen=True)
class OdometryNoise:
    """Per-axis standard deviations of the odometry error.

    Parameters
    ----------
    sigma_p:
        Position (m), in W.
    sigma_v:
        Velocity (m/s), in W.
    sigma_att:
        Attitude (rad), a right perturbation ``R_WB exp(hat(delta))`` with ``delta`` in B.
    sigma_omega:
        Body rate (rad/s), in B.
    """

    sigma_p: float = 0.01
    sigma_v: float = 0.02
    sigma_att: float = float(np.deg2rad(0.5))
    sigma_omega: float = 0.01

    def __post_init__(self) -> None:
        for name in ("sigma_p", "sigma_v", "sigma_att", "sigma_omega"):
            val = getattr(self, name)
            if not (np.isfinite(val) and val >= 0):
                raise ConfigError(f"odometry.{name}", f"must be a finite std >= 0, got {val}")


def noisy_odometry(
    state: RigidBodyState, noise: OdometryNoise, rng: np.random.Generator
) -> RigidBodyState:
    """One odometry sample: ``state`` with independent Gaussian errors of ``noise``'s stds.

    Draws 12 normals from ``rng`` (always, so the stream does not depend on which stds are 0).
    """
    n = rng.standard_normal(12)
    return RigidBodyState._trusted(
        state.p_W + noise.sigma_p * n[0:3],
        state.v_W + noise.sigma_v * n[3:6],
        state.R_WB @ expm_so3(noise.sigma_att * n[6:9]),
        state.omega_B + noise.sigma_omega * n[9:12],
    )
