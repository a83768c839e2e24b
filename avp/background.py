"""Replanning beside the control loop: a :class:`~avp.replan.Replanner` in a worker process.

In the paper's loop (Sec. IV) the planner runs beside the controller: a plan is computed from the
odometry of ``t_rp`` while the vehicle flies the committed plan, and it takes over at
``t_ex = t_rp + latency``, where the anticipation (6) puts its start. :class:`BackgroundReplanner`
runs that way: the :class:`~avp.replan.Replanner` (or a subclass: a moving pad's, a line's) lives
in a :class:`PlanningWorker` process, on another core, and the loop's own call,
:meth:`BackgroundReplanner.step`, never plans. At each call it

1. adopts the worker's finished step, if there is one (a step that committed a plan makes that
   plan the one to fly from its ``t0 = t_ex``), and
2. sends this call's time, odometry and estimate to the worker when the worker is idle (while it
   is busy, the call sends nothing; an estimate it brought is kept and goes with the next request,
   so that an estimate given once is not lost).

Its cost in the loop is two messages and their pickles (``docs/performance.md``); the plans,
their certificates and the policy are the wrapped replanner's, unchanged. An adopted step's
``result.qp.solution`` (the back-end's own record, with the QP's matrices) is ``None``: it stays in
the worker.

A request and its plan's adoption are at least one call apart. So that the plan still starts in
the future when it is adopted, set ``ReplanConfig.latency`` to at least the loop's period (with a
margin for the worker's planning time): a plan adopted after its ``t_ex`` is flown from its
adoption on, and :attr:`BackgroundStep.late` says by how much its start had passed (the plan
starts from the anticipated state at ``t_ex``, not from where the vehicle is at adoption).

Waiting: the first plan (nothing to fly yet) is waited for. ``wait=True`` (a constructor default,
or per call) waits for the step in flight before sending the next: each request is adopted at
the next call whatever the worker's speed, as in real time when a plan takes less than a period;
the simulator runs this way (reproducible). Without it a call never waits once a plan is
committed.

The wrapped replanner is sent to the worker (pickled): the object passed in is not updated. The
worker is a fresh interpreter on POSIX (:class:`PlanningWorker`); start one and pass it to several
replanners in turn to pay its start (about a second) once. A worker that dies raises
:class:`~avp.errors.WorkerError` at the next call.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import multiprocessing
import os
import pickle
import socket
import subprocess
import sys
import time
import weakref
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

from . import _validate as v
from ._blas import warm as _warm_blas
from .errors import AvpError, ConfigError, WorkerError
from .replan import ReplanAction, Replanner, ReplanStep, check_step_input, flown_plan
from .trajectory import FlatOutput, Trajectory
from .types import PerchTarget, State

__all__ = ["BackgroundReplanner", "BackgroundStep", "PlanningWorker"]

_STOP, _HOST, _STEP, _READY, _DONE, _FAILED = "stop", "host", "step", "ready", "done", "failed"
"""The messages between a :class:`PlanningWorker` and its process."""


def _serve(conn: Connection) -> None:
    """The worker process: host a replanner (``_HOST``), run its steps (``_STEP``) until
    ``_STOP`` or the pipe closes. A step's exception goes back as ``_FAILED`` (the replanner
    raises only for bad input, which :meth:`BackgroundReplanner.step` checks before sending)."""
    replanner: Replanner | None = None
    _warm_blas()
    while True:
        try:
            data = conn.recv_bytes()
        except (EOFError, OSError):
            return
        try:
            msg = pickle.loads(data)
        except Exception as exc:
            conn.send((_FAILED, WorkerError(f"the worker could not read a message: {type(exc).__name__}: {exc}")))
            continue
        kind = msg[0]
        if kind == _STOP:
            return
        if kind == _HOST:
            replanner = msg[1]
            conn.send((_READY,))
            continue
        c0, w0 = time.thread_time(), time.perf_counter()
        try:
            if replanner is None:  # pragma: no cover - PlanningWorker hosts before it submits
                raise WorkerError("no replanner hosted")
            step = replanner.step(*msg[1:])
        except Exception as exc:
            try:
                conn.send((_FAILED, exc))
            except Exception:
                conn.send((_FAILED, WorkerError(f"{type(exc).__name__}: {exc}")))
            continue
        conn.send((_DONE, _portable(step), time.thread_time() - c0, time.perf_counter() - w0))


def _portable(step: ReplanStep) -> ReplanStep:
    """``step`` without its QP's back-end record (``result.qp.solution``, with the QP's matrices:
    about 90 % of a solving step's pickle), which stays in the worker."""
    result = step.result
    qp = getattr(result, "qp", None)
    if result is None or qp is None or getattr(qp, "solution", None) is None:
        return step
    return dataclasses.replace(step, result=dataclasses.replace(result, qp=dataclasses.replace(qp, solution=None)))


def _serve_fd(fd: int) -> None:
    """The worker's entry point in a fresh interpreter (``start_method="subprocess"``): serve on
    the inherited socket ``fd``."""
    _serve(Connection(fd))


class _Subprocess:
    """A worker in a fresh interpreter (``subprocess``), with the calls :func:`_shutdown` makes."""

    def __init__(self) -> None:
        parent, child = socket.socketpair()
        package_root = str(Path(__file__).resolve().parent.parent)  # this avp, not another on the path
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(p for p in (package_root, env.get("PYTHONPATH", "")) if p)
        self.popen = subprocess.Popen(
            [sys.executable, "-c", f"from avp.background import _serve_fd; _serve_fd({child.fileno()})"],
            pass_fds=(child.fileno(),), stdin=subprocess.DEVNULL, env=env, close_fds=True)
        child.close()
        self.conn = Connection(parent.detach())

    def is_alive(self) -> bool:
        return self.popen.poll() is None

    def join(self, timeout: float) -> None:
        with contextlib.suppress(subprocess.TimeoutExpired):
            self.popen.wait(timeout)

    def terminate(self) -> None:
        self.popen.terminate()

    @property
    def exitcode(self) -> int | None:
        return self.popen.poll()


class _Multiprocess:
    """A worker started by ``multiprocessing`` (``spawn``, ``forkserver``, ``fork``)."""

    def __init__(self, method: str) -> None:
        ctx: Any = multiprocessing.get_context(method)
        parent, child = ctx.Pipe()
        self.process = ctx.Process(target=_serve, args=(child,), daemon=True, name="avp-planning-worker")
        self.process.start()
        child.close()
        self.conn = parent

    def is_alive(self) -> bool:
        return self.process.is_alive()

    def join(self, timeout: float) -> None:
        self.process.join(timeout)

    def terminate(self) -> None:
        self.process.terminate()

    @property
    def exitcode(self) -> int | None:
        return self.process.exitcode


def _shutdown(process: _Subprocess | _Multiprocess) -> None:
    """Stop a worker process: ask, then wait a little, then terminate."""
    with contextlib.suppress(OSError, ValueError):
        process.conn.send((_STOP,))
    process.join(2.0)
    if process.is_alive():
        process.terminate()
        process.join(2.0)
    process.conn.close()


def start_methods() -> tuple[str, ...]:
    """The :class:`PlanningWorker` start methods of this platform: ``subprocess`` (POSIX: a fresh
    interpreter, the default) and ``multiprocessing``'s."""
    own = ("subprocess",) if os.name == "posix" else ()
    return own + tuple(multiprocessing.get_all_start_methods())


class PlanningWorker:
    """A process that runs one :class:`~avp.replan.Replanner` at a time for
    :class:`BackgroundReplanner` (module docstring).

    Parameters
    ----------
    start_method:
        ``"subprocess"`` (the default on POSIX): a fresh interpreter that imports this ``avp``
        (about a second); it never runs the caller's main module, so a script needs no
        ``if __name__ == "__main__":`` guard. Or one of ``multiprocessing``'s methods (the default
        elsewhere: ``spawn``, which runs the main module again and needs that guard; ``fork``
        copies the caller's threads' state, BLAS pools included: not advised).
    timeout:
        Seconds a call waits for the worker before raising :class:`~avp.errors.WorkerError`
        (its start, the first plan, a step in flight with ``wait``; a plan takes milliseconds).
    """

    def __init__(self, start_method: str | None = None, timeout: float = 60.0) -> None:
        methods = start_methods()
        method = methods[0] if start_method is None else start_method
        if method not in methods:
            raise ConfigError("start_method", f"{method!r} is not one of this platform's start methods {methods}")
        self.timeout = v.positive_float("timeout", timeout)
        self.start_method = method
        self._process = _Subprocess() if method == "subprocess" else _Multiprocess(method)
        self._conn = self._process.conn
        self._busy = False
        self._finalizer = weakref.finalize(self, _shutdown, self._process)

    @property
    def alive(self) -> bool:
        """The worker process is running."""
        return self._finalizer.alive and self._process.is_alive()

    def close(self) -> None:
        """Stop the worker process (idempotent; also at garbage collection and exit)."""
        self._finalizer()

    def __enter__(self) -> PlanningWorker:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _send(self, msg: tuple[Any, ...]) -> None:
        if not self._finalizer.alive:
            raise WorkerError("the planning worker is closed: start a new PlanningWorker")
        try:
            self._conn.send(msg)
        except (OSError, ValueError) as exc:
            raise WorkerError(f"the planning worker is gone ({type(exc).__name__}: {exc}); start a new one") from exc

    def _receive(self) -> tuple[Any, ...]:
        if not self._finalizer.alive:
            raise WorkerError("the planning worker is closed: start a new PlanningWorker")
        if not self._conn.poll(self.timeout):
            raise WorkerError(f"the planning worker did not answer within {self.timeout:g} s (timeout)")
        try:
            return self._conn.recv()  # type: ignore[no-any-return]
        except (EOFError, OSError) as exc:
            self._busy = False
            self._process.join(1.0)
            raise WorkerError(f"the planning worker exited (exit code {self._process.exitcode}); start a new "
                              "PlanningWorker") from exc

    def host(self, replanner: Replanner) -> None:
        """Send ``replanner`` to the worker (it replaces the one hosted before); waits until
        it is there. A step still in flight is received and dropped first."""
        if self._busy:
            self._busy = False
            self._receive()
        self._send((_HOST, replanner))
        reply = self._receive()
        if reply[0] == _FAILED:
            raise ConfigError("replanner", f"{reply[1]} (a subclass must be importable in the worker: defined in "
                              "a module, not in the main script or a function)")
        if reply[0] != _READY:  # pragma: no cover - the protocol's own check
            raise WorkerError(f"unexpected reply {reply[0]!r} to hosting a replanner")

    def submit(self, t: float, odometry: State, target_estimate: PerchTarget | None) -> None:
        """Start the hosted replanner's step (the worker must be idle)."""
        if self._busy:  # pragma: no cover - BackgroundReplanner sends only when idle
            raise WorkerError("the planning worker is busy: receive its step first")
        self._send((_STEP, t, odometry, target_estimate))
        self._busy = True

    @property
    def busy(self) -> bool:
        """A step is in flight."""
        return self._busy

    def finished(self) -> bool:
        """The step in flight has finished (its answer, or the worker's end, is waiting)."""
        return self._busy and self._conn.poll()

    def receive(self) -> tuple[ReplanStep, float, float]:
        """The step in flight (waits for it, up to ``timeout``): the step, and the worker's CPU and
        wall seconds on it. Re-raises what the step raised."""
        if not self._busy:  # pragma: no cover - BackgroundReplanner receives only when busy
            raise WorkerError("no step in flight")
        reply = self._receive()
        self._busy = False
        if reply[0] == _FAILED:
            exc = reply[1]
            raise exc if isinstance(exc, AvpError) else WorkerError(f"{type(exc).__name__}: {exc}")
        return reply[1], reply[2], reply[3]


@dataclasses.dataclass(frozen=True, kw_only=True)
class BackgroundStep:
    """What one :meth:`BackgroundReplanner.step` call did.

    ``adopted``: the worker's step that finished since the previous call and is now in force (its
    plan committed when ``adopted.committed``), or ``None``; ``requested``: the time of the request
    it answered; ``sent``: this call's odometry and estimate went to the worker (it was idle);
    ``late`` (s): how far past the adopted plan's start (``t_ex``) this call adopted it (0 when it
    committed nothing or was in time); ``waited`` (s, wall): how long this call waited for the
    worker (the first plan, ``wait``); ``plan_cpu`` and ``plan_wall`` (s): the worker's CPU and
    wall time on the adopted step (NaN without one).
    """

    t: float
    adopted: ReplanStep | None = None
    requested: float = math.nan
    sent: bool = False
    late: float = 0.0
    waited: float = 0.0
    plan_cpu: float = math.nan
    plan_wall: float = math.nan


class BackgroundReplanner:
    """A :class:`~avp.replan.Replanner` run in a worker process (module docstring).

    Parameters
    ----------
    replanner:
        The replanner to run (a :class:`~avp.replan.Replanner` or a subclass); a pickled copy runs
        in the worker, so this object is not updated (read :attr:`history` and
        :attr:`trajectory` here).
    worker:
        A :class:`PlanningWorker` to host it (default: a new one, closed by :meth:`close`; one
        passed in stays open and may host another replanner afterwards).
    wait:
        Every call waits for the step in flight before sending the next (lock-step; module
        docstring); a call's own ``wait`` overrides it.
    """

    def __init__(self, replanner: Replanner, *, worker: PlanningWorker | None = None, wait: bool = False) -> None:
        if not isinstance(replanner, Replanner):
            raise ConfigError("replanner", f"expected avp.Replanner (or a subclass), got {type(replanner).__name__}")
        if worker is not None and not isinstance(worker, PlanningWorker):
            raise ConfigError("worker", f"expected avp.PlanningWorker or None, got {type(worker).__name__}")
        self.wait = v.boolean("wait", wait)
        try:
            pickle.dumps(replanner)
        except Exception as exc:
            raise ConfigError("replanner", f"cannot be sent to a worker process ({type(exc).__name__}: {exc}); "
                              "a subclass must be defined at module level and hold picklable state") from exc
        self._owns = worker is None
        self.worker = worker if worker is not None else PlanningWorker()
        self.worker.host(replanner)
        self.config = replanner.config
        self.replan = replanner.replan
        self.target = replanner.target
        """The latest estimate handed to :meth:`step` (sent or waiting to be)."""
        self.trajectory: Trajectory | None = replanner.trajectory
        """The committed plan adopted last (``None`` before the first)."""
        self._previous: Trajectory | None = None
        self.history: list[ReplanStep] = []
        """The worker's steps, in the order adopted."""
        self._target_type = replanner._target_type
        self._last_t: float | None = None
        self._requested: float | None = None  # the time of the request in flight
        self._unsent: PerchTarget | None = None  # an estimate that came while the worker was busy

    # -- the loop's call ---------------------------------------------------------------------
    def step(self, t: float, odometry: State, target_estimate: PerchTarget | None = None, *,
             wait: bool | None = None) -> BackgroundStep:
        """One cycle of the loop at ``t`` (module docstring): adopt the worker's finished step,
        then send this call's input when the worker is idle. Input is checked here as
        :meth:`Replanner.step <avp.replan.Replanner.step>` checks it (``ConfigError``); a worker
        that died or does not answer raises :class:`~avp.errors.WorkerError`."""
        t = check_step_input(t, self._last_t, odometry, target_estimate, self._target_type)
        wait = self.wait if wait is None else v.boolean("wait", wait)
        if target_estimate is not None:
            self.target = target_estimate
            self._unsent = target_estimate
        out: dict[str, Any] = {}
        waited = 0.0
        if self.worker.busy and (wait or self.trajectory is None or self.worker.finished()):
            waited += self._adopt(t, out)
        sent = False
        if not self.worker.busy:
            self.worker.submit(t, odometry, self._unsent)
            self._requested, self._unsent, sent = t, None, True
            if self.trajectory is None:  # the first plan: nothing to fly without it
                waited += self._adopt(t, out)
        self._last_t = t
        return BackgroundStep(t=t, sent=sent, waited=waited, **out)

    def _adopt(self, t: float, out: dict[str, Any]) -> float:
        """Receive the step in flight and put it in force; its fields go into ``out``. Returns the
        wall seconds spent waiting for it."""
        w0 = time.perf_counter()
        step, cpu, wall = self.worker.receive()
        waited = time.perf_counter() - w0
        if step.committed and step.trajectory is not None:
            if step.action is not ReplanAction.INITIAL_PLAN:
                self._previous = self.trajectory
            self.trajectory = step.trajectory
        self.history.append(step)
        out.update(adopted=step, requested=self._requested, plan_cpu=cpu, plan_wall=wall,
                   late=max(t - step.t_ex, 0.0) if step.committed and step.action is not ReplanAction.INITIAL_PLAN else 0.0)
        self._requested = None
        return waited

    # -- what the loop flies -------------------------------------------------------------------
    @property
    def pending(self) -> bool:
        """A request is in flight."""
        return self.worker.busy

    @property
    def cannot_reach(self) -> bool:
        """The last adopted step reported ``CANNOT_REACH``."""
        return bool(self.history) and self.history[-1].action is ReplanAction.CANNOT_REACH

    def plan_at(self, t: float) -> Trajectory:
        """The plan being flown at ``t`` (:meth:`Replanner.plan_at <avp.replan.Replanner.plan_at>`,
        on the adopted plans)."""
        return flown_plan(self.trajectory, self._previous, v.finite_float("t", t))

    def reference(self, t: float) -> FlatOutput:
        """Flat output to track at ``t`` (:meth:`Replanner.reference
        <avp.replan.Replanner.reference>`, on the adopted plans)."""
        traj = self.plan_at(t)
        return traj.flat_output(min(max(float(t), traj.t0), traj.tf))

    # -- life cycle --------------------------------------------------------------------------------
    def close(self) -> None:
        """Stop the worker if this replanner started it (a step in flight is dropped)."""
        if self._owns:
            self.worker.close()

    def __enter__(self) -> BackgroundReplanner:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
