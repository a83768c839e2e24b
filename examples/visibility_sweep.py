"""The paper's Table I: target visibility (time % / path %) against the contact velocity.

Sign convention (docs/perception.md, docs/conventions.md): the paper's tables swap the component names.
Columns are the speed *into* the pad (our ``ContactVelocity.normal = -v``, the paper's "v_S1" in
{0, 1, 2}; its 0 column is planned at 0.05 m/s, since a contact velocity with ``v . s3 >= 0``
never reaches the pad and is rejected); rows are the slide along the slope (our ``ContactVelocity.slope``, the paper's "v_S3"
in {free, -3, -2, -1, 0, 1}; negative = down the slope). Every plan has the same duration (as in
the paper), a 90 deg wall 3.5 m ahead, start hovering at the pad height facing it.

    python examples/visibility_sweep.py --out visibility_sweep.png [--distance 3.5] [--no-fov]
"""

from __future__ import annotations

import argparse
import dataclasses
import math

import numpy as np

from avp import (
    ContactVelocity,
    FovConfig,
    PerchTarget,
    PlannerConfig,
    State,
    plan_detailed,
    visibility,
)
from avp.timing import initial_durations

INTO_PAD = (0.05, 1.0, 2.0)
SLOPE = (None, -3.0, -2.0, -1.0, 0.0, 1.0)


def sweep(distance: float, fov: bool) -> np.ndarray:
    """``(len(SLOPE), len(INTO_PAD), 2)`` array of (time, path) fractions; NaN = no plan."""
    state = State.hover([0.0, 0.0, 1.0])
    target = PerchTarget.from_incline([distance, 0.0, 1.0], math.radians(90.0))
    base = PlannerConfig(fov=FovConfig(enabled=fov))
    T = initial_durations(state, target, base)
    out = np.full((len(SLOPE), len(INTO_PAD), 2), np.nan)
    for i, slope in enumerate(SLOPE):
        for j, into in enumerate(INTO_PAD):
            cfg = dataclasses.replace(base, contact_velocity=ContactVelocity(normal=-into, slope=slope))
            result = plan_detailed(state, target, cfg, durations=T)
            if result.ok and result.trajectory is not None:
                vis = visibility(result.trajectory, target, cfg.fov.camera, dt=1e-3)
                out[i, j] = vis.time_fraction, vis.path_fraction
    return out


def table(values: np.ndarray) -> str:
    head = "v.s1 (slope) \\ into pad | " + " | ".join(f"{v:>13g} m/s" for v in INTO_PAD)
    lines = [head, "-" * len(head)]
    for i, slope in enumerate(SLOPE):
        cells = [
            "   no plan   " if np.isnan(values[i, j, 0]) else f"{100 * values[i, j, 0]:5.1f}%/{100 * values[i, j, 1]:5.1f}%"
            for j in range(len(INTO_PAD))
        ]
        lines.append(f"{'free' if slope is None else f'{slope:+g}':>23} | " + " | ".join(f"{c:>17}" for c in cells))
    return "\n".join(lines)


def heatmap(values: np.ndarray, path: str, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(9, 4.5), constrained_layout=True)
    for k, (ax, name) in enumerate(zip(axes, ("time", "path"), strict=True)):
        im = ax.imshow(100 * values[:, :, k], vmin=0, vmax=100, cmap="viridis")
        ax.set_xticks(range(len(INTO_PAD)), [f"{v:g}" for v in INTO_PAD])
        ax.set_yticks(range(len(SLOPE)), ["free" if s is None else f"{s:+g}" for s in SLOPE])
        ax.set_xlabel("speed into the pad, -v.s3 (m/s)")
        ax.set_ylabel("slide v.s1 (m/s, - = down)")
        ax.set_title(f"{name} visible (%)")
        for i in range(len(SLOPE)):
            for j in range(len(INTO_PAD)):
                val = values[i, j, k]
                ax.text(j, i, "-" if np.isnan(val) else f"{100 * val:.0f}", ha="center", va="center", color="w")
        fig.colorbar(im, ax=ax, shrink=0.8)
    fig.suptitle(title)
    fig.savefig(path, dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="visibility_sweep.png", help="heatmap PNG path")
    parser.add_argument("--distance", type=float, default=3.5, help="start-to-wall distance (m)")
    parser.add_argument("--no-fov", action="store_true", help="plan without the FoV rows (8)")
    args = parser.parse_args()
    vals = sweep(args.distance, not args.no_fov)
    title = f"90 deg wall, {args.distance:g} m, FoV rows {'off' if args.no_fov else 'on'}"
    print(title)
    print(table(vals))
    heatmap(vals, args.out, title)
    print(f"wrote {args.out}")
