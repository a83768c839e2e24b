"""Real-time loops whose replanner plans in a worker process (avp.BackgroundReplanner).

The replanning loop (30 Hz) never plans: its call sends the new odometry and estimate to the
worker. The control loop (here 300 Hz) calls ``poll`` before it reads its reference, so a plan is
flown within a control period of the worker's finishing it, and it starts at its switch time
``t_ex = t + latency`` (the default 20 ms leaves the worker time to plan). Both loops run on the
wall clock here (they sleep to their next tick), with a perfect-tracking stand-in for the vehicle
and an estimate that drifts from 10 cm off towards the truth, as in ``replan_loop.py``.
"""

import time

import numpy as np

import avp

if __name__ == "__main__":  # not needed by the worker (a fresh interpreter), good practice in a script
    truth = avp.PerchTarget.from_incline([3.5, 0.0, 1.5], np.radians(90.0))
    guess = avp.PerchTarget(point=truth.point + [0.10, 0.05, -0.08], R_WS=truth.R_WS)
    replan_period, control_period = 1.0 / 30.0, 1.0 / 300.0
    with avp.BackgroundReplanner(avp.Replanner(guess)) as replanner:  # starts the worker; closes it at the end
        odometry = avp.State.hover([0.0, 0.0, 1.5])
        t, t_next_replan, t_wall0 = 0.0, 0.0, time.perf_counter()
        loop_cpu, lates = [], []
        while True:
            c0 = time.thread_time()
            if t >= t_next_replan:  # the replanning loop's tick: sends (waits only for the first plan)
                blend = min(t / 1.0, 1.0)  # the estimate converges over the first second
                estimate = avp.PerchTarget(point=(1 - blend) * guess.point + blend * truth.point, R_WS=truth.R_WS)
                out = replanner.step(t, odometry, estimate)
                t_next_replan += replan_period
            else:  # the control loop's tick: adopts a finished plan, if any
                out = replanner.poll(t)
            loop_cpu.append(time.thread_time() - c0)
            if out is not None and out.adopted is not None:
                s = out.adopted
                lates.append(out.late)
                print(f"t={t:5.3f} s  adopted the step of t={out.requested:5.3f} s: {s.action.name:20s} "
                      f"(worker {out.plan_cpu * 1e3:5.2f} ms CPU, late {out.late * 1e3:.1f} ms)  {s.reason}")
            plan = replanner.trajectory
            if plan is None:
                raise SystemExit("no first plan")
            if t >= plan.tf:
                break
            t = min(t + control_period, plan.tf)
            time.sleep(max(t_wall0 + t - time.perf_counter(), 0.0))  # the next tick, on the wall clock
            ref = replanner.reference(t)  # what the controller tracks now
            odometry = avp.State(position=ref.position, velocity=ref.velocity, acceleration=ref.acceleration,
                                 jerk=ref.jerk, yaw=float(ref.yaw), yaw_rate=float(ref.yaw_rate), time=t)
        final = replanner.trajectory
    miss = np.linalg.norm(final(final.tf) - truth.point)
    cpu_ms = np.array(loop_cpu[1:]) * 1e3  # the first call waited for the first plan
    print(f"contact at t={final.tf:.3f} s, {miss * 100:.1f} cm from the true pad centre; the loops' calls: "
          f"median {np.median(cpu_ms):.3f} ms CPU, max {cpu_ms.max():.3f} ms over {cpu_ms.size} calls; "
          f"{sum(x > 0 for x in lates)} of {len(lates)} steps adopted after their switch time")
