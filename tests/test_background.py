"""Replanning in a worker process (avp.background): the worker's steps are the synchronous
replanner's on the same input, adopted one call later; the loop's call never loses an estimate;
bad input, a dead worker and an unpicklable replanner are clear errors; the simulator's
background mode flies, and counts the plans adopted after their switch time."""

from __future__ import annotations

import dataclasses
import math
import os
import signal
import sys
import time
import types

import numpy as np
import pytest

import avp
from avp.background import (
    BackgroundReplanner,
    BackgroundStep,
    PlanningWorker,
    _portable,
    start_methods,
)
from avp.errors import ConfigError, WorkerError
from avp.replan import ReplanAction, ReplanConfig, Replanner, ReplanStep
from avp.sim.run import Mode, SimScenario, simulate

WALL = avp.PerchTarget.from_incline([4.5, 0.0, 1.5], math.radians(90.0))
START = avp.State.hover([0.0, 0.0, 1.5])
PERIOD = 1.0 / 30.0
RCFG = ReplanConfig(latency=0.04)  # above the period: a plan adopted at the next call is in time


@pytest.fixture(scope="module")
def worker():
    with PlanningWorker() as w:
        yield w


def _inputs(seed: int, n: int) -> list[tuple[float, avp.State, avp.PerchTarget | None]]:
    """A loop's calls: the first plan's reference with millimetres of odometry noise, and a pad
    estimate that drifts by centimetres (replans, holds and partial corrections), not at every
    call (``None``: no new detection)."""
    rng = np.random.default_rng(seed)
    first = avp.plan_detailed(START, WALL).trajectory
    assert first is not None
    calls: list[tuple[float, avp.State, avp.PerchTarget | None]] = [(0.0, START, WALL)]
    point = WALL.point.copy()
    for k in range(1, n):
        t = k * PERIOD
        d = first.derivatives(min(t, first.tf))
        odo = avp.State(position=d[0, :3] + rng.normal(0.0, 0.003, 3), velocity=d[1, :3] + rng.normal(0.0, 0.01, 3),
                        acceleration=d[2, :3], yaw=float(d[0, 3]), time=t)
        est = None
        if rng.random() < 0.6:
            point = point + rng.normal(0.0, 0.02, 3)
            est = avp.PerchTarget(point=point.copy(), R_WS=WALL.R_WS)
        calls.append((t, odo, est))
    return calls


def _same_step(a: ReplanStep, b: ReplanStep) -> None:
    assert (a.action, a.fraction, a.n_solves, a.t_ex, a.reason) == (b.action, b.fraction, b.n_solves, b.t_ex, b.reason)
    if a.trajectory is None or b.trajectory is None:
        assert a.trajectory is b.trajectory is None
    else:
        assert np.array_equal(a.trajectory.coefficients, b.trajectory.coefficients)
        assert np.array_equal(a.trajectory.knots, b.trajectory.knots)


@pytest.mark.parametrize("seed", [0, 1])
def test_lock_step_adopts_the_synchronous_steps_one_call_later(worker, seed):
    """With ``wait``, call k adopts the answer to call k-1's request (from the second call on:
    the first plan is waited for in the first): the worker's steps, its plans bit for bit, are
    those of a synchronous replanner given the same calls, and the plan flown at every time is
    the synchronous replanner's one call earlier."""
    calls = _inputs(seed, 40)
    sync = Replanner(WALL, replan=RCFG)
    bg = BackgroundReplanner(Replanner(WALL, replan=RCFG), worker=worker, wait=True)
    sync_plans = []
    for k, (t, odo, est) in enumerate(calls):
        out = bg.step(t, odo, est)
        assert isinstance(out, BackgroundStep) and out.sent
        if k == 0:  # the first plan is waited for: nothing in flight after it
            assert out.adopted is not None and out.adopted.action is ReplanAction.INITIAL_PLAN
        elif k == 1:
            assert out.adopted is None
        else:
            assert out.adopted is not None and out.requested == calls[k - 1][0]
        if k > 0:
            assert np.array_equal(bg.trajectory.coefficients, sync_plans[-1].coefficients)
            for tt in (t, t + 0.05, bg.trajectory.t0 - 1e-3):
                assert np.array_equal(bg.plan_at(tt).coefficients, sync.plan_at(tt).coefficients)
        sync.step(t, odo, est)
        sync_plans.append(sync.trajectory)
    assert len(bg.history) == len(sync.history) - 1  # the last request is still in flight
    for a, b in zip(bg.history, sync.history, strict=False):
        _same_step(a, b)
    actions = {s.action for s in sync.history}
    assert ReplanAction.REPLANNED in actions and len(actions) >= 3, actions  # the calls exercise the policy


def test_late_is_the_time_past_the_switch(worker):
    """A plan adopted after its ``t_ex`` (latency below the period) says by how much."""
    rcfg = ReplanConfig(latency=0.01)
    bg = BackgroundReplanner(Replanner(WALL, replan=rcfg), worker=worker, wait=True)
    calls = _inputs(3, 12)
    lates = []
    for t, odo, est in calls:
        out = bg.step(t, odo, est)
        if out.adopted is not None and out.adopted.committed and out.adopted.action is not ReplanAction.INITIAL_PLAN:
            assert out.late == pytest.approx(t - out.adopted.t_ex, abs=1e-12)
            assert out.late > 0.0
            lates.append(out.late)
    assert lates, "no replan committed"


def test_portable_step_drops_only_the_back_end_record():
    sync = Replanner(WALL)
    sync.step(0.0, START, WALL)
    step = sync.history[-1]
    assert step.result is not None and step.result.qp is not None and step.result.qp.solution is not None
    light = _portable(step)
    assert light.result.qp.solution is None
    assert light.result.qp.c_hat is step.result.qp.c_hat and light.trajectory is step.trajectory
    assert dataclasses.replace(light.result.qp, solution=step.result.qp.solution) == step.result.qp


# -- a slow replanner, to see the loop's call while the worker is busy ---------------------------------------
class SlowReplanner(Replanner):
    """Sleeps before each step, and says in the reason which estimate it was given."""

    delay = 0.3

    def step(self, t, odometry, target_estimate=None):
        time.sleep(self.delay)
        out = super().step(t, odometry, target_estimate)
        got = "none" if target_estimate is None else f"{target_estimate.point[1]:.3f}"
        return dataclasses.replace(out, reason=f"{out.reason} | estimate y {got}")


@pytest.mark.skipif("fork" not in start_methods(), reason="the test's replanner class reaches the worker by fork")
def test_busy_worker_keeps_the_estimate_for_the_next_request():
    """Without ``wait``, a call while the worker plans sends nothing and does not wait; the
    estimate it brought goes with the next request, not lost."""
    with PlanningWorker(start_method="fork") as w:
        bg = BackgroundReplanner(SlowReplanner(WALL, replan=RCFG), worker=w)
        first = bg.step(0.0, START, WALL)  # waited for
        assert first.adopted is not None and first.adopted.action is ReplanAction.INITIAL_PLAN
        traj = bg.trajectory
        assert traj is not None
        odo = START
        moved = avp.PerchTarget(point=WALL.point + [0.0, 0.05, 0.0], R_WS=WALL.R_WS)
        out1 = bg.step(PERIOD, odo, None)  # the worker starts (slowly)
        assert out1.sent and out1.adopted is None and bg.pending
        w0 = time.perf_counter()
        out2 = bg.step(2 * PERIOD, odo, moved)  # busy: nothing sent, the estimate kept
        assert time.perf_counter() - w0 < 0.5 * SlowReplanner.delay  # did not wait
        assert not out2.sent and out2.adopted is None
        assert bg.target is moved
        time.sleep(1.5 * SlowReplanner.delay)
        out3 = bg.step(3 * PERIOD, odo, None)  # adopts call 1's step, sends with the kept estimate
        assert out3.adopted is not None and out3.requested == PERIOD and out3.sent
        assert out3.adopted.reason.endswith("estimate y none")
        out4 = bg.step(4 * PERIOD, odo, None, wait=True)
        assert out4.adopted is not None and out4.requested == 3 * PERIOD
        assert out4.adopted.reason.endswith("estimate y 0.050")
        bg.close()  # a worker passed in stays open
        assert w.alive


def test_bad_input_is_refused_before_anything_is_sent(worker):
    bg = BackgroundReplanner(Replanner(WALL, replan=RCFG), worker=worker, wait=True)
    bg.step(0.0, START, WALL)
    with pytest.raises(ConfigError, match="^odometry:"):
        bg.step(0.1, "odometry", None)
    with pytest.raises(ConfigError, match="^target_estimate:"):
        bg.step(0.1, START, avp.State.hover([0.0, 0.0, 1.0]))
    with pytest.raises(ConfigError, match="^t:"):
        bg.step(math.nan, START, None)
    assert not bg.pending  # nothing went to the worker
    bg.step(0.1, START, None)
    with pytest.raises(ConfigError, match="^t: went back"):
        bg.step(0.05, START, None)
    with pytest.raises(ConfigError, match="^wait:"):
        bg.step(0.2, START, None, wait="yes")
    with pytest.raises(ConfigError, match="^t: no plan committed yet"):
        BackgroundReplanner(Replanner(WALL), worker=worker).reference(0.0)


def test_constructor_refusals(worker):
    with pytest.raises(ConfigError, match="^replanner:"):
        BackgroundReplanner(WALL, worker=worker)
    with pytest.raises(ConfigError, match="^worker:"):
        BackgroundReplanner(Replanner(WALL), worker="worker")
    with pytest.raises(ConfigError, match="^wait:"):
        BackgroundReplanner(Replanner(WALL), worker=worker, wait=1)

    class Local(Replanner):  # defined in a function: no worker can import it
        pass

    with pytest.raises(ConfigError, match="^replanner: cannot be sent"):
        BackgroundReplanner(Local(WALL), worker=worker)
    with pytest.raises(ConfigError, match="^start_method:"):
        PlanningWorker(start_method="teleport")
    with pytest.raises(ConfigError, match="^timeout:"):
        PlanningWorker(timeout=0.0)


def test_unimportable_replanner_class_is_a_config_error(worker, monkeypatch):
    """A class the worker cannot import (its module exists in this process only) is refused
    when hosted, with the reason, and the worker serves the next replanner."""
    ghost_module = types.ModuleType("avp_test_ghost_module")
    ghost = type("Ghost", (Replanner,), {"__module__": ghost_module.__name__})
    ghost_module.Ghost = ghost
    monkeypatch.setitem(sys.modules, ghost_module.__name__, ghost_module)
    with pytest.raises(ConfigError, match="^replanner: .*importable in the worker"):
        BackgroundReplanner(ghost(WALL), worker=worker)
    bg = BackgroundReplanner(Replanner(WALL), worker=worker)
    assert bg.step(0.0, START, WALL).adopted.action is ReplanAction.INITIAL_PLAN


@pytest.mark.skipif(os.name != "posix", reason="kills the worker with SIGKILL")
def test_a_dead_worker_is_a_worker_error():
    w = PlanningWorker()
    bg = BackgroundReplanner(Replanner(WALL, replan=RCFG), worker=w)
    bg.step(0.0, START, WALL)
    pid = w._process.popen.pid if w.start_method == "subprocess" else w._process.process.pid
    os.kill(pid, signal.SIGKILL)
    with pytest.raises(WorkerError, match="exited|gone"):
        bg.step(PERIOD, START, None, wait=True)
        bg.step(2 * PERIOD, START, None, wait=True)
    w.close()
    assert not w.alive
    with pytest.raises(WorkerError, match="closed"):
        w.host(Replanner(WALL))


def test_first_plan_failure_keeps_waiting_for_a_plan(worker):
    """A first plan that fails (NO_PLAN) leaves nothing to fly: the next call waits again."""
    near = avp.PerchTarget.from_incline([0.05, 0.0, 1.5], math.radians(90.0))  # too close to plan a perch to
    bg = BackgroundReplanner(Replanner(near), worker=worker)
    out = bg.step(0.0, START, near)
    assert out.adopted is not None and out.adopted.action is ReplanAction.NO_PLAN and bg.trajectory is None
    out = bg.step(PERIOD, START, WALL)
    assert out.adopted is not None and out.adopted.action is ReplanAction.INITIAL_PLAN
    assert bg.trajectory is not None and bg.plan_at(PERIOD) is bg.trajectory


def test_simulate_in_the_background(worker):
    """The simulator's background mode perches as the loop's replanner does; with a latency
    below the step period every adopted replan comes after its switch time, above it none."""
    sc = SimScenario(distance=4.5)
    in_time = simulate(sc, Mode.AVP, seed=0, replan=RCFG, background=worker)
    assert in_time.outcome == "success" and in_time.late_commits == 0
    assert sum(s.action is ReplanAction.REPLANNED for s in in_time.steps) >= 3
    late = simulate(sc, Mode.AVP, seed=0, replan=ReplanConfig(latency=0.02), background=worker)
    committed = sum(s.committed for s in late.steps[1:])
    assert committed >= 3 and late.late_commits == committed
    with pytest.raises(ConfigError, match="^background:"):
        simulate(sc, Mode.ONE_SHOT, background=worker)
    with pytest.raises(ConfigError, match="^background:"):
        simulate(dataclasses.replace(sc, compute_slowdown=2.0), Mode.AVP, background=worker)
    with pytest.raises(ConfigError, match="^background:"):
        simulate(sc, Mode.AVP, background="yes")
