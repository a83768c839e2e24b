"""avp._blas.serial_blas: one BLAS thread inside the block, restored after it, and the same
plans bit for bit as with the default threads (the replanner's steps and the public planners
run inside it)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import avp
from avp._blas import serial_blas

threadpoolctl = pytest.importorskip("threadpoolctl")


def _blas_threads() -> list[int]:
    return [lib["num_threads"] for lib in threadpoolctl.threadpool_info() if lib["user_api"] == "blas"]


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


def test_libraries_other_than_a_pooled_openblas_are_set_through_threadpoolctl():
    from avp._blas import _pool

    class Controller:  # what threadpoolctl gives for MKL, BLIS or an OpenMP-threaded OpenBLAS
        def __init__(self, internal_api: str, threading_layer: str) -> None:
            self.internal_api, self.threading_layer, self.dynlib = internal_api, threading_layer, object()

        def get_num_threads(self) -> int:
            return 4

        def set_num_threads(self, n: int) -> None:
            pass

    for lib in (Controller("mkl", "intel"), Controller("openblas", "openmp")):
        get, put = _pool(lib)
        assert get == lib.get_num_threads and put == lib.set_num_threads


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
