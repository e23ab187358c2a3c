"""Stages of ``spectrum`` and ``fit`` run in forked workers on long recordings (issue 13, session
29): the same results as the loop in this process (GEARSPEC_THREADS=1 against 2), and the forked
path is taken where its rule says (so the comparison is not between two loops)."""

from __future__ import annotations

import numpy as np
import pytest

from gearspec.core import parallel
from gearspec.segment import find_segments, plateaus
from gearspec.simulate import plateau_recording


@pytest.fixture(scope="module")
def many_runs():
    """12 plateaus, one run each, 20 s at 1 kHz: 12 pieces, about 250 000 rows."""
    speeds = [0.5, -0.5, 1.0, -1.0, 2.0, -2.0, 4.0, -4.0, 8.0, -8.0, 16.0, -16.0]
    return plateau_recording(speeds, duration=20.0, fs=1000.0, noise=1e-3, one_run_per_plateau=True, seed=3)[0]


def _spy(monkeypatch):
    calls = []
    real = parallel.forked_map

    def spy(fn, items, **kw):
        calls.append(len(list(items)))
        return real(fn, items, **kw)

    monkeypatch.setattr(parallel, "forked_map", spy)
    return calls


def test_segments_forked_equal_serial(many_runs, monkeypatch):
    rec = many_runs
    assert len(rec.pieces()) >= plateaus.FORK_MIN_PIECES and len(rec) >= plateaus.FORK_MIN_ROWS
    monkeypatch.setenv("GEARSPEC_THREADS", "1")
    serial = find_segments(rec)
    calls = _spy(monkeypatch)
    monkeypatch.setenv("GEARSPEC_THREADS", "2")
    forked = find_segments(rec)
    # 12 pieces in chunks of 2 (2 workers x 4 tasks each at most): 6 tasks, in one map
    assert calls == [6]
    assert len(serial) == 12
    assert forked.segments == serial.segments
    assert forked.excluded == serial.excluded and forked.settings == serial.settings
    # each plateau found at its speed (the pieces came back in order)
    speeds = [abs(v) for v in [0.5, -0.5, 1.0, -1.0, 2.0, -2.0, 4.0, -4.0, 8.0, -8.0, 16.0, -16.0]]
    np.testing.assert_allclose([s.speed for s in forked.segments], speeds, rtol=1e-3)
    assert [s.run for s in forked.segments] == list(range(12))


def test_segments_few_pieces_stay_here(many_runs, monkeypatch):
    """Fewer pieces than FORK_MIN_PIECES: no fork (one process's loop)."""
    calls = _spy(monkeypatch)
    monkeypatch.setenv("GEARSPEC_THREADS", "2")
    monkeypatch.setattr(plateaus, "FORK_MIN_PIECES", 13)
    find_segments(many_runs)
    assert calls == []


def test_segments_not_forked_in_daemonic_process(many_runs, monkeypatch):
    """A daemonic process (a Dask worker of ``gearspec batch``) may not fork: the loop here, no error."""
    import multiprocessing

    calls = _spy(monkeypatch)
    monkeypatch.setenv("GEARSPEC_THREADS", "2")
    monkeypatch.setitem(multiprocessing.current_process()._config, "daemon", True)
    seg = find_segments(many_runs)
    assert calls == [] and len(seg) == 12


@pytest.fixture(scope="module")
def fit_data(many_runs):
    from gearspec.fitdata import FitData

    return FitData.from_recording(many_runs, find_segments(many_runs, workers=1))


def test_segment_stats_forked_equal_serial(fit_data, monkeypatch):
    """The segments' statistics (the pass over the samples of every fit) in forked chunks: the same
    numbers as in this process, bit for bit; the forked map is used (chunk rows made small here)."""
    from dataclasses import replace

    from gearspec.core.reduction import one_blas_thread
    from gearspec.identify import stats

    monkeypatch.setattr(stats, "CHUNK_ROWS", 2 ** 14)
    monkeypatch.setattr(stats, "FORK_MIN_ROWS", 2 ** 16)
    freqs = [3.0, 7.5, 11.0]
    sub = fit_data.direction_subset(1)
    calls = _spy(monkeypatch)
    monkeypatch.setenv("GEARSPEC_THREADS", "2")
    stats.segment_stats(replace(sub, cache={}), freqs)   # BLAS on its threads here: the loop
    assert calls == []
    with one_blas_thread():                               # as in ``fit``
        monkeypatch.setenv("GEARSPEC_THREADS", "1")
        serial = stats.segment_stats(replace(sub, cache={}), freqs)
        monkeypatch.setenv("GEARSPEC_THREADS", "2")
        forked = stats.segment_stats(replace(sub, cache={}), freqs)
    assert len(calls) == 1 and calls[0] >= 2
    assert len(serial.segment) == 6
    for name in ("G", "g", "yy", "beta_hat", "rss_hat", "sigma2", "cycles", "speed"):
        np.testing.assert_array_equal(getattr(forked, name), getattr(serial, name), err_msg=name)
    # the constant of each segment's local fit is its mean friction magnitude (no ripple simulated)
    np.testing.assert_allclose(forked.beta_hat[:, 0], 0.01, atol=2e-4)


def test_plateau_acceleration_forked_equal_serial(many_runs, monkeypatch):
    """The position-locked accelerations of the plateaus (``fit``'s derivatives) in forked chunks:
    the same numbers as the loop here (both on one BLAS thread, as ``fit`` runs them)."""
    from gearspec.core.reduction import one_blas_thread
    from gearspec.segment import poslock

    rec = many_runs
    seg = find_segments(rec, workers=1)
    acc0 = np.zeros(len(rec))
    monkeypatch.setattr(poslock, "FORK_MIN_ROWS", 100_000)
    with one_blas_thread():
        monkeypatch.setenv("GEARSPEC_THREADS", "1")
        serial = poslock.plateau_acceleration(rec, seg.segments, [0.5], acc0)
        calls = _spy(monkeypatch)
        monkeypatch.setenv("GEARSPEC_THREADS", "2")
        forked = poslock.plateau_acceleration(rec, seg.segments, [0.5], acc0)
    assert calls == [6]
    assert forked[1:] == serial[1:] and serial[1] == 12
    np.testing.assert_array_equal(forked[0], serial[0])
    # constant speed on every plateau (no ripple simulated): the locked acceleration is about 0
    # there, while the ramps between keep acc0
    rows = np.concatenate([np.arange(s.start, s.stop) for s in seg.segments])
    assert np.abs(forked[0][rows]).max() < 1.0 and np.count_nonzero(forked[0][rows]) > 0.9 * len(rows)
