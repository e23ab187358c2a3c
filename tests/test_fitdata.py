"""FitData: quasi-static points and plateau averages against hand-computed values."""

import math
from collections import Counter

import numpy as np
import pytest

from gearspec.fitdata import FitData
from gearspec.recording import Recording
from gearspec.segment import Segment, Segmentation


def test_points_are_one_segment_each_and_plateaus_sort_by_direction_then_speed():
    # five operating points (Lola/CROPS style), given in no order; y has the sign of the motion
    v = [3.0, -1.0, 1.0, -3.0, 2.0]
    y = [0.30, -0.12, 0.10, -0.32, 0.20]
    data = FitData.from_points(v, y, load=[5.0, 6.0, 7.0, 8.0, 9.0])
    assert len(data) == 5 and data.n_segments == 5
    # segment and run ids are integers a user can count and index with
    assert np.bincount(data.groups("run")).tolist() == [5]
    assert np.bincount(data.groups("segment")).tolist() == [1, 1, 1, 1, 1]
    p = data.plateaus()
    # forwards first, then backwards, each by increasing speed; one sample: no standard error
    assert p["direction"].tolist() == [1, 1, 1, -1, -1]
    assert p["speed"].tolist() == [1.0, 2.0, 3.0, 1.0, 3.0]
    assert p["segment"].tolist() == [2, 4, 0, 1, 3]
    assert p["level"].tolist() == [0.10, 0.20, 0.30, 0.12, 0.32]       # friction magnitude
    assert p["load"].tolist() == [7.0, 9.0, 5.0, 6.0, 8.0]
    assert p["run"].tolist() == [0] * 5 and p["n"].tolist() == [1] * 5
    assert p["level_se"].isna().all()


def test_plateau_standard_error_from_eight_block_means():
    # one 16-sample plateau whose friction steps from 1.0 to 2.0 halfway: the 8 block means are
    # 1,1,1,1,2,2,2,2, so level 1.5 and se = std(ddof=1) / sqrt(8) = sqrt(2/7) / sqrt(8) = 1 / (2 sqrt 7)
    # (exact up to rounding: rel 1e-12)
    y = np.repeat([1.0, 2.0], 8)
    data = FitData(theta=None, v=np.full(16, 0.5), y=y)
    # without segment and run ids: one segment of one run, integer ids a user can count with
    assert np.bincount(data.groups("segment")).tolist() == [16]
    assert np.bincount(data.groups("run")).tolist() == [16]
    assert data.direction.tolist() == [1] * 16
    p = data.plateaus()
    assert p.loc[0, "level"] == 1.5 and p.loc[0, "n"] == 16 and p.loc[0, "speed"] == 0.5
    assert p.loc[0, "level_se"] == pytest.approx(1 / (2 * math.sqrt(7)), rel=1e-12)
    # two blocks: means 1 and 2, se = (1/sqrt 2) / sqrt 2 = 0.5
    assert data.plateaus(blocks=2).loc[0, "level_se"] == pytest.approx(0.5, rel=1e-12)


def _two_run_recording(with_velocity=True):
    """Run 0 forwards at 2 rad/s, run 1 backwards at 1 rad/s (100 Hz, 2 s each), with a logged
    velocity carrying a 5 % ripple, an output load, and a drive torque that is a friction of 0.3 Nm
    plus the load carried to the motor through a ratio 2 (|load| / 2, against the motion)."""
    t1 = np.arange(200) / 100.0
    d = np.repeat([1.0, -1.0], 200)
    ripple = 1 + 0.05 * np.sin(2 * np.pi * 3 * t1)
    vel = np.concatenate([2.0 * ripple, -1.0 * ripple])
    load = np.concatenate([4.0 + t1, -(3.0 + t1)])
    rec = Recording.from_arrays(t=np.concatenate([t1, t1 + 3.0]), theta=np.concatenate([2.0 * t1, 4.0 - t1]),
                                torque=d * (0.3 + np.abs(load) / 2.0), velocity=vel if with_velocity else None,
                                load=load, run=np.repeat([0, 1], 200))
    seg = Segmentation([Segment(0, 20, 180, 1, 2.0), Segment(1, 220, 380, -1, 1.0)], Counter({"transient": 80}), 400)
    seg.check_ledger()
    return rec, seg, vel, load


def test_from_recording_velocity_choice_and_load_carried_to_the_motor():
    rec, seg, vel, load = _two_run_recording()
    rows = np.r_[20:180, 220:380]
    data = FitData.from_recording(rec, seg, load_ratio=2.0)
    # the segment's mean velocity by default; y = tau - d |load| / 2: the 0.3 Nm friction, exact up
    # to rounding of values ~4 Nm (1e-12)
    assert data.v.tolist() == [2.0] * 160 + [-1.0] * 160
    np.testing.assert_allclose(data.y, np.repeat([0.3, -0.3], 160), rtol=0, atol=1e-12)
    assert data.load.tolist() == load[rows].tolist() and data.run.tolist() == [0] * 160 + [1] * 160
    assert any("|load| / 2 against the motion" in n for n in data.notes)
    p = data.plateaus()
    assert p["level"].tolist() == pytest.approx([0.3, 0.3], abs=1e-12)
    assert p["speed"].tolist() == [2.0, 1.0] and p["run"].tolist() == [0, 1]
    # velocity="measured": the logged velocity channel itself, ripple included
    measured = FitData.from_recording(rec, seg, velocity="measured", load_ratio=2.0)
    assert measured.v.tolist() == vel[rows].tolist()
    np.testing.assert_allclose(measured.y, data.y, rtol=0, atol=0)
    # no velocity channel: the Savitzky-Golay derivative of theta, exact on a straight line
    # (order 2 differentiates it to rounding: 1e-9 rad/s)
    rec2, seg2, _, _ = _two_run_recording(with_velocity=False)
    np.testing.assert_allclose(FitData.from_recording(rec2, seg2, velocity="measured").v,
                               np.repeat([2.0, -1.0], 160), rtol=0, atol=1e-9)


def test_plateau_blocks_follow_time_order_when_segments_interleave():
    # rows of two segments interleaved (as points taken alternately): each segment's blocks are its
    # own rows in time order; segment 0 steps from 1 to 2 halfway, so its se is 1 / (2 sqrt 7)
    # exactly as for a contiguous plateau, and segment 1 (constant 3) has se 0
    n = 2000
    seg = np.tile([0, 1], n // 2)
    y = np.where(seg == 0, np.where(np.arange(n) < n // 2, 1.0, 2.0), 3.0)
    data = FitData(theta=None, v=np.full(n, 0.5), y=y, segment=seg)
    p = data.plateaus().set_index("segment")
    assert p.loc[0, "level_se"] == pytest.approx(1 / (2 * math.sqrt(7)), rel=1e-12)
    assert p.loc[1, "level_se"] == 0.0 and p.loc[1, "level"] == 3.0


def test_no_points_is_refused_in_a_sentence():
    from gearspec.errors import InputError
    with pytest.raises(InputError, match="fit data: no points"):
        FitData.from_points([], [])
