"""The onboard computer's time in the closed loop (``SimScenario.compute_slowdown``).

The steps' CPU time is replaced by a fake clock (``avp.sim.run._cpu_clock``), so every verdict
here is deterministic: a step costs exactly what the test says.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

import avp.sim.run as run
from avp.errors import ConfigError
from avp.replan import ReplanAction, ReplanConfig, Replanner
from avp.sim.evaluate import SimConfig
from avp.sim.run import Mode, SimScenario, simulate

WALL = SimScenario(distance=4.5)


class FakeCpu:
    """Each call returns the time, then advances it by ``per_call``: a step that reads the clock
    before and after costs ``per_call`` seconds."""

    def __init__(self, per_call: float) -> None:
        self.t, self.per_call = 0.0, per_call

    def __call__(self) -> float:
        t = self.t
        self.t += self.per_call
        return t


def test_a_step_slower_than_the_loop_period_skips_ticks_and_its_plan_arrives_late(monkeypatch):
    monkeypatch.setattr(run, "_cpu_clock", FakeCpu(2.0**-5))  # 31.25 ms, exact in binary
    r = simulate(dataclasses.replace(WALL, compute_slowdown=2.0), Mode.AVP, seed=0)
    executed = len(r.steps) - 1  # the first plan, at hover, is not timed
    assert executed > 10
    np.testing.assert_array_equal(r.step_delays, np.full(executed, 0.0625))
    # 62.5 ms per step against a 33.3 ms period: the tick after each step finds the computer busy
    assert abs(r.skipped_steps - executed) <= 1
    ticks = np.array([s.t for s in r.steps[1:]])
    assert np.all(np.diff(ticks) >= 0.0625 - 1e-9)
    # 62.5 ms is past every plan's switch time (20 ms of latency): each committed plan arrives late
    committed = sum(s.action in (ReplanAction.REPLANNED, ReplanAction.PARTIAL) for s in r.steps[1:])
    assert committed > 0 and r.late_commits == committed


def test_a_computer_too_slow_for_any_replan_flies_the_first_plan(monkeypatch):
    """Plans that arrive after the flight has ended are never flown: the vehicle tracks the first
    plan exactly as one-shot does (same seed, same noise streams), to the bit."""
    monkeypatch.setattr(run, "_cpu_clock", FakeCpu(100.0))
    sc = dataclasses.replace(WALL, replan_rate_hz=10.0)  # the first tick has a new detection
    avp_run = simulate(dataclasses.replace(sc, compute_slowdown=1.0), Mode.AVP, seed=3)
    one_shot = simulate(sc, Mode.ONE_SHOT, seed=3)
    assert [s.action for s in avp_run.steps] == [ReplanAction.INITIAL_PLAN, ReplanAction.REPLANNED]
    assert avp_run.late_commits == 1 and avp_run.skipped_steps > 10
    assert avp_run.final_plan is not avp_run.first_plan  # committed, never flown
    n = min(avp_run.path_p.shape[0], one_shot.path_p.shape[0])
    assert n > 1000
    np.testing.assert_array_equal(avp_run.path_p[:n], one_shot.path_p[:n])


def test_a_fast_computer_changes_nothing(monkeypatch):
    """A step that costs nothing: the same run as without the computer's time, bit for bit."""
    monkeypatch.setattr(run, "_cpu_clock", FakeCpu(0.0))
    timed = simulate(dataclasses.replace(WALL, compute_slowdown=4.0), Mode.AVP, seed=1)
    ideal = simulate(WALL, Mode.AVP, seed=1)
    np.testing.assert_array_equal(timed.path_p, ideal.path_p)
    assert timed.skipped_steps == timed.late_commits == 0 and timed.step_delays.size == len(timed.steps) - 1
    assert ideal.step_delays.size == 0


def test_the_deadline_and_the_adapted_latency_are_the_onboard_computers(monkeypatch):
    seen = []

    class Recording(Replanner):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            seen.append((self.replan.deadline, self.replan.latency_margin))

    monkeypatch.setattr(run, "Replanner", Recording)
    simulate(dataclasses.replace(WALL, compute_slowdown=4.0, distance=1.5), Mode.AVP, seed=0,
             replan=ReplanConfig(deadline=0.02))
    simulate(dataclasses.replace(WALL, distance=1.5), Mode.AVP, seed=0, replan=ReplanConfig(deadline=0.02))
    margin = ReplanConfig().latency_margin
    assert seen == [(pytest.approx(0.005), pytest.approx(4.0 * margin)), (0.02, margin)]


@pytest.mark.parametrize("bad", [-1.0, math.nan, math.inf])
def test_a_meaningless_slowdown_is_refused(bad):
    with pytest.raises(ConfigError, match="compute_slowdown"):
        SimScenario(compute_slowdown=bad)
    with pytest.raises(ConfigError, match="compute_slowdown"):
        SimConfig(compute_slowdown=bad)


def test_sim_config_hands_its_slowdown_to_the_scenario():
    assert SimConfig(compute_slowdown=3.0).scenario(90.0, 4.5).compute_slowdown == 3.0
    assert SimConfig().scenario(90.0, 4.5).compute_slowdown == 0.0
