"""Your own 30 Hz loop around avp.Replanner: odometry and target estimate in, reference out.

Here a perfect-tracking stand-in replaces the vehicle (odometry = the reference being flown) and
the target estimate drifts from 10 cm off towards the truth, as a camera's would while approaching.
Every committed plan is certified (actuator bounds and trackability); a step whose action is
``CANNOT_REACH`` is the cue to abort or go around (``step.target_error``, ``step.reach_budget``),
as is ``step.off_track`` that persists (the vehicle is off the plan it flies).
"""

import numpy as np

import avp

if __name__ == "__main__":
    truth = avp.PerchTarget.from_incline([3.5, 0.0, 1.5], np.radians(90.0))
    guess = avp.PerchTarget(point=truth.point + [0.10, 0.05, -0.08], R_WS=truth.R_WS)
    # deadline=None: the same steps on any machine; on a vehicle, deadline=0.004 bounds each step
    # near 4 ms (a solve starts only while it is predicted to fit; docs/performance.md)
    replanner = avp.Replanner(guess, replan=avp.ReplanConfig(latency=0.02, deadline=None))

    t, dt = 0.0, 1.0 / 30.0
    odometry = avp.State.hover([0.0, 0.0, 1.5])
    while True:
        blend = min(t / 1.0, 1.0)  # the estimate converges over the first second
        estimate = avp.PerchTarget(point=(1 - blend) * guess.point + blend * truth.point, R_WS=truth.R_WS)
        step = replanner.step(t, odometry, estimate)
        print(f"t={t:5.3f} s  {step.action.name:20s} solve {step.solve_time * 1e3:5.1f} ms  "
              f"off by {step.target_error * 100:4.1f} cm  {step.reason}")
        if step.action is avp.ReplanAction.CANNOT_REACH:
            print(f"  cannot reach the estimate: {step.target_error:.3f} m off, budget {step.reach_budget:.3f} m:"
                  " a real vehicle would go around here")
        if step.off_track:  # the vehicle is off the plan it flies and no plan from it certified
            print(f"  off track by {step.tracking_error:.3f} m: a real vehicle would abort if this persists")
        if step.trajectory is None or t >= step.trajectory.tf:
            break
        t = min(t + dt, step.trajectory.tf)
        ref = replanner.reference(t)  # what the controller tracks now
        odometry = avp.State(position=ref.position, velocity=ref.velocity, acceleration=ref.acceleration,
                             jerk=ref.jerk, yaw=float(ref.yaw), yaw_rate=float(ref.yaw_rate), time=t)

    final = replanner.trajectory
    assert final is not None, "no plan"
    miss = np.linalg.norm(final(final.tf) - truth.point)
    print(f"contact at t={final.tf:.3f} s, {miss * 100:.1f} cm from the true pad centre")
