"""Figures of a plan (matplotlib, an optional extra: ``pip install "avp[plot]"``; the planning
core never imports this module, and this module imports matplotlib only when a figure is drawn).

:func:`plot_plan` draws what the certificates are about:

- a 3D view of the path with **equal axes** (a 45 deg pad looks like 45 deg), the pad to scale,
  the ground plane, thrust arrows (along ``b3``, length proportional to the thrust), the start and
  the contact point, the path coloured where the target is in the camera's field of view;
- time histories of the thrust (10) against ``[thrust_min, thrust_max]`` / mass, of the tilt rate
  ``sqrt(w1^2 + w2^2)`` and the body rate ``|w|`` (22) against their limits, with the certificate's
  verdict and the sampled margin in the legend; roll, pitch and yaw; the height above the ground and
  the distance to the pad plane; knots as dotted lines, the pre-impact window ``[t_f - t_k, t_f]``
  (14) shaded, the visibility band along the time axis;
- with a rotor drag (``VehicleLimits.rotor_drag``), the thrust ``a + g e3 + d v``, and the attitude,
  body rates and camera view it sets, as the certificates have them;
- a failed or relaxed plan stamped as such in the title and across the 3D view.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .errors import ConfigError

if TYPE_CHECKING:  # pragma: no cover
    from .trajectory import Trajectory
    from .types import PerchTarget

__all__ = ["MatplotlibMissingError", "animate_run", "euler_zxy", "figure_plan", "pad_corners", "plot_perch", "plot_plan", "pyplot"]

PAD_HALF_SIZE = 0.15
"""Half the side (m) of the square pad drawn (the paper's pad is about 0.3 m wide)."""

LABEL_COLORS = {"SOLVED": "tab:green", "RELAXED": "tab:orange", "FAILED": "tab:red"}


class MatplotlibMissingError(ImportError):
    """matplotlib is not installed (``pip install "avp[plot]"``)."""


def pyplot() -> Any:
    """``matplotlib.pyplot`` on the non-interactive Agg backend, or :class:`MatplotlibMissingError`."""
    try:
        import matplotlib
    except ImportError as exc:
        raise MatplotlibMissingError('plots need matplotlib: pip install "avp[plot]"') from exc
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def euler_zxy(R: Any) -> np.ndarray:
    """Roll, pitch, yaw (rad) with ``R_WB = Rz(yaw) Rx(roll) Ry(pitch)``, shape ``(..., 3)``.

    This is the convention of the attitude construction (11), (13) (``b2`` stays in the plane of
    ``e3`` and the heading ``(-sin yaw, cos yaw, 0)``), so ``yaw`` is the flat output and the only
    singularity is at roll = +-90 deg; a wall perch (pitch -90 deg) and a ceiling (pitch 180 deg)
    are regular. Pitch and yaw are unwrapped along the first axis."""
    R = np.asarray(R, dtype=float)
    roll = np.arcsin(np.clip(R[..., 2, 1], -1.0, 1.0))
    pitch = np.arctan2(-R[..., 2, 0], R[..., 2, 2])
    yaw = np.arctan2(-R[..., 0, 1], R[..., 1, 1])
    if R.ndim > 2:
        pitch, yaw = np.unwrap(pitch), np.unwrap(yaw)
    return np.stack([roll, pitch, yaw], axis=-1)


def pad_corners(target: PerchTarget, half_size: float = PAD_HALF_SIZE) -> np.ndarray:
    """``(4, 3)`` corners (W, m) of the square pad of side ``2 half_size`` in the plane of
    ``s1, s2`` about the pad centre, in order around it."""
    s1, s2, c = target.s1, target.s2, target.point
    return np.array([c + half_size * (i * s1 + j * s2) for i, j in ((-1, -1), (1, -1), (1, 1), (-1, 1))])


def _verdict(bounds: Any, name: str) -> str:
    """``certified`` / ``VIOLATED`` / ``not certified`` / ``not checked`` for one bound."""
    if bounds is None:
        return "not certified"
    from .bounds import Bound, Certificate

    verdicts = bounds.verdicts.get(Bound(name), ())
    if not verdicts or all(v is Certificate.NOT_CHECKED for v in verdicts):
        return "not checked"
    if any(v is Certificate.VIOLATED for v in verdicts):
        return "VIOLATED"
    return "certified" if all(v is Certificate.WITHIN for v in verdicts) else "not certified"


def plot_plan(result: Any, target: PerchTarget, path: str | Path, *, dpi: int = 110, **kwargs: Any) -> Path:
    """Write :func:`figure_plan` to ``path`` (PNG; ``.png`` is added to a name without a
    suffix, as matplotlib does) and return the path written."""
    plt = pyplot()
    fig = figure_plan(result, target, **kwargs)
    out = Path(path)
    if not out.suffix:
        out = out.with_suffix(".png")
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=dpi)
    plt.close(fig)
    return out


def figure_plan(
    result: Any,
    target: PerchTarget,
    *,
    config: Any = None,
    ground_z: float | None = None,
    title: str = "",
    label: str | None = None,
    pad_half_size: float = PAD_HALF_SIZE,
) -> Any:
    """The matplotlib ``Figure`` of a plan (module docstring).

    ``result`` is a :class:`~avp.planner.PlanResult` (its status, bound report and relaxations
    mark the figure) or a bare :class:`~avp.trajectory.Trajectory`. ``config`` gives the limits,
    the band window and the camera (default :class:`~avp.config.PlannerConfig`); ``label`` is
    ``"SOLVED"``, ``"RELAXED"`` or ``"FAILED"`` (default: from ``result`` as ``avp demo`` decides
    its exit code)."""
    from .config import PlannerConfig
    from .trajectory import Trajectory
    from .types import PerchTarget

    if not isinstance(target, PerchTarget):
        raise ConfigError("target", f"the figure draws a pad perch (avp.PerchTarget), got {type(target).__name__}; "
                                    "a line or a moving pad has no figure here")
    plt = pyplot()
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection  # type: ignore[import-untyped]

    cfg = config if config is not None else PlannerConfig()
    if isinstance(result, Trajectory):
        traj, status_text, bounds, relaxations = result, "", None, ()
        label = label or "SOLVED"
    else:
        traj = result.trajectory
        if traj is None:
            raise ValueError("the result has no trajectory to plot")
        status_text = result.status.value
        bounds = result.bounds
        relaxations = tuple(r.name.lower() for r in result.relaxations)
        if label is None:
            from .cli import plan_label

            label = plan_label(result)
    color = LABEL_COLORS.get(label, "tab:red")

    t = traj.sample(min(1e-3, traj.duration / 400))
    tt = t - traj.t0
    d = traj.derivatives(t, (0, 1, 2, 3))
    p = d[0, :, :3]
    # the thrust is the drag-aware a + g e3 + d v (VehicleLimits.rotor_drag), as certified: the
    # attitude, the camera's view, the thrust and the body rates drawn are the vehicle's
    drag = cfg.limits.rotor_drag
    R = traj.attitude(t, rotor_drag=drag)
    thrust = traj.thrust(t, rotor_drag=drag)
    w = traj.body_rates(t, rotor_drag=drag)
    tilt_rate = np.hypot(w[:, 0], w[:, 1])
    body_rate = np.linalg.norm(w, axis=1)
    visible = cfg.fov.camera.sees(p, R, target.point)
    lim = cfg.limits

    fig = plt.figure(figsize=(15, 9), layout="constrained")
    fig.get_layout_engine().set(wspace=0.06)  # room for the 3D view's z label
    gs = fig.add_gridspec(5, 2, width_ratios=(1.15, 1), height_ratios=(1, 1, 1, 1, 0.35))

    # -- 3D view, equal axes ---------------------------------------------------------------
    ax = fig.add_subplot(gs[:, 0], projection="3d")
    seg_vis = np.where(visible, 0, 1)
    for flag, col, lab in ((0, "tab:blue", "path, target in view"), (1, "0.35", "path, target out of view")):
        pv = np.where((seg_vis == flag)[:, None], p, np.nan)
        ax.plot(pv[:, 0], pv[:, 1], pv[:, 2], "-", color=col, lw=2, label=lab)
    s3, c, h = target.s3, target.point, pad_half_size
    corners = pad_corners(target, h)
    pad = Poly3DCollection([corners], facecolors="tab:purple", edgecolors="k", alpha=0.7)
    pad.set_gid("pad")
    ax.add_collection3d(pad)
    pts = np.vstack([p, corners])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    if ground_z is not None:  # the ground inside the box, whichever side of it the path is
        lo[2], hi[2] = min(lo[2], ground_z), max(hi[2], ground_z)
    span = float((hi - lo).max()) or 1.0
    mid = 0.5 * (lo + hi)
    halves = np.maximum(0.55 * (hi - lo), 0.2 * span)  # per axis; one scale for all (box aspect)
    ax.quiver(*c, *s3, length=0.12 * span, color="tab:purple", lw=1.5)
    # thrust arrows along b3, length proportional to the thrust (m per m/s^2)
    ta = np.linspace(traj.t0, traj.tf, 16)
    Ra = traj.attitude(ta, rotor_drag=drag)
    pa = traj(ta)
    fa = traj.thrust(ta, rotor_drag=drag)
    scale = 0.12 * span / max(float(fa.max()), 1e-9)
    ax.quiver(pa[:, 0], pa[:, 1], pa[:, 2], *(Ra[:, :, 2] * (scale * fa)[:, None]).T,
              color="tab:red", lw=1.2, arrow_length_ratio=0.25)
    ax.scatter(*p[0], s=60, color="tab:green", marker="o", depthshade=False, zorder=5)
    ax.scatter(*p[-1], s=120, color="k", marker="*", depthshade=False, zorder=5)
    if ground_z is not None:
        gx = np.array([mid[0] - halves[0], mid[0] + halves[0]])
        gy = np.array([mid[1] - halves[1], mid[1] + halves[1]])
        GX, GY = np.meshgrid(gx, gy)
        ax.plot_surface(GX, GY, np.full_like(GX, ground_z), color="tab:brown", alpha=0.15, shade=False,
                        gid="ground")
    ax.set_xlim(mid[0] - halves[0], mid[0] + halves[0])
    ax.set_ylim(mid[1] - halves[1], mid[1] + halves[1])
    ax.set_zlim(mid[2] - halves[2], mid[2] + halves[2])
    ax.set_box_aspect(tuple(halves))  # equal scale on every axis: angles are true
    ax.view_init(elev=18, azim=-65)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    handles, _ = ax.get_legend_handles_labels()
    handles += [
        Line2D([], [], color="tab:red", lw=1.2, label="thrust along b3 (to scale)"),
        Patch(facecolor="tab:purple", alpha=0.7, label=f"pad {2 * h:g} m, to scale; arrow s3"),
        Line2D([], [], color="tab:green", marker="o", ls="", label="start"),
        Line2D([], [], color="k", marker="*", ms=10, ls="", label="contact"),
    ]
    if ground_z is not None:
        handles.append(Patch(facecolor="tab:brown", alpha=0.3, label=f"ground z = {ground_z:g} m"))
    ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, 1.0), ncol=3, fontsize=8, framealpha=0.8)
    if label != "SOLVED":
        ax.text2D(0.5, 0.5, label, transform=ax.transAxes, fontsize=60, color=color, alpha=0.25,
                  ha="center", va="center", rotation=25, weight="bold", gid="stamp")

    # -- time histories ------------------------------------------------------------------------
    axes = [fig.add_subplot(gs[k, 1]) for k in range(5)]
    for a in axes[1:]:
        a.sharex(axes[0])
    tk = cfg.t_k
    knots = traj.knots_rel

    def decorate(a: Any) -> None:
        for k in knots[1:-1]:
            a.axvline(k, color="0.5", ls=":", lw=0.8)
        a.axvspan(knots[-1] - tk, knots[-1], color="tab:orange", alpha=0.12, lw=0)
        a.grid(alpha=0.3)

    a = axes[0]
    a.plot(tt, thrust, color="tab:red", label=f"thrust ({_verdict(bounds, 'thrust_max')} max, "
                                              f"{_verdict(bounds, 'thrust_min')} min)")
    margin = min(lim.accel_max - thrust.max(), thrust.min() - lim.accel_min)
    a.axhline(lim.accel_max, color="k", ls="--", lw=1, label=f"limits / mass (sampled margin {margin:.2f})",
              gid="thrust_max")
    a.axhline(lim.accel_min, color="k", ls="--", lw=1, gid="thrust_min")
    a.set_ylabel("thrust (m/s$^2$)")
    a.legend(fontsize=7, loc="upper left")
    decorate(a)

    a = axes[1]
    a.plot(tt, tilt_rate, color="tab:blue", label=f"tilt rate ({_verdict(bounds, 'tilt_rate')})")
    a.plot(tt, body_rate, color="tab:purple", lw=1, label=f"body rate |w| ({_verdict(bounds, 'body_rate')})")
    for val, col, name in ((lim.tilt_rate_max, "tab:blue", "tilt-rate limit"),
                           (lim.body_rate_max, "tab:purple", "body-rate limit")):
        if math.isfinite(val):
            a.axhline(val, color=col, ls="--", lw=1, label=f"{name} {val:g}", gid=name)
    finite = [x for x in (lim.tilt_rate_max, lim.body_rate_max) if math.isfinite(x)]
    peak = float(body_rate.max())
    if finite and peak > 3 * max(finite):  # keep the limit readable; say how far the peak goes
        a.set_ylim(0, 3 * max(finite))
        a.annotate(f"peak {peak:.0f} rad/s", xy=(tt[int(np.argmax(body_rate))], 3 * max(finite)),
                   xytext=(-10, -12), textcoords="offset points", ha="right", fontsize=8, color="tab:red")
    a.set_ylabel("rate (rad/s)")
    a.legend(fontsize=7, loc="upper left")
    decorate(a)

    a = axes[2]
    eul = np.degrees(euler_zxy(R))
    for k, (name, col) in enumerate((("roll", "tab:blue"), ("pitch", "tab:orange"), ("yaw", "tab:green"))):
        a.plot(tt, eul[:, k], color=col, label=name)
    a.set_ylabel("attitude (deg)")
    a.legend(fontsize=7, loc="upper left", ncol=3, title="R_WB = Rz(yaw) Rx(roll) Ry(pitch)", title_fontsize=7)
    decorate(a)

    a = axes[3]
    a.plot(tt, (p - target.point) @ s3, color="tab:purple", label="distance to pad plane (p - pad).s3")
    if ground_z is not None:
        a.plot(tt, p[:, 2] - ground_z, color="tab:brown", label="height above ground")
    a.axhline(0.0, color="k", lw=0.8)
    safety = None if isinstance(result, Trajectory) else getattr(result, "safety", None)
    verdict = None if safety is None else ("workspace certified" if safety.certified else "workspace NOT certified")
    a.set_ylabel("clearance (m)")
    a.legend(fontsize=7, loc="upper right", title=verdict, title_fontsize=7)
    decorate(a)

    a = axes[4]
    a.fill_between(tt, 0, visible.astype(float), step="mid", color="tab:blue", alpha=0.6, lw=0)
    a.set_yticks([])
    a.set_ylim(0, 1)
    a.set_ylabel("in view", rotation=0, ha="right", va="center")
    decorate(a)
    a.set_xlabel("time since start (s); dotted: knots, shaded: pre-impact window t_k")
    for a in axes[:-1]:
        a.tick_params(labelbottom=False)

    head = title or "perching plan"
    sub = f"{label}: {status_text}" if status_text else label
    if relaxations:
        sub += f" (relaxed: {', '.join(relaxations)})"
    sub += f"; {traj.duration:.2f} s, {traj.n_segments} segments, in view {100 * visible.mean():.0f}% of the time"
    fig.suptitle(f"{head}\n{sub}", fontsize=12, color=color if label != "SOLVED" else "k")
    return fig


def plot_perch(trajectory: Trajectory, target: PerchTarget, path: str | Path, title: str = "") -> Path:
    """A trajectory on its own (no status, default limits): :func:`plot_plan` of it."""
    return plot_plan(trajectory, target, path, title=title)


def animate_run(run: Any, path: str | Path, *, fps: int = 20, speed: float = 0.5, pad_half_size: float | None = None) -> Path:
    """Animated GIF of a closed-loop run (:class:`avp.sim.run.SimResult`): the true path in the
    vertical plane of the approach (x, z; equal axes), the pad, the vehicle with its thrust axis,
    the committed plan, and whether the pad is in the camera's view; ``speed`` is the playback
    rate (0.5: half real time), ``fps`` the frame rate. Uses matplotlib's Pillow writer."""
    plt = pyplot()
    from matplotlib.animation import FuncAnimation, PillowWriter

    if run.path_t.size < 2:
        raise ValueError("the run has no flight to animate")
    sc = run.scenario
    target = sc.target()
    h = sc.pad_half_size if pad_half_size is None else pad_half_size
    t, p = run.path_t - run.path_t[0], run.path_p
    n_frames = max(2, int(t[-1] / speed * fps) + 1)
    idx = np.searchsorted(t, np.linspace(0.0, t[-1], n_frames)).clip(0, t.size - 1)
    fig, ax = plt.subplots(figsize=(7, 4.5), layout="constrained")
    ends = np.array([target.point - h * target.s1, target.point + h * target.s1])
    ax.plot(ends[:, 0], ends[:, 2], "-", color="tab:purple", lw=5, label="pad")
    plan = run.final_plan
    drag = sc.vehicle.limits.rotor_drag  # the planner's (one vehicle description, avp.sim.run)
    if plan is not None:
        pp = plan(plan.sample(0.01))
        ax.plot(pp[:, 0], pp[:, 2], ":", color="0.5", lw=1, label="last committed plan")
    lo = np.minimum(p.min(axis=0), ends.min(axis=0)) - 0.3
    hi = np.maximum(p.max(axis=0), ends.max(axis=0)) + 0.3
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[2], hi[2])
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("z (m)")
    ax.grid(alpha=0.3)
    (trail,) = ax.plot([], [], "-", color="tab:blue", lw=1.5, label="flown path")
    (body,) = ax.plot([], [], "o", color="k", ms=6)
    (axis,) = ax.plot([], [], "-", color="tab:red", lw=2, label="planned thrust axis b3")
    ax.legend(loc="upper left", fontsize=8)
    title = ax.set_title("")
    span = float((hi - lo).max())

    def draw(k: int) -> tuple[Any, ...]:
        i = int(idx[k])
        trail.set_data(p[: i + 1, 0], p[: i + 1, 2])
        body.set_data([p[i, 0]], [p[i, 2]])
        body.set_color("tab:green" if run.visible[i] else "k")
        # the run records positions only: draw the committed plan's b3 where it covers this time
        if plan is not None and plan.t0 <= run.path_t[i] <= plan.tf:
            b3 = plan.attitude(run.path_t[i], rotor_drag=drag)[:, 2]
            axis.set_data([p[i, 0], p[i, 0] + 0.08 * span * b3[0]], [p[i, 2], p[i, 2] + 0.08 * span * b3[2]])
        else:
            axis.set_data([], [])
        title.set_text(f"{run.mode.name.lower()}, seed {run.seed}: t = {t[i]:.2f} s "
                       f"({'pad in view' if run.visible[i] else 'pad out of view'}); {run.outcome}")
        return trail, body, axis, title

    out = Path(path)
    if out.suffix.lower() != ".gif":
        plt.close(fig)
        raise ConfigError("gif", f"the animation is a GIF: give a path ending in .gif, got {str(path)!r}")
    anim = FuncAnimation(fig, draw, frames=n_frames, blit=False)
    out.parent.mkdir(parents=True, exist_ok=True)
    anim.save(out, writer=PillowWriter(fps=fps))
    plt.close(fig)
    return out
