"""The loader's fast paths for long recordings (issue 13, "Honest at scale"): each gives the same
rows and numbers as the code it replaces, checked against that code's formula on inputs where the
fast path and its fallbacks are taken, plus the refusals they keep."""

from __future__ import annotations

import sys
import warnings

import numpy as np
import pandas as pd
import pytest

from gearspec.errors import InputError
from gearspec.recording import load_recording
from gearspec.recording.load import _COUNTED_RUN_SPAN, _numeric_column, _run_ids
from gearspec.recording.readers import _release_freed_memory


def _unique(r: np.ndarray):
    """The run numbering the loader used before the counting path: numpy.unique of the ids as integers."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a cast beyond int64 (the last case below)
        return np.unique(r.astype(np.int64), return_inverse=True)


@pytest.mark.parametrize("r", [
    np.repeat(np.arange(40), 50),                      # contiguous runs 0..39 (the usual case: counted)
    np.repeat([7, 3, 9, 3], 5),                       # unsorted, a run id repeated after another
    np.random.default_rng(0).integers(-50, 50, 500),  # negative ids, interleaved
    np.array([5]),                                    # one row
    np.array([0, 1 << 40, 0, 3]),                     # ids spread far apart: sorted, not counted
    np.array([2 ** 60, 1, 2 ** 60]),                  # above 2**53: the old arithmetic, unchanged
    np.array([2.0 ** 70, 1.0, 1.0]),                  # beyond int64: the old (wrapped) cast, unchanged
])
@pytest.mark.parametrize("dtype", [float, np.int64])
def test_run_ids_are_numpy_unique_of_the_integer_ids(r, dtype):
    """Float ids (a column with a NaN somewhere, or written 1.0) and int64 ids as read (no float
    on the way: every id exact, those 0..k-1 their own index) numbered like numpy.unique."""
    if dtype is np.int64 and np.abs(np.asarray(r, dtype=float)).max() >= 2.0 ** 63:
        pytest.skip("not an int64")
    r = np.asarray(r, dtype=dtype)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # the loader's own cast beyond int64 (last case)
        ids, inv = _run_ids("f.csv", r)
    ids0, inv0 = _unique(r)
    # the same arrays, exactly (integers: no tolerance applies)
    assert ids.dtype == ids0.dtype and inv.dtype == inv0.dtype
    np.testing.assert_array_equal(ids, ids0)
    np.testing.assert_array_equal(inv, inv0)


def test_run_ids_spread_far_apart_are_sorted_not_counted():
    # counting would allocate one slot per id between the smallest and the largest: 8 TB here
    span = float(1 << 40)
    assert span > _COUNTED_RUN_SPAN * 4 + 1024
    ids, inv = _run_ids("f.csv", np.array([0.0, span, 0.0, span]))
    np.testing.assert_array_equal(ids, [0, 1 << 40])
    np.testing.assert_array_equal(inv, [0, 1, 0, 1])


@pytest.mark.parametrize("bad", [[0.0, 0.5, 1.0], [2.0 ** 40, 0.25]])
def test_run_ids_refuse_non_integers_naming_file_and_column(bad):
    with pytest.raises(InputError, match=r"f\.csv: column 'run' holds non-integer values"):
        _run_ids("f.csv", np.array(bad))


def test_numeric_columns_are_converted_or_refused_in_one_sentence():
    frame = pd.DataFrame({"b": np.arange(5), "c": ["1", "2.5", " ", "4", "5"]})
    b = _numeric_column("f.csv", frame, "b")
    assert b.dtype == np.float64 and b.tolist() == [0.0, 1.0, 2.0, 3.0, 4.0]
    c = _numeric_column("f.csv", frame, "c")
    assert c.dtype == np.float64 and np.isnan(c.iloc[2]) and c.iloc[1] == 2.5
    frame.loc[3, "c"] = "x"
    with pytest.raises(InputError, match="column 'c', data row 4: 'x' is not a number"):
        _numeric_column("f.csv", frame, "c")


def test_loaded_csv_is_the_file_bit_for_bit(tmp_path):
    """A csv with run ids that are not 0..k-1, an extra integer channel and a text channel loads to
    the values pandas reads (columns as pandas infers them; run ids renumbered in order)."""
    rng = np.random.default_rng(1)
    n = 3000
    run = np.repeat([12, 5, 30], n // 3)
    t = np.tile(np.arange(n // 3) / 1000.0, 3)
    theta = 0.3 + 2.0 * t + 1e-3 * run
    torque = 0.2 + 0.02 * np.sin(5 * theta) + 0.005 * rng.standard_normal(n)
    src = pd.DataFrame({"t": t, "theta": theta, "torque": torque, "run": run,
                        "count": np.arange(n), "state": np.where(t > 0.5, "hold", "move")})
    path = tmp_path / "rec.csv"
    src.to_csv(path, index=False, float_format="%.17g")
    rec = load_recording(path)
    ref = pd.read_csv(path)
    for col in ("t", "theta", "torque"):
        np.testing.assert_array_equal(rec.data[col].to_numpy(), ref[col].to_numpy())
    # runs numbered by their sorted ids: 5 -> 0, 12 -> 1, 30 -> 2
    np.testing.assert_array_equal(rec.data["run"].to_numpy(), np.repeat([1, 0, 2], n // 3))
    assert rec.data["run"].dtype == np.int64
    assert rec.data["count"].dtype == ref["count"].dtype == np.int64
    assert rec.data["state"].tolist() == ref["state"].tolist()


def test_loaded_csv_with_a_bad_cell_is_still_refused_in_one_sentence(tmp_path):
    path = tmp_path / "bad.csv"
    path.write_text("t,theta,torque\n0,0,0.1\n0.001,0.002,oops\n0.002,0.004,0.1\n")
    with pytest.raises(InputError, match="column 'torque', data row 2: 'oops' is not a number"):
        load_recording(path)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's malloc_trim: Linux only")
def test_freed_memory_is_handed_back_on_linux():
    # the trim runs (True) where glibc has it; the memory it returns is measured by the benchmark
    # (bench_cli's peak and resident memory), not here
    assert _release_freed_memory() is True


# ---------------------------------------------------------------------- segments in two threads
def _plateaus():
    from gearspec.gears import load_gear
    from gearspec.simulate import Ripple, plateau_recording

    gear = load_gear("silo4-joint3")
    f_motor = 1 / (2 * np.pi)  # the motor shaft's line, cycles per rad of the motor
    # short plateaus (3000 samples each, far below LS_MAX_SAMPLES): the Lomb-Scargle path
    rec, _ = plateau_recording([40, -40, 80, -80, 120], ripples=[Ripple(f_motor, 1e-3, 0.5), Ripple(1.234, 5e-4, 0.1)],
                               level=0.01, duration=3, fs=1000, noise=1e-4, gear=gear, seed=5)
    return rec


def test_short_segments_get_two_threads_when_two_cpus_may_be_used(monkeypatch):
    import os

    from gearspec.segment import find_segments
    from gearspec.spectrum.analysis import LS_MAX_SAMPLES
    from gearspec.spectrum.pipeline import _n_workers

    seg = find_segments(_plateaus())
    assert len(seg) == 5 and max(s.n for s in seg) < LS_MAX_SAMPLES
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1}, raising=False)
    assert _n_workers("auto", seg) == 2
    from dataclasses import replace

    assert _n_workers("auto", replace(seg, segments=seg.segments[:1])) == 1  # one segment: nothing to share
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0}, raising=False)
    assert _n_workers("auto", seg) == 1        # a process bound to one CPU


def test_two_threads_give_the_numbers_of_one():
    """Each segment's periodogram with one finufft thread inside the pool, with finufft's default
    threads outside it: the JSON must be the same to the last digit (no tolerance: the segments
    are independent and each one's arithmetic is the same)."""
    import json

    from gearspec.spectrum import analyze

    rec = _plateaus()
    one = analyze(rec, workers=1).to_dict()
    two = analyze(rec, workers=2).to_dict()
    assert len(one["segments"]) == 5 and any(p["declared"] for p in one["segments"][0]["peaks"])
    assert json.dumps(one, default=float) == json.dumps(two, default=float)
