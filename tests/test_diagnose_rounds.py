"""What a round of the closed loop computes once for all its candidates (issue 13, "Scale"; helper
"diagloop"): the held-out prediction of the model as it stands, the training residual of a fold, the
held-out rmse of a round, a line's all-data search, the per-segment coverage tables of a line and the
amplitude-law choice from per-segment sums.  Known answers: the direct computation each replaces
(an explicit least-squares fit on the training rows, the per-sample rule, the stacked design of the
amplitude laws), equal to round-off (1e-9 relative: the same products summed in another order on
well-conditioned columns), and the plateau speeds and position-Nyquist rule of the recording.
Timings of the default twin are a benchmark, not a test.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import gearspec.diagnose as dg
from gearspec.diagnose import coverage, loop
from gearspec.diagnose.candidates import PeriodicCandidate, choose_amplitude_law
from gearspec.diagnose.context import Round
from gearspec.diagnose.frommodel import state_from_model
from gearspec.identify import MIN_CYCLES
from gearspec.model import FrictionModel
from gearspec.simulate import model_recording
from gearspec.spectrum import MEASURABLE_FRACTION
from gearspec.terms import amplitude_law

FS = 500.0
SPEEDS = np.geomspace(0.5, 16, 6)
MODEL = FrictionModel("stribeck", {"tau_c": 0.05, "tau_s": 0.08, "v_s": 1.5, "viscous": 2e-3,
                                   "harmonics": [{"frequency": 0.75, "amplitude": 4e-3, "phase": 0.3, "decay": 0.0,
                                                  "law": "const"}]})


@pytest.fixture(scope="module")
def dd():
    speeds = [x for s in SPEEDS for x in (s, -s)]
    rec, _ = model_recording(MODEL, speeds, noise=1e-3, seed=2, duration=1.5, fs=FS)
    return dg.DiagnoseData.from_recording(rec).without_edges()


@pytest.fixture(scope="module")
def rnd(dd):
    return Round(dd, state_from_model(MODEL, dd), loop.folds_of(dd, 4))


def _lstsq_held_out(rnd):
    """The held-out prediction fitted fold by fold with numpy's least squares on the training rows."""
    dd = rnd.dd
    p = np.zeros(len(dd))
    for f in range(rnd.K):
        test = rnd.fold == f
        tr, te = rnd.rows(~test), rnd.rows(test)
        beta = np.linalg.lstsq(rnd.X[tr], dd.y[tr], rcond=None)[0]
        p[te] = rnd.X[te] @ beta
    return p


def test_the_rounds_held_out_prediction_is_each_fold_fitted_without_it(rnd):
    p0 = rnd.held_out_prediction()
    want = _lstsq_held_out(rnd)
    scale = float(np.max(np.abs(want)))
    # 1e-9 of the torque scale: normal equations against an orthogonal factorisation on columns
    # whose condition number is below 1e4 (round-off 1e-16 x 1e4^2 at most)
    assert np.max(np.abs(p0 - want)) < 1e-9 * scale
    assert rnd.held_out_prediction() is p0                  # computed once per round
    # the same prediction the round's held-out rmse is measured with
    h = rnd.baseline_holdout()
    r = rnd.dd.y - want
    assert h["rmse"] == pytest.approx(math.sqrt(float(r @ r) / len(r)), rel=1e-9)
    again = rnd.baseline_holdout()
    assert again is not h and again["rmse"] == h["rmse"] and again["sse"] is h["sse"]


def test_every_candidate_of_a_round_shares_its_held_out_residual(rnd):
    """One array of rows per round, not one per candidate (18 candidates of 10^7 rows: 1.4 GB)."""
    from gearspec.diagnose.candidates import FixedCandidate, per_direction

    a = loop._run_folds(rnd, FixedCandidate("other", "offset", per_direction(rnd, "offset", key="offset")))
    b = loop._run_folds(rnd, PeriodicCandidate(2.1, 0.05))
    assert a.r0 is b.r0 and np.array_equal(a.r0, rnd.dd.y - rnd.held_out_prediction())
    assert not np.array_equal(a.p1, b.p1)                    # each its own held-out prediction


def test_a_folds_training_residual_is_the_residual_at_its_rows(rnd):
    dd = rnd.dd
    train = rnd.fold != 1
    rows = rnd.rows(train)
    r0 = rnd.train_residual(train)
    want = dd.y[rows] - rnd.X[rows] @ rnd.beta(train)
    assert r0.shape == want.shape and np.allclose(r0, want, rtol=0, atol=1e-12 * float(np.max(np.abs(dd.y))))
    assert rnd.train_residual(train) is r0
    with pytest.raises(ValueError):
        r0[0] = 0.0                                         # shared by every candidate: read-only
    assert np.array_equal(rnd.channel("speed"), np.abs(dd.at("v")))


def test_an_extended_round_without_standard_errors_fits_the_same(rnd):
    ext = Round(rnd.dd, rnd.state, rnd.fold, standard_errors=False)
    assert ext.fitted.nonlinear_se == {} and rnd.fitted.nonlinear_se   # the Stribeck velocity's SE
    assert np.array_equal(ext.X, rnd.X) and np.array_equal(ext.fitted.coef, rnd.fitted.coef)


def test_a_lines_all_data_search_is_kept_for_the_round_a_folds_is_not(rnd):
    cand = PeriodicCandidate(2.1, 0.05)
    every = rnd.all_groups()
    p = cand.propose(rnd, every)
    assert p is not None and cand.propose(rnd, every) is p       # accept_first asks again: the same
    train = rnd.fold != 0
    assert cand.propose(rnd, train) is not cand.propose(rnd, train)
    other = Round(rnd.dd, rnd.state, rnd.fold)
    assert cand.propose(other, other.all_groups()) is not p       # another round searches again


def test_line_coverage_from_segment_tables_is_the_per_sample_rule(dd):
    f = dd.fit
    nyq = coverage.segment_nyquist(dd)
    span = coverage.segment_span(dd)
    for freq in (0.05, 0.75, 12.0, 30.0, 400.0):
        res = freq < MEASURABLE_FRACTION * nyq
        assert np.array_equal(coverage.resolved(dd, freq), res)
        meas = res & (freq * span >= MIN_CYCLES)
        assert np.array_equal(coverage.measurable(dd, freq), meas)
        for d in (0, 1, -1):
            sel = meas & (f.v != 0) & ((f.direction == d) if d else True)
            want = (float(np.min(np.abs(f.v[sel]))), float(np.max(np.abs(f.v[sel])))) if sel.any() else None
            assert coverage.line_speed_range(dd, freq, d) == want
    # known answers: every plateau carries a line at 0.75 cycles/rad; at 30 cycles/rad the position
    # step v / fs resolves it below 0.8 of the position Nyquist frequency fs / (2 v), i.e. v < 6.7 rad/s
    lo, hi = coverage.line_speed_range(dd, 0.75, 1)
    assert lo == pytest.approx(SPEEDS[0], rel=1e-9) and hi == pytest.approx(SPEEDS[-1], rel=1e-9)
    _, hi30 = coverage.line_speed_range(dd, 30.0, -1)
    top = MEASURABLE_FRACTION * FS / (2 * 30.0)
    assert hi30 == pytest.approx(max(s for s in SPEEDS if s < top), rel=1e-9) and hi30 < SPEEDS[-1]
    assert coverage.line_speed_range(dd, 400.0, 1) is None     # above every plateau's limit


def _stacked_rss(theta, speed, seg, r, freq, law, b):
    """The amplitude law's residual sum of squares from its stacked design (segment means removed)."""
    x = 2 * np.pi * freq * theta
    g = amplitude_law(law, speed, b)

    def dm(a):
        out = a.copy()
        for s in np.unique(seg):
            out[seg == s] -= a[seg == s].mean()
        return out

    A = np.column_stack([dm(g * np.sin(x)), dm(g * np.cos(x))])
    rr = dm(r)
    beta = np.linalg.lstsq(A, rr, rcond=None)[0]
    e = rr - A @ beta
    return float(e @ e)


@pytest.mark.parametrize("true_law, decay", [("exp", 3.0 / 16), ("const", 0.0)])
def test_amplitude_law_from_segment_sums_equals_the_stacked_design(true_law, decay):
    """A line ``g(|v|) sin(2 pi f theta + 0.4)`` with known law, 1e-3 white noise, 8 plateaus of
    600 samples and a per-plateau offset: the law chosen is the truth's and every law's residual
    sum of squares is the stacked design's."""
    rng = np.random.default_rng(5)
    speeds = np.geomspace(0.5, 16, 8)
    seg = np.repeat(np.arange(8), 600)
    speed = np.repeat(speeds, 600)
    theta = np.concatenate([s * np.arange(600) / FS + rng.uniform(0, 3) for s in speeds])
    freq = 1.3
    r = (0.01 * amplitude_law(true_law, speed, decay) * np.sin(2 * np.pi * freq * theta + 0.4)
         + rng.normal(0, 1e-3, len(seg)) + np.repeat(rng.normal(0, 0.01, 8), 600))
    law, dec, rss = choose_amplitude_law(theta, speed, seg, r, freq)
    assert law == true_law
    if true_law == "exp":
        # the truth is on the grid (decay x top speed = 3)
        assert dec * speeds[-1] == pytest.approx(3.0, rel=1e-12)
    const = _stacked_rss(theta, speed, seg, r, freq, "const", 0.0)
    assert rss["const"] == pytest.approx(const, rel=1e-9)      # sums in another order: round-off
    if "exp" in rss:
        best = min(_stacked_rss(theta, speed, seg, r, freq, "exp", g / speeds[-1])
                   for g in (-1.0, -0.5, 0.25, 0.5, 1.0, 2.0, 3.0, 5.0))
        assert rss["exp"] == pytest.approx(best, rel=1e-9)


def test_amplitude_law_with_speed_varying_within_a_segment_uses_the_samples():
    """Whole trajectories: |v| varies within a segment; the stacked design is used (same answer)."""
    rng = np.random.default_rng(6)
    seg = np.repeat(np.arange(4), 800)
    speed = np.abs(np.concatenate([np.linspace(0.5, 8, 800) for _ in range(4)])) + 0.01 * rng.random(3200)
    theta = np.cumsum(speed) / FS
    r = 0.01 * amplitude_law("exp", speed, 0.3) * np.sin(2 * np.pi * 0.9 * theta) + rng.normal(0, 1e-3, 3200)
    law, _, rss = choose_amplitude_law(theta, speed, seg, r, 0.9)
    assert law == "exp"
    assert rss["const"] == pytest.approx(_stacked_rss(theta, speed, seg, r, 0.9, "const", 0.0), rel=1e-9)


def test_a_dense_spectrum_is_drawn_with_every_peak_and_trough():
    """10^5 frequencies, a line of 1e-3 Nm at 7.3 cycles/rad and a null of 1e-9 at 0.41 over a 1e-6
    noise floor: the drawn curve keeps both extremes at their frequencies in at most 2 x 3000 points."""
    from gearspec.plots.diagnose import SPECTRUM_POINTS, _drawn

    rng = np.random.default_rng(1)
    f = np.linspace(0.0, 100.0, 100_001)
    a = 1e-6 * (1 + rng.random(len(f)))
    i_peak, i_null = np.searchsorted(f, 7.3), np.searchsorted(f, 0.41)
    a[i_peak], a[i_null] = 1e-3, 1e-9
    fd, ad = _drawn(f, a)
    assert len(fd) <= 2 * SPECTRUM_POINTS and np.all(np.diff(fd) >= 0) and np.all(fd > 0)
    assert ad.max() == 1e-3 and fd[np.argmax(ad)] == f[i_peak]
    assert ad.min() == 1e-9 and fd[np.argmin(ad)] == f[i_null]
    assert np.all(np.isin(fd, f))                                # points of the spectrum, not bin centres
    short_f, short_a = _drawn(f[:500], a[:500])                  # short: as it is (but f = 0)
    assert np.array_equal(short_f, f[1:500]) and np.array_equal(short_a, a[1:500])


def test_a_proposals_remembered_fit_is_the_fit_and_keeps_no_round_alive(dd):
    import gc
    import weakref

    from gearspec.diagnose.candidates import FixedCandidate, Proposal, per_direction, train_fit

    rnd = Round(dd, state_from_model(MODEL, dd), loop.folds_of(dd, 4))
    cand = FixedCandidate("other", "offset", per_direction(rnd, "offset", key="offset"))
    prop = Proposal.of(rnd, cand.blocks)
    keep = rnd.keep_mask(())
    train = rnd.fold != 2
    beta, rss = train_fit(rnd, keep, prop, train)
    again, rss2 = train_fit(rnd, keep, prop, train)
    assert again is beta and rss2 == rss                      # asked again: remembered
    prop.fits.clear()
    fresh, rss3 = train_fit(rnd, keep, prop, train)
    assert np.array_equal(fresh, beta) and rss3 == rss         # and what a fresh fit gives
    other, _ = train_fit(rnd, keep, prop, rnd.fold != 1)
    assert not np.array_equal(other, beta)                     # other training groups: another fit
    ref = weakref.ref(rnd)
    del rnd
    gc.collect()
    assert ref() is None                                       # the memo does not hold the round (its X)


@pytest.mark.parametrize("seg", [np.repeat([5, 2, 9, 3], [40, 2, 25, 60]),  # contiguous, unsorted ids, a 2-row one
                                 np.repeat([1, 2, 1, 3], [10, 20, 30, 5])])           # id 1 in two runs
def test_a_residual_spectrums_segments_are_the_masks_of_their_ids(seg):
    """The per-segment means, steps and spans of a residual spectrum from one pass over the
    segment column: the same elements, in the same order, as the mask of every id (ascending)."""
    from gearspec.diagnose.residual import _demean_by_segment, _segment_slices, _spacing

    rng = np.random.default_rng(4)
    y = rng.normal(size=len(seg))
    theta = np.cumsum(rng.random(len(seg)))
    parts = _segment_slices(seg)
    masks = [seg == k for k in np.unique(seg)]
    assert [list(np.arange(len(seg))[p]) for p in parts] == [list(np.flatnonzero(m)) for m in masks]
    want = y.copy()
    for m in masks:
        want[m] -= want[m].mean()
    assert np.array_equal(_demean_by_segment(seg, y), want)         # identical: same sums, same order
    steps = np.concatenate([np.abs(np.diff(theta[m])) for m in masks if m.sum() > 2])
    assert _spacing(theta, seg) == float(np.percentile(steps[steps > 0], 90))


def test_per_segment_spectra_hold_memory_of_one_segment_not_of_every_one(dd):
    """The indices of every segment's spectrum are views of one array: the spectra of every segment
    add to the analysis's peak memory about what one segment's spectrum needs, not rows x segments
    (a fresh index array of all rows per segment: 12 x 8 bytes per row here, 400 x 8 on the
    default twin)."""
    import tracemalloc

    from gearspec.diagnose.residual import position_spectra

    r = dd.y - dd.y.mean()
    position_spectra(dd, r, per_segment=True)                # warm caches

    def peak(per_segment):
        tracemalloc.start()
        try:
            base = tracemalloc.get_traced_memory()[0]
            out = position_spectra(dd, r, per_segment=per_segment)
            return tracemalloc.get_traced_memory()[1] - base, out
        finally:
            tracemalloc.stop()

    pooled, _ = peak(False)
    every, out = peak(True)
    n_seg = len(out["segments"])
    assert n_seg == 2 * len(SPEEDS)
    # what the per-segment spectra add (measured 57 bytes per row: their grids and periodograms) is
    # below the 8 bytes x rows x segments the bug held on top of it (it measured 150)
    assert every - pooled < 8 * len(dd) * n_seg, ((every - pooled) / len(dd), n_seg)
