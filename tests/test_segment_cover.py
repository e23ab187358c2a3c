"""Long constant-speed plateaus are covered whole (issue 13: "nothing lost silently").

A plateau whose position is a straight line to round-off (noise-free positions, as a simulation
or an integrated command writes them) has no scatter in the middle of its segment: the
straight-line band of ``ramps._trim_to_line`` used to be round-off wide, and the round-off's own
random walk (1e-13 of the travel, from summing the speed) then trimmed up to 40 % of a 25 s
plateau as "transient".  The band is now at least the piece's position noise
(``ramps._LINE_NOISE``).  (A quantised position is rounded to whole counts, which ends the random
walk: exactly quantised lines were not cut.)"""

from __future__ import annotations

import numpy as np
import pytest

from gearspec.segment import find_segments
from gearspec.segment import ramps
from gearspec.simulate import plateau_recording

RPM = 2 * np.pi / 60


@pytest.fixture(scope="module")
def long_plateaus():
    """Three plateaus of 24.6 s at 1 kHz (the 10^7-row benchmark's), one run each, noise-free
    positions.  Before the floor the segments held 19 785 of 505.7 rpm's 24 600 plateau rows and
    20 745 of 6500 rpm's (11 rpm: all but the 20 edge rows)."""
    speeds = [505.7 * RPM, -6500 * RPM, 11.0 * RPM]
    return plateau_recording(speeds, level=0.008, duration=24.6, fs=1000.0, noise=3e-4,
                             one_run_per_plateau=True, seed=13)


def _held_cover(rec, seg, truth):
    t, run = rec.t, rec.run
    inside = np.zeros(len(rec), bool)
    for s in seg:
        inside[s.start:s.stop] = True
    out = []
    for tr in truth:
        rows = (run == tr["run"]) & (t >= tr["t0"] - 1e-9) & (t <= tr["t1"] + 1e-9)
        out.append((int((inside & rows).sum()), int(rows.sum())))
    return out


def test_long_noise_free_plateaus_are_covered_to_their_edges(long_plateaus):
    rec, truth = long_plateaus
    seg = find_segments(rec)
    seg.check_ledger()
    assert len(seg) == 3
    for (covered, rows), tr in zip(_held_cover(rec, seg, truth), truth):
        # 24 600 held rows; the 20 ms window (4 blocks of 5 rows) cannot tell the blocks within a
        # window of each ramp: 10 rows at each end, nothing more
        assert rows == 24_600
        assert covered == 24_580, (tr["speed"] / RPM, covered)
    # the rows outside segments are the 0.2 s ramps (400 per run) and those 20 edge rows; the 15 rows
    # of the ramp down joined to the last 10 are a piece too short to be a plateau
    assert sum(s.n for s in seg) == 3 * 24_580
    assert dict(seg.excluded) == {"transient": 3 * 395, "short_plateau": 3 * 25}


def test_a_shorter_cut_loses_nothing_either():
    # the same speeds for 1.5 s: length was not the cause (before: 1255 of 4247 rpm's 1500 rows)
    speeds = [4247.0 * RPM, -2774.9 * RPM, 1184.6 * RPM]
    rec, truth = plateau_recording(speeds, level=0.008, duration=1.5, fs=1000.0, noise=3e-4,
                                   one_run_per_plateau=True, seed=13)
    seg = find_segments(rec)
    for covered, rows in _held_cover(rec, seg, truth):
        assert rows == 1500 and covered >= 1480, covered


def test_the_band_floor_is_the_position_noise():
    # rows 0-999 on a line; the first 100 rows 1e-9 off it (round-off scale): without a floor the
    # band is set by the middle (exactly on the line: 1e-12) and cuts the first 100 rows; a noise
    # of 1e-6 keeps them; a 1e-6 rad step (one noise) is cut again only above the band
    t = np.arange(1000) * 1e-3
    theta = 2.0 * t
    theta[:100] += 1e-9
    assert ramps._trim_to_line(t, theta, 0, 1000, 4) == (100, 1000)
    assert ramps._trim_to_line(t, theta, 0, 1000, 4, noise=1e-6) == (0, 1000)
    theta[:100] += 2e-6
    assert ramps._trim_to_line(t, theta, 0, 1000, 4, noise=1e-6) == (100, 1000)
