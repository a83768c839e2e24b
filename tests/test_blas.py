"""avp._blas.serial_blas: one BLAS thread inside the block, restored after it, and the same
plans bit for bit as with the default threads (the replanner's steps run inside it)."""

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
    default = avp.plan_detailed(state, moved, durations=durations, previous=first.trajectory)
    with serial_blas():
        serial = avp.plan_detailed(state, moved, durations=durations, previous=first.trajectory)
    assert default.status is serial.status
    assert default.trajectory is not None and serial.trajectory is not None
    assert np.array_equal(default.trajectory.coefficients, serial.trajectory.coefficients)
    assert np.array_equal(default.trajectory.knots, serial.trajectory.knots)
