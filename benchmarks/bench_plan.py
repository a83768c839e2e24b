"""Planning latency: median and p95 of ``avp.plan`` over the standard scenarios per QP back-end,
and, in the same run, the same QP written with cvxpy and solved by OSQP (baseline). Rows:
the perching QP alone (FoV rows and certificate off), then the default pipeline stage by stage
(+ the Sturm certificate of the vehicle limits, + the FoV SQP step).

    python benchmarks/bench_plan.py [--repeats 30]

Prints a table; the ratio column is cvxpy+OSQP median over each back-end's median. Timings are
wall-clock on this machine; nothing here is asserted.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np
import qpsolvers

import avp
from avp.qp import build_perching_qp
from avp.timing import initial_durations

INCLINES = (0, 30, 60, 90)
STANDOFFS = (1.5, 3.5, 7.5)


def scenarios() -> list[tuple[avp.State, avp.PerchTarget]]:
    out = []
    pad = np.array([0.0, 0.0, 1.5])
    for inc in INCLINES:
        for d in STANDOFFS:
            target = avp.PerchTarget.from_incline(pad, math.radians(inc))
            start = pad + np.array([-d, 0.0, 1.0 if inc < 45 else 0.0])
            out.append((avp.State.hover(start), target))
    return out


def time_plan(config: avp.PlannerConfig, repeats: int) -> np.ndarray:
    samples = []
    for state, target in scenarios():
        avp.plan(state, target, config)  # warm caches
        for _ in range(repeats):
            t0 = time.perf_counter()
            avp.plan(state, target, config)
            samples.append(time.perf_counter() - t0)
    return np.array(samples)


def time_cvxpy(repeats: int) -> tuple[np.ndarray, np.ndarray]:
    """The full-form QP (5) of each scenario in cvxpy, solved by OSQP at the tolerance avp gives
    OSQP. Returns (problem construction + solve, solve only of an already-built problem). The
    matrices come from avp's assembly, which is not counted: the baseline is generous. A planner
    builds a new problem every plan (the data change), so construction + solve is the baseline."""
    import cvxpy as cp

    config = avp.PlannerConfig()
    full, solve_only = [], []
    for state, target in scenarios():
        qp = build_perching_qp(state, target, config, initial_durations(state, target, config))
        A, b = qp.stacked_equalities()
        G, lo, hi = qp.stacked_inequalities()

        def build(qp=qp, A=A, b=b, G=G, lo=lo, hi=hi) -> cp.Problem:
            x = cp.Variable(qp.layout.n_variables)
            cons = [A @ x == b, G @ x <= hi, G @ x >= lo]
            return cp.Problem(cp.Minimize(0.5 * cp.quad_form(x, cp.psd_wrap(qp.P))), cons)

        opts = dict(solver=cp.OSQP, eps_abs=1e-9, eps_rel=1e-9, max_iter=200_000)
        prob = build()
        prob.solve(**opts)
        for _ in range(repeats):
            t0 = time.perf_counter()
            build().solve(**opts)
            full.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            prob.solve(**opts)
            solve_only.append(time.perf_counter() - t0)
    return np.array(full), np.array(solve_only)


def row(name: str, s: np.ndarray, base: float | None) -> str:
    med, p95 = np.median(s) * 1e3, np.percentile(s, 95) * 1e3
    ratio = f"{base / np.median(s):8.1f}x" if base else "   (base)"
    return f"{name:<28} {med:9.3f} {p95:9.3f} {ratio}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=30)
    args = ap.parse_args()
    print(f"avp {avp.__version__}: plan() over {len(scenarios())} standard scenarios x {args.repeats} repeats")
    try:
        base, cached = time_cvxpy(max(3, args.repeats // 5))
        base_med = float(np.median(base))
    except ImportError:
        base, base_med = None, None
        print("cvxpy not installed (pip install avp[bench]): no baseline")
    print(f"{'configuration':<28} {'median ms':>9} {'p95 ms':>9} {'vs cvxpy':>9}")
    if base is not None:
        print(row("cvxpy + OSQP (build+solve)", base, None))
        print(row("cvxpy + OSQP (solve only)", cached, base_med))
    # The perching QP alone: no FoV rows, no certificate.
    bare = dict(fov=avp.FovConfig(enabled=False), bounds=avp.BoundsPolicy(certify=False))
    for solver in ("daqp", "proxqp", "osqp"):
        if solver not in qpsolvers.available_solvers:
            continue
        s = time_plan(avp.PlannerConfig(solver=solver, **bare), args.repeats)
        print(row(f"perching QP [{solver}]", s, base_med))
    s = time_plan(avp.PlannerConfig(solver="proxqp", qp_form=avp.QpForm.FULL, **bare), args.repeats)
    print(row("perching QP [proxqp, full]", s, base_med))
    s = time_plan(avp.PlannerConfig(fov=avp.FovConfig(enabled=False)), args.repeats)
    print(row("+ certificate [daqp]", s, base_med))
    s = time_plan(avp.PlannerConfig(), args.repeats)
    print(row("+ FoV SQP (defaults) [daqp]", s, base_med))


if __name__ == "__main__":
    main()
