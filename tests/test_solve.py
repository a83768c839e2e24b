"""QP back-ends (avp.solve): the one table of back-end facts drives warm starts and iteration caps,
and a missing back-end is a typed SolverError."""

from __future__ import annotations

import dataclasses

import pytest
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
    assert direct.dual_residual() == float(np.abs(Px + red.g + red.G.T @ direct.lam).max())
    assert direct.duality_gap() > 0.0 and direct.duality_gap() == pytest.approx(
        abs(direct.x @ Px + red.g @ direct.x + float(np.where(direct.lam > 0, red.upper, 0.0) @ np.maximum(direct.lam, 0.0)
                                                    + np.where(direct.lam < 0, red.lower, 0.0) @ np.minimum(direct.lam, 0.0))),
        rel=1e-12)
