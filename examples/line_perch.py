"""Perch upside down under a powerline and plan the recovery (Paneque et al.'s 180 deg case).

    python examples/line_perch.py
"""

from __future__ import annotations

import math

import numpy as np

import avp

limits = avp.VehicleLimits(mass=0.8, thrust_min=0.5, thrust_max=4 * 0.8 * 9.81)  # T/W 4:1
config = avp.PlannerConfig(limits=limits, workspace=avp.Workspace(ground_z=0.8))  # min height
line = avp.LineTarget.segment([2.0, -1.5, 3.7], [2.0, 1.5, 3.7], pitch=math.pi, gripper_offset=0.15)
result = avp.plan_line(avp.State.hover([0.0, 0.0, 2.5]), line, config)

print(f"status: {result.status.name}")
perch, recovery = result.perch, result.recovery
b3 = perch.attitude(perch.tf)[:, 2]
gripper = perch(perch.tf) - line.gripper_offset * b3
print(f"perch {perch.duration:.2f} s, gripper {1e3 * line.distance(gripper):.1e} mm from the line, "
      f"b3 = {np.round(b3, 6).tolist()}")
print(f"recovery {recovery.duration:.2f} s to {np.round(recovery(recovery.tf), 3).tolist()}")
print(f"certificates: {sum(c.ok for c in result.certificates)}/{len(result.certificates)} proven, "
      f"bounds {'certified' if result.bounds.certified and result.recovery_bounds.certified else 'NOT certified'}")
print(f"planning time {1e3 * result.timings['total']:.1f} ms")
