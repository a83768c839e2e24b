"""Serial BLAS for latency-bound calls (a replanning step).

OpenBLAS runs a matrix product above about 2.6e5 multiply-adds on several threads; the
reduction of a QP with a few hundred inequality rows (``G Z``: 175 x 96 by 96 x 33) is just
above. On a loaded machine the calling thread then waits, spinning, for a second core: one
step of the 30 Hz loop took 13-26 ms CPU instead of 8 (``benchmarks/bench_replan.py``). With
one thread the products are computed by the same kernel on the calling thread, and the results
were the same bit for bit on the benchmark's closed-loop runs (row blocking instead of a thread
limit was not: it changes the kernel OpenBLAS picks).

Smaller calls thread too: SciPy's OpenBLAS splits the triangular solve of an SQP step's new
rows (``PerchingQp.least_distance``: 48 rows and more over a 33 x 33 factor) over its threads,
which then spin, waiting for more work, for about 110 ms of a second core's CPU after the call.
Planned back to back, a default ``plan()`` with three SQP steps cost 2.2 ms of its own thread's
CPU and 6.1 ms of the process's, and Gao et al.'s 90 deg perch 4.5 and 8.5 ms, on a 2-core
machine (``benchmarks/bench_rounds.py`` prints both).
The public planners (:func:`serial` below) therefore plan with one BLAS thread too.

:func:`serial_blas` limits the BLAS libraries loaded in the process to one thread for the
duration of a ``with`` block, through ``threadpoolctl`` (a dependency; without it the block does
nothing). The limit is process-wide while it holds: another thread's BLAS call made meanwhile
runs serially too.
"""

from __future__ import annotations

import contextlib
import functools
import threading
from collections.abc import Callable, Iterator
from typing import Any, TypeVar

__all__ = ["serial", "serial_blas", "warm"]

_F = TypeVar("_F", bound=Callable[..., Any])

_LIBS: list[list[Any]] = []  # [the BLAS library controllers of threadpoolctl], found on first use
_LOCK = threading.Lock()


def _blas_libraries() -> list[Any]:
    with _LOCK:
        if not _LIBS:
            try:
                from threadpoolctl import ThreadpoolController
            except ImportError:  # pragma: no cover - a dependency, but optional at run time
                _LIBS.append([])
            else:
                import scipy.linalg  # noqa: F401  # load every BLAS the planner uses first
                _LIBS.append([lib for lib in ThreadpoolController().lib_controllers if lib.user_api == "blas"])
        return _LIBS[0]


def warm() -> None:
    """Find the BLAS libraries now (about 1 ms, once per process), not in the first limited call."""
    _blas_libraries()


_DEPTH = [0]  # blocks open in the process (threads may nest or overlap them)
_SAVED: list[int] = []  # the thread counts the first open block found


def _set_threads(lib: Any, n: int) -> None:
    """``lib.set_num_threads(n)`` from any thread. threadpoolctl (3.6 and later) lets only the
    first thread that sets OpenBLAS's shared pool (the main thread, usually) set it again; other
    threads' calls do nothing, so a replanner stepped in a thread of its own planned with every
    BLAS thread. The pool is process-wide either way: when the call did nothing, the controlling
    thread is released before the call and after it (``clear_controlling_thread``, public API,
    as ``threadpool_limits`` does when it ends)."""
    lib.set_num_threads(n)
    clear = getattr(type(lib), "clear_controlling_thread", None)
    if clear is None or lib.get_num_threads() == n:
        return
    clear(force=True)
    try:
        lib.set_num_threads(n)
    finally:
        clear()


def serial(fn: _F) -> _F:
    """``fn`` with every call inside :func:`serial_blas` (the public planners)."""
    @functools.wraps(fn)
    def serially(*args: Any, **kwargs: Any) -> Any:
        with serial_blas():
            return fn(*args, **kwargs)
    return serially  # type: ignore[return-value]


@contextlib.contextmanager
def serial_blas() -> Iterator[None]:
    """Run the block with one BLAS thread (module docstring); about 4 us to enter and leave
    (the libraries' own get/set calls; ``threadpoolctl``'s ``limit`` context takes 12 us).
    Blocks may nest or overlap across threads: the first to open saves the thread counts, the
    last to close restores them."""
    libs = _blas_libraries()
    with _LOCK:
        if _DEPTH[0] == 0:
            _SAVED[:] = [lib.get_num_threads() for lib in libs]
            for lib, n in zip(libs, _SAVED, strict=True):
                if n != 1:
                    _set_threads(lib, 1)
        _DEPTH[0] += 1
    try:
        yield
    finally:
        with _LOCK:
            _DEPTH[0] -= 1
            if _DEPTH[0] == 0:
                for lib, n in zip(libs, _SAVED, strict=True):
                    if n != 1:
                        _set_threads(lib, n)
