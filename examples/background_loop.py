"""A real-time 30 Hz loop whose replanner plans in a worker process (avp.BackgroundReplanner).

The loop's call never plans: it adopts the plan the worker finished since the last call and sends
the new odometry and estimate, so it costs a fraction of a millisecond whatever a plan costs. A
plan requested at one call is adopted at a later one, so ``ReplanConfig.latency`` is set above
the loop's period: the plan then starts (at ``t_ex``) after it is adopted. The loop runs on the
wall clock here (it sleeps to its next tick), with a perfect-tracking stand-in for the vehicle
and an estimate that drifts from 10 cm off towards the truth, as in ``replan_loop.py``.
"""

import time

import numpy as np

import avp

if __name__ == "__main__":  # not needed by the worker (a fresh interpreter), good practice in a script
    truth = avp.PerchTarget.from_incline([3.5, 0.0, 1.5], np.radians(90.0))
    guess = avp.PerchTarget(point=truth.point + [0.10, 0.05, -0.08], R_WS=truth.R_WS)
    dt = 1.0 / 30.0
    inner = avp.Replanner(guess, replan=avp.ReplanConfig(latency=1.5 * dt))  # latency above the period
    with avp.BackgroundReplanner(inner) as replanner:  # starts the worker; closes it at the end
        odometry = avp.State.hover([0.0, 0.0, 1.5])
        t, t_wall0, loop_cpu = 0.0, time.perf_counter(), []
        while True:
            blend = min(t / 1.0, 1.0)  # the estimate converges over the first second
            estimate = avp.PerchTarget(point=(1 - blend) * guess.point + blend * truth.point, R_WS=truth.R_WS)
            c0 = time.thread_time()
            out = replanner.step(t, odometry, estimate)  # adopts, sends; waits only for the first plan
            loop_cpu.append(time.thread_time() - c0)
            if out.adopted is not None:
                s = out.adopted
                print(f"t={t:5.3f} s  adopted the step of t={out.requested:5.3f} s: {s.action.name:20s} "
                      f"(worker {out.plan_cpu * 1e3:5.2f} ms CPU, late {out.late * 1e3:.1f} ms)  {s.reason}")
            plan = replanner.trajectory
            if plan is None:
                raise SystemExit("no first plan")
            if t >= plan.tf:
                break
            t = min(t + dt, plan.tf)
            time.sleep(max(t_wall0 + t - time.perf_counter(), 0.0))  # the next tick, on the wall clock
            ref = replanner.reference(t)  # what the controller tracks now
            odometry = avp.State(position=ref.position, velocity=ref.velocity, acceleration=ref.acceleration,
                                 jerk=ref.jerk, yaw=float(ref.yaw), yaw_rate=float(ref.yaw_rate), time=t)
        final = replanner.trajectory
    miss = np.linalg.norm(final(final.tf) - truth.point)
    cpu_ms = np.array(loop_cpu[1:]) * 1e3  # the first call waited for the first plan
    print(f"contact at t={final.tf:.3f} s, {miss * 100:.1f} cm from the true pad centre; the loop's calls: "
          f"median {np.median(cpu_ms):.3f} ms CPU, max {cpu_ms.max():.3f} ms over {cpu_ms.size} calls")
