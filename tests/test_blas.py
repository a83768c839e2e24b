"""avp._blas.serial_blas: one BLAS thread inside the block, restored after it, and the same
plans bit for bit as with the default threads (the replanner's steps and the public planners
run inside it)."""

from __future__ import annotations

import math
import threading

import numpy as np
import pytest

import avp
from avp._blas import serial_blas

threadpoolctl = pytest.importorskip("threadpoolctl")


def _blas_threads() -> list[int]:
    return [lib["num_threads"] for lib in threadpoolctl.threadpool_info() if lib["user_api"] == "blas"]


__import__("scipy.linalg")  # SciPy's BLAS loaded before the marker below looks
threaded = pytest.mark.skipif(max(_blas_threads(), default=1) <= 1,
                              reason="every BLAS already runs on one thread here (one core, or OPENBLAS_NUM_THREADS=1)")


@threaded
def test_serial_blas_limits_and_restores_the_thread_count():
    before = _blas_threads()
    with serial_blas():
        assert _blas_threads() and all(n == 1 for n in _blas_threads())
    assert _blas_threads() == before
    with pytest.raises(RuntimeError), serial_blas():  # restored on an exception too
        raise RuntimeError("planning failed")
    assert _blas_threads() == before


def test_nested_and_overlapping_blocks_restore_the_first_counts():
    before = _blas_threads()
    outer = serial_blas()
    outer.__enter__()
    with serial_blas():  # another replanner (or thread) inside the first block
        assert all(n == 1 for n in _blas_threads())
    assert all(n == 1 for n in _blas_threads())  # the outer block still holds
    inner = serial_blas()
    inner.__enter__()
    outer.__exit__(None, None, None)  # overlapping: the first to open closes first
    assert all(n == 1 for n in _blas_threads())
    inner.__exit__(None, None, None)
    assert _blas_threads() == before


@threaded
def test_serial_blas_holds_in_any_thread():
    # threadpoolctl lets only the first thread that set OpenBLAS's pool set it again: a block
    # opened in another thread (a replanner stepped in a thread of its own) did nothing
    import threading

    before = _blas_threads()
    with serial_blas():  # the main thread sets the pool first
        pass
    seen: list[list[int]] = []

    def planning_thread() -> None:
        with serial_blas():
            seen.append(_blas_threads())
        seen.append(_blas_threads())

    thread = threading.Thread(target=planning_thread)
    thread.start()
    thread.join()
    assert seen[0] and all(n == 1 for n in seen[0])
    assert seen[1] == before == _blas_threads()
    with serial_blas():  # and the main thread still can
        assert all(n == 1 for n in _blas_threads())
    assert _blas_threads() == before


class _Controller:
    """What threadpoolctl gives for a library avp does not call directly."""

    def __init__(self, internal_api: str, threading_layer: str) -> None:
        self.internal_api, self.threading_layer, self.dynlib = internal_api, threading_layer, object()

    def get_num_threads(self) -> int:
        return 4

    def set_num_threads(self, n: int) -> None:
        pass


def test_libraries_other_than_a_pooled_openblas_are_set_through_threadpoolctl():
    from avp._blas import _pool

    for api, layer, per_thread in (("mkl", "intel", True), ("openblas", "openmp", True), ("blis", "pthreads", False),
                                   ("flexiblas", "pthreads", False)):
        lib = _Controller(api, layer)
        (get, put), local = _pool(lib)
        assert get == lib.get_num_threads and put == lib.set_num_threads
        assert local is per_thread


class _PerThreadLibrary:
    """A BLAS whose thread count is per thread, as threadpoolctl presents MKL (its local limit)."""

    user_api, internal_api, threading_layer, dynlib = "blas", "mkl", "intel", None

    def __init__(self, default: int = 4) -> None:
        self.local, self.default = threading.local(), default

    def get_num_threads(self) -> int:
        return getattr(self.local, "n", self.default)

    def set_num_threads(self, n: int) -> None:
        self.local.n = n


class _SharedLibrary:
    """A BLAS with one process-wide count, as threadpoolctl presents BLIS."""

    user_api, internal_api, threading_layer, dynlib = "blas", "blis", "pthreads", None

    def __init__(self) -> None:
        self.n = 4

    def get_num_threads(self) -> int:
        return self.n

    def set_num_threads(self, n: int) -> None:
        self.n = n


@pytest.fixture
def fake_pools(monkeypatch):
    """Make the given fake controllers the process's BLAS libraries (found by ``_pools``) for
    one test."""
    import avp._blas as blas

    def install(*libraries: object) -> None:
        monkeypatch.setattr(threadpoolctl, "ThreadpoolController",
                            lambda: type("Controller", (), {"lib_controllers": list(libraries)})())
        monkeypatch.setattr(blas, "_POOLS", [])
        monkeypatch.setattr(blas, "_SAVED", [])
        monkeypatch.setattr(blas, "_LOCAL", threading.local())
        monkeypatch.setattr(blas, "_SHARES", {})

    return install


def test_a_per_thread_library_is_limited_in_each_planning_thread(fake_pools):
    # a process-wide count would limit only the first thread to open a block, and the last to
    # close would write the saved count into its own thread
    lib = _PerThreadLibrary()
    fake_pools(lib)
    seen: dict[str, int] = {}
    a_in, b_in, a_out = threading.Event(), threading.Event(), threading.Event()

    def a() -> None:
        with serial_blas():
            seen["A inside"] = lib.get_num_threads()
            a_in.set()
            b_in.wait(5)
        seen["A after"] = lib.get_num_threads()
        a_out.set()

    def b() -> None:
        a_in.wait(5)
        with serial_blas():
            seen["B inside, overlapping A"] = lib.get_num_threads()
            b_in.set()
            a_out.wait(5)
        seen["B after"] = lib.get_num_threads()

    threads = [threading.Thread(target=a), threading.Thread(target=b)]
    for th in threads:
        th.start()
    for th in threads:
        th.join(10)
    assert seen == {"A inside": 1, "B inside, overlapping A": 1, "A after": 4, "B after": 4}


def test_a_limit_that_fails_part_way_is_undone(fake_pools):
    import avp._blas as blas

    def refusing_once(lib):
        real = lib.set_num_threads
        calls = []

        def set_num_threads(n: int) -> None:
            calls.append(n)
            if len(calls) == 1:
                raise OSError("the library refused")
            real(n)

        lib.set_num_threads = set_num_threads
        return lib

    for broken in (refusing_once(_SharedLibrary()), refusing_once(_PerThreadLibrary())):
        for_all = (_SharedLibrary(), _PerThreadLibrary())
        fake_pools(*for_all, broken)
        with pytest.raises(OSError), serial_blas():
            pass
        # the libraries set before the error have their counts back, and nothing stays open
        assert [lib.get_num_threads() for lib in for_all] == [4, 4] and blas._SHARES == {}
        with serial_blas():
            assert [lib.get_num_threads() for lib in (*for_all, broken)] == [1, 1, 1]
        assert [lib.get_num_threads() for lib in (*for_all, broken)] == [4, 4, 4]


def test_a_library_that_fails_to_answer_or_to_restore_leaves_nothing_open(fake_pools):
    import avp._blas as blas

    shared, local = _SharedLibrary(), _PerThreadLibrary()
    asked = []
    real_get = local.get_num_threads

    def get_once_fails() -> int:
        asked.append(1)
        if len(asked) == 1:
            raise OSError("the library did not answer")
        return real_get()

    local.get_num_threads = get_once_fails  # type: ignore[method-assign]
    fake_pools(shared, local)
    with pytest.raises(OSError), serial_blas():
        pass
    assert blas._SHARES == {} and shared.get_num_threads() == 4  # the shared block opened first was closed
    # a library that refuses its count back does not keep the others at one thread
    first, refusing, last = _SharedLibrary(), _SharedLibrary(), _SharedLibrary()
    real_set = refusing.set_num_threads
    refusing.set_num_threads = lambda n: real_set(n) if n == 1 else (_ for _ in ()).throw(OSError("refused"))  # type: ignore[method-assign]
    fake_pools(first, refusing, last)
    with pytest.raises(OSError), serial_blas():
        pass
    assert (first.get_num_threads(), last.get_num_threads()) == (4, 4) and blas._SHARES == {}


def test_a_block_closed_in_another_thread_leaves_that_threads_blocks_alone(fake_pools):
    # a generator holding a block, advanced here and finished in another thread
    import avp._blas as blas

    shared, local = _SharedLibrary(), _PerThreadLibrary()
    fake_pools(shared, local)

    def holder():
        with serial_blas():
            yield

    gen = holder()
    next(gen)
    seen: dict[str, object] = {}

    def other() -> None:
        try:
            with serial_blas():
                gen.close()  # the other thread's block closes here
                seen["inside"] = (shared.get_num_threads(), local.get_num_threads())
            seen["after"] = (shared.get_num_threads(), local.get_num_threads())
            with serial_blas():
                seen["again"] = local.get_num_threads()
        except BaseException as exc:  # pragma: no cover - reported below
            seen["error"] = exc

    thread = threading.Thread(target=other)
    thread.start()
    thread.join(10)
    assert "error" not in seen
    assert seen["inside"] == (1, 1) and seen["after"] == (4, 4) and seen["again"] == 1
    assert blas._SHARES == {} and shared.get_num_threads() == 4


@pytest.mark.skipif(not hasattr(__import__("os"), "fork"), reason="POSIX fork")
def test_a_forked_child_is_not_left_inside_another_threads_block(fake_pools):
    import os

    import avp._blas as blas

    shared = _SharedLibrary()
    fake_pools(shared)
    inside, done = threading.Event(), threading.Event()

    def planning() -> None:
        with serial_blas():
            inside.set()
            done.wait(10)

    thread = threading.Thread(target=planning)
    thread.start()
    inside.wait(10)
    pid = os.fork()
    if pid == 0:  # the child: only this thread lives on, with no block of its own open
        ok = blas._SHARES == {} and shared.get_num_threads() == 4
        with serial_blas():  # takes the lock and limits (a lock held at the fork would hang here)
            ok = ok and shared.get_num_threads() == 1
        os._exit(0 if ok and shared.get_num_threads() == 4 else 1)
    done.set()
    thread.join(10)
    _, status = os.waitpid(pid, 0)
    assert os.waitstatus_to_exitcode(status) == 0
    assert shared.get_num_threads() == 4 and blas._SHARES == {}


@threaded
def test_a_planner_that_raises_restores_the_thread_count():
    before = _blas_threads()
    with pytest.raises(avp.ConfigError):
        avp.plan_detailed(avp.State.hover([0.0, 0.0, 1.5]), "not a target")  # type: ignore[arg-type]
    assert _blas_threads() == before


@threaded
def test_scipys_blas_leaves_no_helper_thread_spinning_after_a_limited_call():
    # SciPy's OpenBLAS runs this triangular solve (48 rows over a 33 x 33 factor, as in an SQP
    # step) on two threads by default, and its helper then spins for about 0.1 s; inside the
    # limit nothing may run after the call. The limit must find SciPy's library at all (the
    # threadpoolctl releases before 3.5 did not know the libscipy_openblas of current wheels).
    import os
    import time

    import scipy.linalg.blas

    if (os.cpu_count() or 1) < 2:
        pytest.skip("one core: OpenBLAS starts no helper thread")
    rng = np.random.default_rng(0)
    R = np.triu(rng.random((33, 33))) + 5.0 * np.eye(33)
    G = rng.random((48, 33))

    def others_cpu(call) -> float:  # CPU of the process's other threads during the call and 0.2 s after
        p0, t0 = time.process_time(), time.thread_time()
        call()
        time.sleep(0.2)
        return (time.process_time() - p0) - (time.thread_time() - t0)

    time.sleep(0.2)  # an earlier test's spin ends
    idle = others_cpu(lambda: None)
    with serial_blas():
        limited = others_cpu(lambda: scipy.linalg.blas.dtrsm(1.0, R, G.T, side=0, lower=0, trans_a=1))
    assert limited < idle + 0.02


def test_plans_under_serial_blas_are_the_plans_with_default_threads():
    # a replan-like call whose reduction products (rows x 96 x 33) exceed OpenBLAS's threading threshold
    start = avp.State.hover([0.0, 0.0, 1.5])
    target = avp.PerchTarget.from_incline([4.5, 0.3, 1.5], math.radians(90.0))
    first = avp.plan_detailed(start, target)
    assert first.trajectory is not None
    moved = avp.PerchTarget.from_incline([4.52, 0.28, 1.49], math.radians(88.0))
    mid = first.trajectory.t0 + 0.3 * (first.trajectory.tf - first.trajectory.t0)
    d = first.trajectory.derivatives(mid)
    state = avp.State(position=d[0, :3], velocity=d[1, :3], acceleration=d[2, :3], jerk=d[3, :3],
                      yaw=float(d[0, 3]), yaw_rate=float(d[1, 3]), time=mid)
    durations = np.full(first.trajectory.n_segments, (first.trajectory.tf - mid) / first.trajectory.n_segments)
    threaded = avp.planner.plan_detailed.__wrapped__  # the planner without its serial block
    default = threaded(state, moved, durations=durations, previous=first.trajectory)
    serial = avp.plan_detailed(state, moved, durations=durations, previous=first.trajectory)
    _same_plan(default, serial)


def _same_plan(a: avp.PlanResult, b: avp.PlanResult) -> None:
    assert a.status is b.status and a.log == b.log
    assert a.trajectory is not None and b.trajectory is not None
    assert np.array_equal(a.trajectory.coefficients, b.trajectory.coefficients)
    assert np.array_equal(a.trajectory.knots, b.trajectory.knots)


def test_a_first_plan_with_sqp_steps_is_the_same_with_default_threads():
    # three SQP steps, each adding 48 FoV rows: the triangular solve of 32 rows or more (SciPy's
    # BLAS trsm, PerchingQp.least_distance) runs on several threads by default
    start = avp.State.hover([-7.5, 0.0, 1.5])
    target = avp.PerchTarget.from_incline([0.0, 0.0, 1.5], math.radians(60.0))
    serial = avp.plan_detailed(start, target)
    assert any(line.startswith("SQP step 2: visibility") for line in serial.log)
    _same_plan(avp.planner.plan_detailed.__wrapped__(start, target), serial)


@threaded
@pytest.mark.parametrize("planner", ["plan_detailed", "plan_moving_detailed", "plan_line"])
def test_the_public_planners_plan_with_one_blas_thread(planner, monkeypatch):
    seen: list[list[int]] = []
    import avp.qp.assemble

    real = avp.qp.assemble.PerchingQp.stacked_equalities  # every planner's QPs pass here

    def recording(self):
        seen.append(_blas_threads())
        return real(self)

    monkeypatch.setattr(avp.qp.assemble.PerchingQp, "stacked_equalities", recording)
    before = _blas_threads()
    start = avp.State.hover([0.0, 0.0, 1.5])
    if planner == "plan_detailed":
        result = avp.plan_detailed(start, avp.PerchTarget.from_incline([4.5, 0.0, 1.5], math.radians(90.0)))
    elif planner == "plan_moving_detailed":
        pad = avp.MovingTarget.on_platform([0.0, 0.0, 1.0], incline=0.5, speed=2.0)
        moving_start = avp.State(position=pad.point - [3.0, 0.0, -1.0], velocity=pad.velocity)
        result = avp.plan_moving_detailed(moving_start, pad, avp.PlannerConfig(alpha=5.5))
    else:
        line = avp.LineTarget.segment([2.0, -1.5, 3.7], [2.0, 1.5, 3.7], pitch=0.0, gripper_offset=0.15)
        result = avp.plan_line(avp.State.hover([0.0, 0.0, 2.5]), line)
    assert result.status is not None
    assert seen and all(threads and all(n == 1 for n in threads) for threads in seen)
    assert _blas_threads() == before
