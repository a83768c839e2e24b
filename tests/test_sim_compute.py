"""The onboard computer's time in the closed loop (``SimScenario.compute_slowdown``).

The steps' clock is replaced by a fake one (``avp.sim.run._step_clock``), so every verdict here
is deterministic: a step costs exactly what the test says.
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


@pytest.mark.parametrize(("per_call", "slowdown"), [(2.0**-5, 2.0), (2.0**-6, 3.0)])
def test_a_step_slower_than_the_loop_period_skips_ticks_and_its_plan_arrives_late(monkeypatch, per_call, slowdown):
    monkeypatch.setattr(run, "_step_clock", FakeCpu(per_call))  # exact in binary
    delay = per_call * slowdown  # 62.5 and 46.9 ms
    r = simulate(dataclasses.replace(WALL, compute_slowdown=slowdown), Mode.AVP, seed=0)
    executed = len(r.steps) - 1  # the first plan, at hover, is not timed
    assert executed > 10
    np.testing.assert_array_equal(r.step_delays, np.full(executed, delay))
    # against a 33.3 ms period: the tick after each step finds the computer busy
    assert abs(r.skipped_ticks - executed) <= 1
    ticks = np.array([s.t for s in r.steps[1:]])
    assert np.all(np.diff(ticks) >= delay - 1e-9)
    # past every plan's switch time (20 ms of latency): each committed plan arrives late
    committed = sum(s.action in (ReplanAction.REPLANNED, ReplanAction.PARTIAL) for s in r.steps[1:])
    assert committed > 0 and r.late_commits == committed


def test_a_computer_too_slow_for_any_replan_flies_the_first_plan(monkeypatch):
    """Plans that arrive after the flight has ended are never flown: the vehicle tracks the first
    plan exactly as one-shot does (same seed, same noise streams), to the bit."""
    monkeypatch.setattr(run, "_step_clock", FakeCpu(100.0))
    sc = dataclasses.replace(WALL, replan_rate_hz=10.0)  # the first tick has a new detection
    avp_run = simulate(dataclasses.replace(sc, compute_slowdown=1.0), Mode.AVP, seed=3)
    one_shot = simulate(sc, Mode.ONE_SHOT, seed=3)
    assert [s.action for s in avp_run.steps] == [ReplanAction.INITIAL_PLAN, ReplanAction.REPLANNED]
    assert avp_run.late_commits == 1 and avp_run.skipped_ticks > 10
    assert avp_run.final_plan is avp_run.first_plan  # the plan committed late never arrived: not judged
    n = min(avp_run.path_p.shape[0], one_shot.path_p.shape[0])
    assert n > 1000
    np.testing.assert_array_equal(avp_run.path_p[:n], one_shot.path_p[:n])


@pytest.mark.parametrize("per_call", [2.0**-5, 2.0**-6])  # 62.5 and 31.25 ms per step
def test_the_vehicle_flies_the_previous_plan_until_a_late_plan_arrives(monkeypatch, per_call):
    """Every reference the controller gets: before a late plan's arrival (``t + delay``) the
    plan committed before its step, from the arrival on the new plan, on a static pad and on a
    moving platform (``MovingReplanner``)."""
    refs: list[tuple[float, object]] = []
    real = run.closed_loop

    def logging_loop(state, reference, *args, **kwargs):
        def logged(tt):
            out = reference(tt)
            refs.append((tt, out))
            return out
        return real(state, logged, *args, **kwargs)

    monkeypatch.setattr(run, "closed_loop", logging_loop)
    monkeypatch.setattr(run, "_step_clock", FakeCpu(per_call))
    for sc in (WALL, dataclasses.replace(WALL, platform=run.PlatformMotion(speed=0.5))):
        refs.clear()
        r = simulate(dataclasses.replace(sc, compute_slowdown=2.0), Mode.AVP, seed=0)
        times = np.array([tt for tt, _ in refs])
        checked = 0
        for before, step in zip(r.steps[:-1], r.steps[1:], strict=True):
            if step.action not in (ReplanAction.REPLANNED, ReplanAction.PARTIAL):
                continue
            arrival = step.t + 2.0 * per_call
            old, new = before.trajectory, step.trajectory
            for k in np.flatnonzero((times >= step.t) & (times < arrival + 0.01)):
                tt, out = refs[k]
                want = (old if tt < arrival else new).flat_output(tt)
                np.testing.assert_array_equal(out.position, want.position)
                checked += 1
        assert checked > 100 and r.late_commits > 0


def test_a_plan_that_arrives_before_its_switch_time_changes_nothing(monkeypatch):
    """10 ms per step, under the 20 ms latency: each plan is there before it takes over, and
    no tick finds the computer busy, so the run is the ideal one, bit for bit."""
    monkeypatch.setattr(run, "_step_clock", FakeCpu(2.0**-8))
    timed = simulate(dataclasses.replace(WALL, compute_slowdown=2.0), Mode.AVP, seed=1)
    ideal = simulate(WALL, Mode.AVP, seed=1)
    np.testing.assert_array_equal(timed.path_p, ideal.path_p)
    assert timed.late_commits == timed.skipped_ticks == 0 and np.all(timed.step_delays == 2.0**-7)


def test_a_fast_computer_changes_nothing(monkeypatch):
    """A step that costs nothing: the same run as without the computer's time, bit for bit."""
    monkeypatch.setattr(run, "_step_clock", FakeCpu(0.0))
    timed = simulate(dataclasses.replace(WALL, compute_slowdown=4.0), Mode.AVP, seed=1)
    ideal = simulate(WALL, Mode.AVP, seed=1)
    np.testing.assert_array_equal(timed.path_p, ideal.path_p)
    assert timed.skipped_ticks == timed.late_commits == 0 and timed.step_delays.size == len(timed.steps) - 1
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
