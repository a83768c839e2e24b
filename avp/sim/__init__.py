"""Closed-loop evaluation simulator for avp (not flight code; the core ``avp`` never imports it).

One vehicle and one camera: the simulated vehicle holds the planner's
:class:`avp.config.VehicleLimits` and the camera the planner's :class:`avp.Camera`. Pieces, each
seeded through an explicit ``np.random.Generator`` where random, each effect configurable and
off-able:

- :mod:`~avp.sim.vehicle`: rigid-body dynamics (1), RK4, rotor mixer with per-rotor limits and
  first-order motor lag;
- :mod:`~avp.sim.controller`: geometric SE(3) controller (2) with body-rate (22) and
  angular-acceleration feed-forward;
- :mod:`~avp.sim.flight`: :func:`fly`, vehicle + controller over a stretch of time;
- :mod:`~avp.sim.backend`: what integrates the vehicle, avp's model (1) or rotorpy's
  ``Multirotor`` (optional: ``pip install "avp[rotorpy]"``, imported only when asked for);
- :mod:`~avp.sim.odometry`: odometry at its own rate with white noise and drift;
- :mod:`~avp.sim.camera`: detections in the FoV at 10 Hz with latency, dropouts, range-growing
  noise, scale bias and a tilted normal;
- :mod:`~avp.sim.estimator`: the user-side target filter (inverse-variance fusion);
- :mod:`~avp.sim.contact`: pad contact and the success criterion;
- :mod:`~avp.sim.run` / :mod:`~avp.sim.evaluate`: one run, comparisons and sweeps;
- :mod:`~avp.sim.limit`: the ideal perch on a run's own target estimates (what the estimate allows).
- :mod:`~avp.sim.line_run`: one closed-loop line perch (:func:`~avp.sim.line_run.simulate_line`).
"""

from .camera import FRONT_CAMERA_R_BC, CameraMeasurement, CameraParams, CameraSensor
from .contact import (
    Contact,
    PerchCriteria,
    PerchOutcome,
    PerchPad,
    SuccessCriteria,
    detect_contact,
    judge_perch,
)
from .controller import (
    ControllerGains,
    ControlOutput,
    FlatReference,
    angular_acceleration,
    control,
)
from .estimator import TargetEstimate, TargetEstimator
from .flight import DT_CONTROL, FlightResult, Trace, fly
from .odometry import Odometry, OdometryNoise, noisy_odometry
from .vehicle import RigidBodyState, VehicleParams, step

__all__ = [
    "DT_CONTROL",
    "FRONT_CAMERA_R_BC",
    "CameraMeasurement",
    "CameraParams",
    "CameraSensor",
    "Contact",
    "ControlOutput",
    "ControllerGains",
    "FlatReference",
    "FlightResult",
    "Odometry",
    "OdometryNoise",
    "PerchCriteria",
    "PerchOutcome",
    "PerchPad",
    "RigidBodyState",
    "SuccessCriteria",
    "TargetEstimate",
    "TargetEstimator",
    "Trace",
    "VehicleParams",
    "angular_acceleration",
    "control",
    "detect_contact",
    "fly",
    "judge_perch",
    "noisy_odometry",
    "step",
]
