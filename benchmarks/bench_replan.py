"""Cost of every ``Replanner.step`` inside the simulated 30 Hz closed loop, in CPU time.

    python benchmarks/bench_replan.py [--seeds 40] [--distances 1.5 4.5 7.5] [--inclines 90 45]
                                      [--previous] [--gc-freeze] [--gc-between-steps] [--stages]
                                      [--evict-mb MB]
                                      [--deadline-ms MS] [--adapt-latency] [--no-retime-backoff]
                                      [--realistic] [--backend avp|rotorpy] [--alpha-range LO HI]
                                      [--free-velocity slope|normal|lateral] [--save FILE] [--compare FILE]

Runs ``avp.sim.run.simulate`` in ``Mode.AVP`` for every seed, distance and incline, with the
``Replanner`` the loop builds replaced by a subclass that times each :meth:`step` call with
``time.thread_time`` (CPU of the calling thread: the machine is shared, so wall time carries the
scheduler's slices; the wall figures are printed too) and counts the garbage collections that ran
inside it. ``--gc-between-steps`` turns the cyclic collector off inside each step and on again
after it: a collection that falls due then runs at the loop's next allocation, between steps, as
a real-time loop schedules it (the README's paragraph on ``ReplanConfig(deadline=...)``).
Every step is reported, the initial plan apart: the ``HELD`` and ``FROZEN_NEAR_CONTACT`` steps
that need no solve are real cycles of the 30 Hz loop. Then the steps that solve, with their
solves per step, by action.

Baseline in the same run: after each simulation, every planning call the steps made
(``plan_detailed`` at the same start state, goal, durations and previous plan) is repeated bare,
in the same order and from the same state of the elimination cache (``avp.qp.assemble``) as in
the loop, and timed the same way; a solving step's cost over the sum of its bare planning calls
is the step's overhead (policy, snap certificate, bookkeeping, and the colder CPU caches of a
step that follows 33 ms of simulation). ``--evict-mb MB`` streams through an array of that many
MB before each bare call, so the replay meets data caches as cold as the loop leaves them: how
much of the step's overhead that explains. ``--stages`` splits both by stage, so the cost the
loop adds shows where it falls.

``--backend rotorpy`` flies rotorpy's vehicle instead of avp's model; the planner then knows its
rotor drag (``VehicleLimits.rotor_drag``), a configuration whose replans the default runs do not
cover.

``--alpha-range LO HI`` (m/s^2) and ``--free-velocity COMPONENT`` plan with terminal rows along
the pad's frame, which every re-estimate of the pad changes (``PlannerConfig.alpha_range``, a
``ContactVelocity`` component left free).

``--save FILE`` writes what the replanner decided (every step's action, fraction and solves, and
a digest of every committed plan's coefficients); ``--compare FILE`` checks the run against such
a file, to show a speed change leaves the policy and its plans unchanged. ``--previous`` runs
the code paths this file's speed work replaced (Fraction snap coefficients, threaded BLAS), for
a before/after in one session. Nothing is asserted
by the tests; these numbers are for this machine and its load.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import gc
import hashlib
import json
import time
import warnings
from collections import Counter, OrderedDict, defaultdict
from types import SimpleNamespace
from typing import Any, ClassVar

import numpy as np
from _grid import add_loop_options, add_timing_options, collector_off, loop_scenario, replan_config

import avp.sim.run as sim_run
from avp import _avp_rust, replan, trackability
from avp._blas import serial_blas
from avp.config import PlannerConfig
from avp.planner import plan_detailed
from avp.qp import assemble
from avp.replan import ReplanConfig, Replanner
from avp.sim.evaluate import SimConfig
from avp.sim.run import Mode, SimScenario, simulate

_GC = [0, 0]  # collections started, of which of the oldest generation


def _count_gc(phase: str, info: dict[str, Any]) -> None:
    if phase == "start":
        _GC[0] += 1
        _GC[1] += info["generation"] == 2


class TimedReplanner(Replanner):
    """The library's replanner, each step timed; each planning call's arguments kept."""

    records: ClassVar[list[dict[str, Any]]] = []
    calls: ClassVar[list[tuple[int, tuple[Any, ...]]]] = []

    collect_between_steps: ClassVar[bool] = False
    """``--gc-between-steps``: the collector is off inside each step and back on after it."""

    def step(self, t: float, odometry: Any, target_estimate: Any = None) -> Any:
        gc0, gc2 = _GC[0], _GC[1]
        _STAGE_ON[0] = _STAGE_CPU if self.trajectory is not None else None  # replans only
        with collector_off(TimedReplanner.collect_between_steps):
            w0, c0 = time.perf_counter(), time.thread_time()
            s = super().step(t, odometry, target_estimate)
            c1, w1 = time.thread_time(), time.perf_counter()
        _STAGE_ON[0] = None
        traj = self.trajectory
        TimedReplanner.records.append(dict(
            cpu=c1 - c0, wall=w1 - w0, gc=_GC[0] - gc0, gc2=_GC[1] - gc2, action=s.action.name, n_solves=s.n_solves,
            fraction=s.fraction,
            plan=hashlib.sha1(traj.coefficients.tobytes() + traj.knots.tobytes()).hexdigest()[:16]
            if s.committed and traj is not None else "",
        ))
        return s

    def _plan(self, state: Any, target: Any, durations: Any, previous: Any, config: Any,
              deadline: Any = None) -> Any:
        TimedReplanner.calls.append((len(TimedReplanner.records),
                                     (state, target, durations, previous, config, deadline)))
        return super()._plan(state, target, durations, previous, config, deadline)


STAGES = (  # (module, function, label): CPU inside Replanner.step, per planning call
    ("avp.replan", "plan_detailed", "plan_detailed (all of the below but the snap certificate and blend)"),
    ("avp.attempt", "build_perching_qp", "  build the QP"),
    ("avp.attempt", "workspace_blocks", "  workspace rows"),
    ("avp.perception", "linearise_on", "  FoV linearisation (8)-(9)"),
    ("avp.qp.fov", "fov_rows", "  FoV rows built (when a QP needs them)"),
    ("avp.attempt", "solve_perching_qp", "  reduce and solve the QPs"),
    ("avp.qp.assemble", "_factor", "    of which: elimination QR (cache lookups and misses)"),
    ("avp.qp.assemble", "eliminate_within", "    of which: the pad's rows inside its null space"),
    ("avp.solve", "_solve_two_sided", "    of which: DAQP"),
    ("avp.planner", "_certify", "  bound certificate (Algorithm 1)"),
    ("avp.attempt", "certify_workspace", "  workspace certificate"),
    ("avp.replan", "certify_snap", "snap certificate"),
    ("avp.replan", "_blend", "partial target blend"),
)
_STAGE_CPU: dict[str, float] = defaultdict(float)  # inside the loop's steps
_STAGE_CPU_BARE: dict[str, float] = defaultdict(float)  # inside the bare replays of their planning calls
_STAGE_ON: list[dict[str, float] | None] = [None]  # where the wrappers add their CPU now (None: nowhere)


def instrument_stages() -> None:
    """Wrap the functions of :data:`STAGES` to add their CPU time inside the steps (only)."""
    import importlib

    for mod_name, fn_name, label in STAGES:
        mod = importlib.import_module(mod_name)
        fn = getattr(mod, fn_name, None)
        if fn is None:  # a stage an older version does not have
            continue

        def timed(*a: Any, _fn: Any = fn, _label: str = label, **kw: Any) -> Any:
            into = _STAGE_ON[0]
            if into is None:
                return _fn(*a, **kw)
            c0 = time.thread_time()
            try:
                return _fn(*a, **kw)
            finally:
                into[_label] += time.thread_time() - c0

        setattr(mod, fn_name, timed)


def use_previous_paths() -> None:
    """Switch this process to the code paths before the speed work on ``Replanner.step``: the
    trackability coefficients by :class:`fractions.Fraction` (the kernel's fallback, the
    previous implementation) and planning with the default BLAS threads."""

    def refuse(*args: Any, **kw: Any) -> Any:
        raise _avp_rust.KernelError("coeffs: the Fraction path is measured")

    trackability._avp_rust = SimpleNamespace(  # type: ignore[attr-defined]
        trackability_rows=refuse, KernelError=_avp_rust.KernelError,
        certify_below_many=_avp_rust.certify_below_many)
    replan.serial_blas = contextlib.nullcontext  # type: ignore[attr-defined]
    globals()["serial_blas"] = contextlib.nullcontext
    threaded = getattr(plan_detailed, "__wrapped__", plan_detailed)  # the planner without its own limit
    replan.plan_detailed = threaded  # type: ignore[attr-defined]
    globals()["plan_detailed"] = threaded


_WITHIN: OrderedDict[Any, Any] = getattr(assemble, "_WITHIN", OrderedDict())  # absent before the two-stage elimination


def _factor_cache() -> tuple[OrderedDict[Any, list[Any]], OrderedDict[Any, Any]]:
    return OrderedDict((k, list(v)) for k, v in assemble._FACTORS.items()), OrderedDict(_WITHIN)


def _set_factor_cache(state: tuple[OrderedDict[Any, list[Any]], OrderedDict[Any, Any]]) -> None:
    factors, within = state
    assemble._FACTORS.clear()
    assemble._FACTORS.update((k, list(v)) for k, v in factors.items())
    _WITHIN.clear()
    _WITHIN.update(within)


_EVICT: list[np.ndarray] = []  # the --evict-mb buffer, when asked for


def bare(args: tuple[Any, ...], warm: bool, stages: bool) -> float:
    """CPU seconds of one bare ``plan_detailed`` at a step's planning arguments; ``stages``: its
    stages count in the bare column of ``--stages`` (a replan's call, not a first plan's)."""
    state, target, durations, previous, config, deadline = args
    for buf in _EVICT:  # untimed: push the planner's data out of the CPU caches
        buf += 1.0
    _STAGE_ON[0] = _STAGE_CPU_BARE if stages else None
    c0 = time.thread_time()
    try:
        with serial_blas():  # as Replanner.step plans (avp._blas)
            c_in = time.thread_time()  # plan_detailed's own stage row, timed inside the block as in the loop
            try:
                plan_detailed(state, target, config, durations=durations, previous=previous,
                              warm_start=previous if warm else None, deadline=deadline)
            finally:
                if stages:
                    _STAGE_CPU_BARE[STAGES[0][2]] += time.thread_time() - c_in
    except Exception:  # the step turned the same failure into a result
        pass
    c1 = time.thread_time()
    _STAGE_ON[0] = None
    return c1 - c0


def stats(ms: np.ndarray) -> str:
    if ms.size == 0:
        return f"{0:>6} " + " ".join(f"{'-':>7}" for _ in range(5))
    return (f"{ms.size:>6} {np.median(ms):7.3f} {np.percentile(ms, 95):7.3f} {np.percentile(ms, 99):7.3f} "
            f"{ms.max():7.2f} {int(np.sum(ms > 5.0)):>7}")


HEAD = f"{'steps':>6} {'median':>7} {'p95':>7} {'p99':>7} {'max':>7} {'>5 ms':>7}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_loop_options(ap, seeds=40)
    ap.add_argument("--previous", action="store_true",
                    help="the previous code paths: Fraction snap coefficients, threaded BLAS in the step")
    ap.add_argument("--evict-mb", type=float, default=0.0,
                    help="stream through this many MB before each bare call (cold data caches, as in the loop)")
    ap.add_argument("--stages", action="store_true",
                    help="also print where the steps' CPU goes, per planning call, in the loop and in the bare "
                         "replays of the same calls (wrappers add a little)")
    add_timing_options(ap)
    ap.add_argument("--alpha-range", type=float, nargs=2, metavar=("LO", "HI"),
                    help="PlannerConfig.alpha_range (m/s^2): the contact thrust free in a range")
    ap.add_argument("--free-velocity", choices=["slope", "normal", "lateral"],
                    help="leave this contact velocity component free (ContactVelocity)")
    ap.add_argument("--save", help="write the decisions and committed-plan digests to this JSON file")
    ap.add_argument("--compare", help="compare the decisions and plans with this JSON file")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    if args.evict_mb > 0:
        _EVICT.append(np.zeros(int(args.evict_mb * 2**20 / 8)))
    gc.callbacks.append(_count_gc)
    sim_run.Replanner = TimedReplanner  # type: ignore[misc]  # the loop builds this class
    TimedReplanner.collect_between_steps = args.gc_between_steps
    replan_cfg = replan_config(args)
    def planner_cfg(sc: SimScenario) -> PlannerConfig | None:
        """The planner configuration of ``sc`` (``None``: the simulation's own, as the default
        runs use it) with the options' terminal rows along the pad's frame."""
        if not (args.alpha_range or args.free_velocity):
            return None
        cfg = sim_run._shared(sc, None)[1]  # what simulate() would plan with
        if args.alpha_range:
            cfg = dataclasses.replace(cfg, alpha_range=tuple(args.alpha_range))
        if args.free_velocity:
            cfg = dataclasses.replace(cfg, contact_velocity=dataclasses.replace(
                cfg.contact_velocity, **{args.free_velocity: None}))
        return cfg
    if args.previous:
        use_previous_paths()
    if args.stages:
        instrument_stages()
    if args.gc_freeze:
        first = SimConfig().scenario(args.inclines[0], args.distances[0]) if args.realistic else \
            SimScenario(distance=args.distances[0])
        first = dataclasses.replace(first, backend=args.backend)
        # not counted: the set-up run, on the runs' simulator
        simulate(first, Mode.AVP, seed=10**6, config=planner_cfg(first), replan=replan_cfg)
        gc.collect()
        gc.freeze()
        _STAGE_CPU.clear()  # the set-up run's stages are not counted
        _STAGE_CPU_BARE.clear()
    rows: list[dict[str, Any]] = []
    decisions: dict[str, Any] = {}
    c_all = time.thread_time()
    for inc in args.inclines:
        for d in args.distances:
            for seed in range(args.seeds):
                TimedReplanner.records, TimedReplanner.calls = [], []
                before = _factor_cache()
                sc = loop_scenario(args, inc, d)
                r = simulate(sc, Mode.AVP, seed=seed, config=planner_cfg(sc), replan=replan_cfg)
                recs, calls = TimedReplanner.records, TimedReplanner.calls
                after = _factor_cache()
                _set_factor_cache(before)  # the replay meets the elimination cache the loop met
                base = defaultdict(float)
                for i, a in calls:
                    base[i] += bare(a, ReplanConfig().warm_start, stages=i > 0)
                _set_factor_cache(after)  # and the next run the one this run left
                for i, rec in enumerate(recs):
                    rec["bare"] = base.get(i, 0.0)
                rows.extend(recs[1:])  # the first step is the initial plan, not a replan
                key = f"{inc:g}/{d:g}/{seed}"
                decisions[key] = dict(
                    outcome=r.outcome,
                    steps=[(x["action"], x["fraction"], x["n_solves"], x["plan"]) for x in recs])
    cpu_total = time.thread_time() - c_all

    cpu = np.array([x["cpu"] for x in rows]) * 1e3
    wall = np.array([x["wall"] for x in rows]) * 1e3
    n_solves = np.array([x["n_solves"] for x in rows])
    bare_ms = np.array([x["bare"] for x in rows]) * 1e3
    with_gc = np.array([x["gc"] > 0 for x in rows])
    with_gc2 = np.array([x["gc2"] > 0 for x in rows])
    solving = n_solves > 0
    print(f"{len(decisions)} closed-loop runs (inclines {args.inclines} deg, distances {args.distances} m, "
          f"{args.seeds} seeds), {cpu_total:.1f} s CPU in all; ms per Replanner.step:")
    print(f"{'':<34} {HEAD}")
    print(f"{'all steps, CPU':<34} {stats(cpu)}")
    print(f"{'all steps, wall':<34} {stats(wall)}")
    print(f"{'steps without a solve, CPU':<34} {stats(cpu[~solving])}")
    print(f"{'steps with a solve, CPU':<34} {stats(cpu[solving])}")
    print(f"{'  their bare plan_detailed calls':<34} {stats(bare_ms[solving])}")
    print(f"{'  one bare plan_detailed call':<34} "
          f"{stats(np.array([b / n for b, n in zip(bare_ms[solving], n_solves[solving], strict=True)]))}")
    print(f"{'steps with a garbage collection':<34} {stats(cpu[with_gc])}")
    print(f"{'  of the oldest generation':<34} {stats(cpu[with_gc2])}")
    if solving.any():
        ratio = cpu[solving] / np.maximum(bare_ms[solving], 1e-9)
        print(f"solving steps: {solving.mean():.1%} of steps, {n_solves[solving].mean():.2f} solves per solving step "
              f"(max {n_solves.max()}); step / bare calls: median {np.median(ratio):.2f}, p95 {np.percentile(ratio, 95):.2f}")
    print(f"\n{'by action (solves)':<34} {HEAD}")
    groups: dict[tuple[str, int], list[float]] = defaultdict(list)
    for x, c in zip(rows, cpu, strict=True):
        groups[(x["action"], x["n_solves"])].append(c)
    for (act, n), v in sorted(groups.items()):
        print(f"{act + f' ({n})':<34} {stats(np.array(v))}")
    if args.stages:
        n_calls = int(n_solves.sum())
        solving_cpu = float(cpu[solving].sum())
        print(f"\nwhere the solving steps' CPU goes, ms per planning call ({n_calls} calls, "
              f"{solving_cpu / max(n_calls, 1):.3f} ms of step per call), in the loop and in the bare replay "
              f"of the same calls (warm caches{'' if not args.evict_mb else f', {args.evict_mb:g} MB evicted'}):")
        print(f"  {'':<70} {'loop':>7} {'bare':>7} {'ratio':>6}")
        for _, _, label in STAGES:
            in_loop = _STAGE_CPU[label] * 1e3 / max(n_calls, 1)
            in_bare = _STAGE_CPU_BARE[label] * 1e3 / max(n_calls, 1)
            r_txt = f"{in_loop / in_bare:6.2f}" if in_bare > 0 else f"{'-':>6}"
            print(f"  {label:<70} {in_loop:7.3f} {in_bare:7.3f} {r_txt}")
    outcomes = Counter(v["outcome"].split(":")[0] for v in decisions.values())
    print("\noutcomes:", dict(outcomes))

    if args.save:
        with open(args.save, "w") as fh:
            json.dump(decisions, fh)
        print(f"decisions written to {args.save}")
    if args.compare:
        with open(args.compare) as fh:
            ref = json.load(fh)
        mine = {k: json.loads(json.dumps(v)) for k, v in decisions.items() if k in ref}

        def policy(v: dict[str, Any], width: int = 3) -> Any:
            return v["outcome"], [s[:width] for s in v["steps"]]

        same = [k for k in mine if mine[k] == ref[k]]
        same_policy = [k for k in mine if policy(mine[k]) == policy(ref[k])]
        same_choice = [k for k in mine if policy(mine[k], 2) == policy(ref[k], 2)]
        print(f"compared with {args.compare}: {len(mine)} runs in both; {len(same_choice)} with the same outcome "
              f"and per-step actions and fractions; {len(same_policy)} also with the same solves per step; "
              f"{len(same)} also with every committed plan bit for bit; "
              f"different actions or fractions: {sorted(set(mine) - set(same_choice))[:10]}, "
              f"different solves only: {sorted(set(same_choice) - set(same_policy))[:10]}, "
              f"different plan bits only: {sorted(set(same_policy) - set(same))[:10]}")

if __name__ == "__main__":
    main()
