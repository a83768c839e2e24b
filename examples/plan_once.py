"""Plan one perch on a 60 deg slope, inspect the result and fly it open loop in rotorpy's
trajectory format. The shortest tour of the planning API."""

import math

import numpy as np

import avp

if __name__ == "__main__":
    target = avp.PerchTarget.from_incline([4.0, 1.0, 1.2], math.radians(60), heading=0.2)
    state = avp.State(position=[0.0, 0.0, 1.5], velocity=[0.5, 0.0, 0.0], yaw=0.2)
    limits = avp.VehicleLimits(mass=0.8, thrust_max=0.8 * 18.0, tilt_rate_max=8.0)
    config = avp.PlannerConfig(limits=limits, solver="daqp")

    result = avp.plan_detailed(state, target, config)
    print(f"status: {result.status.value}")
    print("\n".join(f"  {line}" for line in result.log))
    traj = result.trajectory
    if not result.ok or traj is None:
        raise SystemExit(1)

    t = traj.sample(0.001)
    print(f"duration {traj.duration:.3f} s over knots {np.round(traj.knots, 3).tolist()}")
    print(f"thrust {traj.thrust(t, mass=limits.mass).min():.2f}..{traj.thrust(t, mass=limits.mass).max():.2f} N, "
          f"peak tilt rate {np.linalg.norm(traj.body_rates(t)[:, :2], axis=1).max():.2f} rad/s")
    print(f"contact error {np.linalg.norm(traj(traj.tf) - target.point):.1e} m, "
          f"R_WB vs R_WS {math.degrees(avp.frames.rotation_error_angle(traj.attitude(traj.tf), target.R_WS)):.1e} deg")
    print(f"visibility (time, path): {avp.visibility(traj, target)}")
    flat = traj.to_rotorpy().update(0.5)  # rotorpy's flat-output dict, time from the plan start
    print("rotorpy flat output at 0.5 s:", {k: np.round(v, 3).tolist() for k, v in flat.items()})
