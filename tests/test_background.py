"""Replanning in a worker process (avp.background): the worker's steps are the synchronous
replanner's on the same input, adopted one call later or by a poll between calls; the loop's
call never loses an estimate; bad input, a dead worker and an unpicklable replanner are clear
errors; the simulator's background mode flies the loop replanner's flight."""

from __future__ import annotations

import dataclasses
import math
import os
import signal
import subprocess
import sys
import time
import types
from pathlib import Path

import numpy as np
import pytest
from background_helpers import FailingReplanner, GatedReplanner

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

HELPERS = Path(__file__).resolve().parent  # tests/: background_helpers.py
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
        if a.result is not None and a.result.qp is not None:  # the back-end's record stays in the worker
            assert a.result.qp.solution is None and b.result.qp.solution is not None
            assert np.array_equal(a.result.qp.c_hat, b.result.qp.c_hat)
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


def test_busy_worker_keeps_the_estimate_for_the_next_request(worker, tmp_path):
    """Without ``wait``, a call while the worker plans sends nothing and does not wait; the
    estimate it brought goes with the next request, not lost."""
    gate = tmp_path / "go"
    bg = BackgroundReplanner(GatedReplanner(WALL, replan=RCFG, gate=str(gate)), worker=worker)
    first = bg.step(0.0, START, WALL)  # waited for (the first plan is not gated)
    assert first.adopted is not None and first.adopted.action is ReplanAction.INITIAL_PLAN
    moved = avp.PerchTarget(point=WALL.point + [0.0, 0.05, 0.0], R_WS=WALL.R_WS)
    out1 = bg.step(PERIOD, START, None)  # the worker starts, and waits at the gate
    assert out1.sent and out1.adopted is None and bg.pending
    out2 = bg.step(2 * PERIOD, START, moved)  # busy: nothing sent, the estimate kept
    assert not out2.sent and out2.adopted is None and out2.waited == 0.0
    assert bg.poll(2 * PERIOD) is None and bg.target is moved
    gate.touch()
    out3 = bg.step(3 * PERIOD, START, None, wait=True)  # adopts call 1's step, sends with the kept estimate
    assert out3.adopted is not None and out3.requested == PERIOD and out3.sent
    assert out3.adopted.reason.endswith("estimate y none")
    out4 = bg.step(4 * PERIOD, START, None, wait=True)
    assert out4.adopted is not None and out4.requested == 3 * PERIOD
    assert out4.adopted.reason.endswith("estimate y 0.050")
    bg.close()  # a worker passed in stays open
    assert worker.alive


@pytest.mark.parametrize("kind", ["config", "runtime", "unreadable", "unreadable_avp"])
def test_a_failing_replanner_step_is_raised_and_its_estimate_kept(kind):
    """What the hosted replanner raises comes back at the adopting call: an AvpError as it is,
    another exception (or one that does not unpickle here) as a WorkerError with its traceback;
    the worker is fine afterwards and the failed request's estimate goes with the next, unless
    it was refused (a ConfigError: the synchronous replanner would have kept its old target)."""
    with PlanningWorker() as w:
        bg = BackgroundReplanner(FailingReplanner(WALL, replan=RCFG, kind=kind), worker=w, wait=True)
        bg.step(0.0, START, WALL)
        moved = avp.PerchTarget(point=WALL.point + [0.0, 0.02, 0.0], R_WS=WALL.R_WS)
        bg.step(PERIOD, START, moved)  # sent; it fails in the worker
        expected = {"config": (ConfigError, "^replanner.kind: a planned failure"),
                    "runtime": (WorkerError, "RuntimeError: a planned failure(.|\n)*Traceback"),
                    "unreadable": (WorkerError, "Unreadable"),
                    "unreadable_avp": (WorkerError, "UnreadableAvpError(.|\n)*Traceback")}[kind]
        with pytest.raises(expected[0], match=expected[1]):
            bg.step(2 * PERIOD, START, None)  # adopts the failure; nothing sent
        assert w.alive and not bg.pending
        out = bg.step(3 * PERIOD, START, None)
        assert out.sent and bg.pending and out.adopted is None  # lock-step: adopted at the next call
        out = bg.step(4 * PERIOD, START, None)
        assert out.adopted is not None
        assert out.adopted.reason.endswith("seen [0.02, None]" if kind == "config" else "seen [0.02, 0.02]")


def test_an_answer_that_does_not_pickle_closes_the_worker():
    """A step that ran (its plan committed in the worker) but whose answer does not pickle
    leaves the worker's replanner ahead of this process: the worker is closed."""
    w = PlanningWorker()
    bg = BackgroundReplanner(FailingReplanner(WALL, replan=RCFG, kind="answer"), worker=w, wait=True)
    bg.step(0.0, START, WALL)
    bg.step(PERIOD, START, None)
    with pytest.raises(WorkerError, match="does not pickle(.|\n)*closed"):
        bg.step(2 * PERIOD, START, None)
    assert not w.alive


def test_a_worker_serves_one_replanner_at_a_time(worker):
    """Hosting a second replanner on a worker ends the first one's use of it: its next call is
    a WorkerError, not a step of the other replanner's."""
    other = avp.PerchTarget.from_incline([2.0, 1.0, 1.0], math.radians(90.0))
    first = BackgroundReplanner(Replanner(WALL, replan=RCFG), worker=worker)
    first.step(0.0, START, WALL)
    second = BackgroundReplanner(Replanner(other, replan=RCFG), worker=worker)
    with pytest.raises(WorkerError, match="hosts another replanner"):
        first.step(PERIOD, START, None)
    with pytest.raises(WorkerError, match="hosts another replanner"):
        first.poll(PERIOD)
    assert not first.pending
    out = second.step(0.0, START, other)
    assert np.allclose(second.trajectory(second.trajectory.tf), other.point, atol=1e-9)
    assert out.adopted.action is ReplanAction.INITIAL_PLAN


def test_a_hung_worker_times_out_and_is_closed(tmp_path):
    """A step in flight for longer than ``timeout`` closes the worker and raises, waiting or not
    (its late answer could no longer be matched to its request). The step's age is set back
    rather than waited for."""
    for wait in (True, False):
        w = PlanningWorker()
        bg = BackgroundReplanner(GatedReplanner(WALL, replan=RCFG, gate=str(tmp_path / "never")), worker=w)
        bg.step(0.0, START, WALL)
        bg.step(PERIOD, START, None)  # held at the gate for good
        assert bg.poll(PERIOD) is None  # not overdue
        w.timeout = 0.5
        w._sent_at -= 1.0
        with pytest.raises(WorkerError, match="timeout(.|\n)*closed"):
            if wait:
                bg.step(2 * PERIOD, START, None, wait=True)
            else:
                bg.poll(2 * PERIOD)
        assert not w.alive and w._process.exitcode is not None
        with pytest.raises(WorkerError, match="closed"):
            bg.step(3 * PERIOD, START, None)


def test_the_worker_ignores_ctrl_c(worker):
    """SIGINT (the terminal's Ctrl-C reaches the whole process group) does not end the worker."""
    if worker.start_method != "subprocess":
        pytest.skip("signals a subprocess worker")
    bg = BackgroundReplanner(Replanner(WALL, replan=RCFG), worker=worker, wait=True)
    bg.step(0.0, START, WALL)
    os.kill(worker._process.popen.pid, signal.SIGINT)
    time.sleep(0.2)
    assert worker.alive
    bg.step(PERIOD, START, None)
    assert bg.step(2 * PERIOD, START, None).adopted is not None


def test_the_worker_imports_the_callers_avp_and_modules(tmp_path):
    """The worker gets the caller's sys.path: a decoy ``avp`` or ``json`` in the working
    directory (which a plain ``python -c`` would put first) is not imported, and a replanner
    subclass in a module beside the caller's script is found."""
    cwd, scripts = tmp_path / "cwd", tmp_path / "scripts"
    (cwd / "avp").mkdir(parents=True)
    (cwd / "avp" / "__init__.py").write_text("raise ImportError('the decoy avp was imported')\n")
    (cwd / "json.py").write_text("raise ImportError('the decoy json was imported')\n")  # before sys.path is set
    scripts.mkdir()
    (scripts / "mine.py").write_text("import avp\n\nclass MyReplanner(avp.Replanner):\n    pass\n")
    (scripts / "run.py").write_text(
        "import math\nimport avp\nfrom mine import MyReplanner\n"
        "wall = avp.PerchTarget.from_incline([4.5, 0.0, 1.5], math.radians(90.0))\n"
        "with avp.BackgroundReplanner(MyReplanner(wall)) as bg:\n"
        "    print(bg.step(0.0, avp.State.hover([0.0, 0.0, 1.5]), wall).adopted.action.name)\n")
    proc = subprocess.run([sys.executable, str(scripts / "run.py")], capture_output=True, text=True, timeout=120,
                          cwd=cwd)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "INITIAL_PLAN"


def test_a_replanner_that_has_stepped_carries_on(worker):
    """A replanner wrapped after steps of its own keeps its time, plans and history: an earlier
    ``t`` is refused at the call, and the flown plan is its own."""
    sync = Replanner(WALL, replan=RCFG)
    calls = _inputs(4, 6)
    for t, odo, est in calls[:4]:
        sync.step(t, odo, est)
    bg = BackgroundReplanner(sync, worker=worker, wait=True)
    assert bg.history == sync.history and bg.trajectory is sync.trajectory
    for tt in (calls[3][0], sync.trajectory.t0 - 1e-3, sync.trajectory.t0 + 0.1):
        assert bg.plan_at(tt) is sync.plan_at(tt)
    with pytest.raises(ConfigError, match="^t: went back"):
        bg.step(calls[2][0], calls[2][1], None)
    assert not bg.pending


def test_a_subclass_checks_its_input_at_the_call(worker, monkeypatch):
    """A subclass's own input checks (a moving pad's estimate time; for a first plan, the
    constructor's estimate's) run at the call, before anything is sent to the worker."""
    from avp.moving import MovingConfig, MovingReplanner
    from avp.platform import MovingTarget

    sent = []
    real_submit = worker._submit
    monkeypatch.setattr(worker, "_submit", lambda *a: (sent.append(a), real_submit(*a))[1])
    start = avp.State(position=[-3.0, 0.0, 1.0], velocity=[2.0, 0.0, 0.0])
    stale = MovingTarget.on_platform([0.0, 0.0, 1.0], incline=0.5, speed=2.0, time=1.7e9)
    with pytest.raises(ConfigError) as exc:  # the first plan's estimate is the constructor's
        BackgroundReplanner(MovingReplanner(stale, moving=MovingConfig()), worker=worker).step(0.0, start, None)
    assert exc.value.field == "target.time" and not sent
    pad = MovingTarget.on_platform([0.0, 0.0, 1.0], incline=0.5, speed=2.0)
    bg = BackgroundReplanner(MovingReplanner(pad, moving=MovingConfig()), worker=worker)
    assert bg.step(0.0, start, pad).adopted.action is ReplanAction.INITIAL_PLAN and len(sent) == 1
    with pytest.raises(ConfigError) as exc:
        bg.step(PERIOD, start, stale)
    assert exc.value.field == "target_estimate.time" and len(sent) == 1 and not bg.pending


def test_the_worker_has_the_callers_interpreter_flags(tmp_path):
    """``python -O``'s flag reaches the worker (its asserts are off as the caller's are)."""
    script = tmp_path / "run.py"
    script.write_text(
        f"import math, sys\nsys.path.insert(0, {str(HELPERS)!r})\nimport avp\n"
        "from background_helpers import FlagsReplanner\n"
        "wall = avp.PerchTarget.from_incline([4.5, 0.0, 1.5], math.radians(90.0))\n"
        "with avp.BackgroundReplanner(FlagsReplanner(wall)) as bg:\n"
        "    print(bg.step(0.0, avp.State.hover([0.0, 0.0, 1.5]), wall).adopted.reason)\n")
    proc = subprocess.run([sys.executable, "-O", str(script)], capture_output=True, text=True, timeout=120,
                          cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "optimize=1"


@pytest.mark.skipif("fork" not in start_methods(), reason="a fork worker")
def test_a_fork_worker_ends_with_the_parents_end_of_the_pipe():
    """A forked worker closes its copy of the parent's end: when the parent's end closes (the
    parent died), the worker sees the end of the pipe and exits."""
    w = PlanningWorker(start_method="fork")
    BackgroundReplanner(Replanner(WALL), worker=w)  # started and serving
    w._process.conn.close()
    w._process.join(10.0)
    assert w._process.exitcode == 0
    w.close()


def test_a_worker_that_cannot_start_is_a_worker_error(monkeypatch):
    monkeypatch.setattr(sys, "executable", str(Path("/nonexistent/python")))
    with pytest.raises(WorkerError, match="could not start a worker interpreter"):
        PlanningWorker(start_method="subprocess")
    with pytest.raises(ConfigError, match="^timeout: must be at most"):
        PlanningWorker(timeout=1e10)


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
    w._process.join(5.0)
    assert not w.alive  # seen dead before anything is sent
    with pytest.raises(WorkerError, match="exited|gone"):
        bg.step(PERIOD, START, None, wait=True)
        bg.step(2 * PERIOD, START, None, wait=True)
    with pytest.raises(WorkerError, match="closed"):
        bg.step(3 * PERIOD, START, None)
    w.close()
    with pytest.raises(WorkerError, match="closed"):
        BackgroundReplanner(Replanner(WALL), worker=w)


def test_first_plan_failure_keeps_waiting_for_a_plan(worker):
    """A first plan that fails (NO_PLAN) leaves nothing to fly: the next call waits again."""
    near = avp.PerchTarget.from_incline([0.05, 0.0, 1.5], math.radians(90.0))  # too close to plan a perch to
    bg = BackgroundReplanner(Replanner(near), worker=worker)
    out = bg.step(0.0, START, near)
    assert out.adopted is not None and out.adopted.action is ReplanAction.NO_PLAN and bg.trajectory is None
    out = bg.step(PERIOD, START, WALL)
    assert out.adopted is not None and out.adopted.action is ReplanAction.INITIAL_PLAN
    assert bg.trajectory is not None and bg.plan_at(PERIOD) is bg.trajectory


def test_poll_adopts_between_steps(worker):
    """``poll`` adopts the finished step without sending: polled right after each call (as a
    controller would at its next step), the background replanner flies what the synchronous
    one flies at every call, with the default latency, and nothing is adopted late."""
    calls = _inputs(2, 30)
    sync = Replanner(WALL)
    bg = BackgroundReplanner(Replanner(WALL), worker=worker)
    assert bg.poll(0.0) is None  # nothing in flight
    for t, odo, est in calls:
        out = bg.step(t, odo, est)
        sync.step(t, odo, est)
        assert out.sent
        got = bg.poll(t + 0.002, wait=True) if out.adopted is None else out
        assert got is not None and got.adopted is not None and got.requested == t
        assert got.late == 0.0 and not bg.pending
        _same_step(got.adopted, sync.history[-1])
        assert np.array_equal(bg.plan_at(t + 0.005).coefficients, sync.plan_at(t + 0.005).coefficients)
    assert bg.poll(calls[-1][0] + 0.01, wait=True) is None
    with pytest.raises(ConfigError, match="^t: went back"):
        bg.poll(calls[-1][0] - 0.01)


def test_simulate_in_the_background_flies_the_loop_replanners_flight(worker):
    """The simulator's background mode adopts each request at its own time, so the flight is
    the loop replanner's: the same steps, plans bit for bit, the same contact."""
    sc = SimScenario(distance=4.5)
    loop = simulate(sc, Mode.AVP, seed=1)
    bg = simulate(sc, Mode.AVP, seed=1, background=worker)
    assert len(bg.steps) == len(loop.steps) and sum(s.action is ReplanAction.REPLANNED for s in bg.steps) >= 3
    for a, b in zip(loop.steps, bg.steps, strict=True):
        _same_step(a, b)
    assert (bg.outcome, bg.late_commits) == (loop.outcome, 0)
    assert np.array_equal(bg.path_p, loop.path_p)
    with pytest.raises(ConfigError, match="^background:"):
        simulate(sc, Mode.ONE_SHOT, background=worker)
    with pytest.raises(ConfigError, match="^background:"):
        simulate(dataclasses.replace(sc, compute_slowdown=2.0), Mode.AVP, background=worker)
    with pytest.raises(ConfigError, match="^background:"):
        simulate(sc, Mode.AVP, background="yes")
