"""Fly an avp plan in rotorpy (an independent quadrotor simulator: motor dynamics, drag, its own
SE(3) controller) and report how well the vehicle follows it to the perch.

Needs the optional extra: ``pip install "avp[rotorpy]"`` (rotorpy >= 3.0). Without rotorpy the
script says how to install it and exits 0. Run: ``python examples/fly_in_rotorpy.py [--incline-deg 45]``.

rotorpy has no pad to hit: the vehicle flies through the pad's position, and we compare its state
at the plan's contact time with the plan (position, thrust axis ``b3`` against the pad normal
``s3``, velocity). Measured at 3 m (2026-12-05): 45 deg 2.6 cm / 6.7 deg, 60 deg 2.4 cm / 14.8 deg,
90 deg 6.5 cm / 23.4 deg. rotorpy's ``SE3Control`` tracks the attitude without body-rate feed-forward, so
``b3`` lags the fast pitch-up before contact, and it builds the attitude from the heading
``b1 = (cos yaw, sin yaw, 0)``, which is singular when the thrust axis is horizontal along the
heading, as on a wall (avp's own construction (11), (13) uses ``b2`` and is regular there).
``avp simulate --backend rotorpy`` flies the closed loop (replanning, camera, odometry) on
rotorpy's vehicle with avp's feed-forward controller instead (docs/simulation.md).
"""

from __future__ import annotations

import argparse
import math
import sys

import numpy as np

import avp


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--incline-deg", type=float, default=45.0, help="pad incline (deg)")
    parser.add_argument("--distance", type=float, default=3.0, help="stand-off (m)")
    args = parser.parse_args()
    try:
        from rotorpy.controllers.quadrotor_control import SE3Control
        from rotorpy.environments import Environment
        from rotorpy.vehicles.hummingbird_params import quad_params
        from rotorpy.vehicles.multirotor import Multirotor
        from rotorpy.world import World
    except ImportError:
        print('rotorpy is not installed: pip install "avp[rotorpy]" to fly the plan in it')
        return 0
    from scipy.spatial.transform import Rotation

    pad = np.array([args.distance, 0.0, 1.5])
    target = avp.PerchTarget.from_incline(pad, math.radians(args.incline_deg))
    start = avp.State.hover(pad - [args.distance, 0.0, 0.0 if args.incline_deg >= 45 else -1.0])
    # rotorpy's hummingbird: 0.5 kg; plan within its thrust (4 rotors, k_eta * 1500^2 each)
    mass = quad_params["mass"]
    f_max = 4 * quad_params["k_eta"] * quad_params["rotor_speed_max"] ** 2
    config = avp.PlannerConfig(limits=avp.VehicleLimits(mass=mass, thrust_max=min(f_max, 2 * 9.81 * mass)))
    traj = avp.plan(start, target, config)
    print(f"plan: {traj.duration:.2f} s, {traj.n_segments} segments; {traj!r}")

    vehicle = Multirotor(quad_params, initial_state={
        "x": start.position.copy(), "v": np.zeros(3), "q": np.array([0.0, 0.0, 0.0, 1.0]), "w": np.zeros(3),
        "wind": np.zeros(3), "rotor_speeds": np.full(4, math.sqrt(9.81 * mass / (4 * quad_params["k_eta"])))})
    lo, hi = np.minimum(traj(traj.sample(0.01)).min(axis=0), 0) - 1.0, traj(traj.sample(0.01)).max(axis=0) + 1.0
    world = World.empty((lo[0], hi[0], lo[1], hi[1], lo[2], hi[2]))
    env = Environment(vehicle=vehicle, controller=SE3Control(quad_params), trajectory=traj.to_rotorpy(),
                      world=world, sim_rate=500)
    result = env.run(t_final=traj.duration, use_mocap=False, terminate=False, plot=False, verbose=False)

    t = np.asarray(result["time"])
    k = int(np.argmin(np.abs(t - traj.duration)))
    x, v = result["state"]["x"][k], result["state"]["v"][k]
    b3 = Rotation.from_quat(result["state"]["q"][k]).as_matrix()[:, 2]
    pos_err = float(np.linalg.norm(x - traj(traj.tf)))
    vel_err = float(np.linalg.norm(v - traj(traj.tf, 1)))
    tilt_err = math.degrees(math.acos(float(np.clip(b3 @ target.s3, -1.0, 1.0))))
    track = float(np.max(np.linalg.norm(result["state"]["x"] - traj(traj.t0 + np.clip(t, 0, traj.duration)), axis=1)))
    print(f"rotorpy flew {t[k]:.2f} s: at contact time position error {100 * pos_err:.1f} cm, velocity error "
          f"{vel_err:.2f} m/s, b3 vs s3 {tilt_err:.1f} deg; largest tracking error {100 * track:.1f} cm")
    return 0


if __name__ == "__main__":
    sys.exit(main())
