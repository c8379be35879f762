"""Independent simulation tasks spread over worker processes, with results independent of their number.

Simulated products (:mod:`fuelhm_bench.datasets.fleets`, :mod:`fuelhm_bench.datasets.doe`)
are sums of independent pieces: every flight draws its randomness from its own
generator (:func:`fuelhm_bench.flights.fleet.rng_for`), so a batch of flights
gives the same bytes whichever process simulates it and whatever else that
process simulates. :func:`run_ordered` runs such pieces on ``workers``
processes and returns their results **in submission order**, so the
concatenated table is byte-identical for any number of workers (tested in
``tests/test_datasets_parallel.py``).

The workers are forked from this process where the platform allows it (Linux),
so they start with the modules already imported and the numba functions
already compiled or loaded from the numba cache (:func:`warm_up` loads them
first, once); elsewhere they are spawned and load both themselves. The pool
is kept for the process's lifetime (one per number of workers) and shut down
at exit. Inside a process that may not have children (a Dask worker, a
daemon process) or with ``workers=1``, the pieces run in this process, in
order.
"""

from __future__ import annotations

import atexit
import contextlib
import multiprocessing
import os
import sys
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool

from fuelhm_bench.errors import ParameterError

__all__ = ["check_workers", "default_workers", "ensure_pool", "run_concurrently", "run_ordered", "submit", "tune_allocator", "warm_up"]

_POOLS: dict[int, ProcessPoolExecutor] = {}
_WARM = False
_TUNED = False
#: glibc allocator settings of a process building simulated data (:func:`tune_allocator`).
MMAP_THRESHOLD_BYTES = 32 * 2**20
TRIM_THRESHOLD_BYTES = 256 * 2**20


def tune_allocator() -> bool:
    """Keep freed flight-sized arrays in this process's heap instead of returning them to the system (glibc only).

    A batch of flights allocates and frees arrays of one to tens of megabytes many
    times over. With glibc's default policy each is mapped afresh (or the heap is
    trimmed and regrown), and every first write to a page is a page fault: about
    1,900 faults per 25-minute flight and a fifth of the CPU time spent in the
    kernel. Here arrays up to ``MMAP_THRESHOLD_BYTES`` come from the heap and up to
    ``TRIM_THRESHOLD_BYTES`` of free heap is kept for the next batch (about 360
    faults per flight). Only speed changes: no number depends on where memory comes
    from. Called once per process by :func:`run_ordered` and by the workers.

    Returns
    -------
    bool
        Whether the settings were applied (False off glibc, or when already applied).
    """
    global _TUNED
    if _TUNED or not sys.platform.startswith("linux"):
        return False
    _TUNED = True
    import ctypes
    import platform

    if platform.libc_ver()[0] != "glibc":
        return False
    try:
        libc = ctypes.CDLL("libc.so.6")
        m_trim_threshold, m_mmap_threshold = -1, -3  # <malloc.h>
        return bool(libc.mallopt(m_mmap_threshold, MMAP_THRESHOLD_BYTES)) and bool(
            libc.mallopt(m_trim_threshold, TRIM_THRESHOLD_BYTES))
    except (OSError, AttributeError):  # pragma: no cover - no usable libc
        return False


def default_workers() -> int:
    """Number of processes the simulation uses by default: the CPUs this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def check_workers(workers, where: str) -> int:
    """``workers`` as an int >= 1 (None: :func:`default_workers`), or a ParameterError naming ``where``."""
    if workers is None:
        return default_workers()
    if not isinstance(workers, int) or isinstance(workers, bool) or workers < 1:
        raise ParameterError(f"The 'workers' parameter of {where} must be an integer >= 1 or None. "
                             f"Got {workers!r} instead.")
    return workers


def warm_up() -> None:
    """Load (or compile) the simulator's and the extractor's numba functions in this process, once.

    A two-minute flight of one unit, simulated and reduced to indicators: every
    compiled function the fleets use is then in memory, and forked workers
    inherit it instead of each loading it again.
    """
    global _WARM
    if _WARM:
        return
    from fuelhm_bench.datasets.fleets import fleet_indicators
    from fuelhm_bench.flights.fleet import FleetConfig
    from fuelhm_bench.flights.mission import MissionProfile

    fleet_indicators(FleetConfig(n_units=1, n_flights=1, mission=MissionProfile(duration_s=120.0)), workers=1)
    _WARM = True


def _can_have_children() -> bool:
    return not multiprocessing.current_process().daemon


def _pool(workers: int) -> ProcessPoolExecutor:
    pool = _POOLS.get(workers)
    if pool is None:
        if sys.platform == "linux":
            warm_up()
            context = multiprocessing.get_context("fork")
        else:  # pragma: no cover - macOS and Windows start fresh interpreters
            context = multiprocessing.get_context("spawn")
        pool = ProcessPoolExecutor(max_workers=workers, mp_context=context, initializer=_worker_init)
        _POOLS[workers] = pool
    return pool


def ensure_pool(workers: int) -> bool:
    """Start the pool of ``workers`` processes now, if :func:`run_ordered` would use one; returns whether it did.

    A caller that is about to start threads calls it first: the workers are then
    forked before those threads exist (a fork while another thread holds a lock,
    e.g. an import lock, can leave the worker waiting on it for ever).
    """
    if workers <= 1 or not _can_have_children():
        return False
    pool = _pool(workers)
    if getattr(pool, "_executor_manager_thread", True) is None:  # not started: a forking pool forks at its first task
        pool.submit(int)
    return True


def _worker_init() -> None:
    """Workers ignore Ctrl-C: the parent handles it (one message, no partial output) and ends them; like
    the harness, they are not dumpable (sealed methods cannot read their environment or memory)."""
    import signal

    from fuelhm_bench.methods.sandbox import protect_process

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    tune_allocator()
    protect_process()


def _terminate(workers: int) -> None:
    """End a pool now: its processes are killed (their tasks are pure; nothing is lost but work)."""
    pool = _POOLS.pop(workers, None)
    if pool is None:
        return
    for process in list((getattr(pool, "_processes", None) or {}).values()):
        with contextlib.suppress(OSError, AttributeError):  # already gone
            process.kill()
    pool.shutdown(wait=False, cancel_futures=True)


def _shutdown() -> None:
    for workers in list(_POOLS):
        _terminate(workers)


atexit.register(_shutdown)


def run_ordered(fn: Callable, tasks: Sequence[tuple], *, workers: int = 1, sizes: Sequence[int] | None = None,
                progress: Callable[[int], object] | None = None) -> list:
    """``[fn(*t) for t in tasks]``, computed on ``workers`` processes, in the order of ``tasks``.

    Parameters
    ----------
    fn : callable
        A module-level function (picklable); its arguments and result must pickle.
    tasks : sequence of tuple
        Arguments of each call.
    workers : int, default=1
        Processes; 1 (or a process that may not have children): this process, in order.
    sizes : sequence of int, optional
        What each task counts for ``progress`` (e.g. its number of flights); default 1 each.
    progress : callable, optional
        Called with ``sizes[i]`` as each task completes (in completion order).

    Returns
    -------
    list
        The results, in the order of ``tasks``.
    """
    sizes = [1] * len(tasks) if sizes is None else list(sizes)
    tune_allocator()
    if workers <= 1 or len(tasks) <= 1 or not _can_have_children():
        out = []
        for t, n in zip(tasks, sizes):
            out.append(fn(*t))
            if progress is not None:
                progress(n)
        return out
    pool = _pool(workers)
    futures = {pool.submit(fn, *t): i for i, t in enumerate(tasks)}
    results: list = [None] * len(tasks)
    pending = set(futures)
    try:
        while pending:
            finished, pending = wait(pending, return_when=FIRST_COMPLETED)
            for f in finished:
                i = futures[f]
                results[i] = f.result()
                if progress is not None:
                    progress(sizes[i])
    except BaseException as exc:
        if isinstance(exc, BrokenProcessPool) or not isinstance(exc, Exception):
            # A worker died, or Ctrl-C: stop now; the next call starts a new pool. The pool settles its
            # pending futures itself: one cancelled here as well made the pool's own thread fail
            # (InvalidStateError: it marks every pending future broken, Python 3.11).
            _terminate(workers)
        else:
            for f in pending:
                f.cancel()
        raise
    return results


def run_concurrently(calls: Sequence[Callable[[], object]], *, workers: int = 1) -> list:
    """``[call() for call in calls]``, the calls made at once on threads of this process when ``workers`` > 1.

    Meant for builds of independent products whose pieces go to the same pool of
    ``workers`` processes (:func:`run_ordered`): made one after the other, each
    build ends with a tail where one worker waits for the other's last piece, and
    its serial part in this process (joining, fitting, storing) leaves both workers
    idle; made at once, their pieces share one queue and that part overlaps the
    next build's simulation. Each result is the same object as in series (every
    piece is deterministic and :func:`run_ordered` keeps submission order); the
    pool is started before the threads (:func:`ensure_pool`). With ``workers`` <= 1
    (or a process that may not have children) the calls are made in this thread,
    in order. A call's exception is raised here (the first in call order); Ctrl-C
    ends the pool (the threads' pieces fail with it) and is raised here.

    Parameters
    ----------
    calls : sequence of callable
        Zero-argument callables, thread-safe with respect to each other.
    workers : int, default=1
        The pool size the calls use.

    Returns
    -------
    list
        Their results, in the order of ``calls``.
    """
    if len(calls) <= 1 or not ensure_pool(workers):
        return [call() for call in calls]
    import threading

    results: list = [None] * len(calls)
    errors: list = [None] * len(calls)

    def run(i: int) -> None:
        try:
            results[i] = calls[i]()
        except BaseException as exc:  # noqa: BLE001 - handed to the calling thread
            errors[i] = exc

    threads = [threading.Thread(target=run, args=(i,), name=f"fuelhm-build-{i}", daemon=True)
               for i in range(len(calls))]
    for t in threads:
        t.start()
    try:
        for t in threads:
            t.join()
    except BaseException:  # Ctrl-C while waiting: stop the pool's work now; the threads end with it
        _terminate(workers)
        raise
    for exc in errors:
        if exc is not None:
            raise exc
    return results


class _Deferred:
    """A call made when its result is asked for (what :func:`submit` returns without workers)."""

    def __init__(self, fn: Callable, args: tuple) -> None:
        self._fn, self._args = fn, args

    def result(self):
        return self._fn(*self._args)


def submit(fn: Callable, *args, workers: int = 1):
    """Start ``fn(*args)`` on a worker process now; returns an object whose ``result()`` waits for it.

    It queues behind the pieces already submitted to the same pool (so it uses
    a core when one frees). With ``workers=1`` (or no children allowed) the call
    is made in this process when ``result()`` is called.
    """
    if workers <= 1 or not _can_have_children():
        return _Deferred(fn, args)
    return _pool(workers).submit(fn, *args)
