"""gearspec.core.parallel.forked_map: the results of the loop, in order, from worker processes."""

import os

import numpy as np
import pytest

from gearspec.core import parallel
from gearspec.core.parallel import forked_map, in_worker, worker_count

fork_only = pytest.mark.skipif(parallel.can_fork() is False, reason="no fork on this system")


def _lstsq_task(seed):
    # a small least-squares fit, as a search runs thousands of: the same numbers in a worker
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(400, 12))
    y = X @ np.arange(12.0) + rng.normal(size=400)
    return np.linalg.lstsq(X, y, rcond=None)[0], os.getpid()


@fork_only
def test_results_are_the_loops_in_order_from_two_processes():
    from gearspec.core.reduction import one_blas_thread

    with one_blas_thread():
        serial = [_lstsq_task(s)[0] for s in range(12)]
    got = forked_map(_lstsq_task, range(12), workers=2)
    for a, (b, _) in zip(serial, got):
        assert np.array_equal(a, b)          # bit for bit: the same products on one BLAS thread
    assert os.getpid() not in {pid for _, pid in got}


@fork_only
def test_two_workers_run_at_once():
    # the first two tasks wait for each other: with one process the barrier times out (which worker
    # takes how many tasks depends on the machine's load, so the pids alone prove nothing)
    import multiprocessing

    barrier = multiprocessing.get_context("fork").Barrier(2, timeout=60)
    got = forked_map(lambda k: (barrier.wait(), os.getpid())[1], range(2), workers=2)
    assert len(set(got)) == 2 and os.getpid() not in got


def test_one_worker_or_one_item_is_a_loop_here():
    assert {pid for _, pid in forked_map(_lstsq_task, range(3), workers=1)} == {os.getpid()}
    assert forked_map(_lstsq_task, [5], workers=2)[0][1] == os.getpid()
    assert forked_map(_lstsq_task, [], workers=2) == []


@fork_only
def test_a_closure_over_local_data_is_not_pickled():
    big = np.arange(1000.0)
    fn = lambda k: float(big[k] * 2)    # noqa: E731  (a lambda cannot be pickled: it is inherited)
    assert forked_map(fn, range(5), workers=2) == [0.0, 2.0, 4.0, 6.0, 8.0]


@fork_only
def test_a_map_inside_a_task_runs_in_that_worker():
    def outer(k):
        inner = forked_map(lambda j: os.getpid(), range(3), workers=2)
        return in_worker(), worker_count(2), set(inner) == {os.getpid()}

    assert forked_map(outer, range(2), workers=2) == [(True, 1, True)] * 2
    assert not in_worker()


@fork_only
def test_an_exception_in_a_task_is_raised_here_and_the_map_ends():
    def boom(k):
        if k == 3:
            raise ValueError("task 3 failed")
        return k

    with pytest.raises(ValueError, match="task 3 failed"):
        forked_map(boom, range(6), workers=2)
    assert parallel._JOB is None
    assert forked_map(lambda k: k + 1, range(3), workers=2) == [1, 2, 3]


def test_the_worker_count_follows_gearspec_threads(monkeypatch):
    monkeypatch.setenv("GEARSPEC_THREADS", "1")
    assert worker_count() == 1
    monkeypatch.setenv("GEARSPEC_THREADS", "2")
    assert worker_count() == (2 if parallel.can_fork() else 1)
    with pytest.raises(Exception, match="threads"):
        worker_count(0)


def test_a_bad_worker_count_is_refused_where_fork_is_missing_too(monkeypatch):
    # without fork every map is a loop, but a bad count is still the caller's error, said the same way
    monkeypatch.setattr(parallel, "can_fork", lambda: False)
    assert worker_count(2) == 1
    for bad in (0, -1, 1.5, True):
        with pytest.raises(Exception, match="threads"):
            worker_count(bad)


def _map_in_daemon(q):
    try:
        q.put(("ok", forked_map(lambda k: k * k, range(4), workers=2)))
    except Exception as exc:      # pragma: no cover - what the test reports when the rule is missing
        q.put(("error", repr(exc)))


@fork_only
def test_a_map_in_a_daemonic_process_runs_there():
    # a Dask worker (gearspec batch) is a daemonic process: it may not have children, so its maps
    # run in a loop ("daemonic processes are not allowed to have children" otherwise)
    import multiprocessing

    ctx = multiprocessing.get_context("fork")
    q = ctx.Queue()
    p = ctx.Process(target=_map_in_daemon, args=(q,), daemon=True)
    p.start()
    got = q.get(timeout=60)
    p.join(timeout=60)
    assert got == ("ok", [0, 1, 4, 9])
