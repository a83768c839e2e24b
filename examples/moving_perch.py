"""Perch on a pad carried by a turning car (CTRV model), after Gao et al., "Adaptive Tracking and
Perching for Quadrotor in Dynamic Scenarios": plan once from a tracking position, print the
arrival time, the contact state against the predicted pad and the certificates."""

from __future__ import annotations

import math

import avp


def main() -> None:
    limits = avp.VehicleLimits(mass=1.0, thrust_min=5.0, thrust_max=17.0, tilt_rate_max=3.0)
    # The road is at z = 0: keep the centre of mass 0.3 m above it (certified, like the limits).
    config = avp.PlannerConfig(limits=limits, pre_impact=avp.PreImpactMode.OFF,
                               workspace=avp.Workspace(ground_z=0.3))
    # A 0.5 rad plane in the trunk of a car driving at 2.5 m/s and turning at 0.2 rad/s.
    pad = avp.MovingTarget.on_platform([0.0, 0.0, 1.0], incline=0.5, speed=2.5, turn_rate=0.2)
    start = avp.State(position=[-3.0, 0.0, 1.0], velocity=pad.velocity)  # 3 m behind, tracking
    result = avp.plan_moving_detailed(start, pad, config)
    print(f"status: {result.status.name}, arrival after {result.arrival_time:.2f} s, "
          f"{result.n_solves} QP solves")
    c = result.contact
    assert c is not None
    print(f"contact: position error {c.position:.1e} m, b3 vs s3 {math.degrees(c.attitude):.1e} deg, "
          f"relative normal speed error {c.normal_velocity:.1e} m/s, slip ({c.slip[0]:.2f}, {c.slip[1]:.2f}) m/s, "
          f"thrust {c.thrust:.2f} m/s^2")
    print(f"bounds certified: {result.bounds is not None and result.bounds.certified}")
    print(result.clearance.summary() if result.clearance else "no clearance report")
    print(f"ground and other workspace limits certified: {result.safety is not None and result.safety.certified}")


if __name__ == "__main__":
    main()
