"""Independent tasks of one command (a search's law fits, a round's candidates) on the CPUs this
process may use: :func:`forked_map` runs them in worker processes forked from this one, so that a
task may be a closure over the command's data (nothing is pickled on the way in; each result is
pickled once on the way back), and falls back to a plain loop where forking is not possible or
would not pay.  Workers run BLAS on one thread (the tasks are many small products: two processes
on two cores, not four threads contending), and a task's numbers are those of the same task run
in this process on one BLAS thread."""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence

__all__ = ["forked_map", "forked_map_chunked", "worker_count", "in_worker", "can_fork"]

#: set in a worker process: a :func:`forked_map` called from a task runs its tasks in a loop there
_IN_WORKER = False
#: the task and its items, inherited by the workers through ``fork`` (set only while a map runs)
_JOB: tuple | None = None


def in_worker() -> bool:
    """True inside a worker process of :func:`forked_map`."""
    return _IN_WORKER


def worker_count(workers: int | None = None) -> int:
    """Processes a map uses: ``workers`` when given (>= 1), else the CPUs this process may run on
    (:func:`gearspec.terms.lines.default_threads`: ``GEARSPEC_THREADS`` when set); 1 inside a worker,
    in a daemonic process (which may not start children: a Dask worker) and where the system cannot
    ``fork`` (macOS and Windows start processes anew, which costs more than these tasks)."""
    import multiprocessing

    from ..terms.lines import check_threads

    n = check_threads(workers)      # a bad count is refused on every system, not only where fork exists
    # a daemonic process (a Dask worker of ``gearspec batch``) may not have children
    return 1 if (_IN_WORKER or not can_fork() or multiprocessing.current_process().daemon) else n


def can_fork() -> bool:
    """Whether worker processes start here as copies of this one: Linux with the "fork" start
    method (elsewhere a process starts anew and imports everything again)."""
    import multiprocessing

    return sys.platform.startswith("linux") and "fork" in multiprocessing.get_all_start_methods()


def _start_worker() -> None:
    global _IN_WORKER
    _IN_WORKER = True
    from .reduction import one_blas_thread

    one_blas_thread().__enter__()       # for the life of the worker


def _run(i: int):
    fn, items = _JOB
    return fn(items[i])


def forked_map(fn: Callable, items: Sequence, *, workers: int | None = None, min_items: int = 2) -> list:
    """``[fn(x) for x in items]``, in order, computed by :func:`worker_count` processes forked from
    this one (one task at a time to whichever worker is free).  A loop in this process when one
    worker would do, when there are fewer than ``min_items`` items, or inside a worker.  A task
    sees the state of this process at the call and its changes to it are lost: ``fn`` must return
    everything it computes (a picklable value).  An exception in a task is raised here."""
    global _JOB
    items = list(items)
    n = min(worker_count(workers), len(items))
    if n < 2 or len(items) < max(min_items, 2):
        return [fn(x) for x in items]
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    if _JOB is not None:
        raise RuntimeError("forked_map is not reentrant: a map is already running in this process")
    _JOB = (fn, items)
    try:
        with ProcessPoolExecutor(max_workers=n, mp_context=multiprocessing.get_context("fork"),
                                 initializer=_start_worker) as pool:
            return list(pool.map(_run, range(len(items))))
    finally:
        _JOB = None



def forked_map_chunked(fn: Callable, items: Sequence, *, workers: int, tasks_per_worker: int = 4) -> list:
    """``[fn(x) for x in items]``, in order, by :func:`forked_map` over contiguous chunks of
    ``items`` (``tasks_per_worker`` chunks per worker: many small items, one task per chunk); a loop
    here when ``workers`` < 2."""
    if workers < 2:
        return [fn(x) for x in items]
    size = -(-len(items) // (workers * tasks_per_worker))
    chunks = [items[k:k + size] for k in range(0, len(items), size)]
    return [r for part in forked_map(lambda c: [fn(x) for x in c], chunks, workers=workers) for r in part]
