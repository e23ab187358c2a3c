"""The cheaper segmentation gives the same numbers as the work it replaces (issue 13, scale):

- :func:`gearspec.segment.derivatives` filters pieces of one length, step and window together
  (``kinematics._savgol_rows``): equal to the filter piece by piece (``_savgol``) bit for bit away
  from the pieces' edges, and at the edges to rounding (scipy fits the edges of all rows as one
  least-squares problem with a right-hand side per row, whose last bits may differ from a solve
  per row); exact on a quadratic position (a Savitzky-Golay filter of order 2 reproduces a parabola);
- :func:`gearspec.segment.find_segments` stops the window ladder once its choice is settled
  (``plateaus._ladder``): the same segmentation as trying every window;
- :func:`gearspec.segment.free_motion` counts free rows before cutting blocks: the count is the rows
  of the blocks;
- the ramp test's cubic (``ramps._cubic_values``) from its four Legendre columns' normal equations:
  numpy's ``legval(x, legfit(x, y, 3))`` to 1e-13 of ``max |y|``, and the same segments;
- the quasi-static gate of a run computes its statistics only as far as the rule reads them
  (``quasistatic._at_rest_statistics(lazy=True)``): the same decision and the same numbers.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from gearspec.recording import Recording
from gearspec.segment import derivatives, find_segments, free_motion
from gearspec.segment import kinematics, plateaus
from gearspec.simulate import plateau_recording


def _recording(pieces) -> Recording:
    """A recording of one run per ``(t, theta)`` piece (torque zero: only positions matter here)."""
    t = np.concatenate([p[0] for p in pieces])
    theta = np.concatenate([p[1] for p in pieces])
    run = np.concatenate([np.full(len(p[0]), i) for i, p in enumerate(pieces)])
    data = pd.DataFrame({"t": t, "theta": theta, "torque": np.zeros(len(t)), "run": run})
    return Recording(data, n_read=len(t))


def _quadratic(n, dt, v, a, t0=0.0, jitter=0.0, seed=0):
    """``theta = v t + a t^2 / 2`` on ``n`` samples of step ``dt`` (s), optionally jittered times."""
    t = t0 + dt * np.arange(n)
    if jitter:
        t = t + jitter * dt * np.random.default_rng(seed).uniform(-1, 1, n)
    tt = t - t0
    return t, v * tt + 0.5 * a * tt * tt


def _per_piece(rec):
    """The reference: the filter of each piece on its own (the code before the change)."""
    t, th = rec.t, rec.theta
    vel = np.full(len(t), np.nan)
    acc = np.full(len(t), np.nan)
    for _, a, b in rec.pieces():
        params = kinematics._filter_params(t[a:b], None)
        if params is not None:
            vel[a:b] = kinematics._savgol(t[a:b], th[a:b], *params, 1)
            acc[a:b] = kinematics._savgol(t[a:b], th[a:b], *params, 2)
    return vel, acc


@pytest.fixture(scope="module")
def mixed():
    """Pieces of one length and step (filtered together), others of another step (0.98 ms: the same
    length and window of 21 samples, another delta; 2 ms: another window), one jittered (the
    per-piece path), one shorter than the filter (NaN), with random noise on every position."""
    rng = np.random.default_rng(3)
    pieces = [_quadratic(600, 1e-3, 0.5 + k, 2.0 - k, t0=10.0 * k) for k in range(5)]
    pieces += [_quadratic(600, 0.98e-3, 0.8, 1.0, t0=60.0)]
    pieces += [_quadratic(600, 2e-3, 1.5, -1.0, t0=100.0), _quadratic(800, 1e-3, -2.0, 0.5, t0=200.0)]
    pieces += [_quadratic(900, 1e-3, 1.0, 0.3, t0=300.0, jitter=0.2), _quadratic(4, 1e-3, 1.0, 0.0, t0=400.0)]
    pieces = [(t, th + 1e-6 * rng.standard_normal(len(th))) for t, th in pieces]
    return _recording(pieces)


def _assert_same(rec, got, ref):
    """Bit for bit except the first and last half-window of each piece; there to rounding: 1e-12 of
    the piece's largest value (a least-squares solve of 21 x 3 on positions scaled to unit norm:
    rounding errors of a few 1e-16 relative; a wrong delta or window is off by percents)."""
    assert np.array_equal(np.isnan(got), np.isnan(ref))
    for _, a, b in rec.pieces():
        params = kinematics._filter_params(rec.t[a:b], None)
        if params is None:
            continue
        half = params[1] // 2
        assert np.array_equal(got[a + half:b - half], ref[a + half:b - half])
        scale = np.max(np.abs(ref[a:b]))
        np.testing.assert_allclose(got[a:b], ref[a:b], rtol=0, atol=1e-12 * scale)


def test_derivatives_equal_the_filter_piece_by_piece(mixed):
    vel, acc = derivatives(mixed)
    ref_v, ref_a = _per_piece(mixed)
    _assert_same(mixed, vel, ref_v)
    _assert_same(mixed, acc, ref_a)
    assert np.isnan(vel[-4:]).all()  # the piece shorter than the filter


def test_derivatives_in_small_stacks_equal_too(mixed, monkeypatch):
    # stacks of at most two pieces of 600 samples: the grouping loop runs over several stacks
    monkeypatch.setattr(kinematics, "_ROWS_SAMPLES", 1300)
    vel, acc = derivatives(mixed)
    ref_v, ref_a = _per_piece(mixed)
    _assert_same(mixed, vel, ref_v)
    _assert_same(mixed, acc, ref_a)


def test_derivatives_of_a_parabola_are_exact():
    # a quadratic least-squares filter reproduces a parabola: only rounding remains (positions of
    # order 1 rad, step 1 ms: velocity error ~1e-16 / 1e-3 * window ~1e-11, acceleration ~1e-8)
    rec = _recording([_quadratic(500, 1e-3, 0.7 + k, 3.0 * (k + 1), t0=5.0 * k) for k in range(4)])
    vel, acc = derivatives(rec)
    for k, (_, a, b) in enumerate(rec.pieces()):
        tt = rec.t[a:b] - rec.t[a]
        np.testing.assert_allclose(vel[a:b], 0.7 + k + 3.0 * (k + 1) * tt, rtol=0, atol=1e-9)
        np.testing.assert_allclose(acc[a:b], 3.0 * (k + 1), rtol=0, atol=1e-6)


def _every_window(one, ladder, n):
    return [one(w) for w in ladder]


@pytest.fixture(scope="module")
def rippled():
    """Plateaus with a slow speed ripple (+-30 % at 2 Hz): on the second, the shortest window finds
    2058 of its 3200 rows, the next two nothing, the 0.2 s window 2925 (it averages the ripple out);
    and clean plateaus, where the ladder stops after its first window."""
    ripple = plateau_recording([2.0, -3.0], duration=6.0, fs=500.0, speed_ripple=0.3, speed_ripple_frequency=2.0,
                               one_run_per_plateau=True, seed=1)[0]
    clean = plateau_recording([1.0, -1.5, 4.0], duration=3.0, fs=500.0, noise=1e-4, one_run_per_plateau=True, seed=2)[0]
    return ripple, clean


def _calls(monkeypatch):
    calls = []
    real = plateaus._segment_piece

    def spy(*args):
        calls.append(args[2])
        return real(*args)

    monkeypatch.setattr(plateaus, "_segment_piece", spy)
    return calls


def test_the_ladder_stops_early_with_the_same_segments(rippled, monkeypatch):
    for rec in rippled:
        fast = find_segments(rec)
        with monkeypatch.context() as m:
            m.setattr(plateaus, "_ladder", _every_window)
            full = find_segments(rec)
        assert [s.to_dict() for s in fast] == [s.to_dict() for s in full]
        assert fast.excluded == full.excluded and fast.settings == full.settings
    calls = _calls(monkeypatch)
    find_segments(rippled[1])
    # clean plateaus: at most three windows per piece tried instead of seven
    assert len(calls) <= 3 * len(rippled[1].pieces())


def test_the_rippled_plateaus_need_the_long_windows(rippled):
    # the case where stopping at the first window that finds segments (or at the first covering
    # much of what was seen so far) would be wrong: a piece's chosen window is a later one
    rec = rippled[0]
    seg = find_segments(rec)
    later = 0
    for run, a, b in rec.pieces():
        t, theta = rec.t[a:b], rec.theta[a:b]
        noise, dt = plateaus._position_noise(theta), float(np.median(np.diff(t)))
        found = [w for w in plateaus._WINDOW_LADDER
                 if (r := plateaus._segment_piece(t, theta, w, 0.15, None, None, 32, noise, dt)) and r[0]]
        chosen = {s.window for s in seg if s.run == run}
        assert len(chosen) == 1
        later += chosen.pop() > found[0]
    assert later >= 1


@pytest.mark.parametrize("motion", ["auto", "free"])
def test_free_rows_counted_are_the_rows_of_the_blocks(motion):
    # ramps between plateaus (auto: too few free rows, the plateaus stay) and every moving row (free)
    rec = plateau_recording([1.0, 3.0, -2.0], duration=2.0, fs=500.0, ramp=1.0, noise=1e-5, seed=4)[0]
    seg = free_motion(rec, find_segments(rec), motion=motion)
    blocks = [s for s in seg if s.kind == "free"]
    if motion == "free":
        assert blocks and seg.settings["free_rows"] == sum(s.n for s in blocks)
    else:
        assert not blocks and seg.settings["free_rows"] > 0 and seg.settings["free_share"] < 0.5
    seg.check_ledger()


def _legendre_values(x, y):
    """The reference: numpy's Legendre fit of degree 3 (SVD of the scaled Vandermonde matrix)."""
    return np.polynomial.legendre.legval(x, np.polynomial.legendre.legfit(x, y, 3))


@pytest.mark.parametrize("n", [5, 6, 40, 977, 4096])
def test_the_cubic_of_the_ramp_test_is_numpys_legendre_fit(n):
    from gearspec.segment import ramps
    rng = np.random.default_rng(n)
    x = np.sort(rng.uniform(-1, 1, n))
    x[0], x[-1] = -1.0, 1.0
    cubic = 680.0 + 3.0 * x - 2.0 * x ** 2 + 5.0 * x ** 3       # a ramp's shape on a large mean speed
    # an exact cubic is reproduced; one with ripple and noise is fitted as numpy fits it
    np.testing.assert_allclose(ramps._cubic_values(x, cubic), cubic, rtol=0, atol=1e-12 * 680.0)
    y = cubic + 0.3 * np.sin(40 * x) + rng.standard_normal(n)
    np.testing.assert_allclose(ramps._cubic_values(x, y), _legendre_values(x, y), rtol=0, atol=1e-13 * np.abs(y).max())


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_the_ramp_test_finds_the_same_segments_with_numpys_fit(seed, monkeypatch):
    # bell tops, creeping tails, cruises and rippled plateaus: every split decision the same
    from gearspec.segment import ramps
    from gearspec.simulate.synthetic import excitation_recording

    recs = [excitation_recording(seed=seed)[0],
            plateau_recording([2.0, -3.0, 0.4], duration=4.0, fs=500.0, speed_ripple=0.12, speed_ripple_frequency=1.5,
                              noise=1e-3, one_run_per_plateau=True, seed=seed)[0]]
    for rec in recs:
        fast = find_segments(rec)
        with monkeypatch.context() as m:
            m.setattr(ramps, "_cubic_values", _legendre_values)
            slow = find_segments(rec)
        assert [s.to_dict() for s in fast] == [s.to_dict() for s in slow] and len(fast) > 0
        assert fast.excluded == slow.excluded


def test_the_lazy_quasi_static_gate_decides_as_the_full_one():
    from gearspec.segment import quasistatic as qs
    from gearspec.simulate.synthetic import excitation_recording, quasi_static_recording

    at_rest = quasi_static_recording(noise=1e-3, dt_spread=0.5, repeat_probability=0.05, seed=1)[0]
    steady = plateau_recording([2.0, -5.0], duration=4.0, fs=500.0, ramp=0.1, one_run_per_plateau=True, seed=2)[0]
    quantised = plateau_recording([0.02, -0.03], duration=2.0, fs=500.0, quantum=2e-5, seed=2)[0]
    idle = _recording([(np.arange(200) * 1e-3, np.zeros(200)), (np.arange(30) * 1e-3, np.linspace(0, 1, 30))])
    seen = {"at rest": 0, "both spreads, out": 0, "one spread": 0, "no spread": 0}
    for rec in (at_rest, steady, quantised, excitation_recording(seed=1)[0], idle):
        for _, a, b in rec.pieces():
            t, th = rec.t[a:b], rec.theta[a:b]
            full, lazy = qs._run_statistics(t, th), qs._run_statistics(t, th, lazy=True)
            assert qs._looks_at_rest(lazy) == qs._looks_at_rest(full)
            assert all(full[k] == v for k, v in lazy.items())     # the same numbers, as far as computed
            if "speed_spread" not in lazy:
                seen["no spread"] += 1
            elif lazy["speed_spread"] < qs.QS_MIN_SPEED_SPREAD:
                seen["one spread"] += 1
                assert "step_spread" not in lazy
            else:                       # both spreads needed (at rest, or failing on their ratio)
                seen["at rest" if qs._looks_at_rest(full) else "both spreads, out"] += 1
                assert lazy == full
    # each way out of the rule taken: a map at rest; plateaus (steady speeds: one percentile of two);
    # slow quantised plateaus and moves (speeds spread by the staircase or the motion: both, out on
    # their ratio); a standstill and a run of too few steps (no percentile)
    assert all(seen.values()), seen
