"""Serial BLAS for latency-bound calls (a replanning step).

OpenBLAS runs a matrix product above about 2.6e5 multiply-adds on several threads; the
reduction of a QP with a few hundred inequality rows (``G Z``: 175 x 96 by 96 x 33) is just
above. On a loaded machine the calling thread then waits, spinning, for a second core: one
step of the 30 Hz loop took 13-26 ms CPU instead of 8 (``benchmarks/bench_replan.py``). With
one thread the products are computed by the same kernel on the calling thread, and the results
were the same bit for bit on the benchmark's closed-loop runs (row blocking instead of a thread
limit was not: it changes the kernel OpenBLAS picks).

Smaller calls thread too: SciPy's OpenBLAS splits a triangular solve with 32 right-hand sides
or more over a 33 x 33 factor over its threads (``PerchingQp.least_distance``: every QP's
inequality rows, 45 in a default plan, and an SQP step's new rows), and its helper thread then
spins, waiting for more work, for about 110 ms of a second core's CPU after the call. A single
default ``plan()`` cost that much of a second core; planned back to back, one with three SQP
steps cost 2.2 ms of its own thread's CPU and 6.1 ms of the process's, and Gao et al.'s 90 deg
perch 4.5 and 8.5 ms, on a 2-core machine (``benchmarks/bench_rounds.py`` prints both). The
public planners (:func:`serial` below) therefore plan with one BLAS thread too.

:func:`serial_blas` limits the BLAS libraries loaded in the process to one thread for the
duration of a ``with`` block; :func:`serial` wraps a function in it. ``threadpoolctl`` (a
dependency; without it the block does nothing) finds the libraries; an OpenBLAS with its own
thread pool is then set through its own ``openblas_set_num_threads`` from any Python thread
(threadpoolctl 3.8 lets only the first thread that set that pool set it again, so a replanner
stepped in a thread of its own planned with every BLAS thread), other libraries through
threadpoolctl. A shared pool's limit is process-wide while it holds: another thread's BLAS call
made meanwhile runs serially too, and a ``threadpool_limits`` block another thread opens and
closes meanwhile restores what it found (one thread, which then stays). Libraries limited per
thread (MKL, an OpenMP-threaded OpenBLAS) are limited in the planning thread only.
"""

from __future__ import annotations

import contextlib
import functools
import itertools
import os
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any, TypeVar

__all__ = ["serial", "serial_blas", "warm"]

_F = TypeVar("_F", bound=Callable[..., Any])
_Pool = tuple[Callable[[], Any], Callable[[int], Any]]  # a library's (get, set) of its thread count


@dataclass(frozen=True)
class _Pools:
    """The BLAS libraries' thread-count calls: process-wide pools (one count for every thread),
    and libraries whose count is per thread."""

    shared: list[_Pool]
    per_thread: list[_Pool]


_POOLS: list[_Pools] = []  # found on first use
_LOCK = threading.Lock()


def _pool(lib: Any) -> tuple[_Pool, bool]:
    """``((get, set), per_thread)`` of a threadpoolctl controller's thread count. An OpenBLAS with
    its own thread pool is called through its own symbols
    (``[scipy_]openblas_{get,set}_num_threads[64_|_64]``, the names threadpoolctl looks up),
    which act from any thread; other libraries through the controller. MKL (threadpoolctl sets
    ``MKL_Set_Num_Threads_Local``) and an OpenMP-threaded OpenBLAS (``omp_set_num_threads``)
    are limited per thread; BLIS and FlexiBLAS process-wide."""
    api = getattr(lib, "internal_api", None)
    openmp = getattr(lib, "threading_layer", None) == "openmp"
    dynlib = getattr(lib, "dynlib", None)
    if api == "openblas" and not openmp and dynlib is not None:
        for prefix, suffix in itertools.product(("", "scipy_"), ("", "64_", "_64")):
            get = getattr(dynlib, f"{prefix}openblas_get_num_threads{suffix}", None)
            put = getattr(dynlib, f"{prefix}openblas_set_num_threads{suffix}", None)
            if get is not None and put is not None:
                return (get, put), False
    return (lib.get_num_threads, lib.set_num_threads), api == "mkl" or (api == "openblas" and openmp)


def _pools() -> _Pools:
    with _LOCK:
        if not _POOLS:
            found: list[tuple[_Pool, bool]] = []
            try:
                from threadpoolctl import ThreadpoolController
            except ImportError:  # pragma: no cover - a dependency, but optional at run time
                pass
            else:
                import scipy.linalg  # noqa: F401  # load every BLAS the planner uses first
                found = [_pool(lib) for lib in ThreadpoolController().lib_controllers if lib.user_api == "blas"]
            _POOLS.append(_Pools([p for p, local in found if not local], [p for p, local in found if local]))
        return _POOLS[0]


def warm() -> None:
    """Find the BLAS libraries now (about 1 ms, once per process), not in the first limited call."""
    _pools()


_SAVED: list[Any] = []  # the shared pools' thread counts the first open block found
_SHARES: dict[int, int] = {}  # open blocks per thread (by ident; threads may nest or overlap them)
_LOCAL = threading.local()  # depth of the per-thread libraries' blocks, per thread


@dataclass(frozen=True)
class _Hold:
    """What one open block changed: the pools, the opening thread, and the per-thread libraries'
    counts when it was that thread's outermost block (``None`` otherwise)."""

    pools: _Pools
    thread: int
    local_saved: list[Any] | None


def _set_all(pools: list[_Pool], counts: list[Any]) -> None:
    """Set each pool whose count is not 1 to one thread; on an error, the pools already set get
    their counts back before it propagates."""
    done: list[tuple[_Pool, Any]] = []
    try:
        for pool, n in zip(pools, counts, strict=True):
            if n != 1:
                pool[1](1)
                done.append((pool, n))
    except BaseException:
        _put_back([pool for pool, _ in done], [n for _, n in done], quiet=True)
        raise


def _put_back(pools: list[_Pool], counts: list[Any], quiet: bool = False) -> None:
    """Give every pool whose count is not 1 its count back; a library that refuses does not stop
    the others (the first error is raised after them, unless ``quiet``)."""
    error: BaseException | None = None
    for (_, put), n in zip(pools, counts, strict=True):
        if n != 1:
            try:
                put(n)
            except Exception as exc:  # raised below, after the others
                error = error or exc
    if error is not None and not quiet:
        raise error


def _limit() -> _Hold:
    pools = _pools()
    me = threading.get_ident()
    with _LOCK:
        if not _SHARES:
            saved = [get() for get, _ in pools.shared]
            _set_all(pools.shared, saved)
            _SAVED[:] = saved
        _SHARES[me] = _SHARES.get(me, 0) + 1
    local_saved = None
    try:
        if pools.per_thread:
            depth = getattr(_LOCAL, "depth", 0)
            if depth == 0:
                counts = [get() for get, _ in pools.per_thread]
                _set_all(pools.per_thread, counts)
                local_saved = counts
            _LOCAL.depth = depth + 1
    except BaseException:
        _release_shared(pools, me)
        raise
    return _Hold(pools, me, local_saved)


def _release_shared(pools: _Pools, thread: int) -> None:
    with _LOCK:
        left = _SHARES.get(thread, 1) - 1
        if left > 0:
            _SHARES[thread] = left
        else:
            _SHARES.pop(thread, None)
        if not _SHARES:
            _put_back(pools.shared, _SAVED)


def _restore(hold: _Hold) -> None:
    """Close ``hold``. Its per-thread libraries are the opening thread's: closed in another thread
    (a generator finished elsewhere), that part is left as it is (the opening thread's libraries
    stay limited until its outermost block closes there); the shared pools are released anyway."""
    try:
        if hold.pools.per_thread and threading.get_ident() == hold.thread:
            _LOCAL.depth = max(0, getattr(_LOCAL, "depth", 1) - 1)
            if hold.local_saved is not None:
                _put_back(hold.pools.per_thread, hold.local_saved)
    finally:
        _release_shared(hold.pools, hold.thread)


def _fork_prepare() -> None:
    _LOCK.acquire()  # no block half opened or closed in the child


def _fork_parent() -> None:
    _LOCK.release()


def _fork_child() -> None:
    """Only the forking thread lives on: its own blocks stay open, and when it had none the
    shared pools get the counts other threads' blocks had saved."""
    global _LOCK
    me = threading.get_ident()
    mine = _SHARES.get(me, 0)
    if _SHARES and not mine and _POOLS:
        _put_back(_POOLS[0].shared, _SAVED, quiet=True)
    _SHARES.clear()
    if mine:
        _SHARES[me] = mine
    _LOCK = threading.Lock()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(before=_fork_prepare, after_in_parent=_fork_parent, after_in_child=_fork_child)


def serial(fn: _F) -> _F:
    """``fn`` with every call inside :func:`serial_blas` (the public planners)."""
    @functools.wraps(fn)
    def serially(*args: Any, **kwargs: Any) -> Any:
        hold = _limit()
        try:
            return fn(*args, **kwargs)
        finally:
            _restore(hold)
    return serially  # type: ignore[return-value]


@contextlib.contextmanager
def serial_blas() -> Iterator[None]:
    """Run the block with one BLAS thread (module docstring); 6 us to enter and leave in a
    tight loop, 17 us around a plan (colder caches), about 2 % of a plan without SQP steps.
    Blocks may nest or overlap across threads: for the shared pools the first to open saves the
    thread counts and the last to close restores them; a per-thread library is limited and
    restored by each thread's outermost block. A ``KeyboardInterrupt`` that lands inside the
    limit's own bookkeeping (a few lines) can leave a block open: the libraries then stay at
    one thread until the process ends."""
    hold = _limit()
    try:
        yield
    finally:
        _restore(hold)
