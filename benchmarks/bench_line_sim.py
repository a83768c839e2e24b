"""Closed-loop line perches in the simulator: Paneque et al.'s pitches.

    python benchmarks/bench_line_sim.py --trials 20
    python benchmarks/bench_line_sim.py --realistic --trials 30

``--realistic``: :func:`avp.sim.line_run.simulate_line`, the realistic models (rotor mixer and
20 ms motor lag, odometry noise with drift, noisy line detections at 30 Hz fused by the user),
one-shot planning against replanning with :class:`avp.LineReplanner`, the success criterion of
:class:`avp.sim.line_run.LineCriteria` (gripper within ``--grip-tol`` of the true line, ``b3``
within ``--angle-tol``, speed below ``--speed-tol``, clearance kept to ``--clear-tol``).

Without it (below): the ideal loop, one-shot with a perfect line estimate.

For each final pitch of ``bench_line.paneque_setups`` (20, 80, 180 deg), ``trials`` seeded runs:
the start is perturbed (``--start-sigma`` m per axis), :func:`avp.plan_line` plans the perch from
the perturbed start, and the SE(3) controller of :mod:`avp.sim` (500 Hz, rigid-body dynamics,
noisy odometry with the simulator's default standard deviations) flies it to ``t_f``. There is no
line contact model: a run **succeeds** when, at ``t_f``, the true gripper (CoM - r b3) is within
``--grip-tol`` of the line, ``b3`` within ``--angle-tol`` of the commanded normal and the speed
below ``--speed-tol``, and the true CoM never came closer to the line than ``r - --clear-tol``
before. The tolerances stand for a gripper's capture envelope (assumed; the paper does not give
one). Vehicle: 0.8 kg, thrust 0.5-31.4 N (T/W 4:1), the inertia of the simulator's default vehicle
scaled by the mass ratio 1.6 (assumed); ideal actuators here (no mixer, no motor lag), the
realistic ones with ``--realistic``. Tracking RMSE is printed next to the
paper's own (Paneque et al., "Perception-Aware Perching on Powerlines with Multirotors", Table I:
position RMSE 2.7-6.9 cm, pitch-roll RMSE 2.0-3.0 deg without perception awareness).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
from pathlib import Path

import numpy as np

import avp
from avp.config import PlannerConfig, Workspace
from avp.line_planner import plan_line
from avp.sim.controller import FlatReference
from avp.sim.flight import fly
from avp.sim.odometry import OdometryNoise
from avp.sim.vehicle import RigidBodyState, VehicleParams

sys.path.insert(0, str(Path(__file__).parent))
from bench_line import paneque_setups


def reference(traj: avp.Trajectory):
    def ref(t: float) -> FlatReference:
        f = traj.flat_output(min(max(t, traj.t0), traj.tf))
        return FlatReference(f.position, f.velocity, f.acceleration, f.jerk, f.snap,
                             float(f.yaw), float(f.yaw_rate), float(f.yaw_acceleration))
    return ref


def vehicle_params(lim: avp.VehicleLimits) -> VehicleParams:
    """Paneque et al.'s vehicle on the simulator's default airframe scaled by the mass ratio."""
    k = lim.mass / 0.5
    base = VehicleParams()
    return VehicleParams(limits=lim, inertia=tuple(k * np.asarray(base.inertia, dtype=float)))


def realistic(args: argparse.Namespace) -> None:
    from avp.sim.line_run import LineCriteria, LineDetector, LineScenario, simulate_line

    lim, setups = paneque_setups()
    params = vehicle_params(lim)
    crit = LineCriteria(gripper=args.grip_tol, angle=math.radians(args.angle_tol), speed=args.speed_tol,
                        clearance=args.clear_tol)
    det = LineDetector(sigma=args.det_sigma, sigma_per_metre=args.det_sigma_per_metre)
    print(f"realistic simulator, {args.trials} seeded trials per pitch and mode, start sigma {args.start_sigma} m, "
          f"detector {det}, criteria: gripper <= {100 * args.grip_tol:g} cm, b3 <= {args.angle_tol:g} deg, "
          f"speed <= {args.speed_tol:g} m/s, clearance >= -{100 * args.clear_tol:g} cm")
    print("| pitch | mode | success | no plan | gripper err cm median / p90 / max | b3 err deg median / max "
          "| min CoM-line dist - r (cm) | final estimate err cm median | solve ms median / p95 |")
    print("|---|---|---|---|---|---|---|---|---|")
    for pitch, (line, start, ground) in setups.items():
        for mode in ("one_shot", "avp"):
            grip, ang, clear, est, solves = [], [], [], [], []
            ok = no_plan = 0
            for trial in range(args.trials):
                rng = np.random.default_rng(1000 * pitch + trial)
                p0 = np.asarray(start, dtype=float) + rng.normal(0.0, args.start_sigma, 3)
                sc = LineScenario(line, p0, ground, detector=det, vehicle=params, criteria=crit)
                res = simulate_line(sc, mode, seed=trial)
                solves.extend(res.solve_times.tolist())
                if res.outcome.startswith("no plan"):
                    no_plan += 1
                    continue
                ok += res.success
                grip.append(res.gripper_error)
                ang.append(math.degrees(res.angle_error))
                clear.append(res.clearance)
                est.append(res.estimate_error)
            n = args.trials
            if not grip:
                print(f"| {pitch} | {mode} | 0/{n} | {no_plan} | - | - | - | - | - |")
                continue
            print(f"| {pitch} | {mode} | {ok}/{n} ({100 * ok / n:.0f} %) | {no_plan} | "
                  f"{100 * np.median(grip):.2f} / {100 * np.percentile(grip, 90):.2f} / {100 * max(grip):.2f} | "
                  f"{np.median(ang):.2f} / {max(ang):.2f} | {100 * min(clear):.2f} | {100 * np.median(est):.1f} | "
                  f"{1e3 * np.median(solves):.1f} / {1e3 * np.percentile(solves, 95):.1f} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--start-sigma", type=float, default=0.05)
    ap.add_argument("--grip-tol", type=float, default=0.03)
    ap.add_argument("--angle-tol", type=float, default=10.0)
    ap.add_argument("--speed-tol", type=float, default=0.3)
    ap.add_argument("--clear-tol", type=float, default=0.02)
    ap.add_argument("--realistic", action="store_true", help="the realistic simulator, one-shot vs replanning")
    ap.add_argument("--det-sigma", type=float, default=0.005, help="line detection noise at 0 m, m per axis")
    ap.add_argument("--det-sigma-per-metre", type=float, default=0.01, help="growth of the detection noise, m per m")
    args = ap.parse_args()
    if args.realistic:
        realistic(args)
        return
    lim, setups = paneque_setups()
    params = dataclasses.replace(vehicle_params(lim), mixer=False, motor_time_constant=0.0)
    noise = OdometryNoise()
    print("| pitch | trials | planned | success | gripper err cm median / max | b3 err deg median / max "
          "| speed at t_f m/s max | min CoM-line dist - r (cm) | pos RMSE cm | paper pos RMSE cm / pitch-roll RMSE deg |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    seed_rmse = {20: "2.7 / 2.1", 80: "3.1 / 2.0", 180: "6.9 / 3.0"}
    for pitch, (line, start, ground) in setups.items():
        cfg = PlannerConfig(limits=lim, workspace=Workspace(ground_z=ground))
        r = line.gripper_offset
        grip, ang, spd, clear, rmse = [], [], [], [], []
        planned = ok = 0
        for trial in range(args.trials):
            rng = np.random.default_rng(1000 * pitch + trial)
            p0 = np.asarray(start, dtype=float) + rng.normal(0.0, args.start_sigma, 3)
            res = plan_line(avp.State.hover(p0), line, cfg)
            if not res.ok or res.perch is None:
                continue
            planned += 1
            tr = res.perch
            R0 = tr.attitude(tr.t0)
            out = fly(RigidBodyState(p_W=p0, R_WB=R0), reference(tr), tr.t0, tr.duration, params,
                      odometry=noise, rng=rng, record=True)
            trace = out.trace
            assert trace is not None
            b3 = out.state.R_WB[:, 2]
            e_grip = line.distance(out.state.p_W - r * b3)
            e_ang = math.degrees(math.acos(min(1.0, float(b3 @ res.contact.n))))
            speed = float(np.linalg.norm(out.state.v_W))
            before = trace.t < tr.tf - 0.05
            d_min = min(line.distance(p) for p in trace.p_W[before]) - r
            err = trace.p_W - tr(np.clip(trace.t, tr.t0, tr.tf))
            rmse.append(float(np.sqrt(np.mean(np.sum(err**2, axis=1)))))
            grip.append(e_grip)
            ang.append(e_ang)
            spd.append(speed)
            clear.append(d_min)
            ok += (e_grip <= args.grip_tol and e_ang <= args.angle_tol and speed <= args.speed_tol
                   and d_min >= -args.clear_tol)
        if not planned:
            print(f"| {pitch} | {args.trials} | 0 | - | - | - | - | - | - | {seed_rmse[pitch]} |")
            continue
        print(f"| {pitch} | {args.trials} | {planned} | {ok}/{planned} ({100 * ok / planned:.0f} %) | "
              f"{100 * np.median(grip):.2f} / {100 * max(grip):.2f} | {np.median(ang):.2f} / {max(ang):.2f} | "
              f"{max(spd):.3f} | {100 * min(clear):.2f} | {100 * np.median(rmse):.2f} | {seed_rmse[pitch]} |")


if __name__ == "__main__":
    main()
