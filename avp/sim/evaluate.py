"""One-shot planning versus AVP over seeded trials: the paper's Tables V and VI and success rates.

:func:`compare` runs ``n_trials`` seeds of every condition (incline x distance x lateral x height)
in both :class:`~avp.sim.run.Mode` s, with the same seeds for both modes (the initial detections
and the first odometry sample are shared, so the comparison is paired). :class:`Comparison`
prints the tables and writes the plots (matplotlib, Agg backend).

Axes. Interception errors are reported in our pad frame S: ``s1`` along the slope (vertical on a
wall) and ``s2`` lateral. The paper's Table VI names the same two axes ``s3`` and ``s2`` (its
``s1`` is the pad normal, along which it measures the stand-off), so the paper's
``s2 / s3`` = our ``s2 / s1``. Anticipation errors (Table V) are per world axis.
"""

from __future__ import annotations

import dataclasses
import math
import sys
import time
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from .. import _validate as v
from ..camera import Camera
from ..config import ContactVelocity, PlannerConfig
from ..errors import ConfigError
from ..replan import ReplanConfig
from .backend import Backend
from .camera import CameraParams
from .controller import ControllerGains
from .odometry import OdometryNoise
from .run import MAX_INITIAL_FRAMES, MAX_OFFSET, Mode, SimResult, SimScenario, simulate
from .vehicle import VehicleParams

__all__ = ["REPLAN_PERIOD", "Comparison", "Condition", "SimConfig", "SweepPoint", "SweepResult", "compare",
           "sweep", "wilson_interval"]

REPLAN_PERIOD = 1.0 / 30.0
"""The paper's replanning cycle (s); latencies are reported as a fraction of it."""


@dataclass(frozen=True)
class Condition:
    """One cell of the sweep: incline (rad), stand-off (m), lateral and height offsets (m)."""

    incline: float
    distance: float
    lateral: float = 0.0
    height: float | None = None

    def label(self) -> str:
        s = f"{math.degrees(self.incline):g} deg, {self.distance:g} m"
        if self.lateral:
            s += f", lateral {self.lateral:+g} m"
        if self.height:
            s += f", height {self.height:+g} m"
        return s


def _mean_std(x: np.ndarray) -> str:
    if x.size == 0:
        return "-"
    return f"{x.mean():.3f} ± {x.std():.3f}"


@dataclass
class Comparison:
    """Results of :func:`compare`: ``results[(condition, mode)]`` is the list of runs (by seed)."""

    conditions: list[Condition]
    seeds: list[int]
    results: dict[tuple[Condition, Mode], list[SimResult]] = field(default_factory=dict)
    wall_time: float = 0.0

    # -- statistics -----------------------------------------------------------------------
    def runs(self, cond: Condition, mode: Mode) -> list[SimResult]:
        return self.results.get((cond, mode), [])

    def success_rate(self, cond: Condition, mode: Mode) -> float:
        rs = self.runs(cond, mode)
        return sum(r.success for r in rs) / len(rs) if rs else float("nan")

    def interception(self, cond: Condition, mode: Mode) -> np.ndarray:
        """``(n, 2)`` absolute contact-point errors ``(|s1|, |s2|)`` (m) of the runs with contact."""
        pts = [np.abs(r.interception) for r in self.runs(cond, mode) if r.interception is not None]
        return np.array(pts, dtype=float).reshape(-1, 2)

    def anticipation_rmse(self, cond: Condition, mode: Mode = Mode.AVP) -> np.ndarray:
        """RMSE (m) per world axis of the anticipated position at ``t_ex`` (all replans, all runs)."""
        errs = [r.anticipation_error for r in self.runs(cond, mode) if r.anticipation_error.size]
        if not errs:
            return np.full(3, np.nan)
        e = np.concatenate(errs)
        return np.sqrt(np.mean(e**2, axis=0))

    def solve_times(self, mode: Mode = Mode.AVP) -> np.ndarray:
        """Wall-clock planning times (s) of every replanning step (first plans excluded)."""
        out = [r.solve_times[1:] for (c, m), rs in self.results.items() if m is mode for r in rs]
        return np.concatenate(out) if out else np.zeros(0)

    def outcomes(self, cond: Condition, mode: Mode) -> dict[str, int]:
        counts: dict[str, int] = {}
        for r in self.runs(cond, mode):
            counts[r.outcome] = counts.get(r.outcome, 0) + 1
        return counts

    # -- tables ---------------------------------------------------------------------------
    def table_anticipation(self) -> str:
        lines = ["Anticipation error (6), AVP: RMSE (m) of the anticipated position at t_ex "
                 "(cf. paper Table V, simulation: x 0.014/0.02/0.03, z 0.003/0.003/0.006 at 1.5/3.5/7.5 m)",
                 f"  {'condition':34s} {'x':>7s} {'y':>7s} {'z':>7s} {'replans':>8s}"]
        for c in self.conditions:
            rmse = self.anticipation_rmse(c)
            n = sum(r.anticipation_error.shape[0] for r in self.runs(c, Mode.AVP))
            lines.append(f"  {c.label():34s} {rmse[0]:7.4f} {rmse[1]:7.4f} {rmse[2]:7.4f} {n:8d}")
        return "\n".join(lines)

    def table_interception(self) -> str:
        lines = ["Interception error |contact point - pad centre| (m), mean ± std over runs with contact; "
                 "our s1 (slope) = paper's s3, our s2 (lateral) = paper's s2 "
                 "(paper Table VI at 7.5 m: one-shot s2 0.10 / s3 0.25, AVP 0.03 / 0.09)",
                 f"  {'condition':34s} {'mode':9s} {'s1 (paper s3)':>16s} {'s2 (paper s2)':>16s} {'contacts':>9s}"]
        for c in self.conditions:
            for m in Mode:
                ic = self.interception(c, m)
                n = len(self.runs(c, m))
                lines.append(f"  {c.label():34s} {m.name.lower():9s} {_mean_std(ic[:, 0]):>16s} "
                             f"{_mean_std(ic[:, 1]):>16s} {ic.shape[0]:4d}/{n:<4d}")
        return "\n".join(lines)

    def table_success(self) -> str:
        lines = ["Success rate (at the plan's contact time: <= 3 cm from the pad plane, < 10 cm from the "
                 "centre, b3 within 10 deg of s3); paper: 4.5 m one-shot cannot perch, AVP 60 %",
                 f"  {'condition':34s} {'mode':9s} {'success':>8s}  outcomes"]
        for c in self.conditions:
            for m in Mode:
                rate = self.success_rate(c, m)
                oc = ", ".join(f"{k} x{n}" for k, n in sorted(self.outcomes(c, m).items()))
                lines.append(f"  {c.label():34s} {m.name.lower():9s} {100 * rate:7.0f}%  {oc}")
        return "\n".join(lines)

    def table_latency(self) -> str:
        st = self.solve_times()
        if st.size == 0:
            return "Replanning step latency: no replans"
        med, p95, mx = (float(np.percentile(st, q)) for q in (50, 95, 100))
        return (f"Replanning step latency (wall clock, {st.size} replans): median {med * 1e3:.1f} ms "
                f"({med / REPLAN_PERIOD:.0%} of the 33 ms cycle), p95 {p95 * 1e3:.1f} ms "
                f"({p95 / REPLAN_PERIOD:.0%}), max {mx * 1e3:.1f} ms")

    def report(self) -> str:
        """Every table, as printed by ``avp simulate``."""
        return "\n\n".join([self.table_success(), self.table_interception(), self.table_anticipation(),
                            self.table_latency(),
                            f"{len(self.seeds)} trials x {len(self.conditions)} condition(s) x 2 modes "
                            f"in {self.wall_time:.1f} s"])

    # -- plots ----------------------------------------------------------------------------
    def plot(self, output_dir: str | Path, max_paths: int = 10) -> list[Path]:
        """Write ``paths_*.png`` (x-z paths of both modes), ``visibility.png`` and
        ``estimate_error.png`` into ``output_dir``; return the paths."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        out = Path(output_dir)
        out.mkdir(parents=True, exist_ok=True)
        written: list[Path] = []
        colors = {Mode.ONE_SHOT: "tab:red", Mode.AVP: "tab:blue"}
        for i, c in enumerate(self.conditions):
            fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), sharey=True)
            for ax, m in zip(axes, Mode, strict=True):
                for r in self.runs(c, m)[:max_paths]:
                    if r.path_p.size:
                        ls = "-" if r.success else ":"
                        ax.plot(r.path_p[:, 0], r.path_p[:, 2], ls, color=colors[m], lw=1, alpha=0.8)
                    if r.initial_target is not None:
                        ax.plot(*r.initial_target.point[[0, 2]], "x", color="gray", ms=5)
                sc = self.runs(c, m)[0].scenario if self.runs(c, m) else None
                if sc is not None:
                    p, s1, h = sc.target().point, sc.target().s1, sc.pad_half_size
                    ax.plot([p[0] - h * s1[0], p[0] + h * s1[0]], [p[2] - h * s1[2], p[2] + h * s1[2]],
                            "k-", lw=4, label="pad")
                ax.set_title(f"{m.name.lower()}: {100 * self.success_rate(c, m):.0f}% success")
                ax.set_xlabel("x (m)")
                ax.grid(alpha=0.3)
            axes[0].set_ylabel("z (m)")
            fig.suptitle(f"True paths, {c.label()} (solid: success, dotted: failure, x: first estimate)")
            fig.tight_layout()
            path = out / f"paths_{i}_{c.distance:g}m.png"
            fig.savefig(path, dpi=110)
            plt.close(fig)
            written.append(path)

        fig, ax = plt.subplots(figsize=(7, 4))
        for c in self.conditions:
            for m, ls in ((Mode.ONE_SHOT, "--"), (Mode.AVP, "-")):
                rs = [r for r in self.runs(c, m) if r.path_t.size]
                if not rs:
                    continue
                grid = np.linspace(0.0, 1.0, 101)
                vis = [np.interp(grid, (r.path_t - r.path_t[0]) / max(r.path_t[-1] - r.path_t[0], 1e-9),
                                 r.visible.astype(float)) for r in rs]
                ax.plot(grid, np.mean(vis, axis=0), ls, label=f"{m.name.lower()}, {c.distance:g} m")
        ax.set_xlabel("normalised flight time (0: first plan, 1: contact or timeout)")
        ax.set_ylabel("share of runs with the pad in the FoV")
        ax.set_ylim(-0.05, 1.05)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        fig.tight_layout()
        path = out / "visibility.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        written.append(path)

        fig, ax = plt.subplots(figsize=(7, 4))
        det = [r.detections for (c, m), rs in self.results.items() if m is Mode.AVP for r in rs if r.detections.size]
        if det:
            d = np.concatenate(det)
            ax.semilogy(d[:, 1], d[:, 2], ".", ms=3, alpha=0.4, label="single detection")
            ax.semilogy(d[:, 1], d[:, 3], ".", ms=3, alpha=0.4, label="fused estimate")
            sc0 = next(iter(self.results.values()))[0].scenario
            dd = np.linspace(max(d[:, 1].min(), 0.1), d[:, 1].max(), 100)
            ax.semilogy(dd, 1.6 * sc0.camera.sigma_position(dd), "k--", lw=1, label="model: 1.6 sigma_p(d)")
        ax.set_xlabel("camera-pad distance (m)")
        ax.set_ylabel("position error (m)")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
        ax.set_title("Target estimate error vs distance (AVP runs)")
        fig.tight_layout()
        path = out / "estimate_error.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        written.append(path)
        return written


def _progress(done: int, total: int, t0: float, label: str, stream: TextIO) -> None:
    width = 30
    filled = int(width * done / max(total, 1))
    eta = (time.perf_counter() - t0) / max(done, 1) * (total - done)
    stream.write(f"\r[{'#' * filled}{'.' * (width - filled)}] {done}/{total} {label:40s} eta {eta:5.0f} s")
    if done == total:
        stream.write("\n")
    stream.flush()


def compare(
    n_trials: int = 5,
    inclines: Iterable[float] = (math.pi / 2,),
    distances: Iterable[float] = (4.5, 7.5),
    lateral_offsets: Iterable[float] = (0.0,),
    height_offsets: Iterable[float | None] = (None,),
    seed: int = 0,
    *,
    scenario: SimScenario | None = None,
    config: PlannerConfig | None = None,
    replan: ReplanConfig | None = None,
    progress: bool = True,
    stream: TextIO | None = None,
    **simulate_kwargs: Any,
) -> Comparison:
    """Run ``n_trials`` seeds (``seed, seed + 1, ...``) of every condition in both modes.

    Parameters
    ----------
    n_trials:
        Trials per condition and mode.
    inclines, distances, lateral_offsets, height_offsets:
        The sweep (rad, m, m, m); ``None`` height: the scenario's default.
    seed:
        First seed.
    scenario:
        Base :class:`SimScenario` (noise, pad, vehicle); its incline, distance, lateral and height
        are replaced by the sweep's.
    config, replan:
        Passed to :func:`~avp.sim.run.simulate`.
    progress:
        Write a progress bar to ``stream`` (default stderr).
    """
    base = scenario if scenario is not None else SimScenario()
    stream = stream if stream is not None else sys.stderr
    conds = [Condition(float(i), float(d), float(lat), h) for i in inclines for d in distances
             for lat in lateral_offsets for h in height_offsets]
    seeds = [int(seed) + k for k in range(int(n_trials))]
    comp = Comparison(conds, seeds)
    total, done, t0 = len(conds) * len(seeds) * 2, 0, time.perf_counter()
    for c in conds:
        sc = dataclasses.replace(base, incline=c.incline, distance=c.distance, lateral=c.lateral, height=c.height)
        for m in Mode:
            runs = comp.results.setdefault((c, m), [])
            for s in seeds:
                runs.append(simulate(sc, m, seed=s, config=config, replan=replan, **simulate_kwargs))
                done += 1
                if progress:
                    _progress(done, total, t0, f"{m.name.lower()} {c.label()} seed {s}", stream)
    comp.wall_time = time.perf_counter() - t0
    return comp


# -- sweeps over realism knobs -----------------------------------------------------------------------


def wilson_interval(successes: int, n: int, z: float = 1.959964) -> tuple[float, float]:
    """Wilson score interval (95 % by default) of a binomial proportion ``successes / n``."""
    if n <= 0:
        return (float("nan"), float("nan"))
    p = successes / n
    den = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / den
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    return (max(0.0, centre - half), min(1.0, centre + half))


@v.typed_keywords("sim_config")
@dataclass(frozen=True)
class SimConfig:
    """Every realism knob of a sweep, as flat scalars (for CLI flags or a TOML table).

    The defaults are the "realistic" point: 20 ms motor lag through a rotor mixer,
    odometry at 200 Hz with 3 mm / 1 cm/s white noise and 5 mm/sqrt(s) drift, detections at
    10 Hz in the FoV with 50 ms latency, 10 % dropouts, range-growing noise (Fig. 9), a 3 %
    range scale bias of random sign and a 2 deg tilt of the measured normal.
    :meth:`scenario` turns a config into a :class:`~avp.sim.run.SimScenario`;
    :func:`sweep` varies any numeric field one at a time.

    Parameters
    ----------
    n_trials, seed:
        Seeded trials per point and mode (seeds ``seed .. seed + n_trials - 1``; both modes use
        the same seeds: paired).
    modes:
        Names of :class:`~avp.sim.run.Mode` to run (``"one_shot"``, ``"avp"``).
    inclines_deg, distances:
        Conditions (pad incline in deg: 90 wall, 45 slope; stand-off in m).
    motor_time_constant:
        Rotor lag (s); 0: instantaneous rotors.
    mixer:
        Rotor-level allocation with per-rotor limits (False: a moment box).
    odometry_sigma_p, odometry_sigma_v, odometry_sigma_att_deg, odometry_drift, odometry_rate_hz:
        Odometry white noise (m, m/s, deg), position random walk (m/sqrt(s)), rate (Hz).
    perfect_odometry:
        Ignore the odometry knobs: the state is known exactly.
    camera_noise_scale:
        Multiplies the Fig. 9 noise model (0: noise-free detections).
    camera_scale_bias, camera_bias_sign:
        Range-proportional bias (fraction) and its sign (None: random per trial).
    camera_normal_tilt_deg:
        Tilt of the measured pad normal (deg).
    camera_latency, camera_dropout, camera_rate_hz:
        Detection latency (s), dropout probability, frame rate (Hz).
    camera_uptilt_deg:
        The front camera's mount tilted up by this angle (deg, :meth:`avp.Camera.front`): the
        simulated vehicle's one camera, which the planner's FoV rows and the sensor share. 10:
        in the fast part of a wall approach the vehicle pitches nose down and rotor drag tilts
        it 7-9 deg further (more on rotorpy, whose drag grows with the rotor speeds), which took
        the pad out of a level camera's 35 deg cone for up to 1.6 s; mounted 10 deg up, AVP on
        rotorpy's wall perched 92 / 94 of 100 seeds not used before (100-199; 4.5 / 7.5 m)
        against 81 / 81 with the level camera, and 96 / 92 % on the grid's seeds 0-99 against
        84 / 84 % (docs/simulation.md, "The camera's uptilt"). 0: the paper's level front
        camera. A planner ``config`` passed to :func:`~avp.sim.run.simulate` (or ``planner=``
        to :func:`sweep`) brings its own camera, which the sensor then uses instead.
    initial_frames:
        Detections fused at hover before the first plan.
    filter_scale_error, filter_range_ratio, filter_estimate_scale:
        The user-side target filter (:class:`~avp.sim.estimator.TargetEstimator`): assumed scale
        error (the prior's std), the range window (None: fuse every detection) and whether to
        estimate the scale error from the approach.
    aim_normal, aim_slope:
        Where the user-side code aims off the estimated pad centre (m): into the pad, and down the
        slope times ``sin(incline)`` (:class:`~avp.sim.run.SimScenario`). 1.5 cm and 7 cm: an
        early contact (a pad found too deep) slides up the slope, 6.7 cm per cm on a wall, and
        the vehicle tracked about 1 cm short before the controller's thrust lead (with the lead
        the aim was checked again on seeds 200-259 and kept). Chosen on seeds 0-59 (wall, 4.5 / 7.5 m: 43 / 43 of
        60 with this aim, 32 / 32 at the estimate); on seeds 100-179, 47 / 55 of 80 against 33 / 37
        (docs/simulation.md). A user-side calibration, not a planner change; set both to 0 for a
        moving platform.
    alpha_nominal:
        The contact thrust on steep pads the user-side configuration asks of the planner
        (``PlannerConfig.alpha_nominal``, m/s^2; ``None``: the planner's 4). 6: with 20 ms of
        motor lag the rotors need room above their floor in the final pitch-up; on the wall at
        7.5 m AVP perched 92 / 100 with 6 against 83 / 100 with 4 (seeds 0-99), and 94 against 82
        on seeds 100-199, not used to choose it (before the thrust lead; docs/simulation.md).
    contact_normal, contact_slope:
        The velocity at contact the user-side configuration asks of the planner
        (:class:`avp.ContactVelocity` ``normal`` and ``slope``, m/s; the slide is scaled by
        ``sin(incline)``): the paper's 0.3 m/s into the pad and 2 m/s down the slope (the
        planner's default). A pad met early, found too deep by the estimate, lands up the slope
        by about the slide over the normal speed per centimetre of depth error (6.7 here), so
        a sweep axis worth having; a slower slide did not pay on rotorpy's wall
        (docs/simulation.md, "The contact velocity").
    backend:
        Simulator back-end (:class:`~avp.sim.backend.Backend` name): ``"avp"`` or ``"rotorpy"``.
    drag_feedforward:
        Feed the back-end's rotor drag forward in the controller (rotorpy's:
        :func:`~avp.sim.backend.rotorpy_gains`; avp's model has none). False:
        ``ControllerGains(rotor_drag=(0, 0, 0))``.
    lag_feedforward:
        Lead the controller's collective thrust by the rotors' lag
        (``ControllerGains.lag_feedforward``, :func:`~avp.sim.controller.thrust_lead`). False:
        the controller without it (docs/simulation.md, "The rotors' lag fed forward", compares).
    compute_slowdown:
        How many times slower than this computer the onboard computer is
        (:attr:`~avp.sim.run.SimScenario.compute_slowdown`): each replanning step lasts that
        many times its wall time here, of simulated time. 0 (the default): planning takes no
        simulated time.
    """

    n_trials: int = 100
    seed: int = 0
    modes: tuple[str, ...] = ("one_shot", "avp")
    inclines_deg: tuple[float, ...] = (90.0, 60.0, 45.0)
    distances: tuple[float, ...] = (4.5, 7.5)
    motor_time_constant: float = 0.02
    mixer: bool = True
    odometry_sigma_p: float = 0.003
    odometry_sigma_v: float = 0.01
    odometry_sigma_att_deg: float = 0.2
    odometry_drift: float = 0.005
    odometry_rate_hz: float = 200.0
    perfect_odometry: bool = False
    camera_noise_scale: float = 1.0
    camera_scale_bias: float = 0.03
    camera_bias_sign: float | None = None
    camera_normal_tilt_deg: float = 2.0
    camera_latency: float = 0.05
    camera_dropout: float = 0.1
    camera_rate_hz: float = 10.0
    camera_uptilt_deg: float = 10.0
    initial_frames: int = 3
    filter_scale_error: float = 0.03
    filter_range_ratio: float | None = None
    filter_estimate_scale: bool = True
    aim_normal: float = 0.015
    aim_slope: float = 0.07
    alpha_nominal: float | None = 6.0
    contact_normal: float = -0.3
    contact_slope: float = -2.0
    backend: str = "avp"
    drag_feedforward: bool = True
    lag_feedforward: bool = True
    compute_slowdown: float = 0.0

    def __post_init__(self) -> None:
        v.flags("sim", self)
        Backend.parse(self.backend, "sim.backend")
        for name in ("contact_normal", "contact_slope"):  # m/s
            v.finite_float(f"sim.{name}", getattr(self, name))
        if not abs(v.finite_float("sim.camera_uptilt_deg", self.camera_uptilt_deg)) < 60.0:
            raise ConfigError("sim.camera_uptilt_deg", f"must be within +-60 deg, got {self.camera_uptilt_deg!r}")
        if self.contact_normal >= 0:
            raise ConfigError("sim.contact_normal", f"must be < 0 m/s (into the pad), got {self.contact_normal}")
        object.__setattr__(self, "n_trials", v.integer("sim.n_trials", self.n_trials, 1, hint="(trials per point and mode)"))
        object.__setattr__(self, "seed", v.integer("sim.seed", self.seed, 0, hint="(the first random generator seed)"))
        object.__setattr__(self, "initial_frames", v.integer("sim.initial_frames", self.initial_frames, 1,
                                                             MAX_INITIAL_FRAMES, hint="(detections before the first plan)"))
        modes = v.sequence("sim.modes", self.modes, "mode names ('one_shot', 'avp')")
        for m in modes:
            if not isinstance(m, (str, Mode)):
                raise ConfigError("sim.modes", f"expected mode names ('one_shot', 'avp'), got {m!r}")
            try:
                Mode.parse(m)
            except ConfigError as exc:
                raise ConfigError("sim.modes", exc.message) from None
        object.__setattr__(self, "modes", modes)
        for name, what in (("inclines_deg", "pad inclines (deg, in [0, 180])"),
                           ("distances", f"stand-offs (m, in (0, {MAX_OFFSET:g}])")):
            values = tuple(v.finite_float(f"sim.{name}", x) for x in v.sequence(f"sim.{name}", getattr(self, name), what))
            if not values:
                raise ConfigError(f"sim.{name}", f"need at least one: give a sequence of {what}")
            bad = next((x for x in values if not (0.0 <= x <= 180.0 if name == "inclines_deg" else 0.0 < x <= MAX_OFFSET)),
                       None)
            if bad is not None:
                raise ConfigError(f"sim.{name}", f"must be a sequence of {what}, got {bad}")
            object.__setattr__(self, name, values)
        for name in ("odometry_rate_hz", "camera_rate_hz"):
            v.positive_float(f"sim.{name}", getattr(self, name))
        if not 0.0 <= v.finite_float("sim.camera_dropout", self.camera_dropout) < 1.0:
            raise ConfigError("sim.camera_dropout", f"must be a probability in [0, 1), got {self.camera_dropout}")
        if self.camera_bias_sign not in (None, 1, -1) or isinstance(self.camera_bias_sign, (bool, np.bool_)):
            raise ConfigError("sim.camera_bias_sign", f"must be +1, -1 or None (random per run), got {self.camera_bias_sign!r}")
        v.nonnegative_float("sim.filter_scale_error", self.filter_scale_error)
        if self.filter_range_ratio is not None and v.finite_float("sim.filter_range_ratio", self.filter_range_ratio) < 1.0:
            raise ConfigError("sim.filter_range_ratio", f"must be >= 1 or None, got {self.filter_range_ratio}")
        for name in ("aim_normal", "aim_slope"):
            v.finite_float(f"sim.{name}", getattr(self, name))
        if self.alpha_nominal is not None:
            v.positive_float("sim.alpha_nominal", self.alpha_nominal)
        for name in ("motor_time_constant", "odometry_sigma_p", "odometry_sigma_v", "odometry_sigma_att_deg",
                     "odometry_drift", "camera_noise_scale", "camera_scale_bias", "camera_normal_tilt_deg",
                     "camera_latency", "compute_slowdown"):
            val = getattr(self, name)
            if not (isinstance(val, (int, float)) and math.isfinite(val) and val >= 0):
                raise ConfigError(f"sim.{name}", f"must be a finite number >= 0, got {val!r}")

    def scenario(self, incline_deg: float, distance: float) -> SimScenario:
        """The :class:`~avp.sim.run.SimScenario` of one condition with this config's realism."""
        base_cam = CameraParams()
        cam = dataclasses.replace(
            base_cam, camera=dataclasses.replace(base_cam.camera,
                                                 R_BC=Camera.front(math.radians(self.camera_uptilt_deg)).R_BC),
            sigma0_pos=base_cam.sigma0_pos * self.camera_noise_scale,
            sigma0_ang=base_cam.sigma0_ang * self.camera_noise_scale,
            scale_bias=float(self.camera_scale_bias), bias_sign=self.camera_bias_sign,
            normal_tilt=math.radians(self.camera_normal_tilt_deg), latency=float(self.camera_latency),
            dropout=float(self.camera_dropout), rate_hz=float(self.camera_rate_hz),
        )
        odo = None if self.perfect_odometry else OdometryNoise(
            sigma_p=float(self.odometry_sigma_p), sigma_v=float(self.odometry_sigma_v),
            sigma_att=math.radians(self.odometry_sigma_att_deg), sigma_omega=0.01,
            drift_p=float(self.odometry_drift), rate_hz=float(self.odometry_rate_hz))
        vehicle = VehicleParams(motor_time_constant=float(self.motor_time_constant), mixer=bool(self.mixer))
        backend = Backend.parse(self.backend, "sim.backend")
        gains = ControllerGains(rotor_drag=None if self.drag_feedforward else (0.0, 0.0, 0.0),
                                lag_feedforward=bool(self.lag_feedforward))
        return SimScenario(incline=math.radians(incline_deg), distance=float(distance), camera=cam, backend=backend,
                           gains=gains,
                           odometry=odo, vehicle=vehicle, initial_frames=int(self.initial_frames),
                           filter_scale_error=float(self.filter_scale_error),
                           filter_range_ratio=self.filter_range_ratio,
                           filter_estimate_scale=bool(self.filter_estimate_scale),
                           aim_normal=float(self.aim_normal), aim_slope=float(self.aim_slope),
                           alpha_nominal=self.alpha_nominal, compute_slowdown=float(self.compute_slowdown),
                           contact_velocity=ContactVelocity(normal=float(self.contact_normal),
                                                            slope=float(self.contact_slope)))

    def perfect_estimate(self) -> SimConfig:
        """The same vehicle with a perfect target estimate and perfect odometry (and a filter that
        fits no scale error: with noise-free detections a fitted scale absorbs the small mismatch
        of a fitted turn rate and moved a CTRV platform's estimate by metres)."""
        return dataclasses.replace(self, camera_noise_scale=0.0, camera_scale_bias=0.0, camera_normal_tilt_deg=0.0,
                                   perfect_odometry=True, filter_scale_error=0.0, filter_estimate_scale=False)


@dataclass(frozen=True)
class SweepPoint:
    """The runs of one sweep point: ``axis = value`` (``axis`` ``"base"`` for the base config)
    under one condition and mode. ``errors_S`` is ``(n, 3)`` position errors at the evaluation
    time in the pad frame (s1, s2, normal; m), ``attitude`` the b3-s3 angles (deg).
    ``step_delays`` (concatenated), ``late_commits`` and ``skipped_ticks`` (summed) collect the
    runs' :class:`~avp.sim.run.SimResult` fields of the same names (with ``compute_slowdown``;
    empty and 0 without)."""

    axis: str
    value: float
    incline_deg: float
    distance: float
    mode: str
    successes: int
    n: int
    errors_S: np.ndarray
    attitude: np.ndarray
    outcomes: dict[str, int]
    step_delays: np.ndarray = field(default_factory=lambda: np.zeros(0))
    late_commits: int = 0
    skipped_ticks: int = 0

    @property
    def rate(self) -> float:
        return self.successes / self.n if self.n else float("nan")

    @property
    def interval(self) -> tuple[float, float]:
        """Wilson 95 % interval of the success rate."""
        return wilson_interval(self.successes, self.n)


@dataclass(kw_only=True)
class SweepResult:
    """What :func:`sweep` measured: one :class:`SweepPoint` per (axis value, condition, mode),
    the replan step latencies (s) of every AVP solve, and the config."""

    config: SimConfig
    points: list[SweepPoint]
    latencies: np.ndarray
    wall_time: float = 0.0

    def table(self) -> str:
        """Success rates with Wilson 95 % intervals, one row per point and mode."""
        lines = [f"Success at the plan's contact time (<= 3 cm from the pad plane, < 10 cm from the centre, "
                 f"b3 within 10 deg of s3); {self.config.n_trials} seeded trials per point, Wilson 95 % CI",
                 f"  {'axis':24s} {'value':>8s} {'incline':>8s} {'dist':>5s} {'mode':9s} {'success':>8s} "
                 f"{'95% CI':>13s}  {'|e_s1|':>7s} {'|e_s2|':>7s} {'|e_n|':>7s} {'att':>6s}"]
        for p in self.points:
            lo, hi = p.interval
            e = np.abs(p.errors_S) if p.errors_S.size else np.full((1, 3), np.nan)
            att = float(np.mean(p.attitude)) if p.attitude.size else float("nan")
            lines.append(f"  {p.axis:24s} {p.value:8.4g} {p.incline_deg:8.0f} {p.distance:5.1f} {p.mode:9s} "
                         f"{100 * p.rate:7.1f}% [{100 * lo:4.1f},{100 * hi:5.1f}]  "
                         f"{np.mean(e[:, 0]):7.3f} {np.mean(e[:, 1]):7.3f} {np.mean(e[:, 2]):7.3f} {att:6.2f}")
        return "\n".join(lines)

    def table_latency(self) -> str:
        st = self.latencies
        if st.size == 0:
            return "Replan step latency: no solves"
        med, p95, mx = (float(np.percentile(st, q)) for q in (50, 95, 100))
        return (f"Replan step latency inside the closed-loop runs ({st.size} steps with a solve): median "
                f"{med * 1e3:.1f} ms, p95 {p95 * 1e3:.1f} ms, max {mx * 1e3:.1f} ms")

    def table_compute(self) -> str:
        """Per AVP point: success, the simulated step durations (median, p99, max, ms) and, per
        run, the plans that arrived after their switch time and the loop's ticks skipped while
        the computer was busy (``compute_slowdown``; ``nan`` and 0 without)."""
        lines = ["Onboard computer (SimConfig.compute_slowdown: each step lasts that many times its wall time here)",
                 f"  {'slowdown':>8s} {'incline':>8s} {'dist':>5s} {'success':>8s} {'step median':>11s} "
                 f"{'p99':>7s} {'max':>7s} {'late plans/run':>14s} {'skipped ticks/run':>17s}"]
        for p in self.points:
            if p.mode != "avp":
                continue
            slowdown = p.value if p.axis == "compute_slowdown" else self.config.compute_slowdown
            d = p.step_delays * 1e3
            med, p99, mx = (float(np.percentile(d, q)) for q in (50, 99, 100)) if d.size else (math.nan,) * 3
            lines.append(f"  {slowdown:8.3g} {p.incline_deg:8.0f} {p.distance:5.1f} {100 * p.rate:7.1f}% "
                         f"{med:11.2f} {p99:7.2f} {mx:7.2f} {p.late_commits / p.n:14.2f} {p.skipped_ticks / p.n:17.2f}")
        return "\n".join(lines)

    def report(self) -> str:
        """:meth:`table`, the latency line and the wall time."""
        return "\n\n".join([self.table(), self.table_latency(),
                            f"{len(self.points)} points in {self.wall_time:.0f} s"])

    def plot(self, output_dir: str | Path) -> list[Path]:
        """One ``success_vs_<axis>.png`` per varied axis (success with 95 % CI against the value,
        one line per condition and mode); returns the paths."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        out = Path(output_dir)
        out.mkdir(parents=True, exist_ok=True)
        written = []
        axes = sorted({p.axis for p in self.points if p.axis != "base"})
        for axis in axes:
            pts = [p for p in self.points if p.axis == axis]
            fig, ax = plt.subplots(figsize=(7, 4.2))
            keys = sorted({(p.incline_deg, p.distance, p.mode) for p in pts})
            for inc, dist, mode in keys:
                ps = sorted((p for p in pts if (p.incline_deg, p.distance, p.mode) == (inc, dist, mode)),
                            key=lambda p: p.value)
                x = np.array([p.value for p in ps])
                y = np.array([100 * p.rate for p in ps])
                ci = np.array([[100 * (p.rate - p.interval[0]), 100 * (p.interval[1] - p.rate)] for p in ps]).T
                ax.errorbar(x, y, yerr=ci, capsize=3, ls="-" if mode == "avp" else "--",
                            marker="o" if mode == "avp" else "s", label=f"{mode}, {inc:g} deg, {dist:g} m")
            ax.set_xlabel(axis)
            ax.set_ylabel("success (%) with 95 % CI")
            ax.set_ylim(-5, 105)
            ax.grid(alpha=0.3)
            ax.legend(fontsize=7)
            fig.tight_layout()
            path = out / f"success_vs_{axis}.png"
            fig.savefig(path, dpi=110)
            plt.close(fig)
            written.append(path)
        return written


_NOT_NUMERIC = ("modes", "inclines_deg", "distances", "backend")


def sweep(
    config: SimConfig | None = None,
    vary: dict[str, Iterable[float]] | None = None,
    *,
    planner: PlannerConfig | None = None,
    replan: ReplanConfig | None = None,
    include_base: bool = True,
    progress: bool = False,
    stream: TextIO | None = None,
) -> SweepResult:
    """Fly ``config.n_trials`` seeded trials per point in every mode and condition.

    Parameters
    ----------
    config:
        :class:`SimConfig` (default: the realistic point).
    vary:
        One-at-a-time axes: ``{field: values}`` with ``field`` a numeric :class:`SimConfig` field
        (e.g. ``{"camera_scale_bias": (0, 0.03, 0.06), "motor_time_constant": (0, 0.02, 0.04)}``);
        every value is run with all other fields at ``config``'s.
    planner, replan:
        Planner configuration (default :func:`~avp.sim.run.sim_config` with the simulated vehicle
        and camera) and replanning policy (default :class:`~avp.replan.ReplanConfig`).
    include_base:
        Also run ``config`` itself (axis ``"base"``).
    progress, stream:
        Progress bar on ``stream`` (default stderr).

    Returns
    -------
    SweepResult
        ``.report()`` / ``.table()`` text, ``.plot(dir)`` figures, ``.points`` raw numbers.

    Raises
    ------
    ConfigError
        An unknown or non-numeric field in ``vary``.
    """
    cfg = config if config is not None else SimConfig()
    runs: list[tuple[str, float, SimConfig]] = [("base", 0.0, cfg)] if include_base else []
    for name, values in (vary or {}).items():
        if name not in SimConfig.__dataclass_fields__ or name in _NOT_NUMERIC:
            raise ConfigError(f"vary.{name}", f"not a numeric SimConfig field; choose from "
                              f"{sorted(f for f in SimConfig.__dataclass_fields__ if f not in _NOT_NUMERIC)}")
        for val in values:
            current = getattr(cfg, name)
            cast: Any = int(val) if isinstance(current, int) and not isinstance(current, bool) else float(val)
            runs.append((name, float(val), dataclasses.replace(cfg, **{name: cast})))
    stream = stream if stream is not None else sys.stderr
    points: list[SweepPoint] = []
    lat: list[np.ndarray] = []
    total = len(runs) * len(cfg.inclines_deg) * len(cfg.distances) * len(cfg.modes) * cfg.n_trials
    done, t0 = 0, time.perf_counter()
    for axis, value, c in runs:
        for inc in c.inclines_deg:
            for dist in c.distances:
                sc = c.scenario(inc, dist)
                for mode_name in c.modes:
                    mode = Mode.parse(mode_name)
                    errs: list[np.ndarray] = []
                    atts: list[float] = []
                    outs: dict[str, int] = {}
                    delays: list[np.ndarray] = []
                    k = late = skipped = 0
                    for s in range(c.seed, c.seed + c.n_trials):
                        r = simulate(sc, mode, seed=s, config=planner, replan=replan)
                        k += r.success
                        outs[r.outcome] = outs.get(r.outcome, 0) + 1
                        if r.perch is not None:
                            errs.append(r.perch.error_S)
                            atts.append(math.degrees(r.perch.attitude_error))
                        if mode is Mode.AVP:
                            lat.append(np.array([st.solve_time for st in r.steps[1:] if st.solved]))
                        if r.step_delays is not None:
                            delays.append(r.step_delays)
                        late += r.late_commits
                        skipped += r.skipped_ticks
                        done += 1
                        if progress:
                            _progress(done, total, t0, f"{axis}={value:g} {mode.name.lower()} {inc:g} deg {dist:g} m", stream)
                    points.append(SweepPoint(axis, value, float(inc), float(dist), mode.name.lower(), k, c.n_trials,
                                             np.array(errs, dtype=float).reshape(-1, 3), np.array(atts), outs,
                                             np.concatenate(delays) if delays else np.zeros(0), late, skipped))
    latencies = np.concatenate(lat) if lat else np.zeros(0)
    return SweepResult(config=cfg, points=points, latencies=latencies, wall_time=time.perf_counter() - t0)
