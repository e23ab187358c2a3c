"""Known-answer tests of the spectral engine.

Signal-to-noise: "SNR" here is ripple amplitude over the standard deviation of the white torque
noise, per sample.  At SNR 20 with a few thousand samples per segment the statistical error of an
amplitude is ~0.1 %, so the 2 % / 0.05 rad tolerances test for *bias* (leakage between lines,
speed ripple, a component too slow to complete a cycle, resampling); the coverage tests check the
standard errors themselves, where the noise is large.
"""

import math

import numpy as np
import pytest

from gearspec.gears import GearTrain, load_gear
from gearspec.simulate import Ripple, plateau_recording
from gearspec.spectrum import (LombScargle, analyze, analyze_segment, harmonic_fit, min_degree_for_cycles,
                               order_spectrum, resample_over_position)

SILO4 = load_gear("silo4-joint3")
F = {ln.label: ln.frequency for ln in SILO4.declared_lines()}
F_JOINT, F_WORM, F_MOTOR = F["output shaft"], F["planetary output shaft"], F["motor shaft"]


def wrap(x):
    return (x + np.pi) % (2 * np.pi) - np.pi


@pytest.mark.parametrize("periodogram", ["lombscargle", "fft"])
def test_amplitudes_and_phases_at_every_declared_line(periodogram):
    """Several declared lines, direction-dependent amplitudes and phases, decay with speed, 3 %
    closed-loop speed ripple, a joint-rotation component that never completes a cycle, SNR 20."""
    ripples = [Ripple(F_JOINT, 3e-4, 1.2),                                    # < 1 cycle per segment
               Ripple(F_WORM, (6e-4, 5e-4), (0.4, 2.0), (1.2e-3, 1.1e-3)),
               Ripple(F_MOTOR, (1.5e-4, 1.2e-4), (np.pi - 0.2, -1.0), (5e-4, 1e-4))]
    speeds = [30, 60, 120, 250, -30, -60, -120, -250]
    durations = [max(2.0, 3.0 / (F_WORM * abs(v))) for v in speeds]
    noise = 1.2e-4 / 20
    rec, truth = plateau_recording(speeds, ripples=ripples, level=8e-3, duration=durations, fs=2000, ramp=0.3,
                                   speed_ripple=0.03, speed_ripple_frequency=7 * F_MOTOR, noise=noise,
                                   one_run_per_plateau=True, gear=SILO4, seed=11)
    res = analyze(rec, periodogram=periodogram)
    assert len(res.segments) == len(speeds)
    checked = 0
    for s in res.segments:
        tr = next(t for t in truth if t["run"] == s.segment.run)
        for r in tr["ripples"]:
            label = {F_JOINT: "output shaft", F_WORM: "planetary output shaft", F_MOTOR: "motor shaft"}[r["frequency"]]
            p = s.peak(label)
            if r["frequency"] == F_JOINT:
                assert p is None and any(k["label"] == "output shaft" for k in s.skipped)
                continue
            assert p is not None and p.declared
            assert p.amplitude == pytest.approx(r["amplitude"], rel=0.02), (s.speed, label)
            assert abs(wrap(p.phase - r["phase"])) < 0.05, (s.speed, label)
            assert p.fap < 1e-10
            checked += 1
    assert checked == 2 * len(speeds)
    # the level has no viscous term, so the speed ripple (7 per motor turn) puts nothing at 7x motor
    # itself; but it modulates the speed-dependent amplitudes, and the only undeclared peaks found
    # are those real modulation sidebands, 7 f_motor -+ f_worm: nothing else is invented
    sidebands = np.array([7 * F_MOTOR - F_WORM, 7 * F_MOTOR + F_WORM])
    for f in res.unexplained()["frequency"]:
        assert np.min(np.abs(sidebands - f)) < 1e-3 * f, f


def test_close_lines_do_not_leak_into_each_other():
    # two declared shafts 1.5 resolution steps apart, amplitudes 1 and 0.05
    g = GearTrain.from_dict({"name": "close", "reference": "motor",
                             "stages": [{"name": "s", "kind": "spur", "ratio": 1.02}]})
    f1, f2 = 1 / (2 * np.pi), 1 / (2 * np.pi * 1.02)
    rng = np.random.default_rng(2)
    span = 1.5 / (f1 - f2)
    theta = np.sort(rng.uniform(0, span, 20000))
    y = 1.0 * np.sin(2 * np.pi * f1 * theta + 0.3) + 0.05 * np.sin(2 * np.pi * f2 * theta - 1.0) \
        + 0.5 + rng.normal(0, 0.01, theta.size)
    s = analyze_segment(theta, y, g, keep_spectra=True)
    p1, p2 = s.peak("motor shaft"), s.peak("output shaft")
    assert p1.amplitude == pytest.approx(1.0, rel=0.005)
    assert p2.amplitude == pytest.approx(0.05, rel=0.02)
    assert abs(wrap(p2.phase + 1.0)) < 0.05
    # the windowed FFT cannot tell the weak line from the strong one's leakage
    fft_at = np.interp(f2, s.fft_frequency, s.fft_amplitude)
    assert abs(fft_at - 0.05) > 0.1 * 0.05


def test_component_with_less_than_a_cycle_does_not_bias_the_others():
    rng = np.random.default_rng(4)
    theta = np.linspace(0, 60, 6000)
    slow = 2.0 * np.sin(2 * np.pi * theta / 150 + 0.7)   # 0.4 cycle in the segment, 40x the line
    y = slow + 0.05 * np.sin(2 * np.pi * 0.2 * theta + 0.5) + rng.normal(0, 0.0025, theta.size)
    # the degree the analysis picks for a 0.4-cycle component (see min_degree_for_cycles)
    deg = min_degree_for_cycles(0.4)
    direct = harmonic_fit(theta, y, [0.2], degree=deg)
    naive = harmonic_fit(theta, y, [0.2], degree=1)
    assert direct.amplitude[0] == pytest.approx(0.05, rel=0.02)
    assert abs(wrap(direct.phase[0] - 0.5)) < 0.05
    assert direct.sigma < 1.2 * 0.0025                          # the slow component is absorbed
    assert abs(naive.amplitude[0] / 0.05 - 1) > 0.02            # a trend-only nuisance is biased


def test_auto_nuisance_degree_follows_slow_declared_lines():
    theta = np.linspace(0, 100, 5000)
    rng = np.random.default_rng(5)
    # with the SILO4 train at the motor, the output shaft completes 0.055 cycles, the worm 1.1
    y = 3e-4 * np.sin(2 * np.pi * F_JOINT * theta + 1) + 6e-4 * np.sin(2 * np.pi * F_WORM * theta + 0.4) \
        + 1.5e-4 * np.sin(2 * np.pi * F_MOTOR * theta + 3) + rng.normal(0, 5e-6, theta.size)
    s = analyze_segment(theta, y, SILO4, keep_spectra=False)
    assert s.degree >= 3
    assert s.peak("planetary output shaft").amplitude == pytest.approx(6e-4, rel=0.02)
    assert s.peak("motor shaft").amplitude == pytest.approx(1.5e-4, rel=0.02)


def _coverage(noise_kind, n_seeds=150, noise_model="local", periodogram="auto"):
    g = GearTrain.from_dict({"name": "g", "reference": "motor",
                             "stages": [{"name": "a", "kind": "spur", "ratio": 3.0},
                                        {"name": "b", "kind": "spur", "ratio": 5.0}]})
    lines = [ln.frequency for ln in g.declared_lines()]
    amps = [0.02, 0.03, 0.05]
    phases = [0.3, -1.2, 2.5]
    hits_a = hits_p = total = 0
    for seed in range(n_seeds):
        rng = np.random.default_rng(1000 + seed)
        n = 3000
        theta = np.cumsum(rng.uniform(0.05, 0.15, n)) + 10
        if noise_kind == "white":
            e = rng.normal(0, 0.2, n)
        else:  # AR(1), strongly coloured: 16x more noise power at the slow line than white noise of
            # the same innovation; innovations scaled so that every line keeps an SNR (A / s.e.) >= 4,
            # where the delta-method errors hold (below it the amplitude is Rice-biased upwards)
            w = rng.normal(0, 0.01, n)
            e = np.empty(n)
            e[0] = w[0]
            for i in range(1, n):
                e[i] = 0.9 * e[i - 1] + w[i]
        y = 1.0 + sum(a * np.sin(2 * np.pi * f * theta + p) for a, f, p in zip(amps, lines, phases)) + e
        s = analyze_segment(theta, y, g, max_peaks=0, noise=noise_model, periodogram=periodogram)
        for a, f, p in zip(amps, lines, phases):
            pk = next(q for q in s.peaks if abs(q.frequency - f) < 1e-12)
            hits_a += abs(pk.amplitude - a) < 1.96 * pk.amplitude_se
            hits_p += abs(wrap(pk.phase - p)) < 1.96 * pk.phase_se
            total += 1
    return hits_a / total, hits_p / total


@pytest.mark.slow
@pytest.mark.parametrize("periodogram", ["lombscargle", "fft"])
@pytest.mark.parametrize("noise_kind", ["white", "ar1"])
def test_standard_errors_cover_the_truth(noise_kind, periodogram):
    """95 % intervals hold the truth ~95 % of the time (450 intervals: +-2 sd is +-2 %).

    The local noise level is itself estimated: at the lowest frequencies from as few as ~10-20
    independent bins (more would blur a steep coloured spectrum), which makes +-1.96 s.e. a
    t-interval with 20-40 degrees of freedom (92-94 % coverage); hence the band 0.90-0.98."""
    cov_a, cov_p = _coverage(noise_kind, periodogram=periodogram)
    assert 0.90 <= cov_a <= 0.98, cov_a
    assert 0.90 <= cov_p <= 0.98, cov_p


@pytest.mark.slow
def test_white_noise_errors_would_be_wrong_for_coloured_noise():
    # the same AR(1) data with white-noise error bars: the slow line's bars are far too narrow
    cov_a, _ = _coverage("ar1", n_seeds=60, noise_model="white")
    assert cov_a < 0.85


@pytest.mark.parametrize("periodogram", ["lombscargle", "fft"])
def test_found_peaks_harmonics_and_integer_hints(periodogram):
    rng = np.random.default_rng(8)
    theta = np.linspace(0, 300, 30000)
    y = (0.01 + 1e-3 * np.sin(2 * np.pi * F_MOTOR * theta)          # declared
         + 4e-4 * np.sin(2 * np.pi * 2 * F_MOTOR * theta + 1.0)   # a harmonic of it
         + 3e-4 * np.sin(2 * np.pi * 7 * F_MOTOR * theta - 0.5)   # 7 per motor turn: a pole-pair order?
         + 2e-4 * np.sin(2 * np.pi * 1.234 * theta + 0.2)         # nothing explains this one
         + rng.normal(0, 1e-4, theta.size))
    s = analyze_segment(theta, y, SILO4, periodogram=periodogram)
    found = {round(p.frequency, 3): p for p in s.peaks if not p.declared}
    assert set(found) == {round(2 * F_MOTOR, 3), round(7 * F_MOTOR, 3), 1.234}
    h2 = found[round(2 * F_MOTOR, 3)]
    assert h2.label == "2x motor shaft" and h2.amplitude == pytest.approx(4e-4, rel=0.03)
    h7 = found[round(7 * F_MOTOR, 3)]
    assert h7.label is None and h7.hint == "7x motor shaft"
    assert h7.frequency == pytest.approx(7 * F_MOTOR, rel=1e-4)
    assert abs(wrap(h7.phase + 0.5)) < 0.05
    u = found[1.234]
    assert u.label is None and u.hint is None and u.fap < 1e-6
    assert u.frequency == pytest.approx(1.234, rel=1e-4)


@pytest.mark.slow
@pytest.mark.parametrize("periodogram", ["lombscargle", "fft"])
def test_no_false_discoveries_on_pure_noise(periodogram):
    """fap threshold 0.01 per segment: over 100 noise-only segments, expect ~1 with a false peak."""
    false = 0
    for seed in range(100):
        rng = np.random.default_rng(seed)
        theta = np.cumsum(rng.uniform(0.05, 0.15, 2000))
        s = analyze_segment(theta, rng.normal(0, 1, theta.size), None, periodogram=periodogram)
        false += any(not p.declared for p in s.peaks)
    assert false <= 5  # binomial(100, 0.01): P(> 5) < 1e-3


def test_order_spectrum_is_amplitude_calibrated():
    h = 0.01
    x = np.arange(8192) * h
    f_on = 100 / (8192 * h)
    a, f_grid = order_spectrum(np.sin(2 * np.pi * f_on * x) * 0.7 + 3, h)[::-1]
    assert a[np.argmin(np.abs(f_grid - f_on))] == pytest.approx(0.7, rel=0.005)
    f_off = 100.5 / (8192 * h)
    f2, a2 = order_spectrum(0.7 * np.sin(2 * np.pi * f_off * x), h, window="flattop")
    assert a2.max() == pytest.approx(0.7, rel=0.01)


def test_lomb_scargle_backends_agree_and_are_calibrated():
    rng = np.random.default_rng(3)
    theta = np.sort(rng.uniform(0, 50, 3000))
    y = 2 + 0.4 * np.sin(2 * np.pi * 1.5 * theta) + rng.normal(0, 0.1, theta.size)
    ls = LombScargle(theta, y)
    fmin, df, nf = 0.1, 0.01, 500
    p_n = LombScargle(theta, y, method="nifty").power_grid(fmin, df, nf)
    f = fmin + df * np.arange(nf)
    p_a = LombScargle(theta, y, method="astropy").power(f)
    p_s = LombScargle(theta, y, method="scipy").power(f)
    assert np.allclose(p_n, p_a, rtol=1e-4, atol=1e-6 * p_a.max())
    assert np.allclose(p_s, p_a, rtol=1e-6, atol=1e-9 * p_a.max())
    assert ls.amplitude([1.5])[0] == pytest.approx(0.4, rel=0.02)


def test_resampling_antialiases_and_keeps_the_passband():
    rng = np.random.default_rng(6)
    theta = np.cumsum(rng.uniform(0.5, 1.5, 200000)) * 1e-3   # ~1000 samples per unit
    y = np.sin(2 * np.pi * 5 * theta) + 0.5 * np.sin(2 * np.pi * 180 * theta)
    grid, v = resample_over_position(theta, y, max_frequency=20)   # grid Nyquist >= 50, < 180
    f, a = order_spectrum(v, grid[1] - grid[0], window="flattop")
    assert a[np.argmin(np.abs(f - 5))] == pytest.approx(1.0, rel=0.01)
    assert a[f > 8].max() < 0.01                                  # the 180 line did not fold in
    # a drive that sits still for a while: the many samples at one place are averaged, not aliased
    th = np.concatenate([np.linspace(0, 1, 1000), np.full(5000, 1.0), np.linspace(1, 2, 1000)])
    yy = np.concatenate([np.zeros(1000), rng.normal(0, 1, 5000), np.zeros(1000)])
    g2, v2 = resample_over_position(th, yy)
    assert np.max(np.abs(v2)) < 0.1


def test_result_json_contract_and_row_ledger(tmp_path):
    import json

    rec, _ = plateau_recording([40, -40], ripples=[Ripple(F_MOTOR, 1e-3, 0.5)], level=0.01, duration=3,
                               fs=1000, noise=1e-4, gear=SILO4, seed=2)
    res = analyze(rec)
    path = res.to_json(tmp_path / "s.json")
    d = json.loads(path.read_text())
    assert sum(s["n"] for s in d["segments"]) + sum(d["excluded"].values()) == len(rec) == d["n_rows"]
    for s in d["segments"]:
        assert s["direction"] in (1, -1) and s["speed"] > 0 and "run" in s
        for p in s["peaks"]:
            assert set(p) >= {"frequency", "amplitude", "amplitude_se", "phase", "phase_se", "fap", "order", "label"}
        assert any(p["label"] == "motor shaft" for p in s["peaks"])


# ---------------------------------------------------------------------- the fast paths are exact
def _reference_fit(theta, y, freq, degree):
    """Joint least squares in double precision with a full design matrix (the slow reference)."""
    from numpy.polynomial import legendre

    lo, hi = theta.min(), theta.max()
    x = 2 * (theta - lo) / (hi - lo) - 1
    ph = np.multiply.outer(theta, freq)
    ph = 2 * np.pi * (ph - np.floor(ph))
    X = np.hstack([legendre.legvander(x, degree), np.cos(ph), np.sin(ph)])
    beta = np.linalg.lstsq(X, y, rcond=None)[0]
    a, b = beta[degree + 1:degree + 1 + len(freq)], beta[degree + 1 + len(freq):]
    return np.hypot(a, b), np.arctan2(a, b)


def test_single_precision_normal_equations_match_double_precision_far_from_zero():
    # 200 000 samples around theta = 1e5 (a long run at speed), lines up to 0.4 of the Nyquist
    rng = np.random.default_rng(21)
    theta = 1e5 + np.cumsum(rng.uniform(0.05, 0.15, 200_000))
    freq = np.array([0.0123, 0.15915, 0.4321, 2.0])
    y = 0.4 + sum(a * np.sin(2 * np.pi * f * theta + p) for a, f, p in zip([0.03, 0.01, 0.005, 0.002], freq,
                                                                               [0.7, -1.1, 2.0, 0.3]))
    y = y + rng.normal(0, 0.05, theta.size)
    amp, ph = _reference_fit(theta, y, freq, 3)
    fit = harmonic_fit(theta, y, freq, degree=3)
    # rounding errors far below the statistical ones (phase s.e. here 0.003 .. 0.08 rad)
    assert np.allclose(fit.amplitude, amp, rtol=1e-4)
    assert np.max(np.abs(wrap(fit.phase - ph))) < 5e-5
    assert np.all(np.abs(wrap(fit.phase - ph)) < 1e-3 * fit.phase_se)
    r = y - fit.predict(theta)
    assert abs(np.std(r) - fit.sigma) < 1e-3 * fit.sigma


def test_extended_equations_equal_a_full_pass():
    from gearspec.spectrum.harmonic import NormalEquations, refine_frequencies

    rng = np.random.default_rng(22)
    theta = np.cumsum(rng.uniform(0.05, 0.15, 50_000))
    dec, found = [0.01, 0.15915], [0.0893, 0.3183]
    y = (1 + 0.02 * np.sin(2 * np.pi * 0.01 * theta) + 0.01 * np.sin(2 * np.pi * 0.15915 * theta + 1)
         + 0.005 * np.sin(2 * np.pi * 0.08931 * theta - 2) + 0.004 * np.sin(2 * np.pi * 0.31831 * theta + 0.3)
         + rng.normal(0, 0.02, theta.size))
    base = NormalEquations.accumulate(theta, y, dec, 2)
    ext = base.extend(theta, y, found)
    full = NormalEquations.accumulate(theta, y, dec + found, 2, free=[2, 3])
    scale = np.sqrt(np.outer(np.diag(full.G), np.diag(full.G)))
    assert np.max(np.abs(ext.G - full.G) / scale) < 1e-6
    assert np.allclose(ext.frequency_step()[0], full.frequency_step()[0], rtol=1e-4, atol=1e-12)
    f1, se1, eq1 = refine_frequencies(theta, y, dec + found, [2, 3], degree=2, base=base)
    f2, se2, eq2 = refine_frequencies(theta, y, dec + found, [2, 3], degree=2)
    assert np.allclose(f1, f2, rtol=1e-9) and np.allclose(eq1.fit().amplitude, eq2.fit().amplitude, rtol=1e-5)
    assert f1[2] == pytest.approx(0.08931, abs=2e-5) and f1[3] == pytest.approx(0.31831, abs=2e-5)


def test_single_precision_search_spectrum_matches_double_precision():
    from scipy.signal import get_window

    from gearspec.spectrum.fft import hann_spectrum, hann_spectrum32

    for n in (4, 17, 1000):
        w = get_window("hann", n, fftbins=False)
        _, _, wsum, enbw = hann_spectrum32(np.ones(n), 1.0)
        assert wsum == pytest.approx(w.sum(), rel=1e-12) and enbw == pytest.approx(n * (w @ w) / w.sum()**2, rel=1e-12)
    rng = np.random.default_rng(23)
    n = 20001
    m = np.arange(n)
    coef = np.array([0.4, 0.003, -0.002])
    a, b = -1.0, 2.0 / (n - 1)
    from numpy.polynomial import legendre

    v = legendre.legval(a + b * m, coef) + 0.01 * np.sin(2 * np.pi * 0.0123 * m) + rng.normal(0, 0.05, n)
    s64, df, ws, en = hann_spectrum(v - legendre.legval(a + b * m, coef), 1.0)
    s32, df2, ws2, en2 = hann_spectrum32(v, 1.0, legendre=(coef, a, b))
    assert df == df2 and ws == pytest.approx(ws2) and en == pytest.approx(en2)
    p64, p32 = np.abs(s64) ** 2, np.abs(s32.astype(complex)) ** 2
    noise = np.median(p64)
    assert np.max(np.abs(p32 - p64)) < 1e-3 * noise + 1e-5 * p64.max()


def test_resampling_fast_path_equals_cell_averages():
    rng = np.random.default_rng(24)
    from gearspec.spectrum.resample import resample_uniform

    for jitter in (0.3, 0.8):  # within 0.49 of a cell of the grid (fast path), and beyond
        n = 50_000
        theta = 5.0 + (np.arange(n) + rng.uniform(-jitter, jitter, n)) * 0.01
        theta.sort()
        y = np.sin(theta) + rng.normal(0, 0.1, n)
        for th, yy in ((theta, y), (theta[::-1], y[::-1])):
            lo, h, v = resample_uniform(th, yy)
            # the general method, spelt out: cell means, then linear interpolation at the grid
            m = int(np.floor((th.max() - lo) / h)) + 1
            cell = np.minimum(((th - lo) / h + 0.5).astype(int), m - 1)
            cnt = np.bincount(cell, minlength=m)
            ok = cnt > 0
            xs = np.bincount(cell, th, m)[ok] / cnt[ok]
            ys = np.bincount(cell, yy, m)[ok] / cnt[ok]
            assert np.array_equal(v, np.interp(lo + h * np.arange(m), xs, ys))


def test_segments_in_threads_give_the_same_result():
    rec, _ = plateau_recording([40, -40, 80, -80], ripples=[Ripple(F_MOTOR, 1e-3, 0.5), Ripple(1.234, 5e-4, 0.1)],
                               level=0.01, duration=3, fs=1000, noise=1e-4, gear=SILO4, seed=3)
    one = analyze(rec, periodogram="fft", workers=1)
    two = analyze(rec, periodogram="fft", workers=2, keep_spectra=True)
    assert len(one.segments) == 4
    import json

    assert json.dumps(one.to_dict(), default=float) == json.dumps(
        {**two.to_dict(), "settings": one.to_dict()["settings"]}, default=float)


def test_an_empty_user_segmentation_is_refused_not_replaced_by_the_defaults():
    """Issue 10 item 8: an empty Segmentation is falsy; ``segmentation or find_segments(...)``
    dropped the user's options (the JSON then said ``window: auto``) and analysed other segments."""
    from gearspec.errors import InputError
    from gearspec.segment import find_segments

    rec, _ = plateau_recording([40, -40], ripples=[Ripple(F_MOTOR, 1e-3, 0.5)], level=0.01, duration=3,
                               fs=1000, noise=1e-4, gear=SILO4, seed=2)
    assert len(find_segments(rec)) == 2  # the defaults find both plateaus
    seg = find_segments(rec, min_speed=1e3)  # faster than any plateau: nothing
    assert len(seg) == 0 and seg.settings.get("min_speed") == 1e3
    with pytest.raises(InputError, match="no constant-speed segment"):
        analyze(rec, segmentation=seg)
    # a non-empty user segmentation is used as given, its settings recorded
    seg2 = find_segments(rec, window=0.2)
    res = analyze(rec, segmentation=seg2)
    assert res.settings["window"] == seg2.settings["window"] != "auto"


# ---------------------------------------------------------------------- the search's rules, one at a time
def test_search_excludes_slow_declared_and_taken_peaks_and_keeps_the_strongest_first():
    """``_search`` on a flat noise power of exactly 1 with spikes: the local noise level is then 1
    (the spikes are above 10 x the median / ln 2 and left out of every block), so z is the spike's
    power and every spike of 1000 or more is significant (fap ~ 0); a spike between equal
    neighbours is refined to its own bin.  Which spikes come back is decided by the rules alone."""
    from gearspec.spectrum.search import _Grid, _LocalNoise, _search
    span, oversample = 10.0, 2.0
    df, base, nbin = 1 / (span * oversample), 1 / span, 400          # f(i) = 0.1 + 0.05 i, up to 20.05
    grid = _Grid(base, df, 0, nbin)
    power = np.ones(nbin)

    def spike(f, p):
        i = round((f - base) / df)
        power[i] = p
        return grid.at(i)

    spike(0.15, 5000.0)   # 1.5 cycles in the segment: below f_found_min = 2 / span (the polynomial's)
    spike(5.1, 4000.0)    # within 1.5 resolution steps (0.15) of the declared line at 5.0
    spike(8.2, 3000.0)    # within the guard (3 steps = 0.3) of 8.0, found before
    f_a = spike(3.0, 2000.0)
    spike(3.2, 1500.0)    # within the guard of the stronger 3.0
    f_b = spike(12.0, 1000.0)
    noise = _LocalNoise(power, width=int(100 * oversample), min_width=int(20 * oversample), mask=None, enbw=1.0)
    assert noise.level(np.array([10, 150, 390])) == pytest.approx([1.0, 1.0, 1.0], rel=1e-12)
    kw = {"span": span, "guard": 3 / span, "f_found_min": 2 / span, "fap_threshold": 0.01,
          "m_eff": nbin / oversample, "oversample": oversample}
    found = _search(power, grid, noise, [5.0], [8.0], room=8, **kw)
    assert found == [pytest.approx(f_a, rel=1e-12), pytest.approx(f_b, rel=1e-12)]
    assert f_a == pytest.approx(3.0, rel=1e-12) and f_b == pytest.approx(12.0, rel=1e-12)
    # room for one: the strongest allowed
    assert _search(power, grid, noise, [5.0], [8.0], room=1, **kw) == [pytest.approx(3.0, rel=1e-12)]
    # and without the declared / taken lines their spikes are found (the rules, not the powers, excluded them)
    assert len(_search(power, grid, noise, [], [], room=8, **kw)) == 4


def test_z_floor_is_the_known_level_bound_of_the_false_alarm_probability():
    # a known noise level: P(one frequency > z) = exp(-z), over m: 1 - (1 - exp(-z))^m; the floor is
    # the z where this equals the threshold: -ln(1 - (1 - fap)^(1/m)), lowered by 1e-9 for rounding
    from gearspec.spectrum.search import _z_floor
    from gearspec.spectrum.periodogram import false_alarm_probability
    for fap, m, z in ((0.01, 1.0, 4.60517), (0.01, 1000.0, 11.50791), (0.001, 200.0, 12.20557)):
        zf = _z_floor(fap, m)
        assert zf == pytest.approx(-math.log(1 - (1 - fap) ** (1 / m)), rel=1e-8)
        assert zf == pytest.approx(z, abs=1e-5)          # evaluated to 5 decimals
        assert false_alarm_probability(zf, m) == pytest.approx(fap, rel=1e-6)
        assert false_alarm_probability(zf * 1.001, m) < fap < false_alarm_probability(zf * 0.999, m)


def test_local_noise_falls_back_to_the_median_where_no_block_has_a_level():
    # every bin masked (all of them near fitted lines): no block has a level; the level is the
    # median power everywhere (the documented fallback), and no bins are counted
    from gearspec.spectrum.search import _LocalNoise
    power = np.arange(1.0, 101.0)
    nm = _LocalNoise(power, width=200, min_width=40, mask=np.ones(100, bool), enbw=1.0)
    np.testing.assert_array_equal(nm.level(np.array([0, 50, 99])), [50.5, 50.5, 50.5])
    np.testing.assert_array_equal(nm.bins(np.array([0, 99])), [0.0, 0.0])
    assert nm.lowest() == 0.0


def test_noise_blocks_fold_a_runt_last_block_into_its_neighbour():
    # hand-computed edges for 985 bins, width 200, min_width 40, relative 0.3: growing blocks
    # 0, 40, 80, 120, 160, 208, 270, 351, 456, 592, 769, one full block to 969, and 16 bins left
    # (< min_width / 2 = 20): folded into the block before, which ends at 985
    from gearspec.spectrum.periodogram import noise_blocks
    centres, levels, counts = noise_blocks(np.ones(985), width=200, min_width=40)
    edges = np.array([0, 40, 80, 120, 160, 208, 270, 351, 456, 592, 769, 985])
    np.testing.assert_array_equal(centres, 0.5 * (edges[:-1] + edges[1:] - 1))
    np.testing.assert_array_equal(counts[:-1], np.diff(edges)[:-1])
    np.testing.assert_array_equal(levels, 1.0)
    # 20 bins left (not a runt): a block of their own
    c2, _, k2 = noise_blocks(np.ones(989), width=200, min_width=40)
    np.testing.assert_array_equal(c2[-2:], [0.5 * (769 + 969 - 1), 0.5 * (969 + 989 - 1)])
    assert k2[-1] == 20


def test_autogrid_from_a_given_lowest_frequency():
    # span 9.99: df = 1 / (2 x 9.99); the lowest frequency is the one asked, never below df (0 or
    # a negative one would be the mean, not a line); nf counts the grid points up to fmax
    theta = np.arange(1000) * 0.01
    ls = LombScargle(theta, np.sin(2 * np.pi * 3 * theta))
    df = 1 / (2 * 9.99)
    assert ls.autogrid(oversample=2, fmax=5.0) == (pytest.approx(1 / 9.99), pytest.approx(df), 98)
    assert ls.autogrid(oversample=2, fmax=5.0, fmin=1.3) == (1.3, pytest.approx(df), 74)
    assert ls.autogrid(oversample=2, fmax=5.0, fmin=0.0) == (pytest.approx(df), pytest.approx(df), 99)


def _two_lines(n=4000, h=0.01, seed=0):
    """Lines of 0.02 at 3 and at 10 cycles per unit, white noise 0.002: amplitude se
    0.002 sqrt(2 / 4000) = 4.5e-5."""
    rng = np.random.default_rng(seed)
    th = np.arange(n) * h
    return th, 0.5 + 0.02 * np.sin(2 * np.pi * 3 * th + 0.3) + 0.02 * np.sin(2 * np.pi * 10 * th) \
        + 0.002 * rng.standard_normal(n)


def test_max_frequency_caps_the_search():
    th, y = _two_lines()
    both = analyze_segment(th, y)
    assert sorted(round(p.frequency, 3) for p in both.peaks) == [3.0, 10.0]
    capped = analyze_segment(th, y, max_frequency=5.0)
    assert len(capped.peaks) == 1
    p = capped.peaks[0]
    # frequency se ~ sqrt(6) se_A / (pi A span) ~ 5e-5: 1e-3 is 20 se; amplitude 10 se
    assert p.frequency == pytest.approx(3.0, abs=1e-3) and p.amplitude == pytest.approx(0.02, abs=5e-4)


def test_auto_periodogram_is_lomb_scargle_up_to_the_limit_then_fft(monkeypatch):
    from gearspec.spectrum import analysis
    th, y = _two_lines()

    def run(p):
        s = analyze_segment(th, y, periodogram=p, keep_spectra=True)
        return [(q.frequency, q.snr, q.fap) for q in s.peaks], s.ls_frequency

    ls, fft = run("lombscargle"), run("fft")
    assert ls[0] != fft[0]          # the two paths differ (noise level, grid): the comparison can tell them apart
    auto = run("auto")              # 4000 samples <= LS_MAX_SAMPLES
    assert auto[0] == ls[0] and np.array_equal(auto[1], ls[1])
    monkeypatch.setattr(analysis, "LS_MAX_SAMPLES", 3999)
    auto = run("auto")              # one sample over the limit
    assert auto[0] == fft[0] and np.array_equal(auto[1], fft[1])


def test_a_line_too_slow_for_the_segment_is_skipped_with_its_kind_and_cycles():
    # spur 3:1 seen from the motor: output shaft 1/(6 pi) = 0.0531, motor shaft 1/(2 pi) = 0.159
    # cycles/rad; over 40 rad they make 2.12 and 6.37 cycles: with min_cycles 3 the output shaft
    # is skipped as too slow (and absorbed by the polynomial), the motor shaft measured
    gear = GearTrain.from_dict({"name": "g", "reference": "motor", "stages": [{"name": "s", "kind": "spur", "ratio": 3.0}]})
    rng = np.random.default_rng(4)
    th = np.linspace(0.0, 40.0, 4000)
    f_out, f_mot = 1 / (6 * np.pi), 1 / (2 * np.pi)
    y = 0.5 + 0.01 * np.sin(2 * np.pi * f_out * th) + 0.02 * np.sin(2 * np.pi * f_mot * th + 0.4) \
        + 0.002 * rng.standard_normal(th.size)
    s = analyze_segment(th, y, gear, min_cycles=3.0, max_peaks=0)
    assert len(s.skipped) == 1
    sk = s.skipped[0]
    assert (sk["label"], sk["kind"]) == ("output shaft", "too_slow")
    assert sk["frequency"] == pytest.approx(f_out, rel=1e-12)
    assert sk["reason"].startswith("2.12 cycles in the segment (< 3)")
    assert [p.label for p in s.peaks] == ["motor shaft"]
    assert s.peaks[0].amplitude == pytest.approx(0.02, abs=5e-4)   # se 4.5e-5 (noise 0.002, 4000 samples)
    assert s.peaks[0].phase == pytest.approx(0.4, abs=0.03)         # se 2.2e-3 rad
