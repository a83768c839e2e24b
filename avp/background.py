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

A plan is flown once it is adopted, and it starts at ``t_ex``. :meth:`BackgroundReplanner.poll`
adopts a finished step without sending anything: a control loop faster than the replanning
calls (the controller's, at hundreds of Hz) calls it before :meth:`~BackgroundReplanner.reference`,
so a plan is adopted within a control period of the worker's finishing. Set
``ReplanConfig.latency`` above the time from a request to its adoption: the worker's planning
time (a few milliseconds, more on a slower computer) plus the polling interval, or the
replanning period when only :meth:`~BackgroundReplanner.step` adopts. A plan adopted after its
``t_ex`` is flown from its adoption on, and :attr:`BackgroundStep.late` says by how much its start
had passed (the plan starts from the anticipated state at ``t_ex``, not from where the vehicle is
at adoption).

Waiting: the first plan (nothing to fly yet) is waited for. ``wait=True`` (a constructor default,
or per call of :meth:`~BackgroundReplanner.step` and :meth:`~BackgroundReplanner.poll`) waits for
the step in flight: with it the adoptions do not depend on the worker's speed (the simulator polls
with it at the tick's first control step, at the tick's own time:
``avp.sim.run.simulate(background=...)``). Without it a call
never waits once a plan is committed.

The wrapped replanner is sent to the worker (pickled): the object passed in is not updated. The
worker is a fresh interpreter on POSIX (:class:`PlanningWorker`); start one and pass it to several
replanners in turn to pay its start (about a second) once. A worker that dies, has a step in
flight for longer than its ``timeout`` (hung) or now hosts another replanner raises
:class:`~avp.errors.WorkerError` at the next call (the first two close it); what the hosted
replanner's step raised is raised at the call that adopts it, and that step's estimate goes with
the next request (unless it was refused: a ``ConfigError``). The worker runs in its own session
and ignores SIGINT: a loop that catches Ctrl-C keeps its worker.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import multiprocessing
import os
import pickle
import signal
import socket
import subprocess
import sys
import time
import traceback
import weakref
from multiprocessing.connection import Connection
from typing import Any

from . import _validate as v
from ._blas import warm as _warm_blas
from .errors import AvpError, ConfigError, WorkerError
from .replan import ReplanAction, Replanner, ReplanStep, check_step_time, flown_plan
from .trajectory import FlatOutput, Trajectory
from .types import PerchTarget, State

__all__ = ["BackgroundReplanner", "BackgroundStep", "PlanningWorker"]

_STOP, _HOST, _STEP, _READY, _DONE, _FAILED = "stop", "host", "step", "ready", "done", "failed"
"""The messages between a :class:`PlanningWorker` and its process. A ``_FAILED`` answer carries
the exception and what failed: ``"step"`` (the hosted replanner's step raised; the worker goes
on), ``"input"`` (the worker could not read the message: a class it cannot import) or
``"answer"`` (the step ran but its answer does not pickle: the worker's replanner has moved on
without the parent, so the parent closes it)."""


def _reply_failed(conn: Connection, exc: BaseException, what: str) -> None:
    """Send ``exc`` back as ``_FAILED``: an ``AvpError`` that survives a pickle round trip as it
    is (the caller re-raises it), anything else as a :class:`~avp.errors.WorkerError` with its
    traceback."""
    data = b""
    if isinstance(exc, AvpError):
        try:
            data = pickle.dumps((_FAILED, exc, what))
            pickle.loads(data)
        except Exception:
            data = b""
    if not data:
        text = "".join(traceback.format_exception(exc)).rstrip()
        data = pickle.dumps((_FAILED, WorkerError(f"the hosted replanner raised {type(exc).__name__}: {exc}\n{text}"),
                             what))
    conn.send_bytes(data)


def _serve(conn: Connection) -> None:
    """The worker process: host a replanner (``_HOST``), run its steps (``_STEP``) until
    ``_STOP`` or the pipe closes. A step's exception goes back as ``_FAILED`` (the parent checks
    the input first, :meth:`Replanner._check_input <avp.replan.Replanner._check_input>`, so it is
    a fault of the replanner's). SIGINT is ignored: the loop's Ctrl-C is the loop's to handle, and
    the worker ends with the pipe."""
    with contextlib.suppress(ValueError, OSError, AttributeError):  # not the main thread, no signals
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    replanner: Replanner | None = None
    _warm_blas()
    while True:
        try:
            data = conn.recv_bytes()
        except (EOFError, OSError):
            return
        try:
            msg = pickle.loads(data)
        except Exception as exc:  # a class this process cannot import, say
            _reply_failed(conn, WorkerError(f"the worker could not read it: {type(exc).__name__}: {exc}"), "input")
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
            _reply_failed(conn, exc, "step")
            continue
        try:
            answer = pickle.dumps((_DONE, _portable(step), time.thread_time() - c0, time.perf_counter() - w0))
        except Exception as exc:
            _reply_failed(conn, exc, "answer")
            continue
        conn.send_bytes(answer)


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


def _serve_process(conn: Connection, parent_end: Connection) -> None:
    """The worker's entry point under ``multiprocessing``: close the parent's end of the pipe
    (inherited by ``fork``; with it open, the worker would never see the parent's end) and
    serve."""
    parent_end.close()
    _serve(conn)


_BOOT = ("import json, os, sys; sys.path[:] = json.loads(os.environ.pop('AVP_WORKER_SYS_PATH')); "
         "from avp.background import _serve_fd; _serve_fd({fd})")
"""What the fresh interpreter runs (with ``-P``: nothing from the working directory is imported
before): the parent's ``sys.path`` (so it imports the same ``avp`` and the modules beside the
caller's script), then the worker's loop on the inherited socket."""


def _parent_path() -> str:
    """This process's ``sys.path`` as JSON, its entries absolute (``''``: the working
    directory); entries that are not strings are left out."""
    cwd = os.getcwd()
    return json.dumps([os.path.join(cwd, p) if p else cwd for p in sys.path if isinstance(p, str)])


class _Subprocess:
    """A worker in a fresh interpreter (``subprocess``), with the calls :func:`_shutdown` makes.
    It runs in its own session: the terminal's Ctrl-C never reaches it, not even while it starts."""

    def __init__(self) -> None:
        parent, child = socket.socketpair()
        try:
            env = dict(os.environ)
            env["AVP_WORKER_SYS_PATH"] = _parent_path()
            flags: list[str] = getattr(subprocess, "_args_from_interpreter_flags", list)()  # -W, -X, -O... as here
            self.popen = subprocess.Popen(
                [sys.executable, *flags, "-P", "-c", _BOOT.format(fd=child.fileno())],
                pass_fds=(child.fileno(),), stdin=subprocess.DEVNULL, env=env, close_fds=True,
                start_new_session=True)
        except (OSError, ValueError, TypeError) as exc:
            parent.close()
            raise WorkerError(f"could not start a worker interpreter ({sys.executable!r}): "
                              f"{type(exc).__name__}: {exc}") from exc
        finally:
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
        try:
            self.process = ctx.Process(target=_serve_process, args=(child, parent), daemon=True,
                                       name="avp-planning-worker")
            self.process.start()
        except Exception as exc:
            parent.close()
            raise WorkerError(f"could not start a worker process ({method}): {type(exc).__name__}: {exc}") from exc
        finally:
            child.close()
        self.conn = parent

    def is_alive(self) -> bool:
        return bool(self.process.is_alive())

    def join(self, timeout: float) -> None:
        self.process.join(timeout)

    def terminate(self) -> None:
        self.process.terminate()

    @property
    def exitcode(self) -> int | None:
        return self.process.exitcode  # type: ignore[no-any-return]


def _shutdown(process: _Subprocess | _Multiprocess, state: dict[str, Any]) -> None:
    """Stop a worker process. An idle one is asked to stop (it does at once); one with a step in
    flight, or one that does not stop, is terminated: a step is not waited for."""
    if not state["busy"]:
        with contextlib.suppress(OSError, ValueError):
            process.conn.send((_STOP,))
        process.join(1.0)
    if process.is_alive():
        process.terminate()
        process.join(1.0)
    process.conn.close()


_LONGEST_WAIT = 1e6
"""The longest timeout (s) a :class:`PlanningWorker` takes (about 11 days: a wait the system
calls can express)."""


def _seconds(field: str, value: Any) -> float:
    out = v.positive_float(field, value)
    if out > _LONGEST_WAIT:
        raise ConfigError(field, f"must be at most {_LONGEST_WAIT:g} s, got {out:g}")
    return out


def start_methods() -> tuple[str, ...]:
    """The :class:`PlanningWorker` start methods of this platform: ``subprocess`` (POSIX: a fresh
    interpreter, the default) and ``multiprocessing``'s."""
    own = ("subprocess",) if os.name == "posix" else ()
    return own + tuple(multiprocessing.get_all_start_methods())


class PlanningWorker:
    """A process that runs one :class:`~avp.replan.Replanner` at a time for
    :class:`BackgroundReplanner` (module docstring). Several replanners may use one worker in
    turn: hosting a new one ends the previous one's use of it (its next call raises
    :class:`~avp.errors.WorkerError`).

    Parameters
    ----------
    start_method:
        ``"subprocess"`` (the default on POSIX): a fresh interpreter with this process's
        ``sys.path`` and interpreter flags, so it imports this ``avp`` and the modules beside the
        caller's script (a replanner subclass must be importable from one; the main script's own
        classes are not); it never runs the main script, which needs no
        ``if __name__ == "__main__":`` guard. Or one of ``multiprocessing``'s methods (the default
        elsewhere: ``spawn``, which runs the main module again and needs that guard; ``fork``
        copies the caller's threads' state, BLAS pools included: not advised). A
        ``multiprocessing`` worker shares the terminal's process group: a Ctrl-C while it starts
        (before it ignores SIGINT) ends it.
    timeout:
        Seconds a step may be in flight (s): a call that waits for it longer, or finds it older
        (a hung worker), closes the worker and raises :class:`~avp.errors.WorkerError`, since
        its answer can no longer be matched to its request. A plan takes milliseconds.
    start_timeout:
        Seconds hosting a replanner may take (the first one waits for the interpreter's start,
        about a second).
    """

    def __init__(self, start_method: str | None = None, timeout: float = 60.0, start_timeout: float = 120.0) -> None:
        methods = start_methods()
        method = methods[0] if start_method is None else start_method
        if method not in methods:
            raise ConfigError("start_method", f"{method!r} is not one of this platform's start methods {methods}")
        self.timeout = _seconds("timeout", timeout)
        self.start_timeout = _seconds("start_timeout", start_timeout)
        self.start_method = method
        self._process = _Subprocess() if method == "subprocess" else _Multiprocess(method)
        self._conn = self._process.conn
        self._state: dict[str, Any] = {"busy": False}  # shared with the finalizer
        self._sent_at = 0.0  # perf_counter of the step in flight's request
        self._host_token: object | None = None  # who is hosted (BackgroundReplanner._token)
        self._finalizer = weakref.finalize(self, _shutdown, self._process, self._state)

    @property
    def alive(self) -> bool:
        """The worker process is running (and not closed)."""
        return self._finalizer.alive and self._process.is_alive()

    def close(self) -> None:
        """Stop the worker process (idempotent; also at garbage collection and exit). A step in
        flight is dropped: the process is terminated, not waited for."""
        self._finalizer()

    def __enter__(self) -> PlanningWorker:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- the protocol (BackgroundReplanner's) ---------------------------------------------------
    def _fail(self, message: str, cause: BaseException | None = None) -> WorkerError:
        """Close the worker (terminated at once: its answers can no longer be matched to
        requests) and return the error to raise."""
        self.close()
        self._state["busy"] = False
        err = WorkerError(message + "; the worker is closed: start a new PlanningWorker")
        err.__cause__ = cause
        return err

    def _closed(self) -> WorkerError:
        return WorkerError("the planning worker is closed: start a new PlanningWorker")

    def _send(self, msg: tuple[Any, ...]) -> None:
        if not self._finalizer.alive:
            raise self._closed()
        try:
            self._conn.send(msg)
        except (OSError, ValueError) as exc:
            raise self._fail(f"the planning worker is gone ({type(exc).__name__}: {exc})", exc) from exc

    def _reply(self, timeout: float) -> tuple[Any, ...]:
        """The next answer (waits up to ``timeout``); a timeout, the worker's end or an answer
        that does not read close the worker."""
        if not self._finalizer.alive:
            raise self._closed()
        try:
            ready = self._conn.poll(timeout)
        except (OSError, ValueError) as exc:
            raise self._fail(f"the planning worker is gone ({type(exc).__name__}: {exc})", exc) from exc
        if not ready:
            raise self._fail(f"the planning worker did not answer in time (timeout {self.timeout:g} s)")
        try:
            data = self._conn.recv_bytes()
        except (EOFError, OSError) as exc:
            self._process.join(1.0)
            raise self._fail(f"the planning worker exited (exit code {self._process.exitcode})", exc) from exc
        try:
            return pickle.loads(data)  # type: ignore[no-any-return]
        except Exception as exc:
            raise self._fail(f"the planning worker's answer does not read here ({type(exc).__name__}: {exc})",
                             exc) from exc

    def _left(self) -> float:
        """Seconds the step in flight may still take."""
        return max(self.timeout - (time.perf_counter() - self._sent_at), 0.0)

    def _host(self, replanner: Replanner, token: object) -> None:
        """Send ``replanner`` to the worker (it replaces the one hosted before, whose next call
        then raises); waits until it is there. A step still in flight is received and dropped
        first."""
        if self._busy:
            self._reply(self._left())
            self._state["busy"] = False
        self._host_token = None
        self._send((_HOST, replanner))
        reply = self._reply(self.start_timeout)
        if reply[0] == _FAILED:
            raise ConfigError("replanner", f"{reply[1]} (a subclass must be importable in the worker: defined in "
                              "a module on this process's sys.path, not in the main script or a function)")
        if reply[0] != _READY:  # pragma: no cover - the protocol's own check
            raise self._fail(f"unexpected reply {reply[0]!r} to hosting a replanner")
        self._host_token = token

    def _check_host(self, token: object) -> None:
        """The worker is open and hosts the replanner of ``token``."""
        if not self._finalizer.alive:
            raise self._closed()
        if self._host_token is not token:
            raise WorkerError("this PlanningWorker now hosts another replanner (or none): a BackgroundReplanner "
                              "uses its worker until another is built on it")

    def _submit(self, t: float, odometry: State, target_estimate: PerchTarget | None) -> None:
        """Start the hosted replanner's step (the worker is idle)."""
        self._send((_STEP, t, odometry, target_estimate))
        self._state["busy"] = True
        self._sent_at = time.perf_counter()

    @property
    def _busy(self) -> bool:
        return bool(self._state["busy"]) and self._finalizer.alive

    def _finished(self) -> bool:
        """The step in flight has finished (its answer, or the worker's end, is waiting); one in
        flight for longer than ``timeout`` closes the worker and raises."""
        if not self._busy:
            return False
        try:
            if self._conn.poll():
                return True
        except (OSError, ValueError) as exc:
            raise self._fail(f"the planning worker is gone ({type(exc).__name__}: {exc})", exc) from exc
        if self._left() <= 0.0:
            raise self._fail(f"the planning worker has not answered for {self.timeout:g} s (timeout: hung?)")
        return False

    def _receive(self) -> tuple[Any, ...]:
        """The answer to the step in flight (waits for it, up to ``timeout`` from its request):
        ``(_DONE, step, cpu, wall)`` or ``(_FAILED, exception, what)``. An answer the parent
        can no longer follow (``"answer"``: the worker's replanner moved on without it) closes
        the worker and raises."""
        reply = self._reply(self._left())
        self._state["busy"] = False
        if reply[0] == _FAILED and reply[2] == "answer":
            raise self._fail(f"the hosted replanner's step ran but its answer does not pickle ({reply[1]}); the "
                             "worker's replanner has moved on without this process")
        return reply


@dataclasses.dataclass(frozen=True, kw_only=True)
class BackgroundStep:
    """What one :meth:`BackgroundReplanner.step` (or an adopting :meth:`~BackgroundReplanner.poll`)
    call did.

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
        The replanner to run (a :class:`~avp.replan.Replanner` or a subclass, importable in the
        worker); a pickled copy runs in the worker, so this object is not updated: read
        :attr:`history` and :attr:`trajectory` here. State a subclass keeps beyond those (a
        :class:`~avp.line_replan.LineReplanner`'s ``recovery``) is in the adopted steps' results.
        One that has stepped already carries on (its time, plans and history are kept).
    worker:
        A :class:`PlanningWorker` to host it (default: a new one, closed by :meth:`close`; one
        passed in stays open and may host another replanner afterwards, which ends this one's
        use of it).
    wait:
        Every call waits for the step in flight (lock-step; module docstring); a call's own
        ``wait`` overrides it.
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
        self._token = object()  # this replanner's claim on the worker (PlanningWorker._host)
        try:
            self.worker._host(replanner, self._token)
        except BaseException:
            if self._owns:
                self.worker.close()
            raise
        self._kind = type(replanner)  # its input checks (Replanner._check_input)
        self.config = replanner.config
        self.replan = replanner.replan
        self.target = replanner.target
        """The latest estimate handed to :meth:`step` (sent or waiting to be)."""
        self.trajectory: Trajectory | None = replanner.trajectory
        """The committed plan adopted last (``None`` before the first)."""
        self._previous: Trajectory | None = replanner._previous
        self.history: list[ReplanStep] = list(replanner.history)
        """The replanner's steps, then the worker's, in the order adopted."""
        self._last_t: float | None = replanner._last_t
        self._requested: float | None = None  # the time of the request in flight
        self._in_flight: PerchTarget | None = None  # the estimate it carries
        self._unsent: PerchTarget | None = None  # an estimate that came while the worker was busy

    # -- the loop's calls ----------------------------------------------------------------------
    def step(self, t: float, odometry: State, target_estimate: PerchTarget | None = None, *,
             wait: bool | None = None) -> BackgroundStep:
        """One cycle of the loop at ``t`` (module docstring): adopt the worker's finished step,
        then send this call's input when the worker is idle. Input is checked here as the
        replanner's own ``step`` checks it (``ConfigError``), before anything is sent; a worker
        that died, hung past its ``timeout`` or was given to another replanner raises
        :class:`~avp.errors.WorkerError`, and what the hosted replanner's step raised is
        re-raised (an ``AvpError`` as it is)."""
        self.worker._check_host(self._token)
        t = self._kind._check_input(t, odometry, target_estimate, self._last_t,
                                    self.target if self.trajectory is None else None)
        wait = self.wait if wait is None else v.boolean("wait", wait)
        if target_estimate is not None:
            self.target = target_estimate
            self._unsent = target_estimate
        out: dict[str, Any] = {}
        waited = 0.0
        if self.pending and (wait or self.trajectory is None or self.worker._finished()):
            waited += self._adopt(t, out)
        sent = False
        if not self.pending:
            self.worker._submit(t, odometry, self._unsent)
            self._requested, self._in_flight, self._unsent, sent = t, self._unsent, None, True
            if self.trajectory is None:  # the first plan: nothing to fly without it
                waited += self._adopt(t, out)
        self._last_t = t
        return BackgroundStep(t=t, sent=sent, waited=waited, **out)

    def _adopt(self, t: float, out: dict[str, Any]) -> float:
        """Receive the step in flight and put it in force; its fields go into ``out``. Returns the
        wall seconds spent waiting for it. When the step raised, the exception is raised, and
        the step's estimate goes with the next request unless a newer one came or the input was
        refused (a ``ConfigError``: the synchronous replanner would have refused it too)."""
        w0 = time.perf_counter()
        reply = self.worker._receive()
        waited = time.perf_counter() - w0
        requested, estimate = self._requested, self._in_flight
        self._requested = self._in_flight = None
        if reply[0] == _FAILED:
            exc, what = reply[1], reply[2]
            if what == "input":
                raise ConfigError("odometry, target_estimate", f"{exc} (a subclass of State or PerchTarget must be "
                                  "importable in the worker: defined in a module, not in the main script)")
            if self._unsent is None and not isinstance(exc, ConfigError):
                self._unsent = estimate
            raise exc
        step, cpu, wall = reply[1], reply[2], reply[3]
        replan = step.committed and step.action is not ReplanAction.INITIAL_PLAN
        if step.committed and step.trajectory is not None:
            self._previous, self.trajectory = self.trajectory, step.trajectory
        self.history.append(step)
        out.update(adopted=step, requested=requested, plan_cpu=cpu, plan_wall=wall,
                   late=max(t - step.t_ex, 0.0) if replan else 0.0)
        return waited

    def poll(self, t: float, *, wait: bool = False) -> BackgroundStep | None:
        """Adopt the worker's step if it has finished (with ``wait``, wait for the one in flight),
        sending nothing: for a control loop faster than the replanning calls, so that a plan is
        flown as soon as it is ready rather than at the next :meth:`step` (module docstring).
        ``t`` (s) is the loop's clock now, not before the last step's; ``None`` when nothing
        was adopted. Raises as :meth:`step` does."""
        self.worker._check_host(self._token)
        t = check_step_time(t, self._last_t)
        wait = v.boolean("wait", wait)
        if not self.pending or not (wait or self.worker._finished()):
            return None
        out: dict[str, Any] = {}
        waited = self._adopt(t, out)
        return BackgroundStep(t=t, waited=waited, **out)

    # -- what the loop flies -------------------------------------------------------------------
    @property
    def pending(self) -> bool:
        """A request of this replanner's is in flight."""
        return self.worker._busy and self.worker._host_token is self._token

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
