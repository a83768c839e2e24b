"""Closed-loop evaluation simulator for avp (not flight code; the core ``avp`` never imports it).

Pieces, each seeded through an explicit ``np.random.Generator`` where random:

- :mod:`~avp.sim.vehicle`: rigid-body dynamics (1), RK4, thrust and moment limits;
- :mod:`~avp.sim.controller`: geometric SE(3) controller (2) with body-rate (22) and
  angular-acceleration feed-forward;
- :mod:`~avp.sim.flight`: :func:`fly`, vehicle + controller over a stretch of time;
- :mod:`~avp.sim.odometry`: odometry noise;
- :mod:`~avp.sim.camera`: front camera with FoV (7), 10 Hz and distance-dependent error (Fig. 9);
- :mod:`~avp.sim.estimator`: inverse-variance fusion of the detections;
- :mod:`~avp.sim.contact`: pad contact and the success criterion.
"""

from .camera import FRONT_CAMERA_R_BC, Camera, CameraMeasurement, CameraParams, in_fov
from .contact import Contact, PerchPad, SuccessCriteria, detect_contact
from .controller import (
    ControllerGains,
    ControlOutput,
    FlatReference,
    angular_acceleration,
    control,
)
from .estimator import TargetEstimate, TargetEstimator
from .flight import DT_CONTROL, FlightResult, Trace, fly
from .odometry import OdometryNoise, noisy_odometry
from .vehicle import RigidBodyState, VehicleParams, step

__all__ = [
    "DT_CONTROL",
    "FRONT_CAMERA_R_BC",
    "Camera",
    "CameraMeasurement",
    "CameraParams",
    "Contact",
    "ControlOutput",
    "ControllerGains",
    "FlatReference",
    "FlightResult",
    "OdometryNoise",
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
    "in_fov",
    "noisy_odometry",
    "step",
]
