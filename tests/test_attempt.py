"""The one attempt path (avp.attempt): an attempt returns its log lines and timings, and the
planner's record is made of them."""

from __future__ import annotations

import numpy as np
from scenarios import standard

import avp
from avp import perception
from avp.attempt import Attempt, solve_at
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
