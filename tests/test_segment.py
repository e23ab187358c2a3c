"""Constant-speed segments: found from position, per direction, tolerant of ripple and ramps."""

import math

import numpy as np
import pytest

from gearspec.errors import InputError
from gearspec.recording import Recording
from gearspec.segment import derivatives, find_segments, friction_torque
from gearspec.simulate import Ripple, plateau_recording


def _match(segs, truth):
    """For each true plateau, the segment with the same direction whose centre time lies in it."""
    out = []
    for tr in truth:
        hits = [s for s in segs if s.direction == tr["direction"] and s.run == tr["run"]]
        out.append(hits)
    return out


def test_plateaus_found_per_direction_with_ripple_and_ramps():
    speeds = [2.0, 5.0, 11.0, -2.0, -5.0, -11.0]
    rec, truth = plateau_recording(speeds, ripples=[Ripple(0.8, 0.05)], level=0.3, duration=3.0, fs=1000,
                                   ramp=0.25, speed_ripple=0.08, noise=0.01, seed=3)
    seg = find_segments(rec)
    assert len(seg) == len(speeds)
    t = rec.t
    v = np.gradient(rec.theta, t)
    for s, tr in zip(sorted(seg, key=lambda s: s.start), truth):
        assert s.direction == tr["direction"]
        assert s.speed == pytest.approx(tr["speed"], rel=0.01)       # mean speed, under a ripple of 8 %
        t0, t1 = t[s.start], t[s.stop - 1]
        # a segment may take in the last few % of a ramp (within the speed tolerance of 15 %, with
        # the 8 % ripple on top), never more
        ramp_part = (t[s.start:s.stop] < tr["t0"]) | (t[s.start:s.stop] > tr["t1"])
        if ramp_part.any():
            assert np.all(np.abs(np.abs(v[s.start:s.stop][ramp_part]) / tr["speed"] - 1) < 0.15 + 0.08)
        assert (t1 - t0) >= 0.85 * (tr["t1"] - tr["t0"])                # and most of the plateau
    seg.check_ledger()
    assert sum(s.n for s in seg) + sum(seg.excluded.values()) == len(rec)


def test_segments_never_straddle_runs_and_ledger_holds():
    rec, truth = plateau_recording([3.0, -3.0, 6.0], ripples=[], level=0.2, duration=1.5, fs=500,
                                   one_run_per_plateau=True, noise=0.005, seed=1)
    seg = find_segments(rec)
    run = rec.run
    for s in seg:
        assert np.all(run[s.start:s.stop] == s.run)
    assert sorted({s.run for s in seg}) == [0, 1, 2]
    seg.check_ledger()


def test_slow_ramp_is_not_one_plateau():
    # speed creeping from 1 to 2 rad/s over 20 s, then a true plateau at 2 rad/s
    fs = 500
    t = np.arange(0, 30, 1 / fs)
    v = np.where(t < 20, 1 + t / 20, 2.0)
    theta = np.cumsum(v) / fs
    rec = Recording.from_arrays(t=t, theta=theta, torque=0.1 + 0.001 * np.sin(t))
    tol = 0.1
    seg = find_segments(rec, rel_tol=tol)
    # the true plateau is found, whole: it may take in the end of the ramp only where the speed is
    # within tol / 2 of 2 rad/s (half the drift a segment may hold: v >= 1.9 from t = 18 s), and
    # loses at most the shortest segment (0.1 s) at either end
    (p,) = [s for s in seg if t[s.start] <= 25.0 <= t[s.stop - 1]]
    assert 18.0 <= t[p.start] <= 20.1 and t[p.stop - 1] >= 30 - 1 / fs - 0.1
    # its mean speed: 2 rad/s, less at most 0.5 % (2 s of the ramp's last 5 % in 12 s)
    assert p.speed == pytest.approx(2.0, rel=0.005)
    # no segment inside the ramp spans more than a third of the tolerance (segment.py step 5: a run
    # whose speed curve spans more than rel_tol / 3 is a ramp and is split until shown flat)
    for s in seg:
        if s is p:
            continue
        assert t[s.stop - 1] <= 20.0
        vs = v[s.start:s.stop]
        assert vs.max() / vs.min() < 1 + tol / 3, (t[s.start], t[s.stop - 1], vs.min(), vs.max())


def test_stick_slip_plateau_with_long_window():
    # a drive that sticks and slips 4 times a second around a mean of 0.05 rad/s
    fs = 1000
    t = np.arange(0, 8, 1 / fs)
    v = 0.05 * (1 + 0.9 * np.sign(np.sin(2 * np.pi * 4 * t)))
    v[t < 1] = 0.05 * t[t < 1]  # start from rest
    theta = np.cumsum(v) / fs
    rec = Recording.from_arrays(t=t, theta=theta, torque=0.1 + 0.001 * np.sin(t))
    seg = find_segments(rec)
    assert len(seg) == 1
    s = seg.segments[0]
    assert s.speed == pytest.approx(0.05, rel=0.03)
    assert s.window >= 0.5                       # a long window averaged the stick-slip
    assert rec.t[s.stop - 1] - rec.t[s.start] > 5.0


def test_derivatives_and_inertia_removal():
    fs = 1000
    t = np.arange(0, 4, 1 / fs)
    theta = 3 * t + 0.2 * np.sin(2 * np.pi * 2 * t)
    acc_true = -0.2 * (2 * np.pi * 2) ** 2 * np.sin(2 * np.pi * 2 * t)
    J = 0.01
    tau = 0.5 + J * acc_true
    rec = Recording.from_arrays(t=t, theta=theta, torque=tau, gear={"name": "g", "inertia": J})
    vel, acc = derivatives(rec)
    inner = slice(50, -50)
    # a quadratic Savitzky-Golay fit over 21 ms errs by ~(omega h)^2 / 6 of the oscillating part:
    # (2 pi 2 Hz x 10 ms)^2 / 6 = 0.3 %; allow 0.5 %
    v_osc = 0.2 * 2 * np.pi * 2
    assert np.max(np.abs(vel[inner] - (3 + v_osc * np.cos(2 * np.pi * 2 * t[inner])))) < 0.005 * v_osc
    assert np.max(np.abs(acc[inner] - acc_true[inner])) < 0.005 * np.max(np.abs(acc_true))
    f = friction_torque(rec)
    assert np.max(np.abs(f[inner] - 0.5)) < 0.005 * J * np.max(np.abs(acc_true))


def test_bad_options_are_refused():
    rec, _ = plateau_recording([1.0], level=0.1, duration=1.0, fs=200, noise=0.001)
    with pytest.raises(InputError, match="rel_tol"):
        find_segments(rec, rel_tol=1.5)
    with pytest.raises(InputError, match="window"):
        find_segments(rec, window=-1)


@pytest.mark.realdata
def test_emps_plateaus_both_directions(data_dir):
    from gearspec.recording import load_recording

    rec = load_recording(data_dir / "emps" / "DATA_EMPS.mat", "emps", map="theta=qm,torque=vir", scale="torque=gtau")
    seg = find_segments(rec)
    for d in (1, -1):
        speeds = sorted(s.speed for s in seg if s.direction == d)
        for target in (0.04, 0.08, 0.12):
            near = [v for v in speeds if abs(v - target) < 0.2 * target]
            assert len(near) >= 4, (d, target, speeds)   # four cycles of the profile
    seg.check_ledger()


def test_friction_torque_by_segment_equals_the_whole_recording():
    from gearspec.segment import FrictionTorque

    fs = 1000
    t = np.arange(0, 12, 1 / fs)
    theta = 3 * t + 0.2 * np.sin(2 * np.pi * 2 * t) + 0.01 * t**2
    tau = 0.5 + np.random.default_rng(0).normal(0, 0.01, t.size)
    run = (t > 6).astype(int)
    rec = Recording.from_arrays(t=t, theta=theta, torque=tau, run=run, gear={"name": "g", "inertia": 0.01})
    whole = friction_torque(rec)
    ft = FrictionTorque(rec)
    for a, b in [(0, 100), (50, 5000), (5990, 6000), (6000, 6010), (6000, 12000), (7345, 9000), (11995, 12000)]:
        assert np.array_equal(ft[a:b], whole[a:b]), (a, b)
    # sampling that jitters: the piece is resampled to a uniform grid first, as friction_torque does
    t2 = t + np.random.default_rng(1).uniform(0, 0.3 / fs, t.size)
    rec2 = Recording.from_arrays(t=t2, theta=theta, torque=tau, gear={"name": "g", "inertia": 0.01})
    assert np.array_equal(FrictionTorque(rec2)[100:5000], friction_torque(rec2)[100:5000])
    # no inertia: the drive torque itself
    rec3 = Recording.from_arrays(t=t, theta=theta, torque=tau)
    assert np.array_equal(FrictionTorque(rec3)[10:20], tau[10:20])


def test_windows_in_threads_give_the_same_segments():
    rec, _ = plateau_recording([2.0, -5.0, 11.0], ripples=[Ripple(0.8, 0.05)], level=0.3, duration=2.0, fs=1000,
                               ramp=0.25, speed_ripple=0.08, noise=0.01, seed=4)
    one, two = find_segments(rec, workers=1), find_segments(rec, workers=2)
    assert one.segments == two.segments and one.excluded == two.excluded and len(one) == 3
    with pytest.raises(InputError, match="workers"):
        find_segments(rec, workers=0)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_no_segment_on_ramps_bell_tops_or_creeping_tails(seed):
    # an industrial axis moved by excitation trajectories (4 ms): minimum-jerk moves, a move with a
    # genuine 1.5 rad/s cruise between half-cosine ramps, a windowed sum of sines; every move ends
    # in a creeping tail from 0.2 rad/s to rest
    from gearspec.simulate.synthetic import excitation_recording

    rec, truth = excitation_recording(seed=seed)
    v = np.abs(truth["velocity"])
    seg = find_segments(rec)
    seg.check_ledger()
    t = rec.t
    rel_tol = 0.15
    for s in seg:
        vs = v[s.start:s.stop]
        # constant speed over the whole segment: the true speed stays within the third of the
        # tolerance the smooth-speed rule allows a plateau (the rest is for ripple, which has none here)
        assert (vs.max() - vs.min()) / s.speed < rel_tol / 3, (s, vs.min(), vs.max())
        assert np.all(np.abs(vs / s.speed - 1) < rel_tol / 3)
        for t0, t1 in truth["tails"]:
            assert t[s.stop - 1] < t0 or t[s.start] > t1, ("segment on a creeping tail", s)
    # the genuine cruises are kept, nearly whole
    for t0, t1, speed in truth["cruise"]:
        hits = [s for s in seg if t[s.start] < t1 and t[s.stop - 1] > t0]
        assert len(hits) == 1 and hits[0].speed == pytest.approx(speed, rel=0.005)
        assert t[hits[0].stop - 1] - t[hits[0].start] > 0.9 * (t1 - t0)


def test_sweeps_see_a_reversal_at_the_second_row():
    # hand-traced: a log that starts one step before a turning point.  Rows 0-1 go one way by more
    # than the hysteresis tol, then the motion reverses; the turning row (1) ends the first sweep
    # (exact integer positions: no tolerance involved)
    from gearspec.segment.quasistatic import _sweeps
    assert _sweeps(np.array([0.0, 5.0, 4.0, 3.0, 2.0, 1.0]), 0.5) == [(0, 2, 1), (2, 6, -1)]
    assert _sweeps(np.array([0.0, -1.0, 0.0, 1.0, 2.0]), 0.5) == [(0, 2, -1), (2, 5, 1)]
    # a return smaller than tol right after the first row is jitter: one sweep
    assert _sweeps(np.array([0.0, 0.3, 0.1, 1.0, 2.0]), 0.5) == [(0, 5, 1)]
    # every row in one sweep: the bounds tile the rows
    assert _sweeps(np.array([0.0, 1.0, 0.0, -1.0, 0.0, 1.0, 2.0]), 0.5) == [(0, 2, 1), (2, 4, -1), (4, 7, 1)]


def test_rest_is_counted_as_standstill_and_the_ramps_as_transient():
    # 2 s at rest, 0.5 s ramp up, 3 s at 2 rad/s, 0.5 s ramp down, 2 s at rest (1 kHz, position
    # noise 1 urad): 4000 rows at rest, 1000 on ramps, one plateau at rows 2500-5500.  Tolerance
    # 100 rows: the chosen window is 20 ms (4 blocks of 5 rows); a window straddling a rest/ramp
    # boundary is neither, at most two windows (40 rows) per boundary, two boundaries per class
    fs = 1000.0
    v = np.concatenate([np.zeros(2000), np.linspace(0, 2, 500), np.full(3000, 2.0), np.linspace(2, 0, 500),
                        np.zeros(2000)])
    rng = np.random.default_rng(0)
    t = np.arange(len(v)) / fs
    theta = 0.3 + np.cumsum(v) / fs + 1e-6 * rng.standard_normal(len(t))
    rec = Recording.from_arrays(t=t, theta=theta, torque=0.1 + 0.01 * rng.standard_normal(len(t)))
    seg = find_segments(rec)
    (only,) = list(seg)
    assert only.direction == 1 and abs(only.start - 2500) <= 20 and abs(only.stop - 5500) <= 20
    assert only.speed == pytest.approx(2.0, rel=1e-3)
    assert abs(seg.excluded["standstill"] - 4000) <= 100
    assert abs(seg.excluded["transient"] + seg.excluded["short_plateau"] - 1000) <= 100
    assert seg.n_rows == 8000 == sum(s.n for s in seg) + sum(seg.excluded.values())


def test_position_noise_of_a_long_log_from_chunks():
    # 200 000 rows (more than 20 chunks of 5000: the estimate reads chunks spread over the log)
    from gearspec.segment.plateaus import _position_noise
    n = 200_000
    rng = np.random.default_rng(1)
    # at rest with white noise 1e-4 rad: second differences have sd 1e-4 sqrt(6); the MAD estimate
    # from 100 000 of them is within ~0.5 % (1 sd): 3 % tolerance
    assert _position_noise(0.3 + 1e-4 * rng.standard_normal(n)) == pytest.approx(1e-4, rel=0.03)
    # a 16-bit encoder creeping at 0.1 count per row: no second-difference noise (the median of
    # |d2| is 0); the floor is the quantum q / sqrt(12), q the smallest step, exactly
    q = 2 * np.pi / 2 ** 16
    theta = np.round((0.3 + 0.1 * q * np.arange(n)) / q) * q
    assert _position_noise(theta) == pytest.approx(q / math.sqrt(12), rel=1e-9)


def test_quasi_static_sweep_speed_is_travel_over_time_between_its_end_rows():
    # a position map (rows stored at rest after each step, 13 ms median step): each quasi-static
    # sweep's speed is |theta(last row) - theta(first row)| / (t(last row) - t(first row)), to rounding
    from gearspec.simulate.synthetic import quasi_static_recording
    gear = {"name": "bare motor", "stages": [{"name": "cogging", "kind": "other", "ratio": 1.0, "teeth": 6}]}
    rec, _ = quasi_static_recording(ripples=[Ripple(6 / (2 * np.pi), 0.01, 0.3)], levels=(0.05, 0.04), noise=0.002,
                                    dt_spread=0.5, gap_probability=0.03, max_gap=1.0, repeat_probability=0.05,
                                    seed=1, gear=gear)
    qs = [s for s in find_segments(rec) if s.kind == "quasi_static"]
    assert [s.direction for s in qs] == [1, -1]
    for s in qs:
        travel = abs(rec.theta[s.stop - 1] - rec.theta[s.start])
        assert s.speed == pytest.approx(travel / (rec.t[s.stop - 1] - rec.t[s.start]), rel=1e-12)
