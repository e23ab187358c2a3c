"""Order map and order tracks over varying speed, against synthetic recordings with known answers:
torque = sign(v) (c + b |v|) + A0 exp(-d |v|) sin(2 pi f theta + phi) [+ J thetadd] + white noise,
theta integrated from a ramp or chirp velocity (every number below follows from these)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from gearspec.errors import InputError
from gearspec.recording import Recording
from gearspec.spectrum import MEASURABLE_FRACTION, order_analysis, order_map, order_track

FS = 1000.0      # Hz
TOP = 100.0      # rad/s: spacing 0.1 rad at the top, position Nyquist 5 cycles/rad
F = 1.5          # cycles/rad, below 0.8 x Nyquist at every speed
DECAY = 0.01     # s/rad
A_POS, A_NEG = 0.05, 0.03  # Nm: the two directions differ, so mixing them is seen
SIGMA = 0.02     # Nm white noise


def _velocity(kind: str, T: float, top: float = TOP):
    t = np.arange(int(T * FS)) / FS
    if kind == "ramp":  # 0 -> top -> 0 -> -top -> 0, linear
        v = top * np.interp(t, [0, T / 4, T / 2, 3 * T / 4, T], [0, 1, 0, -1, 0])
    elif kind == "chirp":  # a velocity sine sweeping 0.05 -> 0.3 Hz: many reversals, both directions
        v = top * np.sin(2 * np.pi * (0.05 * t + 0.5 * (0.25 / T) * t**2))
    elif kind == "triangle":  # +-top in 0.25 s (240 rad/s^2 at 60 rad/s): never a constant speed
        v = top * (2 / np.pi) * np.arcsin(np.sin(2 * np.pi * t))
    elif kind == "gap":  # ramps over 2..40 and 60..100 rad/s only (a speed step between them)
        v = np.where(t < T / 2, np.interp(t, [0, T / 2], [2, 40]), np.interp(t, [T / 2, T], [60, 100]))
    else:
        raise ValueError(kind)
    return t, v


def _recording(kind="ramp", T=40.0, seed=0, lines=((F, A_POS, A_NEG, 0.3),), inertia=0.0, sigma=SIGMA,
               velocity=False, top=TOP):
    """A synthetic recording (lines: (f, A0 positive, A0 negative, phase); ``velocity``: with the true
    velocity as its ``velocity`` channel)."""
    rng = np.random.default_rng(seed)
    t, v = _velocity(kind, T, top)
    theta = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) / FS)])
    acc = np.gradient(v, 1 / FS)
    tau = np.sign(v) * (0.3 + 0.002 * np.abs(v)) + inertia * acc + sigma * rng.standard_normal(len(t))
    for f, ap, an, phi in lines:
        tau += np.where(v >= 0, ap, an) * np.exp(-DECAY * np.abs(v)) * np.sin(2 * np.pi * f * theta + phi)
    return Recording.from_arrays(t=t, theta=theta, torque=tau, velocity=v if velocity else None)


def _truth(speed, direction, a_pos=A_POS, a_neg=A_NEG):
    return (a_pos if direction > 0 else a_neg) * np.exp(-DECAY * np.asarray(speed))


# ---------------------------------------------------------------------- order track
def test_track_matches_the_decaying_amplitude_within_its_band_in_both_directions():
    # a pointwise 95 % band covers the truth at 95 % of speeds on average; the errors are smooth in
    # speed (a few independent spline pieces), so one recording covers between ~75 and 100 %: over
    # 6 seeds x 2 directions the mean must reach 90 % (a 2 % relative spline bias or a mixed
    # direction, whose amplitude would be the two directions' blend, fails this by far)
    cover = []
    for seed in range(6):
        rec = _recording(seed=seed)
        for d in (1, -1):
            tr = order_track(rec, F, direction=d, inertia=0)
            ok = np.isfinite(tr.amplitude)
            truth = _truth(tr.speed[ok], d)
            cover.append(np.mean((tr.lower[ok] <= truth) & (truth <= tr.upper[ok])))
            # the band is narrow enough to mean something: under 10 % of the amplitude in the middle
            mid = (tr.speed > 20) & (tr.speed < 80)
            assert np.all(tr.upper[mid] - tr.lower[mid] < 0.1 * _truth(tr.speed[mid], d) * 2)
            assert tr.speed_range[0] < 3 and tr.speed_range[1] > 99
    assert np.mean(cover) >= 0.9, cover
    assert min(cover) >= 0.6, cover


def test_track_from_one_chirp():
    # one chirp (many short moves through zero speed): the amplitude at 50 rad/s within 3 standard
    # errors of the truth and within 10 % (se about 2 % here), per direction
    rec = _recording("chirp", T=60.0, seed=3)
    for d in (1, -1):
        tr = order_track(rec, F, direction=d, inertia=0)
        i = int(np.argmin(np.abs(tr.speed - 50)))
        truth = _truth(tr.speed[i], d)
        assert abs(tr.amplitude[i] - truth) < 3 * tr.amplitude_se[i]
        assert abs(tr.amplitude[i] - truth) < 0.1 * truth


def test_band_width_shrinks_with_more_data():
    # twice the samples at every speed: standard errors / sqrt(2) (0.707; 0.6-0.8 allows for the
    # noise in the residual sd and the amplitude-dependent delta-method term)
    se1 = order_track(_recording(T=40.0, seed=1), F, direction=1, inertia=0).amplitude_se
    se2 = order_track(_recording(T=80.0, seed=2), F, direction=1, inertia=0).amplitude_se
    ratio = float(np.nanmedian(se2 / se1))
    assert 0.6 < ratio < 0.8, ratio


def test_inertia_fitted_jointly():
    # J = 0.002 kg m^2 in the torque; the acceleration of the ramp is +-10 rad/s^2 (0.02 Nm): J is
    # found within 4 standard errors and 20 % (se about 2 % of J), and the line's amplitude is unbiased
    rec = _recording(seed=4, inertia=0.002)
    tr = order_track(rec, F, direction=1, inertia="fit")
    assert tr.inertia_how == "fitted"
    assert abs(tr.inertia - 0.002) < 4 * tr.inertia_se and abs(tr.inertia - 0.002) < 0.2 * 0.002
    i = int(np.argmin(np.abs(tr.speed - 50)))
    assert abs(tr.amplitude[i] - _truth(50, 1)) < 3 * tr.amplitude_se[i]


def test_line_above_the_position_nyquist_is_not_tracked_there():
    # f = 8 cycles/rad is below 0.8 x the Nyquist 0.5 / (v dt) only for v < 0.4 / (8 dt) = 50 rad/s:
    # the track stops there (the block rule uses the 95th-percentile spacing of 256 samples, a
    # little wider than the mean: the edge lies between 45 and 50 rad/s) and is NaN beyond
    f_hi = 8.0
    rec = _recording(seed=5, lines=((F, A_POS, A_NEG, 0.3), (f_hi, 0.04, 0.04, 1.0)))
    tr = order_track(rec, f_hi, direction=1, inertia=0)
    v_edge = MEASURABLE_FRACTION * 0.5 / (f_hi / FS)
    assert 45 < tr.speed_range[1] <= v_edge
    assert np.isnan(tr.at(70.0))
    # the samples left out are those faster than the edge (half the ramp's speeds)
    assert 0.4 < tr.n_above_nyquist / (tr.n + tr.n_above_nyquist) < 0.6
    # where measured, it is right
    i = int(np.argmin(np.abs(tr.speed - 25)))
    assert abs(tr.amplitude[i] - 0.04 * np.exp(-DECAY * tr.speed[i])) < 3 * tr.amplitude_se[i]


def test_speeds_without_samples_are_not_reported():
    # the speeds 40..60 rad/s never occur (the recording's velocity channel steps over them): the
    # grid points there are NaN, not an interpolation
    tr = order_track(_recording("gap", seed=6, velocity=True), F, direction=1, inertia=0)
    inside = (tr.speed > 41) & (tr.speed < 59)
    assert inside.any() and np.all(np.isnan(tr.amplitude[inside])) and np.all(tr.counts[inside] == 0)
    assert np.isfinite(tr.at(30.0)) and np.isfinite(tr.at(80.0))


# ---------------------------------------------------------------------- order map
def test_order_map_cell_holds_the_true_amplitude():
    # windows projected at exactly F and at 3.5 cycles/rad (near the limit at 90 rad/s, where linear
    # interpolation alone reads 30 % low: sinc^2(3.5 x 0.09)), root-mean-square over the windows of a
    # 10 rad/s bin.  A^2 varies by +-10 % across a bin (rms = the value at the mean speed to 0.1 %);
    # a cell reads sqrt(A^2 + noise^2) with the noise the bin's median cell of the FFT map; the mean of
    # ~30 half-overlapping windows' A^2 scatters 2.5-3 % (measured over seeds 7, 11, 12): 8 % = 3 sd
    f2 = 3.5
    rec = _recording(T=80.0, seed=7, lines=((F, A_POS, A_NEG, 0.3), (f2, A_POS, A_NEG, 2.0)))
    edges = np.arange(10.0, 101.0, 10.0)
    for d in (1, -1):
        m = order_map(rec, direction=d, orders=[F, f2], speed_bins=edges)
        noise = order_map(rec, direction=d, speed_bins=edges).noise
        expect = np.hypot(_truth(m.speed, d), noise)
        for b in (1, 4, 7, 8):
            assert m.amplitude[b, 0] == pytest.approx(expect[b], rel=0.08)
            assert m.amplitude[b, 1] == pytest.approx(expect[b], rel=0.08)


def test_order_map_masks_cells_above_the_position_nyquist_and_shows_noise_for_absent_lines():
    rec = _recording(T=80.0, seed=8)
    m = order_map(rec, direction=1, speed_bins=np.arange(10.0, 101.0, 10.0))
    # the highest measurable frequency of each bin lies between 0.8 x the Nyquist 0.5 / (v dt) at the
    # bin's fastest and slowest speeds (a window, ~13 rad long, and a 256-sample block of the rule
    # span a range of speeds, and the lowest Nyquist of its samples counts: 10 % slack on the fast side)
    nyq_at = MEASURABLE_FRACTION * 0.5 / (m.speed_edges / FS)
    assert np.all(m.limit <= nyq_at[:-1]) and np.all(m.limit >= 0.9 * nyq_at[1:])
    for b in range(len(m.speed)):
        above = m.frequency >= m.limit[b] * 1.001
        assert np.all(np.isnan(m.amplitude[b, above]))  # never a number above the limit
        assert np.all(np.isfinite(m.amplitude[b, (m.frequency < 0.7 * m.limit[b]) & (m.frequency > 0.2)]))
    # a line absent from the signal (2.7 cycles/rad) reads as noise: within 2 x the bin's median
    # cell (the rms of ~60 windows of noise power scatters ~13 %), and far below the true line
    j_abs = int(np.argmin(np.abs(m.frequency - 2.7)))
    j_true = int(np.argmin(np.abs(m.frequency - F)))
    for b in (1, 3, 5):
        assert m.amplitude[b, j_abs] < 2 * m.noise[b]
        assert m.amplitude[b, j_true] > 5 * m.noise[b]


def test_to_dict_is_strict_json_with_masked_cells_as_null():
    rec = _recording(seed=9)
    res = order_analysis(rec, [F, 8.0], inertia=0)
    d = res.to_dict()
    text = json.dumps(d, allow_nan=False)
    pos = d["maps"]["positive"]
    assert pos["unit"] == "rad" and pos["torque_unit"] == "Nm"
    assert any(x is None for row in pos["amplitude"] for x in row)  # masked cells
    assert len(d["tracks"]) == 4 and "8" in text
    assert pos["order_reference"][0] == pytest.approx(2 * np.pi * pos["frequency"][0])


def test_bad_input_is_one_sentence():
    rec = _recording(T=8.0, seed=10)
    with pytest.raises(InputError, match="direction"):
        order_map(rec, direction=0)
    with pytest.raises(InputError, match="neither a frequency nor a declared line"):
        order_track(rec, "mesh", direction=1)
    with pytest.raises(InputError, match="knots"):
        order_track(rec, F, knots=50)
    with pytest.raises(InputError, match="position Nyquist"):
        order_track(rec, 40.0, direction=1, inertia=0)  # above the Nyquist of every sample


def test_samples_near_rest_belong_to_no_direction():
    # a measured velocity with 0.5 rad/s of noise: near a reversal its sign is a coin toss.  Samples
    # slower than min_speed (default 2 % of the 99th-percentile speed: 2 rad/s, 4 noise sd) are rest
    # or reversal and left out; together with the shortest piece (16 samples) no sample truly moving
    # the other way enters a direction's pieces
    from gearspec.spectrum import motion

    # (the ramp crosses zero at 10 rad/s^2: the noise blurs the sign over ~50 samples there)
    rec = _recording("ramp", T=40.0, seed=11, velocity=True)
    t, v_true = _velocity("ramp", 40.0)
    rng = np.random.default_rng(0)
    rec.data["velocity"] = v_true + 0.5 * rng.standard_normal(len(v_true))
    for d in (1, -1):
        m = motion(rec, d)
        true_v = np.interp(m.t, t, v_true)
        assert np.all(d * true_v > 0)
        assert 1.9 < m.min_speed < 2.1 and m.speed.min() > m.min_speed


# ---------------------------------------------------------------------- command line
def test_cli_recording_without_plateaus_is_analysed_by_its_order_map(tmp_path, capsys):
    from gearspec.cli import main

    path = tmp_path / "triangle.csv"
    _recording("triangle", T=20.0, seed=12, top=60.0).save(path)
    out, js = tmp_path / "out", tmp_path / "r.json"
    assert main(["spectrum", str(path), "--track", "1.5", "--out", str(out), "--json", str(js)]) == 0
    text = capsys.readouterr().out
    assert "order map over varying speed was used instead" in text
    for name in ("order_map.png", "order_tracks.png", "order_map.json", "report.md"):
        assert (out / name).exists()
    assert "the order map over varying speed was used instead" in (out / "report.md").read_text().lower()
    d = json.loads(js.read_text())
    assert d["segments"] == [] and d["order_map"]["maps"]["positive"]["amplitude"]
    tracks = d["order_map"]["tracks"]
    assert {t["direction"] for t in tracks} == {1, -1}
    # the track's amplitude at its middle speed: the truth within 3 standard errors
    t = tracks[0]
    i = len(t["speed"]) // 2
    assert abs(t["amplitude"][i] - _truth(t["speed"][i], t["direction"])) < 3 * t["amplitude_se"][i]


def test_cli_without_plateaus_uses_the_order_map_when_the_gear_declares_lines(tmp_path, capsys):
    # a gear spec: its declared lines are tracked and the order map stands in for the segments; no
    # gear spec and no --order-map: the refusal of today, now saying how to get the order map
    from gearspec.cli import main

    path = tmp_path / "triangle.csv"
    _recording("triangle", T=10.0, seed=15, top=60.0).save(path)
    spec = tmp_path / "g.toml"
    spec.write_text('name = "spur drive"\n[[stages]]\nname = "spur"\nkind = "spur"\nratio = 3.0\nteeth = 28\n')
    assert main(["spectrum", str(path), "--gear", str(spec), "--quiet", "--json", str(tmp_path / "r.json")]) == 0
    tracks = json.loads((tmp_path / "r.json").read_text())["order_map"]["tracks"]
    assert any("spur tooth mesh" in (t["label"] or "") for t in tracks)
    capsys.readouterr()
    assert main(["spectrum", str(path), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "no constant-speed segment" in err and "--order-map" in err


def test_cli_track_that_is_no_line_is_refused_in_one_sentence(tmp_path, capsys):
    from gearspec.cli import main

    path = tmp_path / "ramp.csv"
    _recording(T=10.0, seed=13).save(path)
    assert main(["spectrum", str(path), "--order-map", "--track", "mesh", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("gearspec: error:") and "track 'mesh'" in err and len(err.strip().splitlines()) == 1


def test_short_moves_get_short_windows():
    # triangle moves of 19 rad each way: the longest window of 32..256 grid points that a move holds
    # four times (grid spacing 1 / (2 x the mean-spacing Nyquist) ~ 0.038 rad: 500 points a move: 64),
    # so that a window spans a quarter of the speeds of a move rather than all of them
    m = order_map(_recording("triangle", T=10.0, seed=14, top=60.0), direction=1)
    assert m.window == 64
    # each window's speed is close to the truth it spans: cells fill at least 8 of the 16 speed bins
    assert np.isfinite(m.speed).sum() >= 8


def test_track_normal_equations_equal_the_dense_design():
    # the per-span moments reproduce X'X and X'y of the dense design (B-splines x [1, sin, cos],
    # acceleration) built with scipy's BSpline: 1e-9 relative (sines in single precision: 1e-7 per
    # sample, averaging down over thousands of samples; the moments themselves are double)
    from scipy.interpolate import BSpline

    from gearspec.spectrum import motion
    from gearspec.spectrum.ordertrack import _normal_equations

    m = motion(_recording(seed=16, inertia=0.002), 1, need_acc=True)
    use = np.ones(len(m), bool)
    use[::7] = False
    lo, hi = m.speed[use].min(), m.speed[use].max()
    tk = np.concatenate([[lo] * 4, np.linspace(lo, hi, 6)[1:-1], [hi] * 4])
    A, b, yy = _normal_equations(m, use, F, tk, True)
    r = np.flatnonzero(use)
    B = BSpline.design_matrix(m.speed[r], tk, 3).toarray()
    ph = 2 * np.pi * F * m.theta[r]
    X = np.hstack([B, B * np.sin(ph)[:, None], B * np.cos(ph)[:, None], m.acc[r][:, None]])
    assert np.abs(A - X.T @ X).max() <= 1e-9 * np.abs(X.T @ X).max()
    assert np.abs(b - X.T @ m.y[r]).max() <= 1e-8 * np.abs(X.T @ m.y[r]).max()
    assert yy == pytest.approx(m.y[r] @ m.y[r], rel=1e-12)


def test_slow_position_dependent_force_does_not_leak_into_low_orders():
    # a 2 Nm force varying slowly with position (period 400 rad, like gravity on a joint): over a
    # 13 rad window it is a straight line, taken out per window, so the two lowest frequency bins
    # (0.077 and 0.15 cycles/rad) read noise (within 2 x the bin's median cell; a Hann window alone
    # leaks 0.05-0.09 Nm there: 20-35 x the noise)
    rec = _recording(T=80.0, seed=8)
    theta = rec.data["theta"].to_numpy()
    rec = Recording.from_arrays(t=rec.t, theta=theta, torque=rec.tau + 2.0 * np.sin(2 * np.pi * theta / 400.0))
    m = order_map(rec, direction=1, speed_bins=np.arange(10.0, 101.0, 10.0))
    assert m.frequency[0] < 0.1
    assert np.all(m.amplitude[:, :2] < 2 * m.noise[:, None])


# ---------------------------------------------------------------------- speed (issue 12 benchmark): same numbers
def _reference_block_nyquist(theta, bounds):
    """The position Nyquist of every sample by the package's rule applied block by block (blocks of
    NYQUIST_BLOCK samples per piece, the last joined to its neighbour when shorter than half a block,
    the spacing into a block included): the loop the vectorised rule must reproduce exactly."""
    from gearspec.spectrum import position_nyquist
    from gearspec.spectrum.ordermap import NYQUIST_BLOCK

    out = np.empty(len(theta))
    for s, e in bounds:
        starts = list(range(0, e - s, NYQUIST_BLOCK))
        if len(starts) > 1 and e - s - starts[-1] < NYQUIST_BLOCK // 2:
            starts.pop()
        for i, a in enumerate(starts):
            b = starts[i + 1] if i + 1 < len(starts) else e - s
            out[s + a:s + b] = position_nyquist(theta[s + max(a - 1, 0):s + b])
    return out


def test_position_nyquist_of_all_blocks_at_once_is_the_rule_block_by_block():
    # pieces of 16 .. 1000 samples (last blocks joined or not: 300 = 256 + 44 joined, 400 = 256 + 144
    # not), spacings from a coarse encoder (many exact zeros at low speed, so the zero count moves the
    # percentile's index) and a jittered one: the same numbers, bit for bit
    from gearspec.spectrum.ordermap import _block_nyquist

    rng = np.random.default_rng(17)
    lengths = [16, 129, 255, 256, 257, 300, 383, 384, 400, 511, 1000, 40]
    theta, bounds, n = [], [], 0
    for k, ln in enumerate(lengths):
        step = rng.uniform(0.0, 2e-3, ln) if k % 2 else 1e-3 * (1 + 0.3 * rng.standard_normal(ln))
        th = np.cumsum(np.abs(step)) + (theta[-1][-1] if theta else 0.0)
        if k % 2:
            th = np.round(th / 1.5e-3) * 1.5e-3  # quantised: runs of equal positions
        theta.append(th)
        bounds.append((n, n + ln))
        n += ln
    theta = np.concatenate(theta)
    got, ref = _block_nyquist(theta, bounds), _reference_block_nyquist(theta, bounds)
    assert np.array_equal(got, ref)
    assert len(np.unique(ref)) > 10  # the test sees many different blocks, not one number


def test_lines_fitted_together_are_the_lines_fitted_alone():
    # order_analysis fits the lines measured on the same samples in one pass over them (F and 2.5
    # cycles/rad: below 0.8 x the Nyquist everywhere; 8 cycles/rad only below 50 rad/s): the same
    # amplitudes, phases and bands as order_track line by line to 1e-9 relative (only the order of
    # summation differs: rounding, 1e-12 measured), in the order the lines were given, and a line no
    # sample measures is skipped in its place
    rec = _recording(seed=18, lines=((F, A_POS, A_NEG, 0.3), (8.0, 0.04, 0.04, 1.0), (2.5, 0.02, 0.02, 0.5)))
    res = order_analysis(rec, [F, 8.0, 400.0, 2.5], inertia=0)  # 400: measurable below 1 rad/s only
    assert [(t.direction, t.frequency) for t in res.tracks] == [(d, f) for d in (1, -1) for f in (F, 8.0, 2.5)]
    assert [s["frequency"] for s in res.skipped] == [400.0, 400.0]
    for tr in res.tracks:
        alone = order_track(rec, tr.frequency, direction=tr.direction, inertia=0)
        ok = np.isfinite(alone.amplitude)
        assert np.array_equal(ok, np.isfinite(tr.amplitude)) and ok.sum() > 20
        for name in ("amplitude", "amplitude_se", "phase", "lower", "upper"):
            a, b = getattr(alone, name)[ok], getattr(tr, name)[ok]
            assert np.abs(a - b).max() <= 1e-9 * np.abs(a).max(), name
        assert tr.n == alone.n and tr.sigma == pytest.approx(alone.sigma, rel=1e-12)


def test_two_threads_give_the_numbers_of_one():
    # the directions in two threads: bit for bit the numbers of one thread (each direction's work is
    # the same sequence of operations); the inertia fitted, so that the acceleration path is used
    rec = _recording(seed=19, inertia=0.002)
    one = order_analysis(rec, [F, 8.0], inertia="fit", workers=1).to_dict()
    two = order_analysis(rec, [F, 8.0], inertia="fit", workers=2).to_dict()
    assert json.dumps(one, allow_nan=False) == json.dumps(two, allow_nan=False)
    with pytest.raises(InputError, match="workers"):
        order_analysis(rec, [F], workers=0)


def test_map_windows_across_pieces_are_the_windows_piece_by_piece():
    # the windows of all pieces are laid out at once: each window's lowest Nyquist, samples and speed
    # are those of its own piece only (a window never reaches into the next piece), checked against
    # a direct computation per piece on a chirp (many pieces, Nyquist varying within each)
    from gearspec.spectrum import motion
    from gearspec.spectrum.ordermap import _window_layout

    m = motion(_recording("chirp", T=30.0, seed=20), 1)
    spacing, window = 0.05, 64
    grid, first, speeds, nyqs, counts, ds = _window_layout(m, spacing, window)
    ref_nyq, ref_counts, ref_speed = [], [], []
    for s, e in m.bounds:
        th, nq, tt = m.theta[s:e], m.nyquist[s:e], m.t[s:e]
        g0, g1 = int(np.ceil(th[0] / spacing)), int(np.floor(th[-1] / spacing))
        for a in range(g0, g1 - window + 2, window // 2):
            lo = max(np.searchsorted(th, a * spacing, side="right") - 1, 0)
            mid = np.searchsorted(th, (a + window // 2) * spacing, side="right") - 1
            end = np.searchsorted(th, (a + window) * spacing, side="right") - 1  # the next window's half
            hi = min(np.searchsorted(th, (a + window - 1) * spacing, side="left") + 1, e - s)
            ref_nyq.append(min(nq[lo:max(mid, lo + 1)].min(), nq[mid:max(end, mid + 1)].min()))
            ref_counts.append(hi - lo)
            dur = np.interp((a + window - 1) * spacing, th, tt) - np.interp(a * spacing, th, tt)
            ref_speed.append((window - 1) * spacing / dur)
    assert len(first) == len(ref_nyq) > 100 and len(m.bounds) >= 5
    assert np.array_equal(nyqs, ref_nyq) and np.array_equal(counts, ref_counts)
    assert np.allclose(speeds, ref_speed, rtol=1e-12)
    assert np.unique(nyqs).size > 20


def test_a_line_slower_than_the_travel_near_a_speed_is_not_tracked_there():
    """A ramp to 100 rad/s and back in 40 s: near each grid speed (half a knot span, ~10 rad/s of
    speed, ~1 s each way) the samples travel some 100 rad.  A line of 0.002 cycles/rad (one cycle per
    500 rad) makes a fifth of a cycle there: its sine and cosine cannot be told from the level, so it
    is NaN at every speed (without the rule a curve with a narrow band is drawn); the 1.5 cycles/rad
    line is tracked everywhere the samples reach."""
    rec = _recording("ramp", T=40.0, seed=5, lines=((F, A_POS, A_NEG, 0.3), (0.002, 0.04, 0.04, 1.0)))
    slow = order_track(rec, 0.002, direction=1, inertia=0)
    assert np.all(np.isnan(slow.amplitude)) and any("less than" in n for n in slow.notes)
    fast = order_track(rec, F, direction=1, inertia=0)
    assert np.isfinite(fast.amplitude).mean() > 0.9


# ---------------------------------------------------------------------- the faster paths, against the plain ones
def test_track_grid_cells_are_the_histogram_cells():
    # the cells of the speed grid found by arithmetic (no sort) hold exactly the samples
    # np.histogram puts there, samples lying exactly on an edge included (they belong to the cell
    # above, as in np.histogram); the travel per cell is the speed-weighted histogram
    from gearspec.spectrum.ordertrack import SPEED_GRID, _grid_cells

    rng = np.random.default_rng(30)
    lo, hi = 1.7, 93.1
    grid = np.linspace(lo, hi, SPEED_GRID)
    cell = (hi - lo) / (SPEED_GRID - 1)
    edges = np.concatenate([grid - cell / 2, [hi + cell / 2]])
    x = np.concatenate([rng.uniform(lo, hi, 200_000), edges[1:-1], [lo, hi], np.nextafter(edges[1:-1], 0)])
    cells = _grid_cells(x, edges)
    assert np.array_equal(np.bincount(cells, minlength=SPEED_GRID), np.histogram(x, bins=edges)[0])
    assert np.allclose(np.bincount(cells, weights=x, minlength=SPEED_GRID),
                       np.histogram(x, bins=edges, weights=x)[0], rtol=1e-12)
    assert np.all(edges[cells] <= x) and np.all(x < edges[cells + 1])


def test_99th_percentile_of_the_speeds_is_numpys():
    # min_speed's 99th percentile from the values above a guess: numpy's number (to rounding: 1e-15)
    # on smooth, tied and adversarial speeds; the last one (every 128th value large, so the guess
    # from every 64th value is too high) must take the full partition and still be right
    from gearspec.spectrum.ordermap import _percentile_99

    rng = np.random.default_rng(31)
    n = 300_001
    cases = [np.abs(rng.standard_normal(n)), np.round(rng.uniform(0, 50, n)),
             np.abs(300 * np.sin(np.linspace(0, 400, n)))]
    bad = np.zeros(n)
    bad[::128] = 10.0
    bad[1::2] = rng.uniform(0, 1, len(bad[1::2]))
    cases.append(bad)
    for a in cases:
        assert _percentile_99(a.copy()) == pytest.approx(np.percentile(a, 99), rel=1e-15, abs=0), a[:4]


def test_pieces_shorter_than_the_minimum_are_left_out_of_the_arrays_and_counted():
    # a velocity with moving bursts of 10 samples (shorter than MIN_PIECE = 16) between long moves:
    # the bursts' samples are in no piece and not in the arrays (whose times are exactly those of
    # the long moves), and the ledger counts them
    from gearspec.spectrum import motion
    from gearspec.spectrum.ordermap import MIN_PIECE

    n = 4000
    t = np.arange(n) / FS
    v = np.zeros(n)
    v[100:1100] = 20.0
    v[1500:1510] = 20.0      # a burst of 10 samples
    v[2000:3000] = 20.0
    v[3500:3510] = 20.0
    theta = np.cumsum(v) / FS
    rec = Recording.from_arrays(t=t, theta=theta, torque=np.sign(v) * 0.3, velocity=v)
    m = motion(rec, 1, min_speed=1.0)
    assert 10 < MIN_PIECE
    assert m.bounds == [(0, 1000), (1000, 2000)]
    assert np.array_equal(m.t, np.concatenate([t[100:1100], t[2000:3000]]))
    assert np.array_equal(m.theta, np.concatenate([theta[100:1100], theta[2000:3000]]))
    assert m.excluded[f"pieces shorter than {MIN_PIECE} samples"] == 20
    assert m.excluded["other direction or slower than min_speed"] == n - 2020


def test_map_windows_detrended_in_the_transform_are_the_windows_detrended_first():
    # the line (mean and slope) of every window removed after the transform: the same calibrated
    # power as removing it from the window first, then Hann and FFT, on the FFT bins and on given
    # frequencies (the chirp's friction level, 0.3 Nm, left in a window would dominate its low bins)
    from gearspec.spectrum import motion
    from gearspec.spectrum.ordermap import _window_layout, _window_spectra

    m = motion(_recording("chirp", T=20.0, seed=32), 1)
    spacing, window = 0.05, 64
    grid, first, _, _, _, ds = _window_layout(m, spacing, window)
    hann = np.hanning(window + 2)[1:-1]
    gain = 2.0 / hann.sum()
    ramp = np.arange(window) - 0.5 * (window - 1)
    ramp /= np.sqrt(ramp @ ramp)
    blk = np.lib.stride_tricks.sliding_window_view(grid, window)[first]
    blk = blk - blk.mean(axis=1, keepdims=True)
    blk = blk - np.outer(blk @ ramp, ramp)
    f_k = np.arange(1, window // 2 + 1) / (window * spacing)
    freqs = np.array([F, 3.3])
    k = np.arange(window) * spacing
    for freq, X in ((None, np.fft.rfft(blk * hann, axis=1)[:, 1:window // 2 + 1] * gain),
                    (freqs, blk @ ((hann[:, None] * np.exp(-2j * np.pi * k[:, None] * freqs[None, :])) * gain))):
        fk = f_k if freq is None else freq
        resp = np.maximum(np.sinc(ds[:, None] * fk[None, :]) ** 2, 0.1)
        ref = np.abs(X) ** 2 / resp**2
        got = _window_spectra(m, spacing, window, freq)[3]
        assert got.shape == ref.shape and len(got) > 100
        # the interpolation's response in single precision: 1e-7 relative per cell (1e-6 allowed);
        # the rest is double-precision rounding, 1e-12 of the largest power
        assert np.allclose(got, ref, rtol=1e-6, atol=1e-12 * ref.max())


def test_track_samples_taken_chunk_by_chunk_are_all_the_measured_samples_once():
    # the chunks of a mask (dense, sparse, empty at the start, one sample at the end) hold its True
    # samples in order, each exactly once, at most _CHUNK at a time
    from gearspec.spectrum.ordertrack import _CHUNK, _chunks

    rng = np.random.default_rng(33)
    n = 5 * _CHUNK + 123
    masks = [np.ones(n, bool), rng.uniform(size=n) < 0.03, np.zeros(n, bool)]
    masks[2][-1] = True
    late = np.zeros(n, bool)
    late[3 * _CHUNK:] = True
    masks.append(late)
    for use in masks:
        parts = list(_chunks(use))
        assert all(0 < len(p) <= _CHUNK for p in parts)
        assert np.array_equal(np.concatenate(parts), np.flatnonzero(use))
    assert list(_chunks(np.zeros(10, bool))) == []


def test_close_line_labels_of_the_order_map_go_to_opposite_edges():
    # two lines 2 % of the axis apart (an output shaft and a planetary carrier) would print their
    # labels over each other at the left edge: the upper one goes to the right edge; a line far
    # from both is labelled at the left again
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from gearspec.plots.ordermap import _mark_lines

    fig, ax = plt.subplots()
    ax.set_xlim(0, 300)
    ax.set_ylim(0, 1.0)
    _mark_lines(ax, [(0.50, "far"), (0.012, "carrier"), (0.010, "output shaft"), (2.0, "beyond")], 1.2, 0, 300, 1.0)
    where = {t.get_text(): (t.xy[0], t.get_ha()) for t in ax.texts}
    plt.close(fig)
    assert where == {"output shaft": (0, "left"), "carrier": (300, "right"), "far": (0, "left")}
