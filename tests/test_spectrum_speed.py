"""``gearspec spectrum`` made cheaper without changing a number (issue 13, scale).

Each speed-up here replaces a computation by a faster one that must give the same numbers: the
local noise level's block medians (a sort instead of ``np.nanmedian``'s masked arrays), the small
linear solves on one BLAS thread (OpenBLAS's threads only contend on tens of columns), a page's
fitted peaks drawn with one errorbar per colour and fill.  The known answers are the slower
computations themselves (exact equality: the same operations in the same order), and a synthetic
segment with two lines of known frequency and amplitude.
"""

import math
import warnings

import numpy as np
import pytest
from threadpoolctl import threadpool_info, threadpool_limits

from gearspec.gears import load_gear
from gearspec.segment import find_segments
from gearspec.simulate import Ripple, plateau_recording
from gearspec.spectrum import analysis, analyze
from gearspec.spectrum.periodogram import _row_medians, noise_blocks


def _blocks_by_nanmedian(power, width, mask, min_width, relative=0.3):
    """The block levels as 0.8 computed them: every block's median by ``np.nanmedian``, one block at
    a time (the reference the vectorised :func:`noise_blocks` must equal exactly)."""
    p = np.asarray(power)
    n = len(p)
    edges = [0]
    while edges[-1] < n and relative * edges[-1] < width:
        i = edges[-1]
        edges.append(min(n, i + int(np.clip(relative * i, min_width, width))))
    while edges[-1] + width <= n:
        edges.append(edges[-1] + width)
    if edges[-1] < n:
        if n - edges[-1] < min_width // 2 and len(edges) > 1:
            edges[-1] = n
        else:
            edges.append(n)
    levels = []
    for a, b in zip(edges[:-1], edges[1:]):
        row = np.where(mask[None, a:b], np.nan, p[None, a:b])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            ref = np.nanmedian(row, axis=1, keepdims=True) / math.log(2)
        below = row < 10 * ref
        cnt = np.sum(below, axis=1)
        with np.errstate(invalid="ignore"):
            lev = np.sum(np.where(below, row, 0.0), axis=1) / np.maximum(cnt, 1)
        levels.append(float(np.where(cnt > 0, lev, ref[:, 0])[0]))
    levels = np.array(levels)
    return levels[np.isfinite(levels)]


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_row_medians_equal_nanmedian_bit_for_bit(dtype):
    # odd and even counts of valid bins, rows with one valid bin and rows with none: exactly
    # np.nanmedian's numbers (and dtype), since the same two middle values are averaged the same way
    rng = np.random.default_rng(3)
    for w in (1, 2, 5, 40, 41, 200):
        for frac in (0.0, 0.3, 0.9, 1.0):
            rows = rng.exponential(size=(9, w)).astype(dtype)
            rows[rng.random(rows.shape) < frac] = np.nan
            rows[0, :] = np.nan            # a row of masked bins only: NaN
            rows[1, :] = np.nan
            rows[1, -1] = 0.25             # one valid bin: itself
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                want = np.nanmedian(rows, axis=1)
            got = _row_medians(rows)
            assert got.dtype == want.dtype
            np.testing.assert_array_equal(got, want)
            assert got[1] == dtype(0.25)
    full = rng.exponential(size=(6, 40)).astype(dtype)  # the unmasked path: np.median's numbers
    np.testing.assert_array_equal(_row_medians(full, masked=False), np.median(full, axis=1))


def test_noise_blocks_with_masked_bins_equal_the_nanmedian_blocks():
    # an exponential (chi-squared, 2 dof) periodogram of mean 1 with three strong lines, and the
    # bins around fitted lines masked, as the search masks them: every block level exactly as before
    rng = np.random.default_rng(11)
    power = rng.exponential(size=5000)
    power[[700, 2100, 4321]] = 400.0
    mask = np.zeros(5000, bool)
    for c in (30, 700, 2050, 4321):
        mask[c - 3:c + 4] = True
    mask[1200:1400] = True  # one whole block of the full width masked: no level there
    _, levels, _ = noise_blocks(power, width=200, mask=mask, min_width=40)
    np.testing.assert_array_equal(levels, _blocks_by_nanmedian(power, 200, mask, 40))
    # and the levels are the noise's mean: 1 within 3 standard errors of a block's mean (about 180
    # bins of a unit exponential after the lines are left out: se 1/sqrt(180) = 0.075)
    assert np.all(np.abs(levels[5:] - 1.0) < 3 * 0.075 + 0.05)  # + the 10x-median cut's bias (~5 %)


@pytest.fixture(scope="module")
def plateaus():
    # two plateaus at 30 rad/s, a 1 mNm motor-shaft line (declared by silo4-joint3) and two 0.5 mNm
    # undeclared lines at 2.3 and 3.7 cycles/rad (two peaks of one colour on a page), 0.1 mNm white noise
    rec, _ = plateau_recording([30.0, -30.0], ripples=[Ripple(1 / (2 * np.pi), 1e-3), Ripple(2.3, 5e-4),
                                                       Ripple(3.7, 5e-4)],
                               level=0.01, duration=1.5, fs=1000, noise=1e-4, seed=2, gear=load_gear("silo4-joint3"),
                               one_run_per_plateau=True)
    return rec, find_segments(rec)


def _multi_thread_blas() -> bool:
    return any(i.get("user_api") == "blas" and i.get("num_threads", 1) > 1 for i in threadpool_info())


def test_segments_are_analysed_with_one_blas_thread(plateaus, monkeypatch):
    # the BLAS threads seen inside every segment's analysis: 1 (a 40-column solve took 16 ms with
    # OpenBLAS's two threads contending on a busy 2-core machine, 0.04 ms on one)
    if not _multi_thread_blas():
        pytest.skip("BLAS runs on one thread here already: nothing to limit")
    rec, seg = plateaus
    seen = []
    real = analysis.analyze_segment

    def spy(*a, **k):
        seen.append(max(i["num_threads"] for i in threadpool_info() if i.get("user_api") == "blas"))
        return real(*a, **k)

    monkeypatch.setattr("gearspec.spectrum.pipeline.analyze_segment", spy)
    analyze(rec, segmentation=seg, progress=False)
    assert seen and set(seen) == {1}


def test_one_blas_thread_gives_the_same_numbers_and_the_known_lines(plateaus):
    # known answers: the motor-shaft line at 1/(2 pi) cycles/rad, 1 mNm, and the undeclared ones at
    # 2.3 and 3.7 cycles/rad, 0.5 mNm; with 1.5 s x 1000 Hz samples and 0.1 mNm noise an amplitude's
    # standard error is sqrt(2/n) x 0.1 mNm = 3.7 uNm: 5 se = 0.02 mNm
    rec, seg = plateaus
    with threadpool_limits(limits=None):
        r = analyze(rec, segmentation=seg, progress=False)
    for s in r.segments:
        motor = [p for p in s.peaks if p.declared and abs(p.frequency - 1 / (2 * np.pi)) < 1e-9]
        assert len(motor) == 1 and abs(motor[0].amplitude - 1e-3) < 2e-5
        for f in (2.3, 3.7):
            extra = [p for p in s.peaks if not p.declared and abs(p.frequency - f) < 0.01]
            assert len(extra) == 1 and abs(extra[0].amplitude - 5e-4) < 2e-5
    # the same numbers as a segment analysed alone, outside any limit (the BLAS threads of the
    # machine): the small solves' results do not depend on the threads
    s = seg.segments[0]
    y = rec.tau[s.rows] * s.direction
    alone = analysis.analyze_segment(rec.theta[s.rows], y, r.gear, segment=s)
    got = r.segments[0]
    assert [p.frequency for p in got.peaks] == pytest.approx([p.frequency for p in alone.peaks], rel=1e-12)
    assert [p.amplitude for p in got.peaks] == pytest.approx([p.amplitude for p in alone.peaks], rel=1e-9)


def test_a_page_draws_every_fitted_peak_once_grouped_by_colour_and_fill(plateaus, tmp_path, monkeypatch):
    # the errorbars of a panel: one per colour and fill, together holding every fitted peak's
    # frequency and amplitude once (the figure's information), each bar +1 s.e. upwards only
    from gearspec import plots
    from gearspec.plots import spectrum as ps

    rec, seg = plateaus
    r = analyze(rec, segmentation=seg, progress=False, keep_spectra=True)
    axes = []
    real = ps._spectrum_panel

    def keep(ax, *a, **k):
        axes.append(ax)
        return real(ax, *a, **k)

    monkeypatch.setattr(ps, "_spectrum_panel", keep)
    monkeypatch.setattr(ps, "_save", lambda fig, path, tight=True: path)  # no PNG needed: the artists
    plots.plot_order_spectra(r, str(tmp_path / "p_{:02d}.png"))
    assert len(axes) == len(r.segments)
    for ax, s in zip(axes, r.segments):
        bars = ax.containers
        keys = [(c.lines[0].get_color(), c.lines[0].get_markerfacecolor() != "none") for c in bars]
        assert len(keys) == len(set(keys))  # one errorbar per colour and fill
        assert len(bars) < len(s.peaks)     # two unexplained lines: one errorbar for both
        pts = sorted((float(x), float(y)) for c in bars for x, y in zip(*c.lines[0].get_data()))
        want = sorted((p.frequency, max(p.amplitude, 1e-12)) for p in s.peaks)
        assert pts == want
        for c in bars:  # the bar from the amplitude up by one standard error
            segs = c.lines[2][0].get_segments()
            assert all(v[0][1] <= v[1][1] for v in segs)
    import matplotlib.pyplot as plt

    plt.close("all")


def test_figures_laid_out_by_tight_layout_are_drawn_once_not_cropped(plateaus, monkeypatch):
    # the summary, amplitude and unexplained-peak figures are laid out by tight_layout: saved without
    # bbox_inches="tight" (its second draw)
    from gearspec.plots import spectrum as ps

    rec, seg = plateaus
    r = analyze(rec, segmentation=seg, progress=False)
    calls = {}
    monkeypatch.setattr(ps, "_save", lambda fig, path, tight=True: calls.setdefault(str(path), tight) and path)
    ps.plot_amplitude_vs_speed(r, "amp.png")
    ps.plot_spectrum_summary(r, "summary.png")
    ps.plot_unexplained(r, "unexplained.png")
    assert calls == {"amp.png": False, "summary.png": False, "unexplained.png": False}
    ps.plt.close("all")
