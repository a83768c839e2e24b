"""Optional matplotlib figures (imported lazily by the CLI; the planning core never imports it)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from .trajectory import Trajectory
    from .types import PerchTarget


def plot_perch(trajectory: Trajectory, target: PerchTarget, path: str | Path, title: str = "") -> Path:
    """3D path with thrust-direction arrows (as the paper's Fig. 13) and time histories of
    position, velocity and acceleration; written as PNG to ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = trajectory.sample(1e-3)
    d = trajectory.derivatives(t, (0, 1, 2))
    p, v, a = d[0, :, :3], d[1, :, :3], d[2, :, :3]
    fig = plt.figure(figsize=(13, 6.5))
    ax = fig.add_subplot(1, 2, 1, projection="3d")
    ax.plot(p[:, 0], p[:, 1], p[:, 2], "k-", lw=1.5, label="path")
    ta = np.linspace(trajectory.t0, trajectory.tf, 14)
    R = trajectory.attitude(ta)
    pa = trajectory(ta)
    span = float(np.ptp(p, axis=0).max()) or 1.0
    ax.quiver(pa[:, 0], pa[:, 1], pa[:, 2], R[:, 0, 2], R[:, 1, 2], R[:, 2, 2],
              length=0.12 * span, color="tab:red", label="thrust axis b3")
    # pad as a square in the S frame
    s1, s2, c = target.s1, target.s2, target.point
    h = 0.15 * span
    corners = np.array([c + h * (i * s1 + j * s2) for i, j in ((-1, -1), (1, -1), (1, 1), (-1, 1), (-1, -1))])
    ax.plot(corners[:, 0], corners[:, 1], corners[:, 2], "b-", lw=2, label="pad")
    ax.quiver(*c, *target.s3, length=0.1 * span, color="b")
    mid = 0.5 * (p.max(axis=0) + p.min(axis=0))
    for setter, m in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), mid, strict=True):
        setter(m - 0.55 * span, m + 0.55 * span)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title(title or "perching trajectory")
    for row, (vals, name, unit) in enumerate(((p, "position", "m"), (v, "velocity", "m/s"), (a, "acceleration", "m/s$^2$"))):
        axr = fig.add_subplot(3, 2, 2 * row + 2)
        for k, lab in enumerate("xyz"):
            axr.plot(t - trajectory.t0, vals[:, k], label=lab)
        axr.set_ylabel(f"{name} ({unit})")
        axr.grid(alpha=0.3)
        if row == 0:
            axr.legend(fontsize=8, ncol=3)
    axr.set_xlabel("time (s)")
    fig.tight_layout()
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
