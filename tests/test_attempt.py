"""The one attempt path (avp.attempt): an attempt returns its log lines and timings, and the
planner's record is made of them."""

from __future__ import annotations

import numpy as np
import pytest
from scenarios import standard

import avp
from avp import perception
from avp.attempt import Attempt, _rows_hold, solve_at, solve_fov
from avp.qp.assemble import ConstraintBlock, build_perching_qp
from avp.solve import solve_perching_qp
from avp.timing import initial_durations


def test_attempt_returns_its_log_and_timings_and_the_plan_is_made_of_them() -> None:
    sc = standard(60, 3.5)
    cfg = avp.PlannerConfig()
    T = initial_durations(sc.state, sc.target, cfg)
    attempt = solve_at(sc.state, sc.target, cfg, T)
    assert isinstance(attempt, Attempt) and attempt.trajectory is not None
    assert attempt.log and all(isinstance(line, str) for line in attempt.log)
    assert attempt.build > 0.0 and attempt.solve > 0.0 and attempt.certify > 0.0
    assert attempt.safety is not None and attempt.safety.certified
    result = avp.plan_detailed(sc.state, sc.target, cfg)
    # the plan's log: the allocation line, this attempt's lines in order, then the certificate
    assert result.log[1:1 + len(attempt.log)] == attempt.log
    np.testing.assert_array_equal(result.trajectory.coefficients, attempt.trajectory.coefficients)


def test_fov_wrapper_appends_the_attempt_lines() -> None:
    sc = standard(30, 3.5)
    cfg = avp.PlannerConfig()
    T = initial_durations(sc.state, sc.target, cfg)
    log: list[str] = ["before"]
    attempt = perception.solve_with_fov(sc.state, sc.target, cfg, T, log)
    assert log == ["before", *attempt.log] and attempt.trajectory is not None
    assert perception.FovSolve is Attempt


@pytest.mark.parametrize(("incline", "standoff"), [(90, 1.5), (90, 4.5), (60, 3.5), (45, 7.5), (30, 3.5), (0, 3.5)])
def test_fov_rows_that_hold_at_the_plain_optimum_are_not_re_solved_and_nothing_is_lost(incline: float, standoff: float) -> None:
    """The first SQP step is skipped exactly when every FoV row holds at the FoV-free optimum;
    then a solve with the rows (done here independently) finds no lower cost and the same plan."""
    sc = standard(incline, standoff)
    cfg = avp.PlannerConfig()
    T = initial_durations(sc.state, sc.target, cfg)
    base = build_perching_qp(sc.state, sc.target, cfg, T)
    plain = solve_perching_qp(base, cfg)
    lin = perception.linearise_on(base, base.trajectory(plain.c_hat, cfg.g), sc.target, cfg)
    with_rows = base.with_inequalities(*lin.blocks)
    C, lo, hi = with_rows.stacked_inequalities()
    y = C @ plain.c_hat
    hold = bool(np.all(y <= hi + 1e-9 * (1 + np.abs(hi))) and np.all(y >= lo - 1e-9 * (1 + np.abs(lo))))
    attempt = solve_fov(sc.state, sc.target, cfg, T)
    skipped = any("not re-solved" in line for line in attempt.log)
    assert skipped == hold
    if not hold:
        assert any("SQP step 1" in line and ("solved" in line or "incompatible" in line) for line in attempt.log)
        return
    forced = solve_perching_qp(with_rows, cfg)

    def cost(c: np.ndarray) -> float:
        return 0.5 * float(c @ base.P @ c)

    assert cost(forced.c_hat) >= cost(plain.c_hat) * (1 - 1e-9)  # more rows never lower the cost
    assert cost(forced.c_hat) <= cost(plain.c_hat) * (1 + 1e-7)  # and here they cost nothing
    np.testing.assert_allclose(attempt.trajectory.coefficients, base.trajectory(plain.c_hat, cfg.g).coefficients)
    np.testing.assert_allclose(forced.c_hat, plain.c_hat, rtol=1e-5, atol=1e-6 * np.abs(plain.c_hat).max())


def test_the_rows_check_sees_a_violation_of_one_row() -> None:
    sc = standard(60, 3.5)
    cfg = avp.PlannerConfig()
    T = initial_durations(sc.state, sc.target, cfg)
    base = build_perching_qp(sc.state, sc.target, cfg, T)
    plain = solve_perching_qp(base, cfg)
    lin = perception.linearise_on(base, base.trajectory(plain.c_hat, cfg.g), sc.target, cfg)
    assert _rows_hold(lin.blocks, plain.c_hat)
    block = lin.blocks[-1]
    y = block.matrix @ plain.c_hat
    tight = ConstraintBlock(block.name, block.matrix, block.lower, y.copy())
    tight.upper[0] -= 1e-6 * (1 + abs(y[0]))
    assert not _rows_hold((*lin.blocks[:-1], tight), plain.c_hat)
