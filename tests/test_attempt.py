"""The one attempt path (avp.attempt): an attempt returns its log lines and timings, and the
planner's record is made of them."""

from __future__ import annotations

import math
import pickle
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from scenarios import standard

import avp
from avp import perception
from avp.attempt import Attempt, solve_at, solve_fov
from avp.config import FovPointPolicy
from avp.errors import ConfigError
from avp.qp.assemble import ConstraintBlock, build_perching_qp
from avp.qp.fov import fov_blocks
from avp.qp.layout import layout_for
from avp.safety import certify_workspace
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


def test_fov_rows_that_hold_at_the_plain_optimum_are_not_re_solved_and_nothing_is_lost() -> None:
    """The first SQP step is skipped exactly when every FoV row holds at the FoV-free optimum;
    then a solve with the rows (done here independently) finds no lower cost and the same plan.
    Both branches occur among the scenarios."""
    seen = set()
    for incline, standoff in [(90, 1.5), (90, 4.5), (60, 3.5), (45, 7.5), (30, 3.5), (0, 3.5)]:
        sc = standard(incline, standoff)
        cfg = avp.PlannerConfig()
        T = initial_durations(sc.state, sc.target, cfg)
        base = build_perching_qp(sc.state, sc.target, cfg, T)
        plain = solve_perching_qp(base, cfg)
        lin = perception.linearise_on(base, base.trajectory(plain.c_hat, cfg.g), sc.target, cfg)
        assert lin.blocks
        C = np.vstack([b.matrix for b in lin.blocks])
        lo = np.concatenate([b.lower for b in lin.blocks])
        hi = np.concatenate([b.upper for b in lin.blocks])
        y = C @ plain.c_hat
        excess = np.maximum(y - hi, lo - y) / np.maximum(1.0, np.minimum(np.abs(lo), np.abs(hi)))
        hold = bool(np.max(excess) <= 1e-9)
        seen.add(hold)
        attempt = solve_fov(sc.state, sc.target, cfg, T)
        assert any("not re-solved" in line for line in attempt.log) == hold
        if not hold:
            assert any("SQP step 1" in line and ("solved" in line or "incompatible" in line) for line in attempt.log)
            continue
        forced = solve_perching_qp(base.with_inequalities(*lin.blocks), cfg)

        cost_forced = 0.5 * float(forced.c_hat @ base.P @ forced.c_hat)
        cost_plain = 0.5 * float(plain.c_hat @ base.P @ plain.c_hat)
        assert cost_forced >= cost_plain * (1 - 1e-9)  # more rows never lower the cost
        assert cost_forced <= cost_plain * (1 + 1e-7)  # and here they cost nothing
        np.testing.assert_allclose(attempt.trajectory.coefficients, base.trajectory(plain.c_hat, cfg.g).coefficients)
        np.testing.assert_allclose(forced.c_hat, plain.c_hat, rtol=1e-5, atol=1e-6 * np.abs(plain.c_hat).max())
        assert attempt.linearisation is not None and attempt.sqp_steps == 0
    assert seen == {True, False}


def _rows_hold(blocks: tuple[ConstraintBlock, ...], c_hat: np.ndarray, tol: float = 1e-9) -> bool:
    """The oracle: every row of ``blocks`` evaluated at ``c_hat`` (a NaN fails)."""
    for b in blocks:
        y = b.matrix @ c_hat
        if not (np.all(y <= b.upper + tol * (1 + np.abs(b.upper))) and np.all(y >= b.lower - tol * (1 + np.abs(b.lower)))):
            return False
    return True


def _hold_matches(incline: float, standoff: float, shift: tuple[float, float, float], policy: FovPointPolicy,
                  margin: float, **fov: float) -> list[bool]:
    """``hold_at_linearisation`` against the built rows evaluated at the coefficients the
    linearisation point came from (asserted equal), on the FoV-free optimum and on the optimum
    for a moved target (a point that is not an optimum); returns the outcomes."""
    sc = standard(incline, standoff)
    cfg = avp.PlannerConfig(fov=avp.FovConfig(point_policy=policy, margin=margin, **fov))
    T = initial_durations(sc.state, sc.target, cfg)
    base = build_perching_qp(sc.state, sc.target, cfg, T)
    moved = avp.PerchTarget(point=sc.target.point + np.array(shift), R_WS=sc.target.R_WS)
    other = solve_perching_qp(build_perching_qp(sc.state, moved, cfg, T), cfg)
    out = []
    for c in (solve_perching_qp(base, cfg).c_hat, other.c_hat):
        lin = perception.linearise_on(base, base.trajectory(c, cfg.g), sc.target, cfg)
        assert lin.hold_at_linearisation == _rows_hold(lin.blocks, c), (incline, standoff, policy, margin)
        out.append(lin.hold_at_linearisation)
    return out


@settings(max_examples=60, deadline=None)
@example(incline=120.0, standoff=3.0, shift=(0.0, 0.0, 0.0), policy=FovPointPolicy.SKIP, margin=0.02)
@given(incline=st.sampled_from([0.0, 30.0, 60.0, 90.0, 120.0]), standoff=st.floats(1.0, 8.0),
       shift=st.tuples(st.floats(-0.3, 0.3), st.floats(-0.3, 0.3), st.floats(-0.3, 0.3)),
       policy=st.sampled_from(list(FovPointPolicy)), margin=st.sampled_from([0.0, 0.02]))
def test_hold_at_linearisation_agrees_with_the_rows_evaluated_at_the_point(
        incline: float, standoff: float, shift: tuple[float, float, float], policy: FovPointPolicy,
        margin: float) -> None:
    _hold_matches(incline, standoff, shift, policy, margin)


def test_hold_at_linearisation_on_a_grid_sees_both_outcomes_for_every_policy() -> None:
    """Dense fixed grid (no sampling luck): zero mismatches; both outcomes occur for every policy
    without a margin and for SKIP with one (with a 0.02 margin, KEEP and PROGRESS always leave
    some row violated here), so a rule that ignored the margin or the policy would be caught."""
    for policy in FovPointPolicy:
        for margin in (0.0, 0.02):
            seen = set()
            for incline in (0.0, 30.0, 60.0, 90.0, 120.0):
                for standoff in (1.0, 2.5, 4.5, 8.0):
                    for shift in ((0.0, 0.0, 0.0), (0.0, 0.0, -0.1)):
                        seen.update(_hold_matches(incline, standoff, shift, policy, margin))
            if margin == 0.0 or policy is FovPointPolicy.SKIP:
                assert seen == {True, False}, (policy, margin)
    # infinite trust radii: no trust-region rows, the rule is unchanged
    _hold_matches(90.0, 3.0, (0.0, 0.0, 0.0), FovPointPolicy.SKIP, 0.0, trust_position=math.inf,
                  trust_acceleration=math.inf, trust_yaw=math.inf)


def test_fov_blocks_edge_cases_and_pickling() -> None:
    layout = layout_for(3, 7)
    knots = np.array([0.0, 0.5, 1.0, 1.5])
    t = np.array([0.3, 0.9, 1.4])
    x0 = np.array([[-2.0, 0.0, 1.0], [-1.0, 0.0, 1.0], [-0.5, 0.0, 1.0]])
    psi0 = np.zeros(3)
    s_W = np.array([0.0, 0.0, 1.0])
    fall = np.tile([0.0, 0.0, -avp.frames.GRAVITY], (3, 1))  # no thrust: no usable gradient
    lin = fov_blocks(layout, knots, t, x0, psi0, fall, s_W, avp.FovConfig())
    assert not lin.placed.any() and lin.hold_at_linearisation and lin.blocks == ()
    level = np.zeros((3, 3))  # hover: the target ahead is seen by the front camera
    lin = fov_blocks(layout, knots, t, x0, psi0, level, s_W, avp.FovConfig())
    assert lin.placed.all() and lin.hold_at_linearisation == bool(np.all(lin.h0 <= 0.0))
    assert len(lin.blocks) == 4 and lin.n_rows == 3 + 9 + 9 + 3
    again = pickle.loads(pickle.dumps(lin))
    assert all(np.array_equal(a.matrix, b.matrix) for a, b in zip(again.blocks, lin.blocks, strict=True))
    assert not lin.placed.flags.writeable and not lin.h0.flags.writeable
    behind = np.array([-5.0, 0.0, 1.0])  # a target behind the camera
    prog = fov_blocks(layout, knots, t, x0, psi0, level, behind,
                      avp.FovConfig(point_policy=FovPointPolicy.PROGRESS))
    assert prog.progress.any() and not prog.hold_at_linearisation
    assert not _rows_hold(prog.blocks, _coefficients_through(layout, knots, t, x0, level, psi0))


def _coefficients_through(layout, knots, t, x0, a0, psi0) -> np.ndarray:
    """Some coefficients whose position, acceleration and yaw at ``t`` are ``x0``, ``a0``,
    ``psi0`` (least squares on the rows the FoV block uses)."""
    lin = fov_blocks(layout, knots, t, x0, psi0, a0, np.array([10.0, 0.0, 1.0]),
                     avp.FovConfig(point_policy=FovPointPolicy.KEEP))
    M = np.vstack([b.matrix for b in lin.blocks[1:]])
    rhs = np.concatenate([0.5 * (b.lower + b.upper) for b in lin.blocks[1:]])
    return np.linalg.lstsq(M, rhs, rcond=None)[0]


def test_the_rows_check_on_synthetic_rows() -> None:
    c = np.array([1.0, -2.0, 0.5])
    M = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 1.0]])  # rows: 1, -1.5

    def block(lo: list[float], hi: list[float]) -> ConstraintBlock:
        return ConstraintBlock("fov test", M, np.array(lo), np.array(hi))

    assert _rows_hold((), c)
    assert _rows_hold((block([1.0, -np.inf], [1.0, -1.5]),), c)  # on both bounds exactly
    assert _rows_hold((block([1.0 + 5e-10, -2.0], [2.0, 0.0]),), c)  # inside the tolerance
    assert not _rows_hold((block([1.0 + 1e-6, -2.0], [2.0, 0.0]),), c)  # a lower bound
    assert not _rows_hold((block([0.0, -2.0], [2.0, -1.5 - 1e-6]),), c)  # an upper bound
    assert not _rows_hold((block([0.0, -2.0], [2.0, 0.0]), block([0.0, -2.0], [0.999, 0.0])), c)  # second block
    assert not _rows_hold((block([0.0, -2.0], [2.0, 0.0]),), np.array([np.nan, 0.0, 0.0]))  # NaN fails


def test_sqp_min_gain_stops_a_first_plan_after_a_small_step() -> None:
    """``fov.sqp_min_gain``: a further SQP step only after a kept step that gained at least that
    much. A wall at 1.5 m takes several scored steps by default; with the largest threshold the
    first kept step is the last, and it is the default's first step."""
    state = avp.State.hover([-1.5, 0.0, 1.5])
    target = avp.PerchTarget.from_incline([0.0, 0.0, 1.5], math.radians(90.0))

    def scored(result: avp.PlanResult) -> list[str]:
        return [line for line in result.log if line.startswith("SQP step") and "visibility" in line]

    default = avp.plan_detailed(state, target, avp.PlannerConfig())
    assert len(scored(default)) >= 2
    cfg = avp.PlannerConfig()
    capped = avp.plan_detailed(state, target, replace(cfg, fov=replace(cfg.fov, sqp_min_gain=1.0)))
    assert scored(capped) == scored(default)[:1]
    assert any("sqp_min_gain" in line for line in capped.log)
    assert capped.status is default.status
    # the first step is kept, not discarded: the plan of a one-step SQP, to the bit
    one = avp.plan_detailed(state, target, replace(cfg, fov=replace(cfg.fov, sqp_iterations=1)))
    assert capped.trajectory is not None and one.trajectory is not None
    np.testing.assert_array_equal(capped.trajectory.coefficients, one.trajectory.coefficients)
    assert not np.array_equal(capped.trajectory.coefficients, default.trajectory.coefficients)
    for bad in (-0.01, 1.5):
        with pytest.raises(ConfigError, match="fov.sqp_min_gain"):
            avp.FovConfig(sqp_min_gain=bad)


@pytest.mark.parametrize(("incline", "standoff", "ground_z", "returns_seed"),
                         [(90, 7.5, 0.5, True), (60, 7.5, 0.5, False)])
def test_the_fov_stage_of_a_refined_seed_starts_from_its_rows_and_keeps_its_certificate(
        incline: float, standoff: float, ground_z: float, returns_seed: bool) -> None:
    """A certified search step that needed workspace refinement seeds the FoV stage with its own
    rows: when the FoV rows hold at its solution that certified plan is returned without a solve;
    otherwise the FoV plan keeps every refinement row of the seed and is certified afresh (the
    workspace certificate recomputed here agrees). Both cases occur, one per parameter set."""
    sc = standard(incline, standoff)
    base = avp.PlannerConfig()
    cfg = replace(base, workspace=replace(base.workspace, ground_z=ground_z))
    T = initial_durations(sc.state, sc.target, cfg)
    seed = solve_at(sc.state, sc.target, replace(cfg, fov=replace(cfg.fov, enabled=False)), T)
    assert seed.refined and seed.rounds >= 1 and seed.safe and seed.trajectory is not None
    assert any(b.name.startswith("workspace refinement") for b in seed.rows)
    attempt = solve_at(sc.state, sc.target, cfg, T, seed=seed)
    assert attempt.trajectory is not None and attempt.safe and attempt.rounds >= seed.rounds
    assert not any("before FoV) " in line for line in attempt.log)  # the search step's QP is not solved again
    fresh = certify_workspace(attempt.trajectory, sc.target, cfg.workspace)
    assert fresh.certified
    assert (attempt.trajectory is seed.trajectory) is returns_seed
    if returns_seed:
        assert attempt.safety is seed.safety and attempt.solve == 0.0
        assert attempt.linearisation is not None and attempt.linearisation.hold_at_linearisation
    else:
        assert attempt.solve > 0.0 and attempt.sqp_steps >= 1
        assert set(map(id, seed.rows)) <= set(map(id, attempt.rows))
        assert _rows_hold(seed.rows, attempt.outcome.c_hat, tol=1e-7)
