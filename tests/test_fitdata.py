"""FitData: quasi-static points and plateau averages against hand-computed values."""

import math

import numpy as np
import pytest

from gearspec.fitdata import FitData


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
    p = data.plateaus()
    assert p.loc[0, "level"] == 1.5 and p.loc[0, "n"] == 16 and p.loc[0, "speed"] == 0.5
    assert p.loc[0, "level_se"] == pytest.approx(1 / (2 * math.sqrt(7)), rel=1e-12)
    # two blocks: means 1 and 2, se = (1/sqrt 2) / sqrt 2 = 0.5
    assert data.plateaus(blocks=2).loc[0, "level_se"] == pytest.approx(0.5, rel=1e-12)
