"""QP back-ends (avp.solve): the one table of back-end facts drives warm starts and iteration caps,
and a missing back-end is a typed SolverError."""

from __future__ import annotations

import dataclasses
import time

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scenarios import standard

import avp
from avp import perception, solve
from avp.config import PlannerConfig


def test_backend_table_drives_warm_starts_and_the_fov_iteration_cap() -> None:
    for name, b in solve.BACKENDS.items():
        cfg = dataclasses.replace(PlannerConfig(), solver=name)
        capped = dict(perception._fov_config(cfg).solver_options)
        assert ("max_iter" in capped) == b.iterative, name
        assert (name in solve.WARM_START_SOLVERS) == b.warm_start
        assert solve.SOLVER_DEFAULTS.get(name, {}) == dict(b.defaults)
    assert solve.backend("no-such-backend") == solve.Backend("no-such-backend")
    assert not solve.backend("daqp").warm_start and not solve.backend("daqp").iterative
    assert solve.backend("osqp").max_iter == 200_000


def test_a_known_back_end_not_installed_is_a_solver_error_of_the_plan() -> None:
    import qpsolvers

    missing = next(n for n in ("gurobi", "mosek", "copt", "hpipm") if n not in qpsolvers.available_solvers)
    sc = standard(90, 3.5)
    with pytest.raises(avp.SolverError, match="not installed"):
        avp.plan(sc.state, sc.target, avp.PlannerConfig(solver=missing))


@pytest.mark.parametrize("name, hint", [("no_such_solver", None), ("DAQP", "did you mean 'daqp'")])
def test_a_name_qpsolvers_does_not_know_is_a_config_error(name, hint) -> None:
    """Found by fuzzing: a typo was a SolverError at planning time that suggested
    ``pip install qpsolvers[no_such_solver]``."""
    with pytest.raises(avp.ConfigError, match="not a qpsolvers back-end") as exc:
        avp.PlannerConfig(solver=name)
    assert exc.value.field == "config.solver"
    assert (hint in str(exc.value)) if hint else "did you mean" not in str(exc.value)


@pytest.mark.parametrize("incline", [0, 60, 90])
def test_direct_two_sided_daqp_matches_the_qpsolvers_path(incline) -> None:
    """The reduced QP with FoV rows solved by ``daqp.solve`` on two-sided rows and by qpsolvers
    on the one-sided stacking: the same minimiser, and the same KKT residuals (16) computed by
    TwoSidedSolution and by qpsolvers' own Solution on its problem."""
    import numpy as np
    import qpsolvers

    from avp.qp.layout import layout_for
    from avp.safety import workspace_blocks
    from avp.timing import initial_durations

    sc = standard(incline, 3.5)
    cfg = PlannerConfig()
    T = initial_durations(sc.state, sc.target, cfg)
    knots = np.concatenate([[0.0], np.cumsum(T)])
    qp = avp.qp.build_perching_qp(sc.state, sc.target, cfg, T)
    qp = qp.with_inequalities(*workspace_blocks(layout_for(cfg.n_segments, cfg.degree), knots, sc.state, sc.target, cfg))
    first = solve.solve_perching_qp(qp, cfg)
    lin = perception.linearise_on(qp, qp.trajectory(first.c_hat, cfg.g), sc.target, cfg)
    red = qp.with_inequalities(*lin.blocks).reduce()
    direct = solve._solve_two_sided(red.H, red.g, red.G, red.lower, red.upper, {})
    Gs, hs = solve._one_sided(red.G, red.lower, red.upper)
    reference = qpsolvers.solve_problem(qpsolvers.Problem(P=red.H.copy(), q=red.g, G=Gs, h=hs), solver="daqp")
    assert direct.found and reference.found
    np.testing.assert_allclose(direct.x, reference.x, rtol=1e-9, atol=1e-10)
    assert direct.dual_residual() == pytest.approx(reference.dual_residual(), abs=1e-9)
    assert direct.duality_gap() == pytest.approx(reference.duality_gap(), abs=1e-9)
    assert direct.primal_residual() == pytest.approx(reference.primal_residual(), abs=1e-9)
    assert direct.is_optimal(1e-6)
    # P x is computed once per x: another x gets its own (the residuals from scratch)
    direct.x = direct.x + 1e-3
    Px = red.H @ direct.x
    # (the Rust kernel sums in its order, NumPy's BLAS in its own: rounding apart)
    assert direct.dual_residual() == pytest.approx(float(np.abs(Px + red.g + red.G.T @ direct.lam).max()),
                                                   rel=1e-12, abs=1e-14)
    assert direct.duality_gap() > 0.0 and direct.duality_gap() == pytest.approx(
        abs(direct.x @ Px + red.g @ direct.x + float(np.where(direct.lam > 0, red.upper, 0.0) @ np.maximum(direct.lam, 0.0)
                                                    + np.where(direct.lam < 0, red.lower, 0.0) @ np.minimum(direct.lam, 0.0))),
        rel=1e-12)
    # DAQP given the same QP as a least-distance problem (the planner's path): the same minimiser
    # and multipliers, to the rounding of the transformation
    ldp = qp.with_inequalities(*lin.blocks).least_distance()
    assert ldp is not None
    M, v = ldp.M.copy(), ldp.v.copy()
    via_ldp = solve._solve_two_sided(red.H, red.g, red.G, red.lower, red.upper, {}, ldp)
    assert via_ldp.found
    # DAQP takes writable buffers only; it leaves the cached rows as they were
    assert np.array_equal(ldp.M, M) and np.array_equal(ldp.v, v)
    np.testing.assert_allclose(via_ldp.x, reference.x, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(via_ldp.lam, solve._solve_two_sided(red.H, red.g, red.G, red.lower, red.upper, {}).lam,
                               rtol=1e-7, atol=1e-9)
    assert via_ldp.dual_residual() < 1e-8 and via_ldp.duality_gap() < 1e-8 and via_ldp.primal_residual() < 1e-8


def _exact_dot(row, x):
    from fractions import Fraction

    return sum((Fraction(a) * Fraction(b) for a, b in zip(row, x, strict=True)), Fraction(0))


_finite = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False)


@settings(max_examples=300, deadline=None)
@given(data=st.data(), n=st.integers(0, 6), m_eq=st.integers(0, 5), m_in=st.integers(0, 6))
def test_max_violation_kernel_against_exact_arithmetic(data, n, m_eq, m_in) -> None:
    """``_avp_rust.max_violation``: the largest relative violation, checked against the same
    quantity in exact rational arithmetic (to the rounding of the products), with infinite
    bounds never violated."""
    import math
    from fractions import Fraction

    import numpy as np

    from avp import _avp_rust

    def arr(k):
        return np.array(data.draw(st.lists(_finite, min_size=k, max_size=k)), dtype=float)

    def bounds(k):
        return np.array(data.draw(st.lists(st.one_of(_finite, st.sampled_from([math.inf, -math.inf])),
                                           min_size=k, max_size=k)), dtype=float)

    c, A, b = arr(n), arr(m_eq * n).reshape(m_eq, n), arr(m_eq)
    G = arr(m_in * n).reshape(m_in, n)
    lo, hi = bounds(m_in), bounds(m_in)
    lo = np.where(lo == math.inf, -math.inf, lo)  # a lower bound of +inf is no request anyone makes
    hi = np.where(hi == -math.inf, math.inf, hi)
    got = _avp_rust.max_violation(c, A, b, G, lo, hi)
    exact, slack = Fraction(0), 0.0
    for i in range(m_eq):
        r = _exact_dot(A[i], c) - Fraction(b[i])
        exact = max(exact, abs(r) / max(1, abs(Fraction(b[i]))))
        slack = max(slack, float(np.abs(A[i] * c).sum() + abs(b[i])) / max(1.0, abs(b[i])))
    for i in range(m_in):
        r = _exact_dot(G[i], c)
        mag = float(np.abs(G[i] * c).sum())
        if math.isfinite(hi[i]):
            exact = max(exact, (r - Fraction(hi[i])) / max(1, abs(Fraction(hi[i]))))
            slack = max(slack, (mag + abs(hi[i])) / max(1.0, abs(hi[i])))
        if math.isfinite(lo[i]):
            exact = max(exact, (Fraction(lo[i]) - r) / max(1, abs(Fraction(lo[i]))))
            slack = max(slack, (mag + abs(lo[i])) / max(1.0, abs(lo[i])))
    assert got >= 0.0
    assert abs(got - float(exact)) <= 8 * (n + 2) * 2.0**-52 * slack


@settings(max_examples=300, deadline=None)
@given(data=st.data(), n=st.integers(0, 6), m=st.integers(0, 6))
def test_kkt_residuals_kernel_against_exact_arithmetic(data, n, m) -> None:
    """``_avp_rust.kkt_residuals``: the dual residual and duality gap of a two-sided QP, checked
    against exact rational arithmetic (to the rounding of the products); only the active side
    of a row carries its multiplier, so an infinite bound with a zero multiplier adds nothing."""
    import math
    from fractions import Fraction

    import numpy as np

    from avp import _avp_rust

    def arr(k):
        return np.array(data.draw(st.lists(_finite, min_size=k, max_size=k)), dtype=float)

    H, q, G, x = arr(n * n).reshape(n, n), arr(n), arr(m * n).reshape(m, n), arr(n)
    lam = np.array(data.draw(st.lists(st.one_of(_finite, st.just(0.0)), min_size=m, max_size=m)), dtype=float)
    lo = np.where(lam < 0, arr(m), -math.inf)  # an infinite bound only on the inactive side
    hi = np.where(lam > 0, arr(m), math.inf)
    dual, gap = _avp_rust.kkt_residuals(H, q, G, x, lam, lo, hi)
    F = Fraction
    Hx = [_exact_dot(H[i], x) for i in range(n)]
    stat = [Hx[i] + F(q[i]) + sum((F(G[j, i]) * F(lam[j]) for j in range(m)), F(0)) for i in range(n)]
    exact_dual = max((abs(s) for s in stat), default=F(0))
    exact_gap = abs(sum((F(x[i]) * Hx[i] + F(q[i]) * F(x[i]) for i in range(n)), F(0))
                    + sum((F(hi[j]) * F(lam[j]) for j in range(m) if lam[j] > 0), F(0))
                    + sum((F(lo[j]) * F(lam[j]) for j in range(m) if lam[j] < 0), F(0)))
    mag_dual = float(np.abs(H).sum() * (np.abs(x).max() if n else 0) + np.abs(q).sum()
                     + np.abs(G).sum() * (np.abs(lam).max() if m else 0)) + 1.0
    mag_gap = float(np.abs(x) @ np.abs(H) @ np.abs(x) + np.abs(q) @ np.abs(x)
                    + np.where(np.isfinite(hi), np.abs(hi), 0) @ np.abs(lam)
                    + np.where(np.isfinite(lo), np.abs(lo), 0) @ np.abs(lam)) + 1.0
    assert abs(dual - float(exact_dual)) <= 16 * (n + m + 2) * 2.0**-52 * mag_dual
    assert abs(gap - float(exact_gap)) <= 16 * (n + m + 2) * 2.0**-52 * mag_gap


@settings(max_examples=150, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(0, 6), m_eq=st.integers(0, 5), m_in=st.integers(0, 6),
       layout=st.sampled_from(["F", "strided", "int"]))
def test_the_qp_checks_read_any_layout_by_its_values(seed, n, m_eq, m_in, layout) -> None:
    """The judges take the planner's arrays as they are (no conversion in Python): a
    column-major matrix, a strided view or integer entries give the same figures, bit for bit,
    as the same values in row-major float64."""
    import numpy as np

    from avp import _avp_rust

    rng = np.random.default_rng(seed)

    def shown(a):
        if layout == "F":
            return np.asfortranarray(a)
        if layout == "strided":
            wide = np.zeros(a.shape[:-1] + (2 * a.shape[-1],)) if a.ndim else a
            wide[..., ::2] = a
            return wide[..., ::2]
        return a.astype(np.int64)

    def ints(*shape):
        return rng.integers(-9, 10, size=shape).astype(float)

    c, A, b, G = ints(n), ints(m_eq, n), ints(m_eq), ints(m_in, n)
    lo, hi = ints(m_in) - 10.0, ints(m_in) + 10.0
    assert _avp_rust.max_violation(*map(shown, (c, A, b, G, lo, hi))) == _avp_rust.max_violation(c, A, b, G, lo, hi)
    H, q, lam = ints(n, n), ints(n), ints(m_in)
    assert _avp_rust.kkt_residuals(*map(shown, (H, q, G, c, lam, lo, hi))) == _avp_rust.kkt_residuals(H, q, G, c, lam, lo, hi)


@pytest.mark.parametrize("call, arg", [
    (lambda r, np: r.max_violation(np.zeros(2), np.zeros((1, 3)), np.zeros(1), np.zeros((0, 2)), np.zeros(0),
                                   np.zeros(0)), "a"),
    (lambda r, np: r.max_violation(np.zeros(2), np.zeros((0, 2)), np.zeros(0), np.zeros((1, 2)), np.zeros(1),
                                   np.zeros(2)), "upper"),
    (lambda r, np: r.max_violation(np.zeros(2), np.zeros((0, 2)), np.zeros(0), np.zeros((3, 2)), np.zeros(2),
                                   np.zeros(2)), "lower"),
    (lambda r, np: r.max_violation(np.zeros(0), np.zeros((3, 0)), np.zeros(1), np.zeros((0, 0)), np.zeros(0),
                                   np.zeros(0)), "b"),
    (lambda r, np: r.kkt_residuals(np.eye(2), np.zeros(2), np.zeros((1, 2)), np.zeros(2), np.zeros(2), np.zeros(1),
                                   np.zeros(1)), "lam"),
    (lambda r, np: r.kkt_residuals(np.zeros((0, 0)), np.zeros(0), np.zeros((3, 0)), np.zeros(0), np.zeros(1),
                                   np.zeros(1), np.zeros(1)), "lam"),
    (lambda r, np: r.kkt_residuals(np.eye(3)[:2], np.zeros(3), np.zeros((0, 3)), np.zeros(3), np.zeros(0), np.zeros(0),
                                   np.zeros(0)), "h"),
], ids=["a columns", "upper length", "lower length", "b length without columns", "g rows", "g rows without columns",
        "h rows"])
def test_qp_check_kernels_name_a_bad_argument(call, arg) -> None:
    import numpy as np

    from avp import _avp_rust

    with pytest.raises(_avp_rust.KernelError) as exc:
        call(_avp_rust, np)
    assert exc.value.arg == arg


def test_a_nan_multiplier_is_incompatible_not_a_pass() -> None:
    """A NaN multiplier makes the dual residual and duality gap NaN, and the fallback check (16)
    calls the solve incompatible; a back-end that returns no multipliers (qpsolvers' ``inf``,
    "not defined") is judged by its primal check alone."""
    import math

    import numpy as np
    import qpsolvers

    from avp import _avp_rust

    dual, gap = _avp_rust.kkt_residuals(np.eye(2), np.zeros(2), np.eye(2), np.zeros(2), np.array([math.nan, 0.0]),
                                        np.zeros(2), np.ones(2))
    assert math.isnan(dual) and math.isnan(gap)
    sol = solve.TwoSidedSolution(qpsolvers.Problem(P=np.eye(2), q=np.zeros(2)), G=np.eye(2), lower=np.zeros(2),
                                 upper=np.ones(2))
    sol.found, sol.x, sol.lam = True, np.zeros(2), np.array([math.nan, 0.0])
    outcome = solve.QpOutcome(status=solve.QpStatus.SOLVED, c_hat=np.zeros(2), solver="daqp", build_time=0.0,
                              solve_time=0.0, max_violation=0.0, solution=sol)
    assert "dual residual nan" in (solve.incompatibility(outcome) or "")
    no_duals = qpsolvers.Solution(qpsolvers.Problem(P=np.eye(2), q=np.zeros(2), G=np.eye(2), h=np.ones(2)))
    no_duals.found, no_duals.x = True, np.zeros(2)  # no z: qpsolvers says inf
    assert no_duals.dual_residual() == math.inf
    assert solve.incompatibility(dataclasses.replace(outcome, solution=no_duals)) is None


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 6), m=st.integers(1, 8))
def test_the_one_sided_multipliers_are_those_qpsolvers_judges(seed, n, m) -> None:
    """``z`` (computed from ``lam`` when read) is the multiplier vector of the one-sided stacking
    ``[G; -G] x <= [upper; -lower]``: qpsolvers' own ``Solution`` on that problem, given ``x``
    and this ``z``, finds the residuals the two-sided solution reports; a set ``z`` is kept."""
    import numpy as np
    import qpsolvers

    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n, n))
    H, g, G = A @ A.T + np.eye(n), 3.0 * rng.normal(size=n), rng.normal(size=(m, n))
    lower, upper = -rng.uniform(0.0, 1.0, m), rng.uniform(0.0, 1.0, m)  # 0 is feasible
    direct = solve._solve_two_sided(H, g, G, lower, upper, {})
    assert direct.found and direct.lam is not None and direct.z is not None
    np.testing.assert_array_equal(direct.z, np.concatenate([np.maximum(direct.lam, 0), -np.minimum(direct.lam, 0)]))
    assert (direct.z >= 0).all()
    one_sided = qpsolvers.Solution(qpsolvers.Problem(P=H, q=g, G=np.vstack([G, -G]), h=np.concatenate([upper, -lower])))
    one_sided.found, one_sided.x, one_sided.z = True, direct.x, direct.z
    scale = 1.0 + float(np.abs(g).max()) + float(np.abs(direct.z).max()) * float(np.abs(G).max())
    assert one_sided.dual_residual() == pytest.approx(direct.dual_residual(), abs=1e-12 * scale)
    assert one_sided.duality_gap() == pytest.approx(direct.duality_gap(), abs=1e-12 * scale * (1 + float(np.abs(direct.x).max())))
    assert direct.z is direct.z  # computed once: what is written into it stays
    direct.z = np.ones(2 * m)
    np.testing.assert_array_equal(direct.z, np.ones(2 * m))
    direct.z = None  # set, even to None: kept
    assert direct.z is None


@pytest.mark.parametrize("action", ["error", "always"])
def test_a_back_end_warning_of_a_strict_solve_reaches_the_callers_filters(monkeypatch, action) -> None:
    """The QP without FoV rows is solved without catching its warnings: under the caller's
    "error" filter the back-end's warning is a typed ``SolverError`` naming the back-end; under
    "always" it reaches the caller (once per solve) and the plan is made. The FoV QPs' warnings,
    expected on an incompatible problem (16), are logged, not emitted."""
    import warnings

    import daqp
    from scenarios import standard

    real = daqp.solve

    def noisy(*args, **kwargs):
        warnings.warn("back-end says hi", RuntimeWarning, stacklevel=1)
        return real(*args, **kwargs)

    monkeypatch.setattr(daqp, "solve", noisy)
    sc = standard(60, 7.5)  # a first plan with three SQP steps: one strict solve, three FoV solves
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter(action)
        if action == "error":
            with pytest.raises(avp.SolverError, match="daqp.*back-end says hi"):
                avp.plan_detailed(sc.state, sc.target, PlannerConfig())
            return
        result = avp.plan_detailed(sc.state, sc.target, PlannerConfig())
    assert result.status is avp.PlanStatus.SOLVED
    fov_solves = sum("FoV points placed" in line and "daqp: solved" in line for line in result.log)
    logged = sum("RuntimeWarning: back-end says hi" in line for line in result.log)
    shown = [w for w in caught if "back-end says hi" in str(w.message)]
    assert fov_solves == 3 and logged == fov_solves  # each FoV solve's warning in the log, not shown
    assert len(shown) == 1 and shown[0].category is RuntimeWarning  # the strict solve's, to the caller


def test_the_kkt_figures_follow_every_array_they_read() -> None:
    """The residuals are recomputed when any array they read is replaced (not only ``x``)."""
    import numpy as np
    import qpsolvers

    sol = solve.TwoSidedSolution(qpsolvers.Problem(P=np.eye(2), q=np.zeros(2)), G=np.eye(2), lower=np.zeros(2),
                                 upper=np.ones(2))
    sol.found, sol.x, sol.lam = True, np.ones(2), np.ones(2)
    assert sol.dual_residual() == 2.0  # x + lam
    sol.G = 2.0 * np.eye(2)
    assert sol.dual_residual() == 3.0
    sol.upper = 2.0 * np.ones(2)
    assert sol.duality_gap() == 2.0 + 4.0  # x.x + upper.lam
    sol.lower = None  # the gap needs both bounds; the dual residual does not
    assert sol.duality_gap() == float("inf") and sol.dual_residual() == 3.0
    sol.problem = qpsolvers.Problem(P=2.0 * np.eye(2), q=np.zeros(2))  # a new cost: 2 x + 2 lam
    assert sol.dual_residual() == 4.0
    sol.problem = qpsolvers.Problem(P=2.0 * np.eye(2), q=np.ones(2))
    assert sol.dual_residual() == 5.0


def test_an_overflowed_kkt_residual_of_the_direct_path_is_incompatible() -> None:
    """An infinite residual of the direct DAQP path is an overflow, not qpsolvers' "not
    defined" (its multipliers are always there): the FoV solve is incompatible (16)."""
    import math

    import numpy as np
    import qpsolvers

    sol = solve.TwoSidedSolution(qpsolvers.Problem(P=np.eye(2), q=np.zeros(2)), G=np.ones((2, 2)), lower=np.zeros(2),
                                 upper=np.ones(2))
    sol.found, sol.x, sol.lam = True, np.zeros(2), np.array([math.inf, 0.0])
    outcome = solve.QpOutcome(status=solve.QpStatus.SOLVED, c_hat=np.zeros(2), solver="daqp", build_time=0.0,
                              solve_time=0.0, max_violation=0.0, solution=sol)
    assert sol.dual_residual() == math.inf
    assert "dual residual inf" in (solve.incompatibility(outcome) or "")


def test_rows_of_any_order_and_dtype_are_judged_not_refused() -> None:
    """A QP with a column-major or integer inequality block (``ConstraintBlock`` is public) is
    solved and judged as before: the acceptance check takes any real array."""
    import numpy as np

    from avp.qp.assemble import ConstraintBlock

    sc = standard(60, 3.5)
    cfg = PlannerConfig()
    from avp.timing import initial_durations

    qp = avp.qp.build_perching_qp(sc.state, sc.target, cfg, initial_durations(sc.state, sc.target, cfg))
    n = qp.layout.n_variables
    row = np.zeros((1, n), dtype=np.int64)
    row[0, 0] = 1
    bare = qp.without("")  # no other inequality block: stacking would hand the kernel float64 rows
    for block in (ConstraintBlock("column-major", np.asfortranarray(np.eye(2, n)), np.full(2, -1e3), np.full(2, 1e3)),
                  ConstraintBlock("integer", row, np.array([-1000]), np.array([1000]))):
        one = bare.with_inequalities(block)
        G = one.stacked_inequalities()[0]
        assert not (G.flags.c_contiguous and G.dtype == np.float64)  # the block's own layout reaches the check
        out = solve.solve_perching_qp(one, cfg)
        assert out.ok and out.max_violation < solve.FEASIBILITY_TOL


def test_a_primal_start_is_read_in_the_variables_it_was_given_in(monkeypatch) -> None:
    """With a DAQP setting that depends on the variables (``primal_start``, ``eps_prox``), DAQP
    gets the reduced QP itself, not its least-distance form, and the solution is the same."""
    import daqp
    import numpy as np

    from avp.timing import initial_durations

    sc = standard(60, 3.5)
    cfg = PlannerConfig()
    qp = avp.qp.build_perching_qp(sc.state, sc.target, cfg, initial_durations(sc.state, sc.target, cfg))
    red, ldp = qp.reduce(), qp.least_distance()
    assert ldp is not None
    hessians = []
    real = daqp.solve

    def spy(H, *args, **kwargs):
        hessians.append(np.array(H))
        return real(H, *args, **kwargs)

    monkeypatch.setattr(daqp, "solve", spy)
    plain = solve._solve_two_sided(red.H, red.g, red.G, red.lower, red.upper, {}, ldp)
    started = solve._solve_two_sided(red.H, red.g, red.G, red.lower, red.upper, {"primal_start": plain.x}, ldp)
    proximal = solve._solve_two_sided(red.H, red.g, red.G, red.lower, red.upper, {"eps_prox": 1e-6}, ldp)
    assert np.array_equal(hessians[0], np.eye(red.H.shape[0]))
    assert np.array_equal(hessians[1], red.H) and np.array_equal(hessians[2], red.H)
    np.testing.assert_allclose(started.x, plain.x, rtol=1e-8, atol=1e-9)
    assert proximal.found
    np.testing.assert_allclose(proximal.x, plain.x, rtol=1e-5, atol=1e-5)


def test_a_nan_residual_is_a_violation_not_a_pass() -> None:
    """A residual that overflows to NaN (``inf - inf``) is not dropped by the maximum: the
    point counts as violating (before the kernel, Python's ``max`` skipped a NaN)."""
    import math

    import numpy as np

    from avp import _avp_rust

    v = _avp_rust.max_violation(np.array([1e308, 1e308]), np.zeros((0, 2)), np.zeros(0), np.ones((1, 2)),
                                np.array([-math.inf]), np.array([math.inf]))
    assert math.isnan(v) and not v <= solve.FEASIBILITY_TOL
    # through the planner's judge of a solve: a row that overflows at the solution, not SOLVED
    from avp.timing import initial_durations

    sc = standard(60, 3.5)
    cfg = PlannerConfig()
    qp = avp.qp.build_perching_qp(sc.state, sc.target, cfg, initial_durations(sc.state, sc.target, cfg))
    out = solve.solve_perching_qp(qp, cfg)
    assert out.ok
    G, lo, hi = qp.stacked_inequalities()
    big = np.full((1, G.shape[1]), 1e308)
    judged = solve._outcome(qp, cfg, qp.reduce(), out.solution, np.vstack([G, big]), np.append(lo, -math.inf),
                            np.append(hi, math.inf), 0.0, 0.0)
    assert judged.status is solve.QpStatus.INACCURATE and math.isnan(judged.max_violation)


def test_threads_logging_fov_warnings_leave_the_process_filters_as_they_were(monkeypatch) -> None:
    """Two threads in the FoV solves' warning capture at once: ``warnings.catch_warnings`` swaps
    the process's filter list, so a thread that entered second and leaves last would put back the
    list the first had (its "always" filter and recorder) for good. The capture is serialised:
    the second thread's solve runs inside its own capture only, and the filters are those of
    before. The first solve waits for the second to start (it cannot while the first holds the
    turn, so that wait runs out); the second leaves after the first: the order that corrupted."""
    import threading
    import types
    import warnings

    from avp import attempt

    first_inside, second_inside, first_left = threading.Event(), threading.Event(), threading.Event()
    waited_out: list[bool] = []  # whether the first solve's wait for the second ran out
    before = list(warnings.filters)

    def fake_solve(qp, cfg, initvals):
        if threading.current_thread().name == "first":
            first_inside.set()
            waited_out.append(not second_inside.wait(0.5))  # set at once without the turns
        else:
            second_inside.set()
            first_left.wait(5.0)
        warnings.warn("expected on an incompatible problem", RuntimeWarning, stacklevel=1)
        return types.SimpleNamespace(build_time=0.0, solve_time=0.0)

    monkeypatch.setattr(attempt, "solve_perching_qp", fake_solve)
    logs: dict[str, list[str]] = {}

    def first() -> None:
        ledger = attempt._Ledger()
        ledger.run(None, None, "FoV", False, None)  # type: ignore[arg-type]
        logs["first"] = ledger.log
        first_left.set()

    def second() -> None:
        first_inside.wait(5.0)
        ledger = attempt._Ledger()
        ledger.run(None, None, "FoV", False, None)  # type: ignore[arg-type]
        logs["second"] = ledger.log

    threads = [threading.Thread(target=first, name="first"), threading.Thread(target=second, name="second")]
    for th in threads:
        th.start()
    for th in threads:
        th.join(10.0)
    assert waited_out == [True]  # the second solve could not start while the first was inside
    assert warnings.filters == before
    for name in ("first", "second"):  # each thread's warning in its own log
        assert logs[name] == ["FoV: RuntimeWarning: expected on an incompatible problem"]


@pytest.mark.skipif(not hasattr(__import__("os"), "fork"), reason="POSIX fork")
def test_a_fork_during_another_threads_fov_capture_waits_for_it(monkeypatch) -> None:
    """A fork while another thread captures an FoV solve's warnings waits for the capture to
    end: the child starts with the process's filters as they were, and can capture itself (the
    turn is free there)."""
    import os
    import threading
    import types
    import warnings

    from avp import attempt

    inside = threading.Event()

    def fake_solve(qp, cfg, initvals):
        inside.set()
        time.sleep(0.3)  # the fork is asked for meanwhile
        return types.SimpleNamespace(build_time=0.0, solve_time=0.0)

    monkeypatch.setattr(attempt, "solve_perching_qp", fake_solve)
    before = list(warnings.filters)
    thread = threading.Thread(target=lambda: attempt._Ledger().run(None, None, "FoV", False, None))  # type: ignore[arg-type]
    thread.start()
    inside.wait(5.0)
    pid = os.fork()
    if pid == 0:  # the child: only this thread lives on
        ok = warnings.filters == before
        ok = ok and attempt._CAPTURE.acquire(timeout=2.0)  # free (a lock held at the fork would stay held)
        os._exit(0 if ok else 1)
    thread.join(10.0)
    _, status = os.waitpid(pid, 0)
    assert os.waitstatus_to_exitcode(status) == 0
    assert warnings.filters == before
