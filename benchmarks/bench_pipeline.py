"""Where the time of a default ``avp.plan()`` goes, stage by stage, against a naive pipeline.

    python benchmarks/bench_pipeline.py [--repeats 20] [--fresh]

For each standard scenario of ``bench_plan.py`` (wall and slope perches) and repeat, in this
order, interleaved so both see the same machine load:

* ``avp.plan`` with the defaults (FoV rows and SQP step, bound certificates), timed as it is;
  then, in a second pass over the same plans, its wall time split into stages by wrapping the
  functions that do the work (the wrappers cost a little in every call, so that pass's total is
  printed above the stages, apart from the latency; with ``--fresh`` the second pass plans the
  first pass's starts again, so its caches are warm): **build** (QP assembly), **elimination**
  (``PerchingQp.reduce``: equality elimination and the reduced matrices), **FoV** (linearising the
  rows (8)-(9) and scoring visibility), **solve** (the back-end call: ``daqp.solve`` on the
  two-sided rows for DAQP, ``qpsolvers.solve_problem`` for the others),
  **certify** (Algorithm 1, ``certify_spline``), **workspace** (the clearance/workspace
  certificates and rows of ``avp.safety``, when the planner has them) and **other** (the rest:
  Python glue, checks, trajectory objects);
* a naive pipeline: the same perching QP assembled with NumPy (the row builders of ``avp.qp``
  without any cache), solved in full form by DAQP through qpsolvers, and a floating-point Sturm
  check (``numpy.polynomial``, not sound) of the thrust bounds; no FoV rows.

Prints medians, p95, p99 and max (ms) of both (wall clock, the calling thread's CPU, and the
process's CPU: every thread, so BLAS helper threads too), their ratio, and the per-stage medians
and mean shares; then the floor of the solve stage: the reduced QP of each scenario (no FoV rows) solved
through avp's path (``solve_perching_qp``), through ``qpsolvers.solve_problem`` alone, and by
``daqp.solve`` called directly with two-sided rows (what DAQP itself costs). Nothing is asserted;
the numbers are for this machine and this load.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import itertools
import time
from collections import defaultdict
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import qpsolvers
from bench_plan import scenarios
from numpy.polynomial import polynomial as P

import avp
import avp.bounds
import avp.perception as perception
import avp.planner as planner
import avp.solve

try:  # the one attempt path (absent before it was unified)
    import avp.attempt as attempt
except ImportError:  # pragma: no cover
    attempt = None
from avp.qp import assemble, boundary, fov, perching
from avp.qp.cost import gram
from avp.qp.layout import N_AXES, YAW, layout_for
from avp.timing import initial_durations

STAGES = ("build", "elimination", "FoV", "solve", "certify", "workspace")


class StageTimer:
    """Accumulates wall time per stage for the current plan (outermost stage wins)."""

    def __init__(self) -> None:
        self.current: dict[str, float] = defaultdict(float)
        self.depth = 0

    def wrap(self, stage: str, fn: Callable[..., Any]) -> Callable[..., Any]:
        def timed(*args: Any, **kwargs: Any) -> Any:
            if self.depth:
                return fn(*args, **kwargs)
            self.depth += 1
            t0 = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                self.current[stage] += time.perf_counter() - t0
                self.depth -= 1

        return timed

    def take(self) -> dict[str, float]:
        out, self.current = dict(self.current), defaultdict(float)
        return out


@contextlib.contextmanager
def instrumented(timer: StageTimer) -> Iterator[None]:
    """Wraps the stage functions wherever the planner looks them up; restores them after."""
    targets: list[tuple[Any, str, str]] = [
        (attempt, "build_perching_qp", "build"),  # the one attempt path (avp.attempt)
        (perception, "build_perching_qp", "build"),  # before: FoV solves lived in avp.perception
        (planner, "build_perching_qp", "build"),
        (assemble.PerchingQp, "reduce", "elimination"),
        (perception, "linearise_on", "FoV"),
        (fov, "fov_rows", "FoV"),  # the rows, built on first access to FovLinearisation.blocks
        (perception, "_scores", "FoV"),  # current: scoring several plans in one pass
        (perception, "_score", "FoV"),  # before: one plan at a time
        (qpsolvers, "solve_problem", "solve"),  # other back-ends (and DAQP before the direct call)
        (avp.solve, "_solve_two_sided", "solve"),  # DAQP called directly on two-sided rows
        (avp.bounds, "certify_spline", "certify"),  # through planner._certify -> certify_trajectory
        (planner, "certify_workspace", "workspace"),  # clearance/workspace certificates (avp.safety)
        (planner, "workspace_blocks", "workspace"),
        (planner, "refinement_blocks", "workspace"),
        (attempt, "certify_workspace", "workspace"),
        (attempt, "workspace_blocks", "workspace"),
        (attempt, "refinement_blocks", "workspace"),
    ]
    saved = []
    for obj, name, stage in targets:
        if obj is not None and hasattr(obj, name):
            saved.append((obj, name, getattr(obj, name)))
            setattr(obj, name, timer.wrap(stage, getattr(obj, name)))
    try:
        yield
    finally:
        for obj, name, fn in saved:
            setattr(obj, name, fn)


# ---------------------------------------------------------------- the naive pipeline


def naive_cost(layout, T, position_order: int, yaw_order: int) -> np.ndarray:
    n = layout.n_coeffs
    total = float(np.sum(T))
    Pm = np.zeros((layout.n_variables, layout.n_variables))
    for axis in range(N_AXES):
        j = yaw_order if axis == YAW else position_order
        for seg in range(layout.n_segments):
            s = layout.start(axis, seg)
            Pm[s:s + n, s:s + n] = (total / T[seg]) ** (2 * j - 1) * gram(layout.degree, j)
    return Pm / np.max(np.diag(Pm))


def numpy_sturm_roots(F: np.ndarray, a: float, b: float) -> int:
    """Distinct roots of F in (a, b] by a floating-point Sturm sequence (numpy.polynomial)."""
    F = np.trim_zeros(F, "b")
    if F.size <= 1:
        return 0
    seq = [F, P.polyder(F)]
    while seq[-1].size > 1:
        _, r = P.polydiv(seq[-2], seq[-1])
        r = np.trim_zeros(r, "b")
        if r.size == 0 or np.max(np.abs(r)) < 1e-12 * np.max(np.abs(seq[-1])):
            break
        seq.append(-r)

    def changes(x: float) -> int:
        v = [P.polyval(x, s) for s in seq]
        v = [s for s in v if s != 0.0]
        return int(sum(1 for u, w in itertools.pairwise(v) if u * w < 0))

    return changes(a) - changes(b)


def naive_plan(state: avp.State, target: avp.PerchTarget, cfg: avp.PlannerConfig) -> bool:
    """Assemble with NumPy, solve the full-form QP with DAQP, Sturm-check the thrust bounds."""
    layout = layout_for(cfg.n_segments, cfg.degree)
    T = initial_durations(state, target, cfg)
    knots = np.concatenate([[0.0], np.cumsum(T)])
    ts = float(T.mean())
    Pm = naive_cost(layout, T, cfg.position_cost_order, cfg.yaw_cost_order)
    A0, b0 = boundary.initial_state_rows(layout, T, state, ts)
    Ac = boundary.continuity_rows(layout, T, cfg.continuity_order, ts)
    At, bt, _ = perching.terminal_rows(layout, knots, target, cfg, state.yaw, ts)
    G, lo, hi = perching.pre_impact_rows(layout, knots, target, cfg)
    A = np.vstack([A0, Ac, At])
    b = np.concatenate([b0, np.zeros(Ac.shape[0]), bt])
    Gs = np.vstack([G[np.isfinite(hi)], -G[np.isfinite(lo)]]) if G.shape[0] else None
    hs = np.concatenate([hi[np.isfinite(hi)], -lo[np.isfinite(lo)]]) if G.shape[0] else None
    x = qpsolvers.solve_qp(Pm, np.zeros(layout.n_variables), Gs, hs, A, b, solver="daqp")
    if x is None:
        return False
    coeffs = layout.to_physical(x, T)
    lim = cfg.limits
    ok = True
    for s in range(layout.n_segments):
        acc = [P.polyder(coeffs[s, i], 2) for i in range(3)]
        acc[2] = P.polyadd(acc[2], [cfg.g])
        f2 = sum(P.polymul(u, u) for u in acc)
        for F in (P.polysub(f2, [lim.accel_max**2]), P.polysub([lim.accel_min**2], f2)):
            ends = P.polyval(np.array([0.0, T[s]]), F)
            ok &= bool(np.all(ends < 0) and numpy_sturm_roots(F, 0.0, T[s]) == 0)
    return ok


# ---------------------------------------------------------------- report


def stats(v: np.ndarray) -> str:
    v = np.asarray(v) * 1e3
    return f"{np.median(v):>8.3f} {np.percentile(v, 95):>8.3f} {np.percentile(v, 99):>8.3f} {v.max():>8.3f}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=20)
    ap.add_argument("--fresh", action="store_true",
                    help="move every start by 1 mm per repeat: new durations, so no cached cost matrix "
                         "or equality elimination is reused (the cost of a scenario never seen before)")
    args = ap.parse_args()
    cfg = avp.PlannerConfig()
    timer = StageTimer()
    totals, naive, stage_rows, cpu, naive_cpu, process, naive_process = [], [], [], [], [], [], []
    cases = scenarios()
    for state, target in cases:  # first calls (imports, caches) are not measured
        avp.plan(state, target, cfg)
        naive_plan(state, target, cfg)
    solves = [avp.plan_detailed(state, target, cfg).duration_scale_steps + 1 for state, target in cases]
    def starts() -> Iterator[tuple[int, avp.State, avp.PerchTarget]]:
        for repeat in range(args.repeats):
            for state0, target in cases:
                state = state0
                if args.fresh:
                    state = dataclasses.replace(state0, position=state0.position + np.array([1e-3 * (repeat + 1), 0.0, 0.0]))
                yield repeat, state, target

    # the latency: plain avp.plan, interleaved with the naive pipeline
    for _, state, target in starts():
        t0, c0, p0 = time.perf_counter(), time.thread_time(), time.process_time()
        avp.plan(state, target, cfg)
        totals.append(time.perf_counter() - t0)
        cpu.append(time.thread_time() - c0)
        process.append(time.process_time() - p0)
        t0, c0, p0 = time.perf_counter(), time.thread_time(), time.process_time()
        naive_plan(state, target, cfg)
        naive.append(time.perf_counter() - t0)
        naive_cpu.append(time.thread_time() - c0)
        naive_process.append(time.process_time() - p0)
    # the stages: the same plans again, with the stage functions wrapped (the wrappers add a
    # little to every call, so this pass's total is reported apart from the latency above)
    staged = []
    with instrumented(timer):
        for _, state, target in starts():
            timer.take()
            t0 = time.perf_counter()
            avp.plan(state, target, cfg)
            staged.append(time.perf_counter() - t0)
            stage_rows.append(timer.take())
            naive_plan(state, target, cfg)  # the same interleaving as above
    totals_a, naive_a, staged_a = np.array(totals), np.array(naive), np.array(staged)
    print(f"avp {avp.__version__}: {len(cases)} scenarios x {args.repeats} repeats, interleaved"
          + (" (fresh starts: no cache reuse)" if args.fresh else "")
          + f"; durations tried per plan: mean {np.mean(solves):.2f}, max {max(solves)}")
    print(f"{'pipeline (ms)':<44} {'median':>8} {'p95':>8} {'p99':>8} {'max':>8}")
    print(f"{'avp.plan, defaults (FoV + certificates)':<44} {stats(totals_a)}")
    print(f"{'naive NumPy + DAQP + numpy Sturm, no FoV':<44} {stats(naive_a)}")
    # CPU time of the calling thread: the same work without the time the machine's other
    # processes take from us (the scheduler's 4-8 ms slices dominate wall-clock p95 under load)
    print(f"{'avp.plan, CPU time':<44} {stats(np.array(cpu))}")
    print(f"{'naive pipeline, CPU time':<44} {stats(np.array(naive_cpu))}")
    # every thread's CPU from the call's start to its end: BLAS helper threads included, the
    # work they do for the call and their spinning after it (which the thread's time misses)
    print(f"{'avp.plan, process CPU (every thread)':<44} {stats(np.array(process))}")
    print(f"{'naive pipeline, process CPU':<44} {stats(np.array(naive_process))}")
    print(f"avp / naive (medians): wall {np.median(totals_a) / np.median(naive_a):.2f}, "
          f"CPU {np.median(cpu) / np.median(naive_cpu):.2f}")
    print(f"\n{'stage of avp.plan (ms; a second pass)':<37} {'median':>8} {'p95':>8} {'p99':>8} {'max':>8} {'mean share':>11}")
    print(f"{'avp.plan with the stage timers':<37} {stats(staged_a)} {'':>11}")
    per = {s: np.array([r.get(s, 0.0) for r in stage_rows]) for s in STAGES}
    per["other"] = staged_a - sum(per.values())
    for s, v in per.items():
        print(f"{'  ' + s:<37} {stats(v)} {v.sum() / staged_a.sum():>10.1%}")
    solve_floor(args.repeats)


def solve_floor(repeats: int) -> None:
    import daqp

    from avp.solve import _one_sided, solve_perching_qp

    cfg = avp.PlannerConfig()
    rows: dict[str, list[float]] = defaultdict(list)
    for state, target in scenarios():
        qp = assemble.build_perching_qp(state, target, cfg, initial_durations(state, target, cfg))
        red = qp.reduce()
        Gs, hs = _one_sided(red.G, red.lower, red.upper)
        problem = qpsolvers.Problem(P=red.H.copy(), q=red.g, G=Gs, h=hs)
        H, f, A = np.array(red.H), np.array(red.g), np.array(red.G)  # writable copies
        hi = np.where(np.isfinite(red.upper), red.upper, 1e30)
        lo = np.where(np.isfinite(red.lower), red.lower, -1e30)
        sense = np.zeros(A.shape[0], dtype=np.int32)
        calls = {
            "avp solve_perching_qp (reduced QP)": lambda: solve_perching_qp(qp, cfg),
            "qpsolvers.solve_problem (daqp)": lambda: qpsolvers.solve_problem(problem, solver="daqp"),
            "daqp.solve direct, two-sided rows": lambda: daqp.solve(H, f, A, hi, lo, sense),
        }
        for _ in range(repeats):
            for name, fn in calls.items():
                t0 = time.perf_counter()
                fn()
                rows[name].append(time.perf_counter() - t0)
    print(f"\n{'solve floor, no FoV rows (ms)':<44} {'median':>8} {'p95':>8} {'p99':>8} {'max':>8}")
    for name, v in rows.items():
        print(f"{name:<44} {stats(np.array(v))}")


if __name__ == "__main__":
    main()
