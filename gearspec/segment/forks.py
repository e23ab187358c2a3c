"""How many forked workers (:func:`gearspec.core.parallel.forked_map`) a stage of ``spectrum`` or
``fit`` may use here."""

from __future__ import annotations

__all__ = ["fork_workers"]


def fork_workers() -> int:
    """:func:`~gearspec.core.parallel.worker_count`, but 1 in a daemonic process: a Dask worker
    (``gearspec batch``) may not have child processes, and a forked map there fails ("daemonic
    processes are not allowed to have children") where the loop in the process works."""
    import multiprocessing

    from ..core.parallel import worker_count

    if multiprocessing.current_process().daemon:
        return 1
    return worker_count()


def on_one_blas_thread_now() -> bool:
    """Whether BLAS runs on one thread here now (as in a forked worker): work whose sums BLAS splits
    by thread count gives a worker's numbers only then, so a map that must equal the loop forks
    only then (``fit`` holds one BLAS thread throughout; other callers keep the loop)."""
    from threadpoolctl import threadpool_info

    return all(i.get("num_threads", 1) == 1 for i in threadpool_info() if i.get("user_api") == "blas")
