"""Known-answer tests of the toolbox's decision rules and estimators, one rule at a time.

Each test pins a rule to a number that follows from its definition (a tabulated t quantile, a
closed-form statistic, an exact DFT bin, an exact derivative, a counted row), so that a
deliberate bug in that rule -- a Bonferroni correction dropped, a gate switched off, folds dealt
by sample, a factor 2 lost, an inertia torque added instead of subtracted, a row counted twice --
fails here, fast, instead of surviving behind the end-to-end tests.
"""

from __future__ import annotations

import math
from collections import Counter
from types import SimpleNamespace

import numpy as np
import pytest

from gearspec import identify
from gearspec.diagnose.data import DiagnoseData
from gearspec.diagnose.loop import _decide, _Folds, critical_z, folds_of
from gearspec.fitdata import FitData

# ====================================================================== 1. acceptance rule of the loop
# One-sided upper t quantiles t_{1-p, dof}, written as numbers from a printed Student's t table
# (3 decimals; p = 0.0025 and 0.0005 are the table's two-sided 0.005 and 0.001 columns); the
# tolerance 5e-4 is the table's rounding.
T_TABLE = {(0.01, 9): 2.821, (0.005, 9): 3.250, (0.0025, 9): 3.690, (0.001, 9): 4.297,
           (0.0005, 9): 4.781, (0.01, 10): 2.764, (0.01, 4): 3.747, (0.01, 1): 31.821}


@pytest.mark.parametrize("alpha, candidates, groups, p", [
    (0.01, 1, 10, 0.01),       # one candidate: no correction, 9 dof
    (0.01, 2, 10, 0.005),      # Bonferroni: alpha / 2
    (0.01, 4, 10, 0.0025),     # t_{1-0.01/4, 9}
    (0.01, 10, 10, 0.001),
    (0.01, 20, 10, 0.0005),
    (0.01, 1, 11, 0.01),       # 10 dof
    (0.01, 1, 5, 0.01),        # 4 dof
    (0.01, 1, 2, 0.01),        # 1 dof
    (0.01, 1, 1, 0.01),        # one group: dof floored at 1
    (0.01, 0, 10, 0.01),       # no candidate (validation with nothing accepted): as one
])
def test_critical_z_is_the_bonferroni_t_quantile(alpha, candidates, groups, p):
    dof = max(groups - 1, 1)
    assert critical_z(alpha, candidates, groups) == pytest.approx(T_TABLE[(p, dof)], abs=5e-4)


def test_critical_z_rises_with_the_number_of_candidates():
    z = [critical_z(0.01, m, 10) for m in (1, 2, 4, 10, 20, 100)]
    assert np.all(np.diff(z) > 0)
    # and falls towards the normal quantile with many groups (t -> normal): z_{0.99} = 2.326
    assert critical_z(0.01, 1, 10_000) == pytest.approx(2.326, abs=1e-3)


def _decide_case(z_target: float, *, G: int = 10, s: float = 1.0, fold_of_group=None):
    """The smallest inputs of ``_decide`` whose numbers are known in closed form.

    G groups of 8 rows (np.array_split into 8 blocks: one row per block).  The model as it stands
    predicts p0 = 0, so y = r0.  The candidate predicts a constant correction Delta = d on every
    row; the held-out residual is r0_g = d + e_g with e_g = +s (even g), -s (odd g), so r1 = e_g.
    Per group: <r0, Delta> = 8 d (d + e_g); <r1, Delta>^2 = 64 e^2 d^2 (whole group) beats the sum
    over blocks 8 e^2 d^2, so V_g = 64 s^2 d^2.  With sum_g e_g = 0 (G even):

        Z = sum 8 d (d + e_g) / sqrt(64 G s^2 d^2) = sqrt(G) d / s,
        rmse before^2 = d^2 + s^2, after = s, gain = 1 - s / sqrt(d^2 + s^2).

    Folds: pairs (2i, 2i+1) by default: every fold's drop 16 d^2 > 0, consistency 1.
    ``d`` is set from the Z wanted: d = Z s / sqrt(G)."""
    d = z_target * s / math.sqrt(G)
    n = 8
    e = np.where(np.arange(G) % 2 == 0, s, -s)
    r0 = np.repeat(d + e, n)
    v = np.repeat(1.0 + 0.1 * np.arange(G), n)
    fd = FitData(theta=np.arange(G * n, dtype=float), v=v, y=r0.copy(), segment=np.repeat(np.arange(G), n))
    dd = DiagnoseData.from_fitdata(fd)
    fold = np.arange(G) // 2 if fold_of_group is None else np.asarray(fold_of_group)
    rnd = SimpleNamespace(dd=dd, fold=fold, K=int(fold.max()) + 1)
    fr = _Folds(r0=r0, p1=np.full(G * n, d), proposals=[], contribution=None, n_par=2)
    return rnd, fr, d


def test_decide_z_equals_the_closed_form():
    rnd, fr, d = _decide_case(3.0)
    ev = _decide(rnd, fr, None, z_crit=2.0, min_gain=0.01)
    assert ev.z == pytest.approx(math.sqrt(10) * d / 1.0, rel=1e-12)   # = 3.0; float rounding only
    assert ev.z == pytest.approx(3.0, rel=1e-12)
    assert ev.gain == pytest.approx(1 - 1 / math.sqrt(d * d + 1), rel=1e-12)
    assert ev.rmse_holdout_before == pytest.approx(math.sqrt(d * d + 1), rel=1e-12)
    assert ev.rmse_holdout_after == pytest.approx(1.0, rel=1e-12)
    assert ev.consistency == 1.0
    assert ev.drop == pytest.approx(10 * 8 * d * d, rel=1e-12)       # sum_g 8 (d^2 + 2 d e_g)
    np.testing.assert_allclose(ev.fold_drops, 16 * d * d, rtol=1e-12)
    assert ev.passed


@pytest.mark.parametrize("m", [1, 4])
def test_decide_z_just_above_passes_just_below_fails(m):
    zc = critical_z(0.01, m, 10)
    for factor, passed in ((1 + 1e-6, True), (1 - 1e-6, False)):
        rnd, fr, _ = _decide_case(zc * factor)
        ev = _decide(rnd, fr, None, z_crit=zc, min_gain=0.01, consistency=0.9)
        # the other two gates are far from their thresholds: only the Z rule decides
        assert ev.consistency == 1.0 and ev.gain > 0.2
        assert ev.z == pytest.approx(zc * factor, rel=1e-9)
        assert ev.passed is passed, (m, factor, ev.reason)
        if not passed:
            assert "held-out Z" in ev.reason and "folds" not in ev.reason and "rmse" not in ev.reason


def test_decide_z_between_uncorrected_and_bonferroni_fails_with_many_candidates():
    # t_{0.99, 9} = 2.821 < Z = 3.2 < t_{1-0.01/4, 9} = 3.690
    rnd, fr, _ = _decide_case(3.2)
    one = _decide(rnd, fr, None, z_crit=critical_z(0.01, 1, rnd.dd.n_groups), min_gain=0.01)
    four = _decide(rnd, fr, None, z_crit=critical_z(0.01, 4, rnd.dd.n_groups), min_gain=0.01)
    assert one.passed
    assert not four.passed and "held-out Z 3.20 below 3.69" in four.reason


def test_decide_consistency_gate():
    # d = s: Z = sqrt(10) = 3.16 > 2.82 and gain 1 - 1/sqrt(2) = 0.29, both pass; the groups that
    # gain (drop 8 (d^2 + 2 d s) = 24) all in folds 0-1, those that lose (8 (d^2 - 2 d s) = -8)
    # in folds 2-4: consistency 5 x 24 / (5 x 24 + 5 x 8) = 0.75 < 0.9
    fold = np.array([0, 2, 0, 2, 1, 3, 1, 3, 1, 4])
    rnd, fr, d = _decide_case(math.sqrt(10), fold_of_group=fold)
    assert d == pytest.approx(1.0)
    ev = _decide(rnd, fr, None, z_crit=critical_z(0.01, 1, 10), min_gain=0.01, consistency=0.9)
    assert ev.consistency == pytest.approx(0.75, rel=1e-12)
    assert ev.z > ev.z_crit and ev.gain > 0.01
    assert not ev.passed and "folds carrying only 75 %" in ev.reason
    assert _decide(rnd, fr, None, z_crit=ev.z_crit, min_gain=0.01, consistency=0.7).passed


def test_decide_gain_gate():
    # d = s with paired folds: Z = 3.16, consistency 1, gain 1 - 1/sqrt(2) = 0.2929
    rnd, fr, _ = _decide_case(math.sqrt(10))
    zc = critical_z(0.01, 1, 10)
    below = _decide(rnd, fr, None, z_crit=zc, min_gain=0.30)
    above = _decide(rnd, fr, None, z_crit=zc, min_gain=0.29)
    assert below.gain == pytest.approx(1 - 1 / math.sqrt(2), rel=1e-12)
    assert below.z > zc and below.consistency == 1.0
    assert not below.passed and "needs a fall of 30 %" in below.reason
    assert above.passed


# ====================================================================== 2. fold rules
def _segments_data(n_pos: int, n_neg: int, sizes=None, levels=None, sigma: float = 0.0, seed: int = 0):
    """FitData of n_pos positive and n_neg negative constant-speed segments, the directions
    alternating in time (back and forth) while both last, each direction's speeds (distinct) in a
    shuffled order; segment g has sizes[g] rows and friction level levels[g] plus white noise sigma."""
    G = n_pos + n_neg
    sizes = np.full(G, 50) if sizes is None else np.asarray(sizes)
    levels = np.zeros(G) if levels is None else np.asarray(levels, float)
    rng = np.random.default_rng(seed)
    sign = np.empty(G)
    p = q = 0
    for g in range(G):
        if (g % 2 == 0 and p < n_pos) or q >= n_neg:
            sign[g], p = 1.0, p + 1
        else:
            sign[g], q = -1.0, q + 1
    speed = np.empty(G)
    speed[sign > 0] = 1.0 + 0.5 * rng.permutation(n_pos)
    speed[sign < 0] = 1.0 + 0.5 * rng.permutation(n_neg)
    seg = np.repeat(np.arange(G), sizes)
    v = np.repeat(sign * speed, sizes)
    y = np.repeat(levels, sizes) + sigma * rng.standard_normal(len(seg))
    theta = np.cumsum(v) * 1e-3
    return FitData(theta=theta, v=v, y=y, segment=seg)


def _check_fold_rules(fold_rows: np.ndarray, fd: FitData, k: int):
    """Every segment in exactly one fold; per direction the folds' group counts differ by at most
    one, both directions in every fold when each has at least k groups, and any k neighbouring
    speeds of a direction in k different folds (dealt round-robin over speed)."""
    seg = fd.segment
    fold_of_seg = {}
    for g in np.unique(seg):
        f = np.unique(fold_rows[seg == g])
        assert len(f) == 1, f"segment {g} is split over folds {f}"
        fold_of_seg[g] = int(f[0])
    assert set(fold_of_seg.values()) == set(range(k))
    dirs = {g: int(fd.direction[seg == g][0]) for g in fold_of_seg}
    speed = {g: float(np.mean(np.abs(fd.v[seg == g]))) for g in fold_of_seg}
    for d in (1, -1):
        gs = [g for g in fold_of_seg if dirs[g] == d]
        counts = np.bincount([fold_of_seg[g] for g in gs], minlength=k)
        assert counts.max() - counts.min() <= 1, (d, counts)
        if len(gs) >= k:
            assert counts.min() >= 1, (d, counts)
        # dealt round-robin over speed: any k neighbouring speeds of a direction in k different folds
        by_speed = [fold_of_seg[g] for g in sorted(gs, key=speed.get)]
        for i in range(max(len(by_speed) - k + 1, 1)):
            window = by_speed[i:i + k]
            assert len(set(window)) == len(window), (d, by_speed)
    return fold_of_seg


@pytest.mark.parametrize("n_pos, n_neg, k", [(9, 10, 5), (9, 9, 5), (5, 5, 5), (12, 7, 3), (3, 2, 2)])
def test_identify_folds_deal_whole_segments_by_direction(n_pos, n_neg, k):
    G = n_pos + n_neg
    sizes = 30 + 7 * np.arange(G)  # unequal segments: dealing rows would split them
    fd = _segments_data(n_pos, n_neg, sizes)
    fold = identify.validate._folds(fd, "segment", k)
    assert fold.shape == (len(fd),)
    _check_fold_rules(fold, fd, k)


def test_identify_folds_the_issue_case_nine_positive_ten_negative():
    fd = _segments_data(9, 10, 40 + 3 * np.arange(19))
    fold_of_seg = _check_fold_rules(identify.validate._folds(fd, "segment", 5), fd, 5)
    d = {g: int(fd.direction[fd.segment == g][0]) for g in fold_of_seg}
    pos = np.bincount([f for g, f in fold_of_seg.items() if d[g] > 0], minlength=5)
    neg = np.bincount([f for g, f in fold_of_seg.items() if d[g] < 0], minlength=5)
    assert sorted(pos) == [1, 2, 2, 2, 2] and sorted(neg) == [2, 2, 2, 2, 2]
    assert [np.count_nonzero(np.array(list(fold_of_seg.values())) == f) for f in range(5)] == [4, 4, 4, 4, 3]


@pytest.mark.parametrize("n_pos, n_neg, k", [(9, 10, 5), (9, 9, 5), (5, 5, 5), (12, 7, 3), (2, 2, 5), (3, 1, 4)])
def test_loop_folds_of_deal_whole_groups_balanced(n_pos, n_neg, k):
    G = n_pos + n_neg
    fd = _segments_data(n_pos, n_neg, 30 + 7 * np.arange(G))
    dd = DiagnoseData.from_fitdata(fd)
    fog = folds_of(dd, k)
    assert fog.shape == (dd.n_groups,) == (G,)
    kk = max(2, min(k, G))
    _check_fold_rules(fog[dd.group], dd.fit, kk)
    # the rotation of the negative direction: the folds' total group counts differ by at most one
    total = np.bincount(fog, minlength=kk)
    assert total.max() - total.min() <= 1, total


def _memoriser_case(G_pos=9, G_neg=10, n=200, s=1.0, sigma=0.1, seed=3):
    """Segments with levels of spread exactly s (mean 0, mean square s^2) and white noise sigma."""
    rng = np.random.default_rng(seed)
    mu = rng.standard_normal(G_pos + G_neg)
    mu = s * (mu - mu.mean()) / np.sqrt(np.mean((mu - mu.mean()) ** 2))
    return _segments_data(G_pos, G_neg, np.full(G_pos + G_neg, n), mu, sigma, seed), mu


def _memorise(train: FitData) -> dict:
    return {int(g): float(np.mean(train.y[train.segment == g])) for g in np.unique(train.segment)}


def _recall(means: dict, data: FitData) -> np.ndarray:
    return np.array([means.get(int(g), 0.0) for g in data.segment])  # an unseen segment: the prior mean 0


def test_holdout_by_segment_does_not_leak_a_memorised_segment_mean():
    # known answer: a model that memorises every segment's mean has in-sample error sigma
    # sqrt(1 - 1/n) (~ sigma); held out by whole segments it has never seen the segment and predicts
    # 0, so its error is sqrt(s^2 + sigma^2) (levels of mean square exactly s^2).  Tolerance 2 %:
    # the noise's sample variance over 3800 rows is within 3 x sqrt(2/3800) = 7 % of sigma^2 = 1 %
    # of s^2 + sigma^2, and the cross term 2 <mu, e>/N ~ 3 x 2 s sigma / sqrt(3800) = 1 %.
    s, sigma = 1.0, 0.1
    fd, _ = _memoriser_case(s=s, sigma=sigma)
    def residual(m, t):
        return t.y - _recall(m, t)

    inside = float(np.sqrt(np.mean(residual(_memorise(fd), fd) ** 2)))
    held, why = identify.holdout(_memorise, fd, by="segment", folds=5, residual=residual)
    assert why is None
    assert inside == pytest.approx(sigma, rel=0.05)      # 3 x 1/sqrt(2 x 3800) = 3.4 % on an rmse
    assert held == pytest.approx(math.hypot(s, sigma), rel=0.02)
    assert held > 5 * inside


def test_loop_folds_do_not_leak_a_memorised_segment_mean():
    # the same known answer as above, with the closed loop's folds (folds_of over DiagnoseData)
    s, sigma = 1.0, 0.1
    fd, _ = _memoriser_case(s=s, sigma=sigma)
    dd = DiagnoseData.from_fitdata(fd)
    rows_fold = folds_of(dd, 5)[dd.group]
    f = dd.fit
    r = np.empty(len(f))
    for k in range(5):
        test = rows_fold == k
        r[test] = f.y[test] - _recall(_memorise(f.subset(~test)), f.subset(test))
    held = float(np.sqrt(np.mean(r ** 2)))
    assert held == pytest.approx(math.hypot(s, sigma), rel=0.02)


# ====================================================================== 3. amplitude of the FFT spectra
# A sinusoid A sin(2 pi f0 x + phi) whose frequency is exactly bin k of the transform has, under a
# window w, the DFT (A/2i) [e^{i phi} W(0) - e^{-i phi} W(2k)] with W(0) = sum(w): the amplitude
# read as |X_k| 2 / sum(w) is A up to the window's leakage from the image at -f0, W(2k)/W(0), which
# for the Hann window ~1000 resolution bins away is below 1e-8.  So the known answer is A, to
# rounding: 1e-9 relative in double precision, 1e-5 in single precision (float32 rounding ~6e-8 per
# value, accumulated over a 4096-point transform: ~1e-6).
N_SP, H_SP = 4096, 2.0 ** -6         # samples and spacing (rad): theta = m h exactly in binary
A_SP, PHI_SP = 0.37, 0.8


def _bin_sinusoid(nfft: int, k: int, level: float = 0.5):
    x = np.arange(N_SP) * H_SP
    f0 = k / (nfft * H_SP)
    return x, f0, level + A_SP * np.sin(2 * np.pi * f0 * x + PHI_SP)


def test_order_spectrum_reads_a_bin_sinusoid_at_its_amplitude():
    import scipy.fft

    from gearspec.spectrum.fft import order_spectrum
    nfft = scipy.fft.next_fast_len(N_SP, real=True)
    for k in (300, 1000, 1700):
        _, f0, y = _bin_sinusoid(nfft, k)
        freq, amp = order_spectrum(y, H_SP)
        assert freq[k] == pytest.approx(f0, rel=1e-12)
        assert amp[k] == pytest.approx(A_SP, rel=1e-9)
    # and with padding (the bins of a 4x longer transform)
    _, f0, y = _bin_sinusoid(scipy.fft.next_fast_len(4 * N_SP, real=True), 4000)
    freq, amp = order_spectrum(y, H_SP, pad=4)
    assert freq[4000] == pytest.approx(f0, rel=1e-12) and amp[4000] == pytest.approx(A_SP, rel=1e-9)
    # the mean (bin 0 has no image to share with): a constant c reads c, not 2c, when not detrended
    _, amp = order_spectrum(np.full(N_SP, 0.5), H_SP, detrend=False)
    assert amp[0] == pytest.approx(0.5, rel=1e-12)


def test_hann_spectrum_and_its_single_precision_twin_give_the_amplitude():
    from scipy.signal import get_window

    from gearspec.spectrum.fft import hann_fft_length, hann_spectrum, hann_spectrum32
    nfft = hann_fft_length(N_SP, 2.0)
    k = 1000
    _, f0, y = _bin_sinusoid(nfft, k, level=0.0)
    spec, df, wsum, enbw = hann_spectrum(y, H_SP, pad=2.0)
    assert df * k == pytest.approx(f0, rel=1e-12)
    assert wsum == pytest.approx(get_window("hann", N_SP, fftbins=False).sum(), rel=1e-12)
    assert wsum == pytest.approx((N_SP - 1) / 2, rel=1e-12)          # closed form of the symmetric Hann
    assert enbw == pytest.approx(1.5 * N_SP / (N_SP - 1), rel=1e-12)  # n sum w^2 / (sum w)^2
    assert abs(spec[k]) * 2 / wsum == pytest.approx(A_SP, rel=1e-9)
    spec32, df32, wsum32, enbw32 = hann_spectrum32(y, H_SP, pad=2.0)
    assert spec32.dtype == np.complex64 and len(spec32) == len(spec)
    assert (df32, wsum32) == (pytest.approx(df, rel=1e-12), pytest.approx(wsum, rel=1e-12))
    assert enbw32 == pytest.approx(enbw, rel=1e-12)
    assert abs(spec32[k]) * 2 / wsum32 == pytest.approx(A_SP, rel=1e-5)


def test_analyze_segment_fft_amplitude_is_the_sinusoid_amplitude():
    from gearspec.spectrum import analyze_segment
    from gearspec.spectrum.fft import hann_fft_length
    nfft = hann_fft_length(N_SP, 2.0)   # analyze_segment's default oversample 2 on a grid of N_SP points
    k = 1000
    x, f0, y = _bin_sinusoid(nfft, k)
    s = analyze_segment(x, y, None, keep_spectra=True, periodogram="fft", max_peaks=0)
    assert s.fft_frequency[k] == pytest.approx(f0, rel=1e-6)          # float32 frequencies
    assert s.fft_amplitude[k] == pytest.approx(A_SP, rel=1e-5)
    # the peak is at the bin: its neighbours (half a resolution step off at padding 2) read lower
    assert s.fft_amplitude[k - 1] < A_SP and s.fft_amplitude[k + 1] < A_SP


# ====================================================================== 4. inertia removal
def _accelerating_recording(J: float, fs: float = 1000.0, T: float = 3.0, seed: int = 5):
    """Two runs at known constant accelerations: run 0 speeds up forwards (theta = 0.2 + 1.5 t +
    0.5 x 2.0 t^2), run 1 slows down backwards (theta = 4 - 3 t + 0.5 x 0.8 t^2).  The drive torque
    is a friction with ripple and noise plus J times the acceleration."""
    from gearspec.gears import GearTrain
    from gearspec.recording import Recording
    gear = GearTrain.from_dict({"name": "inertial", "reference": "motor", "inertia": J,
                                "stages": [{"name": "s", "kind": "spur", "ratio": 3.0}]})
    t1 = np.arange(int(T * fs)) / fs
    th0 = 0.2 + 1.5 * t1 + 0.5 * 2.0 * t1 ** 2
    th1 = 4.0 - 3.0 * t1 + 0.5 * 0.8 * t1 ** 2
    acc = np.concatenate([np.full(len(t1), 2.0), np.full(len(t1), 0.8)])
    theta = np.concatenate([th0, th1])
    d = np.concatenate([np.ones(len(t1)), -np.ones(len(t1))])
    rng = np.random.default_rng(seed)
    friction = d * (0.3 + 0.02 * np.sin(7 * theta)) + 0.004 * rng.standard_normal(len(theta))
    rec = Recording.from_arrays(t=np.concatenate([t1, t1 + T + 1.0]), theta=theta, torque=friction + J * acc,
                                run=np.repeat([0, 1], len(t1)), gear=gear)
    return rec, friction, acc


def test_inertia_torque_is_subtracted_at_the_known_acceleration():
    # the Savitzky-Golay filter (order 2) differentiates a quadratic exactly, edges included (its
    # edge mode fits the same polynomial): the estimated acceleration is 2.0 / 0.8 rad/s^2 to
    # rounding (eps |theta| / dt^2 ~ 1e-9), so y = tau - J a is the friction to 1e-8 Nm, where
    # J a = 0.1 / 0.04 Nm: "+" instead of "-" is off by 2 J a, ignoring J by J a.
    from gearspec.segment import Segment, Segmentation
    J = 0.05
    rec, friction, acc = _accelerating_recording(J)
    n1 = len(rec) // 2
    seg = Segmentation([Segment(0, 200, 2800, 1, 4.0), Segment(1, n1 + 100, n1 + 2900, -1, 1.8)],
                       Counter({"transient": 400 + 200}), len(rec))
    seg.check_ledger()
    fd = FitData.from_recording(rec, seg)
    rows = np.r_[200:2800, n1 + 100:n1 + 2900]
    np.testing.assert_allclose(fd.acc, acc[rows], rtol=0, atol=1e-6)
    np.testing.assert_allclose(fd.y, friction[rows], rtol=0, atol=1e-8)
    assert any("inertia removed" in note for note in fd.notes)
    # without inertia removal y is the drive torque itself
    raw = FitData.from_recording(rec, seg, inertia=False)
    np.testing.assert_array_equal(raw.y, rec.tau[rows])
    np.testing.assert_allclose(raw.y - fd.y, J * acc[rows], rtol=0, atol=1e-8)


# ====================================================================== 5. the exclusion ledger
def _ledger_drive(n: int = 4000, fs: float = 1000.0, seed: int = 9) -> dict:
    rng = np.random.default_rng(seed)
    t = np.arange(n) / fs
    theta = 0.3 + 2.0 * t
    torque = 0.2 + 0.02 * np.sin(5 * theta) + 0.005 * rng.standard_normal(n)
    return {"t": t, "theta": theta, "torque": torque}


def _spoil(d: dict) -> tuple[dict, Counter, set]:
    """Known faults: which rows go under which reason (0-based rows of the file)."""
    bad = {}
    # NaN / inf in t, theta or torque: 5 rows (row 100 has two bad cells: counted once)
    for col, i in (("torque", 100), ("t", 100), ("torque", 101), ("theta", 400), ("torque", 900), ("t", 1300)):
        d[col][i] = np.nan if col != "theta" else np.inf
        bad[i] = "nan_or_inf"
    # exact copies of the row before (t, theta and torque): 3 rows, two of them in a row
    for i in (1500, 2200, 2201):
        for values in d.values():
            values[i] = values[i - 1]
        bad[i] = "duplicate_time"
    # isolated repeated stamps with new values (2 of 4000 rows, below the 1 % of a coarse clock)
    for i in (1700, 3100):
        d["t"][i] = d["t"][i - 1]
        bad[i] = "duplicate_time"
    # stamped before the row before: 3 rows
    for i in (2500, 2800, 2801):
        d["t"][i] -= 0.0105
        bad[i] = "non_increasing_time"
    # the torque stuck at its maximum for 10 rows (>= 5 in a row, >= 0.2 % of the rows): saturation
    d["torque"][3300:3310] = np.nanmax(d["torque"]) + 0.05
    for i in range(3300, 3310):
        bad[i] = "saturation"
    return d, Counter(bad.values()), set(bad)


def test_loader_ledger_counts_every_reason_exactly():
    from gearspec.errors import GearspecWarning
    from gearspec.recording import Recording
    d, expected, rows = _spoil(_ledger_drive())
    assert expected == {"nan_or_inf": 5, "duplicate_time": 5, "non_increasing_time": 3, "saturation": 10}
    marker = np.arange(4000, dtype=float)       # an extra channel naming each row of the file
    with pytest.warns(GearspecWarning):
        rec = Recording.from_arrays(**d, row=marker)
    assert rec.excluded == expected
    assert rec.n_read == 4000 and len(rec) == 4000 - 23
    assert rec.n_read == len(rec) + sum(rec.excluded.values())
    # and they are exactly the rows that were spoiled
    assert set(range(4000)) - set(rec.data["row"].astype(int)) == rows


def test_loader_ledger_adds_up_over_files(tmp_path):
    from gearspec.errors import GearspecWarning
    from gearspec.recording import load_recording
    d1, e1, _ = _spoil(_ledger_drive())
    d2 = _ledger_drive(n=1000, seed=2)
    d2["torque"][[10, 20]] = np.nan
    np.savez(tmp_path / "a.npz", **d1)
    np.savez(tmp_path / "b.npz", **d2)
    with pytest.warns(GearspecWarning):
        rec = load_recording([tmp_path / "a.npz", tmp_path / "b.npz"])
    assert rec.excluded == e1 + Counter({"nan_or_inf": 2})
    assert rec.n_read == 5000 and len(rec) == 5000 - 25


def test_segmentation_ledger():
    from gearspec.recording import Recording
    from gearspec.segment import Segment, Segmentation, find_segments
    # check_ledger itself: one row too many or too few is a broken ledger
    ok = Segmentation([Segment(0, 10, 90, 1, 1.0)], Counter({"transient": 15, "standstill": 5}), 100)
    ok.check_ledger()
    for excluded in ({"transient": 14, "standstill": 5}, {"transient": 16, "standstill": 5}, {"transient": 15}):
        with pytest.raises(AssertionError, match="row ledger broken"):
            Segmentation(ok.segments, Counter(excluded), 100).check_ledger()
    # a run too short for any speed window (30 rows < 9 blocks of the shortest window) is all
    # 'transient': the ledger of a recording with it is the one without it plus exactly 30
    d = _ledger_drive()
    d["theta"] = 0.3 + np.where(d["t"] < 2.0, 2.0 * d["t"], 4.0 - 1.5 * (d["t"] - 2.0))  # forth and back
    base = Recording.from_arrays(**d)
    short = _ledger_drive(n=30, seed=4)
    both = Recording.from_arrays(**{k: np.concatenate([d[k], short[k] + (10.0 if k == "t" else 0.0)]) for k in d},
                                 run=np.repeat([0, 1], [4000, 30]))
    s0, s1 = find_segments(base), find_segments(both)
    assert {s.direction for s in s0} == {1, -1}
    assert [(s.start, s.stop, s.direction) for s in s1] == [(s.start, s.stop, s.direction) for s in s0]
    assert s1.excluded == s0.excluded + Counter({"transient": 30})
    assert s1.n_rows == 4030 == sum(s.n for s in s1) + sum(s1.excluded.values())


# ====================================================================== 6. the held-out error, edge cases
def _memoriser_levels(G_pos=9, G_neg=10, n=50):
    """Segments of n rows whose friction is exactly +1 or -1 (alternating), no noise: a model that
    memorises the training segments' means predicts 0 for an unseen one, so every held-out
    residual is exactly +-1 and the held-out rmse over any set of rows is exactly 1."""
    G = G_pos + G_neg
    return _segments_data(G_pos, G_neg, np.full(G, n), np.where(np.arange(G) % 2 == 0, 1.0, -1.0))


def _residual(m, t):
    return t.y - _recall(m, t)


def test_holdout_defaults_hold_out_whole_segments():
    # by="segment" and five folds are the defaults: the value is the memoriser's held-out error 1
    fd = _memoriser_levels()
    rmse, why = identify.holdout(_memorise, fd, residual=_residual)
    assert why is None and rmse == pytest.approx(1.0, rel=1e-12)
    assert identify.holdout_rmse(_memorise, fd, residual=_residual) == pytest.approx(1.0, rel=1e-12)
    # in sample the same model is exact: the held-out value is not the in-sample one
    assert np.all(_residual(_memorise(fd), fd) == 0.0)


def test_holdout_runs_with_two_segments_and_refuses_one():
    # two segments (one direction): two folds, each predicted from the other: rmse exactly 1
    fd = _memoriser_levels(2, 0)
    rmse, why = identify.holdout(_memorise, fd, by="segment", folds=5, residual=_residual)
    assert why is None and rmse == pytest.approx(1.0, rel=1e-12)
    one = _memoriser_levels(1, 0)
    assert identify.holdout(_memorise, one, residual=_residual) == (
        None, "cross-validation needs two held-out segments or more; the data have 1")
    assert identify.holdout_rmse(_memorise, one, residual=_residual) is None


def test_holdout_with_a_fold_that_cannot_be_fitted_says_how_much_it_covers():
    # a fit that needs segment 0 in its training data fails in the one fold holding segment 0:
    # the rmse comes from the other 4 folds (still exactly 1) and the reason counts the samples
    # they cover and the folds that failed out of those that ran
    from gearspec.errors import InputError
    fd = _memoriser_levels()
    fold = identify.validate._folds(fd, "segment", 5)
    left_out = int(np.count_nonzero(fold == fold[fd.segment == 0][0]))
    assert left_out in (150, 200)        # 19 segments of 50 rows in 5 folds: 4 or 3 per fold

    def needs_segment_0(train):
        if not np.any(train.segment == 0):
            raise InputError("segment 0 is needed")
        return _memorise(train)

    rmse, why = identify.holdout(needs_segment_0, fd, residual=_residual)
    assert rmse == pytest.approx(1.0, rel=1e-12)
    assert why == (f"from {950 - left_out} of 950 samples: 1 of 5 folds could not be fitted without their "
                   "segments (segment 0 is needed)")
    assert identify.holdout_rmse(needs_segment_0, fd, residual=_residual) == pytest.approx(1.0, rel=1e-12)


# ====================================================================== 7. acceptance: ties, the null case, the sentences
def test_decide_accepts_at_exactly_the_consistency_and_gain_asked():
    # each gate is ">=": a candidate exactly at the threshold passes.  _decide_case(3): consistency
    # exactly 1 (every fold gains), gain 1 - 1/sqrt(1.9) = 0.27452 (d^2 = 0.9, s = 1)
    rnd, fr, _ = _decide_case(3.0)
    ev = _decide(rnd, fr, None, z_crit=2.0, min_gain=0.01, consistency=0.9)
    assert ev.consistency == 1.0 and ev.gain == pytest.approx(1 - 1 / math.sqrt(1.9), rel=1e-12)
    assert _decide(rnd, fr, None, z_crit=2.0, min_gain=0.01, consistency=1.0).passed
    at_gain = _decide(rnd, fr, None, z_crit=2.0, min_gain=ev.gain, consistency=0.9)
    assert at_gain.passed, at_gain.reason
    assert not _decide(rnd, fr, None, z_crit=2.0, min_gain=math.nextafter(ev.gain, 1.0), consistency=0.9).passed
    # the sentence of an acceptance gives Z, the critical value and the fall of the held-out rmse
    assert ev.reason == "accepted: held-out Z 3.0 >= 2.00, rmse -27.45 %"


def test_decide_when_the_model_already_predicts_every_held_out_row():
    # r0 = 0 everywhere and the candidate changes nothing: no error before, none after, no Z (0),
    # a gain of 0 (not a division by zero), rejected
    rnd, _, _ = _decide_case(3.0)
    N = len(rnd.dd)
    fr = _Folds(r0=np.zeros(N), p1=rnd.dd.y.copy(), proposals=[], contribution=None, n_par=2)
    ev = _decide(rnd, fr, None, z_crit=2.0, min_gain=0.01)
    assert (ev.z, ev.gain, ev.rmse_holdout_before, ev.rmse_holdout_after) == (0.0, 0.0, 0.0, 0.0)
    assert not ev.passed and ev.reason.startswith("held-out Z 0.00 below 2.00")


def test_low_power_note_by_the_number_of_held_out_groups():
    # t_{0.99, dof} over z_{0.99} = 2.326: 10 groups 2.821 / 2.326 = 1.21 (<= 1.5: no note); 5 groups
    # 3.747 / 2.326 = 1.61 and 3 groups 6.965 / 2.326 = 2.99 (little power); 2 groups 31.82 / 2.326
    # = 13.7 (> 3: cannot reach significance)
    from gearspec.diagnose.loop import low_power_note
    assert low_power_note(critical_z(0.01, 1, 10), 10) == ""
    five = low_power_note(critical_z(0.01, 1, 5), 5)
    assert five.startswith("; with 5 held-out groups the test has little power: it needs Z above 3.7 (a t "
                           "quantile with 4 degrees of freedom) where many groups would need 2.3")
    assert "with 3 held-out groups the test has little power: it needs Z above 7.0" in low_power_note(
        critical_z(0.01, 1, 3), 3)
    assert ("with 2 held-out groups the test cannot reach significance in practice: it needs Z above 31.8"
            in low_power_note(critical_z(0.01, 1, 2), 2))
    # no note where there is no t quantile to compare: one group, or an infinite critical value
    assert low_power_note(2.821, 1) == ""
    assert low_power_note(math.inf, 10) == ""
