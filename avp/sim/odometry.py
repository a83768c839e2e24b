"""Odometry: what the controller, the planner and the camera believe about the vehicle's state.

The paper localises the vehicle with VIO upsampled to 300 Hz (Sec. VI-A) and studies injected
zero-mean Gaussian noise (Sec. VI-C, Fig. 10). Real VIO also drifts. :class:`Odometry` is one
estimator shared by every consumer, as on a robot:

- its error is refreshed at ``rate_hz`` (between updates the estimate follows the true motion
  with the last error, as an IMU-propagated filter output does);
- white Gaussian noise per update (``sigma_p``, ``sigma_v``, ``sigma_att``, ``sigma_omega``);
- a position random walk (drift) of ``drift_p`` m/sqrt(s) per axis (VIO drifts slowly).

Everything is drawn from one explicit ``np.random.Generator``. :func:`noisy_odometry` is the
memoryless white-noise sample (no rate, no drift).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import _validate as v
from ..frames import expm_so3
from .vehicle import RigidBodyState

__all__ = ["Odometry", "OdometryNoise", "noisy_odometry"]


@v.typed_keywords("odometry")
@dataclass(frozen=True)
class OdometryNoise:
    """Odometry error model (per-axis standard deviations; module docstring).

    Parameters
    ----------
    sigma_p:
        Position white noise (m), in W.
    sigma_v:
        Velocity white noise (m/s), in W.
    sigma_att:
        Attitude (rad), a right perturbation ``R_WB exp(hat(delta))`` with ``delta`` in B.
    sigma_omega:
        Body rate (rad/s), in B.
    drift_p:
        Position random walk (m/sqrt(s)) per axis; 0: no drift.
    rate_hz:
        Rate at which the error is refreshed (Hz).

    Defaults: 3 mm, 1 cm/s, 0.2 deg, 0.01 rad/s, drift 5 mm/sqrt(s) (about 9 mm after a 3 s
    perch), 200 Hz: a good VIO.
    """

    sigma_p: float = 0.003
    sigma_v: float = 0.01
    sigma_att: float = float(np.deg2rad(0.2))
    sigma_omega: float = 0.01
    drift_p: float = 0.005
    rate_hz: float = 200.0

    def __post_init__(self) -> None:
        for name in ("sigma_p", "sigma_v", "sigma_att", "sigma_omega", "drift_p"):
            object.__setattr__(self, name, v.nonnegative_float(f"odometry.{name}", getattr(self, name)))
        object.__setattr__(self, "rate_hz", v.positive_float("odometry.rate_hz", self.rate_hz))


def noisy_odometry(
    state: RigidBodyState, noise: OdometryNoise, rng: np.random.Generator
) -> RigidBodyState:
    """One memoryless sample: ``state`` with independent white errors of ``noise``'s stds.

    Draws 12 normals from ``rng`` (always, so the stream does not depend on which stds are 0).
    """
    n = rng.standard_normal(12)
    return RigidBodyState._trusted(
        state.p_W + noise.sigma_p * n[0:3],
        state.v_W + noise.sigma_v * n[3:6],
        state.R_WB @ expm_so3(noise.sigma_att * n[6:9]),
        state.omega_B + noise.sigma_omega * n[9:12],
        state.rotor_speeds,
    )


class Odometry:
    """A stateful odometry stream: white noise refreshed at ``rate_hz`` plus a drift."""

    def __init__(self, noise: OdometryNoise, rng: np.random.Generator) -> None:
        self.noise = noise
        self._rng = rng
        self._t_next: float | None = None
        self.drift = np.zeros(3)
        self._white = np.zeros(12)

    def _refresh(self, t: float) -> None:
        period = 1.0 / self.noise.rate_hz
        if self._t_next is None:
            self._t_next = t
        while t + 1e-12 >= self._t_next:
            n = self._rng.standard_normal(15)
            self._white = n[:12]
            self.drift = self.drift + self.noise.drift_p * math.sqrt(period) * n[12:]
            self._t_next += period

    def sample(self, t: float, state: RigidBodyState) -> RigidBodyState:
        """The estimate at time ``t`` (s) of the true ``state``."""
        self._refresh(t)
        nz, n = self.noise, self._white
        return RigidBodyState._trusted(
            state.p_W + nz.sigma_p * n[0:3] + self.drift,
            state.v_W + nz.sigma_v * n[3:6],
            state.R_WB @ expm_so3(nz.sigma_att * n[6:9]),
            state.omega_B + nz.sigma_omega * n[9:12],
            state.rotor_speeds,
        )
