"""Monte Carlo campaigns: a grid of conditions x planning modes x seeds of closed-loop trials, run
serially, on a local process pool, or on Ray (a local instance or a cluster; the same code path),
with results appended to a CSV or Parquet file one row per trial, so an interrupted campaign
resumes where it stopped.

A trial is plain data (:class:`Trial`); :class:`Runner` turns it into a simulator scenario and
flies it (the adapter to :func:`avp.sim.run.simulate`: the only place that knows the simulator's
API), and returns a flat row of every parameter and outcome. Each trial is seeded by its own seed
only, so a trial's row is the same whichever worker runs it and in whatever order (the tests check
serial, pool and Ray against each other). Columns ending in ``_wall_s`` or ``_ms`` are wall-clock
measurements and differ between runs.

Scaling: trials are independent, so throughput grows with workers until the cores are used up; on
a Ray cluster (``address="ray://head:10001"`` or ``"auto"`` on a node of the cluster) each trial is
one task of one CPU, scheduled on any node that has avp installed (ship it with a Ray
``runtime_env`` or the cluster image). Rows stream back to the driver, which alone writes the
results file.
"""

from __future__ import annotations

import concurrent.futures as cf
import csv
import dataclasses
import hashlib
import json
import logging
import math
import multiprocessing
import os
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .configfile import load_settings
from .errors import ConfigError

__all__ = [
    "COLUMNS",
    "ResultStore",
    "Runner",
    "Trial",
    "config_id",
    "execute",
    "format_summary",
    "grid",
    "plot_summary",
    "run",
    "summarize",
]

log = logging.getLogger(__name__)

MODES = ("one_shot", "avp")


@dataclass(frozen=True)
class Trial:
    """One closed-loop trial: pad incline (rad), stand-off (m), lateral and height offsets (m;
    ``None`` height: the scenario's default), planning mode and seed."""

    incline: float
    distance: float
    lateral: float
    height: float | None
    mode: str
    seed: int

    @property
    def trial_id(self) -> str:
        h = "default" if self.height is None else f"{self.height:g}"
        return (f"i{math.degrees(self.incline):g}_d{self.distance:g}_l{self.lateral:g}_h{h}"
                f"_{self.mode}_s{self.seed}")


def grid(inclines_deg: Iterable[float], distances: Iterable[float], laterals: Iterable[float],
         heights: Iterable[float | None], modes: Iterable[str], seeds: Iterable[int]) -> list[Trial]:
    """Every combination, in this nesting order (inclines in degrees, the rest SI)."""
    modes = list(modes)
    for m in modes:
        if m not in MODES:
            raise ConfigError("modes", f"expected one of {MODES}, got {m!r}")
    return [Trial(math.radians(float(i)), float(d), float(lat), None if h is None else float(h), m, int(s))
            for i in inclines_deg for d in distances for lat in laterals for h in heights
            for m in modes for s in seeds]


def config_id(data: Mapping[str, Any]) -> str:
    """Short hash of the configuration mapping: rows of other configurations are not reused."""
    text = json.dumps(data, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:12]


COLUMNS = (
    "trial_id", "config_id", "incline_deg", "distance_m", "lateral_m", "height_m", "mode", "seed",
    "outcome", "success", "contact", "inside_pad", "s1_m", "s2_m", "attitude_error_deg",
    "normal_speed_m_s", "tangential_speed_m_s", "visible_fraction", "replans", "kept_previous",
    "initial_estimate_error_m", "anticipation_rmse_m", "first_plan_duration_s", "contact_time_s",
    "solve_median_ms", "solve_max_ms", "trial_wall_s",
)
"""One row per trial: parameters, outcome, contact, replanning and timing columns."""

WALL_CLOCK = ("solve_median_ms", "solve_max_ms", "trial_wall_s")
"""Columns that are wall-clock measurements (differ between identical runs)."""


class Runner:
    """Callable ``trial -> row`` (or ``(row, SimResult)`` with ``keep_result``) for a configuration
    mapping (the TOML data: ``[planner]``, ``[replan]``, ``[scenario]``). Plain data in, plain
    data out, so it pickles to pool and Ray workers."""

    def __init__(self, data: Mapping[str, Any] | None = None, keep_result: bool = False) -> None:
        self.data = dict(data or {})
        self.keep_result = keep_result
        self.config_id = config_id(self.data)
        self._settings: Any = None

    def __getstate__(self) -> dict[str, Any]:
        return {"data": self.data, "keep_result": self.keep_result, "config_id": self.config_id, "_settings": None}

    def __call__(self, trial: Trial) -> Any:
        from .sim.run import simulate

        if self._settings is None:
            self._settings = load_settings(overrides=self.data)
        s = self._settings
        scenario = s.scenario(incline=trial.incline, distance=trial.distance, lateral=trial.lateral,
                              height=trial.height)
        t0 = time.perf_counter()
        # as simulate()'s own default configuration: the planner keeps GROUND_CLEARANCE above
        # the world's ground and gets the back-end's drag, unless the configuration sets them
        planner_data = self.data.get("planner", {})
        config = s.planner
        if "ground_z" not in planner_data.get("workspace", {}) and scenario.planner_ground_z is not None:
            config = dataclasses.replace(config, workspace=dataclasses.replace(
                config.workspace, ground_z=scenario.planner_ground_z))
        if "alpha_nominal" not in planner_data and scenario.alpha_nominal is not None:
            config = dataclasses.replace(config, alpha_nominal=scenario.alpha_nominal)
        if "contact_velocity" not in planner_data and scenario.contact_velocity is not None:
            config = dataclasses.replace(config, contact_velocity=scenario.contact_velocity)
        own_drag = "rotor_drag" in planner_data.get("limits", {})
        res = simulate(scenario, trial.mode, seed=trial.seed, config=config, replan=s.replan,
                       plan_drag=not own_drag)
        row = trial_row(trial, res, self.config_id, time.perf_counter() - t0)
        return (row, res) if self.keep_result else row


def trial_row(trial: Trial, res: Any, cid: str, wall: float) -> dict[str, Any]:
    """The :data:`COLUMNS` of one :class:`~avp.sim.run.SimResult`."""
    c = res.contact
    nan = float("nan")
    st = np.asarray(res.solve_times, dtype=float)
    ae = np.asarray(res.anticipation_error, dtype=float).reshape(-1, 3)
    actions = res.actions()
    row = {
        "trial_id": trial.trial_id, "config_id": cid, "incline_deg": round(math.degrees(trial.incline), 9),
        "distance_m": trial.distance, "lateral_m": trial.lateral,
        "height_m": nan if trial.height is None else trial.height, "mode": trial.mode, "seed": trial.seed,
        "outcome": res.outcome, "success": bool(res.success), "contact": c is not None,
        "inside_pad": bool(c.inside) if c is not None else False,
        "s1_m": float(res.interception[0]) if res.interception is not None else nan,
        "s2_m": float(res.interception[1]) if res.interception is not None else nan,
        "attitude_error_deg": math.degrees(c.attitude_error) if c is not None else nan,
        "normal_speed_m_s": float(c.normal_speed) if c is not None else nan,
        "tangential_speed_m_s": float(np.linalg.norm(c.v_tangential_S)) if c is not None else nan,
        "visible_fraction": float(res.visible_fraction),
        "replans": int(actions.get("REPLANNED", 0)), "kept_previous": int(actions.get("KEPT_PREVIOUS", 0)),
        "initial_estimate_error_m": (float(np.linalg.norm(res.initial_estimate_error))
                                     if res.initial_estimate_error is not None else nan),
        "anticipation_rmse_m": float(np.sqrt(np.mean(np.sum(ae**2, axis=1)))) if ae.size else nan,
        "first_plan_duration_s": res.first_plan.duration if res.first_plan is not None else nan,
        "contact_time_s": float(c.t - res.t_plan) if c is not None else nan,
        "solve_median_ms": float(np.median(st) * 1e3) if st.size else nan,
        "solve_max_ms": float(st.max() * 1e3) if st.size else nan,
        "trial_wall_s": wall,
    }
    assert tuple(row) == COLUMNS
    return row


# -- executors --------------------------------------------------------------------------------

def _ray_available() -> bool:
    try:
        import ray  # noqa: F401
    except ImportError:
        return False
    return True


def resolve_backend(backend: str) -> str:
    """``auto``: Ray when it is installed, else the process pool."""
    if backend == "auto":
        return "ray" if _ray_available() else "pool"
    if backend not in ("serial", "pool", "ray"):
        raise ConfigError("backend", f"expected auto, serial, pool or ray, got {backend!r}")
    if backend == "ray" and not _ray_available():
        raise ConfigError("backend", "Ray is not installed: pip install \"avp[ray]\" (or use --backend pool)")
    return backend


def execute(fn: Callable[[Trial], Any], trials: Sequence[Trial], *, backend: str = "serial",
            workers: int | None = None, address: str | None = None) -> Iterator[tuple[Trial, Any]]:
    """``(trial, fn(trial))`` for every trial, in completion order.

    ``serial``: in this process. ``pool``: a ``spawn`` process pool of ``workers`` (default: the
    CPU count). ``ray``: one Ray task per trial; ``address=None`` starts (or joins) a local Ray
    instance with ``workers`` CPUs, otherwise connects to that cluster. ``fn`` must pickle."""
    backend = resolve_backend(backend)
    if workers is not None and workers < 1:
        raise ConfigError("workers", f"must be >= 1, got {workers}")
    if not trials:
        return
    if backend == "serial":
        for t in trials:
            yield t, fn(t)
    elif backend == "pool":
        n = workers or os.cpu_count() or 1
        with cf.ProcessPoolExecutor(max_workers=min(n, len(trials)),
                                    mp_context=multiprocessing.get_context("spawn")) as pool:
            futures = {pool.submit(fn, t): t for t in trials}
            try:
                for fut in cf.as_completed(futures):
                    yield futures[fut], fut.result()
            finally:
                for fut in futures:
                    fut.cancel()
    else:
        yield from _execute_ray(fn, trials, workers, address)


def _execute_ray(fn: Callable[[Trial], Any], trials: Sequence[Trial], workers: int | None,
                 address: str | None) -> Iterator[tuple[Trial, Any]]:
    import ray

    if not ray.is_initialized():
        if address is None:
            ray.init(num_cpus=workers or os.cpu_count() or 1, include_dashboard=False, log_to_driver=False,
                     configure_logging=False)
        else:
            ray.init(address=address, log_to_driver=False, configure_logging=False)
    remote = ray.remote(num_cpus=1, max_retries=1)(_call)
    fn_ref = ray.put(fn)
    pending = {remote.remote(fn_ref, t): t for t in trials}
    try:
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            for ref in done:
                yield pending.pop(ref), ray.get(ref)
    finally:
        for ref in pending:
            ray.cancel(ref)


def _call(fn: Callable[[Trial], Any], trial: Trial) -> Any:
    return fn(trial)


# -- results ----------------------------------------------------------------------------------

class ResultStore:
    """Rows of a campaign in a ``.csv`` (appended and flushed row by row) or ``.parquet`` file
    (rewritten every ``flush_every`` rows and at the end; needs ``pyarrow``)."""

    def __init__(self, path: str | Path, flush_every: int = 20) -> None:
        self.path = Path(path)
        self.parquet = self.path.suffix.lower() == ".parquet"
        if not self.parquet and self.path.suffix.lower() != ".csv":
            raise ConfigError("results", f"expected a .csv or .parquet file, got {str(self.path)!r}")
        if self.parquet:
            try:
                import pyarrow  # type: ignore[import-untyped]  # noqa: F401
            except ImportError as exc:
                raise ConfigError("results", "Parquet needs pyarrow: pip install pyarrow (or use a .csv file)") from exc
        self.flush_every = flush_every
        self._pending: list[dict[str, Any]] = []

    def rows(self) -> list[dict[str, Any]]:
        """Every stored row, with numbers and booleans parsed."""
        if not self.path.exists():
            return []
        if self.parquet:
            import pyarrow.parquet as pq  # type: ignore[import-untyped]

            return [dict(r) for r in pq.read_table(self.path).to_pylist()]
        with self.path.open(newline="") as fh:
            return [_parse(r) for r in csv.DictReader(fh)]

    def done(self) -> set[tuple[str, str]]:
        """``(trial_id, config_id)`` of the stored rows."""
        return {(r["trial_id"], r["config_id"]) for r in self.rows()}

    def append(self, row: Mapping[str, Any]) -> None:
        if self.parquet:
            self._pending.append(dict(row))
            if len(self._pending) >= self.flush_every:
                self.flush()
            return
        new = not self.path.exists() or self.path.stat().st_size == 0
        self.path.parent.mkdir(parents=True, exist_ok=True)
        with self.path.open("a", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=COLUMNS)
            if new:
                w.writeheader()
            w.writerow({k: _fmt(v) for k, v in row.items()})

    def flush(self) -> None:
        if not (self.parquet and self._pending):
            return
        import pyarrow as pa  # type: ignore[import-untyped]
        import pyarrow.parquet as pq  # type: ignore[import-untyped]

        rows = self.rows() + self._pending
        self.path.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.path.with_suffix(".parquet.tmp")
        pq.write_table(pa.Table.from_pylist(rows), tmp)
        tmp.replace(self.path)
        self._pending = []


def _fmt(v: Any) -> Any:
    return repr(v) if isinstance(v, float) else v


_INT = {"seed", "replans", "kept_previous"}
_BOOL = {"success", "contact", "inside_pad"}
_STR = {"trial_id", "config_id", "mode", "outcome"}


def _parse(r: Mapping[str, str]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in r.items():
        if k in _STR:
            out[k] = v
        elif k in _BOOL:
            out[k] = v == "True"
        elif k in _INT:
            out[k] = int(v)
        else:
            out[k] = float(v)
    return out


def run(trials: Sequence[Trial], data: Mapping[str, Any] | None, results: str | Path, *,
        backend: str = "auto", workers: int | None = None, address: str | None = None,
        progress: Callable[[Any, int, str], Any] | None = None) -> dict[str, Any]:
    """Run the trials not yet in ``results`` and append their rows; return counts and throughput
    (``ran``, ``skipped``, ``backend``, ``wall_s``, ``trials_per_minute``)."""
    runner = Runner(data)
    store = ResultStore(results)
    done = store.done()
    todo = [t for t in trials if (t.trial_id, runner.config_id) not in done]
    backend = resolve_backend(backend)
    t0 = time.perf_counter()
    outputs = execute(runner, todo, backend=backend, workers=workers, address=address)
    if progress is not None:
        outputs = progress(outputs, len(todo), f"campaign ({backend})")
    try:
        for _, row in outputs:
            store.append(row)
    finally:
        store.flush()
    wall = time.perf_counter() - t0
    return {"ran": len(todo), "skipped": len(trials) - len(todo), "backend": backend, "wall_s": wall,
            "trials_per_minute": 60.0 * len(todo) / wall if todo and wall > 0 else 0.0}


# -- summary ----------------------------------------------------------------------------------

GROUP = ("incline_deg", "distance_m", "lateral_m", "height_m", "mode")


def summarize(rows: Iterable[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """One record per grid cell and mode: trials, success rate, contacts, mean |s1| and |s2| of
    the contacts (m), mean visible fraction, median solve time (ms)."""
    groups: dict[tuple[Any, ...], list[Mapping[str, Any]]] = {}
    for r in rows:
        key = tuple("default" if k == "height_m" and _isnan(r[k]) else r[k] for k in GROUP)
        groups.setdefault(key, []).append(r)
    out = []
    for key, rs in sorted(groups.items(), key=lambda kv: tuple(str(x) if isinstance(x, str) else x for x in kv[0])):
        contacts = [r for r in rs if r["contact"]]
        out.append({
            **dict(zip(GROUP, key, strict=True)), "trials": len(rs),
            "success_rate": sum(bool(r["success"]) for r in rs) / len(rs),
            "contacts": len(contacts),
            "abs_s1_mean_m": float(np.mean([abs(r["s1_m"]) for r in contacts])) if contacts else float("nan"),
            "abs_s2_mean_m": float(np.mean([abs(r["s2_m"]) for r in contacts])) if contacts else float("nan"),
            "visible_fraction_mean": float(np.mean([r["visible_fraction"] for r in rs])),
            "solve_median_ms": float(np.nanmedian([r["solve_median_ms"] for r in rs]))
            if any(not _isnan(r["solve_median_ms"]) for r in rs) else float("nan"),
        })
    return out


def _isnan(x: Any) -> bool:
    return isinstance(x, float) and math.isnan(x)


def format_summary(summary: Sequence[Mapping[str, Any]]) -> str:
    head = (f"{'incline':>7s} {'dist':>5s} {'lat':>5s} {'height':>7s} {'mode':9s} {'trials':>6s} "
            f"{'success':>7s} {'contact':>7s} {'|s1| m':>7s} {'|s2| m':>7s} {'visible':>7s} {'solve ms':>8s}")
    lines = ["Campaign summary (|s1|, |s2|: mean distance of the contact point from the pad centre)", head]
    for s in summary:
        h = s["height_m"] if isinstance(s["height_m"], str) else f"{s['height_m']:g}"
        lines.append(f"{s['incline_deg']:7g} {s['distance_m']:5g} {s['lateral_m']:5g} {h:>7s} {s['mode']:9s} "
                     f"{s['trials']:6d} {100 * s['success_rate']:6.0f}% {s['contacts']:7d} "
                     f"{s['abs_s1_mean_m']:7.3f} {s['abs_s2_mean_m']:7.3f} {100 * s['visible_fraction_mean']:6.0f}% "
                     f"{s['solve_median_ms']:8.1f}")
    return "\n".join(lines)


def wilson_interval(successes: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """Wilson score interval (95 % for ``z = 1.96``) of a success rate from ``n`` trials."""
    if n == 0:
        return 0.0, 1.0
    p = successes / n
    den = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / den
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    return max(0.0, centre - half), min(1.0, centre + half)


def plot_summary(summary: Sequence[Mapping[str, Any]], path: str | Path) -> Path:
    """Success rate against stand-off with 95 % Wilson intervals: one colour per incline /
    lateral / height, solid AVP, dashed one-shot (PNG)."""
    from .plotting import pyplot

    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7.5, 4.5), layout="constrained")
    lines: dict[tuple[Any, ...], list[tuple[float, float, int]]] = {}
    for s in summary:
        key = (s["incline_deg"], s["lateral_m"], s["height_m"], s["mode"])
        lines.setdefault(key, []).append((s["distance_m"], s["success_rate"], s["trials"]))
    cells = sorted({k[:3] for k in lines}, key=str)
    colours = {c: f"C{k % 10}" for k, c in enumerate(cells)}
    dists = sorted({s["distance_m"] for s in summary})
    shift = 0.01 * ((dists[-1] - dists[0]) or 1.0)
    series = sorted(lines.items(), key=lambda kv: str(kv[0]))
    for k, ((inc, lat, h, mode), pts) in enumerate(series):  # small x offsets: no series hides another
        pts.sort()
        d = np.array([x[0] for x in pts]) + shift * (k - (len(series) - 1) / 2)
        rate = np.array([x[1] for x in pts])
        ci = np.array([wilson_interval(round(r * n), n) for _, r, n in pts])
        label = f"{mode}, {inc:g} deg" + (f", lateral {lat:g} m" if lat else "") + (
            "" if isinstance(h, str) else f", height {h:g} m")
        ax.errorbar(d, 100 * rate, yerr=100 * np.abs(ci.T - rate), fmt="o-" if mode == "avp" else "s--",
                    color=colours[(inc, lat, h)], capsize=3, label=label)
    ax.set_xlabel("stand-off (m)")
    ax.set_ylabel("success rate (%), 95 % Wilson interval")
    ax.set_ylim(-5, 105)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    n_total = sum(s["trials"] for s in summary)
    ax.set_title(f"Closed-loop campaign: success rate ({n_total} trials; solid AVP, dashed one-shot)")
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def rows_equal(a: Mapping[str, Any], b: Mapping[str, Any]) -> bool:
    """Same trial outcome, ignoring wall-clock columns (NaN equals NaN)."""
    for k in COLUMNS:
        if k in WALL_CLOCK:
            continue
        x, y = a[k], b[k]
        if _isnan(x) and _isnan(y):
            continue
        if x != y:
            return False
    return True


