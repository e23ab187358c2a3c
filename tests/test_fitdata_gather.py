"""FitData.from_recording gathers each row array slice by slice and frees its temporaries: the
arrays equal the direct computation (an index array of the segments' rows, the formulas as
written before), on a recording with a quasi-static sweep, a piece too short for the derivative
filter (NaN derivatives inside a segment) and position-locked plateau accelerations."""

import dataclasses
from collections import Counter

import numpy as np
import pandas as pd
import pytest

from gearspec.fitdata import FitData, _gather
from gearspec.gears import load_gear
from gearspec.recording import Recording
from gearspec.segment import Segment, Segmentation
from gearspec.segment.kinematics import fit_derivatives
from gearspec.segment.poslock import plateau_acceleration

J = 2e-6


def _recording():
    rng = np.random.default_rng(7)
    fs = 500.0
    parts, run = [], 0
    for speed, n in ((30.0, 1500), (-12.0, 1200), (0.0, 300), (25.0, 9)):   # the last: 9 rows only
        t = np.arange(n) / fs
        theta = speed * t + 0.002 * np.sin(2 * np.pi * 0.15915494309189535 * speed * t) + rng.normal(0, 1e-5, n)
        if speed == 0.0:                      # a quasi-static sweep: slow, torque against position
            theta = np.linspace(0.0, 0.05, n)
        tau = np.sign(speed) * 0.01 + 1e-4 * rng.normal(size=n)
        parts.append(pd.DataFrame({"t": t, "theta": theta, "torque": tau, "run": run}))
        run += 1
    data = pd.concat(parts, ignore_index=True)
    gear = dataclasses.replace(load_gear("silo4-joint3"), inertia=J)
    return Recording(data=data, gear=gear)


def _segmentation(rec):
    b = np.concatenate(([0], np.cumsum([1500, 1200, 300, 9])))
    segs = [Segment(0, 20, 1480, 1, 30.0), Segment(1, int(b[1]) + 30, int(b[2]) - 30, -1, 12.0),
            Segment(2, int(b[2]), int(b[3]), 1, 0.05 / 0.6, kind="quasi_static"),
            Segment(3, int(b[3]), int(b[4]), 1, 25.0)]
    n_in = sum(s.n for s in segs)
    return Segmentation(segs, Counter({"transient": len(rec.data) - n_in}), len(rec.data))


@pytest.mark.parametrize("velocity", ["segment", "measured"])
@pytest.mark.parametrize("lines", [None, [0.15915494309189535]])
def test_arrays_equal_the_direct_computation(velocity, lines):
    rec, = [_recording()]
    seg = _segmentation(rec)
    got = FitData.from_recording(rec, seg, velocity=velocity, lines=lines)
    # the direct computation: one index array of the rows, every formula on whole arrays
    vel, acc, n_locked, _ = fit_derivatives(rec, seg.segments, lines)
    idx = np.concatenate([np.arange(s.start, s.stop) for s in seg.segments])
    qs = np.repeat([s.kind == "quasi_static" for s in seg.segments], [s.n for s in seg.segments])
    v = np.repeat([s.velocity for s in seg.segments], [s.n for s in seg.segments])
    if velocity == "measured":
        v = np.where(qs, v, vel[idx])
    a = np.where(qs, 0.0, np.nan_to_num(acc[idx]))
    assert np.isnan(acc[idx][~qs]).sum() == 9          # the short piece: no derivative there
    expect = {"theta": rec.theta[idx], "t": rec.t[idx], "run": rec.run[idx], "acc": a, "v": v,
              "y": rec.tau[idx] - J * a,
              "speed": np.where(qs | np.isnan(vel[idx]), np.abs(v), np.abs(vel[idx]))}
    for name, want in expect.items():
        have = getattr(got, name)
        assert have.dtype == want.dtype and have.tobytes() == want.tobytes(), name   # bit for bit
    ns = [s.n for s in seg.segments]
    assert np.array_equal(got.segment, np.repeat(np.arange(4), ns)) and got.segment.dtype == np.int64
    assert np.array_equal(got.group, got.segment) and got.group.dtype == np.int64
    assert got.group is got.segment                      # plateaus only: one array, not two
    assert f"{len(idx)} samples in 4 segments" in got.notes[0]
    assert any("9 rows in segments are in pieces too short" in n for n in got.notes)
    assert (n_locked > 0) == (lines is not None)


def test_gather_is_the_index_gather():
    a = np.arange(50.0) ** 1.5
    segs = [Segment(0, 3, 9, 1, 1.0), Segment(0, 9, 10, 1, 1.0), Segment(1, 30, 44, -1, 2.0)]
    idx = np.concatenate([np.arange(s.start, s.stop) for s in segs])
    assert np.array_equal(_gather(a, segs), a[idx])
    g = _gather(a, segs)
    g[0] = -1.0
    assert a[3] != -1.0                                   # a new array, not a view
    assert _gather(a, []).shape == (0,)


def test_plateau_acceleration_in_place_equals_the_copy():
    rec = _recording()
    seg = _segmentation(rec)
    from gearspec.segment.kinematics import derivatives

    _, acc = derivatives(rec)
    before = acc.copy()
    copy, n1, r1 = plateau_acceleration(rec, seg.segments, [0.15915494309189535], acc)
    assert np.array_equal(acc, before, equal_nan=True)   # not modified without in_place
    same, n2, r2 = plateau_acceleration(rec, seg.segments, [0.15915494309189535], acc, in_place=True)
    assert same is acc and (n1, r1) == (n2, r2) and n1 >= 1
    assert np.array_equal(same, copy, equal_nan=True)
    assert not np.array_equal(copy, before, equal_nan=True)


def test_free_motion_blocks_keep_their_own_held_out_units():
    """Blocks of free motion are held out by their stretch (numbered after the segments): then the
    group array is its own, not the segment ids."""
    rec = _recording()
    seg = _segmentation(rec)
    free = [Segment(s.run, s.start, s.stop, s.direction, s.speed, kind="free", unit=7)
            if i < 2 else s for i, s in enumerate(seg.segments)]
    got = FitData.from_recording(rec, Segmentation(free, seg.excluded, seg.n_rows))
    ns = [s.n for s in free]
    assert np.array_equal(got.group, np.repeat([4 + 7, 4 + 7, 2, 3], ns))
    assert got.group is not got.segment
