"""The per-segment spectral analysis of a recording: what ``gearspec spectrum`` runs.

On ``y = direction * (torque - J thetadd)`` of every segment (the friction magnitude, so that
levels and phases mean the same in both directions, SILO4 eq. 11): a joint fit of the declared
lines plus a Legendre nuisance (:mod:`.harmonic`), a periodogram of its residual, a search for
peaks no declared line explains (:mod:`.search`) and their joint fit, repeated on the residual of
every line found; steps in :func:`analyze_segment`.  Nothing above the segment's position Nyquist
frequency (:func:`position_nyquist`) is searched, fitted or reported as measured: such declared
lines are listed (``above_nyquist``) with where they alias, and a peak found there is labelled
``alias of <label>``.  On a quantised position (an encoder's staircase, :func:`quantisation_step`)
nothing above the quantisation limit (:func:`quantisation_limit`) is searched or fitted either:
such declared lines are listed (``above_quantisation_limit``) as not measured.  A declared line's
``fap`` is for that one frequency; a found peak's counts every independent frequency searched.
"""

from __future__ import annotations

import math
import threading

import numpy as np

from ..errors import InputError
from ..gears import GearTrain, alias_frequency, integer_order
from ..segment import Segment
from .harmonic import HarmonicFit, NormalEquations, min_degree_for_cycles, refine_frequencies
from .periodogram import LombScargle
from .results import Peak, SegmentSpectrum, SpectrumResult
from .search import _fft_residual_power, _Grid, _LocalNoise, _search, _significant

__all__ = ["Peak", "SegmentSpectrum", "SpectrumResult", "analyze_segment", "analyze", "position_nyquist",
           "MEASURABLE_FRACTION", "LS_MAX_SAMPLES", "relabel_aliases", "quantisation_step", "quantisation_limit",
           "QUANTISATION_FRACTION", "quantisation_lines", "QUANTISATION_HARMONICS"]

_GUARD = 3.0  # resolution steps kept clear around fitted lines when searching for peaks
_MAX_ROUNDS = 6  # search -> joint fit -> search the residual of all lines found, at most this often
_Q_SIDEBANDS = 3  # sidebands of a staircase's line labelled, each side (_Analysis.staircase_labels)

#: segments up to this many samples search the Lomb-Scargle periodogram of the raw residual;
#: longer ones the Hann spectrum of the residual resampled over position (see analyze_segment)
LS_MAX_SAMPLES = 200_000


def analyze_segment(theta: np.ndarray, y: np.ndarray, gear: GearTrain | None = None, *,
                    segment: Segment | None = None, max_frequency: float | None = None,
                    min_cycles: float = 1.0, harmonics: int = 1, degree: int | str = "auto",
                    fap_threshold: float = 0.01, max_peaks: int = 8, oversample: float = 2.0,
                    noise: str = "local", periodogram: str = "auto", method: str = "auto",
                    keep_spectra: bool = False) -> SegmentSpectrum:
    """Analyse one stretch of friction magnitude ``y`` (direction times torque) over position
    ``theta``; frequencies in cycles per unit of theta, amplitudes in the unit of ``y``.

    Declared lines that complete ``min_cycles`` below the position Nyquist are fitted jointly with
    a Legendre nuisance whose degree grows with the slowest one that does not (so it biases none).
    ``periodogram`` chooses the spectrum searched for undeclared peaks: ``"lombscargle"`` (the
    residual on the raw samples), ``"fft"`` (Hann spectrum of the signal resampled over position,
    fitted lines taken out in closed form: one FFT) or ``"auto"`` (Lomb-Scargle up to
    ``LS_MAX_SAMPLES`` samples); amplitudes, phases and errors always come from the joint fit on
    the raw samples, errors rescaled by the local noise (``noise="local"``).  ``keep_spectra``
    keeps the order spectrum and the Lomb-Scargle of the signal for figures.
    """
    theta = np.asarray(theta, dtype=float)
    y = np.asarray(y, dtype=float)
    n = len(theta)
    if periodogram not in ("auto", "lombscargle", "fft"):
        raise InputError(f"periodogram must be 'auto', 'lombscargle' or 'fft', got '{periodogram}'")
    if noise not in ("local", "white"):
        raise InputError(f"noise must be 'local' or 'white', got '{noise}'")
    if segment is None:
        d = int(np.sign(theta[-1] - theta[0])) or 1
        segment = Segment(run=0, start=0, stop=n, direction=d, speed=float("nan"))
    lo, hi = (float(theta.min()), float(theta.max())) if n else (0.0, 0.0)
    span = hi - lo
    if n < 16 or span <= 0:
        return SegmentSpectrum(segment, [], float(np.mean(y)) if n else float("nan"), float("nan"), span,
                               float("nan"), 0, [], None, note="too few samples to analyse")
    nyquist = position_nyquist(theta)
    step = quantisation_step(theta)
    q_limit = quantisation_limit(step)
    # nothing above the position Nyquist frequency is searched (nor fitted, nor reported as
    # measured): with jittered spacing it is below the mean spacing's 0.5 (n - 1) / span; nor above
    # the quantisation limit of an encoder's staircase
    f_search_max = min(0.5 * (n - 1) / span, nyquist, q_limit)
    if max_frequency is not None:
        f_search_max = min(f_search_max, float(max_frequency))
    fitted, skipped, slow_cycles = _declared_lines(gear, harmonics, span, n, nyquist, min_cycles, q_limit)
    deg = (max(1, min_degree_for_cycles(max(slow_cycles))) if slow_cycles else 1) if degree == "auto" else int(degree)
    n_terms = deg + 1 + 2 * len(fitted)
    if n <= n_terms + 8:
        return SegmentSpectrum(segment, [], float(np.mean(y)), float("nan"), span, nyquist, deg, skipped, None,
                               note=f"{n} samples are too few for {n_terms} terms", quantisation_step=step,
                               quantisation_limit=q_limit)
    a = _Analysis(theta, y, gear, fitted, deg, lo, hi, nyquist, f_search_max, min_cycles=min_cycles,
                  fap_threshold=fap_threshold, max_peaks=max_peaks, oversample=oversample, method=method,
                  step=step)
    # 1. the declared lines: one pass over the samples
    out = SegmentSpectrum(segment, [], level=a.eq.y0, sigma=a.fit0.sigma, span=span, nyquist=nyquist,
                          degree=deg, skipped=skipped, fit=a.fit0, quantisation_step=step, quantisation_limit=q_limit)
    # 2. periodogram of the residual
    use_ls = periodogram == "lombscargle" or (periodogram == "auto" and n <= LS_MAX_SAMPLES)
    a.first_spectrum(use_ls, out if keep_spectra else None)
    first = (a.grid, a.nbin, a.enbw, a.power if keep_spectra else None)
    # 3.-4. peaks no declared line explains, found and fitted round by round
    a.search_rounds()
    out.peaks, out.fit = a.peaks(noise)
    out.sigma = out.fit.sigma
    # 5. spectra for the figures
    if keep_spectra:
        a.spectra_for_figures(out, *first)
    return out


def _declared_lines(gear: GearTrain | None, harmonics: int, span: float, n: int, nyquist: float,
                    min_cycles: float, q_limit: float = math.inf):
    """The gear's declared lines in a segment of ``n`` samples over ``span``: ``(fitted, skipped
    with the reason, cycles of the too-slow ones)``; ``q_limit``: :func:`quantisation_limit`."""
    fitted, skipped, slow_cycles = [], [], []
    for ln in (gear.declared_lines(max_harmonic=harmonics) if gear is not None else []):
        cycles = ln.frequency * span
        if cycles < min_cycles:
            skipped.append({"label": ln.label, "frequency": ln.frequency, "kind": "too_slow",
                            "reason": f"{cycles:.3g} cycles in the segment (< {min_cycles:g}); absorbed by the nuisance polynomial"})
            slow_cycles.append(cycles)
        elif ln.frequency >= MEASURABLE_FRACTION * nyquist:
            skipped.append({"label": ln.label, "frequency": ln.frequency, "kind": "above_nyquist",
                            "alias": alias_frequency(ln.frequency, span / (n - 1)) if ln.frequency > nyquist else None,
                            "reason": f"above {MEASURABLE_FRACTION:g} x the position Nyquist frequency ({nyquist:.4g}): "
                                      "not measured"})
        elif ln.frequency >= q_limit:
            skipped.append({"label": ln.label, "frequency": ln.frequency, "kind": "above_quantisation_limit",
                            "reason": f"above the quantisation limit ({q_limit:.4g} = {QUANTISATION_FRACTION:g} / the "
                                      "encoder step): not measured"})
        else:
            fitted.append(ln)
    return fitted, skipped, slow_cycles


class _Analysis:
    """The steps of :func:`analyze_segment` on one segment, and the state they share."""

    def __init__(self, theta, y, gear, fitted, deg, lo, hi, nyquist, f_search_max, *, min_cycles, fap_threshold,
                 max_peaks, oversample, method, step=0.0):
        self.theta, self.y, self.gear, self.fitted, self.deg = theta, y, gear, fitted, deg
        self.lo, self.hi, self.span, self.nyquist, self.f_search_max = lo, hi, hi - lo, nyquist, f_search_max
        self.min_cycles, self.fap_threshold, self.max_peaks = min_cycles, fap_threshold, max_peaks
        self.oversample, self.method = oversample, method
        self.n = len(theta)
        self.step = step
        self.declared_f = [ln.frequency for ln in fitted]
        self.n_dec = len(self.declared_f)
        self.eq = NormalEquations.accumulate(theta, y, self.declared_f, deg)
        self.fit0 = self.eq.fit()

    def first_spectrum(self, use_ls: bool, keep_into) -> None:
        """Step 2: the periodogram of the declared lines' residual (a sinusoid of amplitude A has
        power n A^2/4) on a uniform grid: Lomb-Scargle, or the Hann spectrum over position (its
        figure spectrum into ``keep_into``)."""
        self.fft_res = None
        if use_ls:
            ls = LombScargle(self.theta, self.y - self.fit0.predict(self.theta), method=self.method,
                             nthreads=_ls_threads())
            fmin, df, nf = ls.autogrid(oversample=self.oversample, fmax=self.f_search_max)
            self.power = np.atleast_1d(ls.power_grid(fmin, df, nf))
            self.grid = _Grid(fmin, df, 0, len(self.power))
            self.enbw = 1.0
        else:
            k_lo, _, df, self.power, self.enbw, self.fft_res = _fft_residual_power(
                self.theta, self.y, self.fit0, self.oversample, self.f_search_max, keep_into, lo=self.lo, hi=self.hi,
                keep_residual=self.max_peaks > 0)
            self.grid = _Grid(0.0, df, k_lo, len(self.power))
        self.nbin = len(self.power)
        self.m_eff = max(1.0, self.nbin / self.oversample)  # independent frequencies searched: the same in every round

    def _residual_power(self, fit: HarmonicFit) -> None:
        """The power spectrum of the residual of every line in ``fit`` (a later round)."""
        theta, y = self.theta, self.y
        if self.fft_res is None and self.nbin >= 3:
            # the later rounds search the Hann spectrum, every fitted line taken out in closed
            # form: one transform for all of them, a fraction of a periodogram's cost
            k_lo, _, df, p1, enbw1, self.fft_res = _fft_residual_power(
                theta, y, self.fit0, self.oversample, self.f_search_max, lo=self.lo, hi=self.hi, keep_residual=True)
            if self.fft_res is not None:
                self.grid, self.enbw, self.nbin = _Grid(0.0, df, k_lo, len(p1)), enbw1, len(p1)
            del p1
        if self.fft_res is not None:
            self.power = self.fft_res.power(fit)
        else:
            ls = LombScargle(theta, y - fit.predict(theta), method=self.method, nthreads=_ls_threads())
            self.power = np.atleast_1d(ls.power_grid(self.grid.base, self.grid.df, self.nbin))

    def search_rounds(self) -> None:
        """Steps 3-4: peaks no declared line explains (:func:`_search`), found iteratively.

        A dense comb of lines raises the local noise level around each of them, so after every
        search the lines found so far are fitted jointly (frequencies refined), the ones no longer
        significant dropped, and the residual of all of them searched again, until a round finds
        nothing (at most ``_MAX_ROUNDS``); ``m_eff`` stays the count of frequencies searched."""
        span, n_dec, oversample = self.span, self.n_dec, self.oversample
        guard = _GUARD / span
        self.f_found_min = max(2.0, self.min_cycles, (self.deg + 1) / math.pi) / span
        eq_dec = eq = self.eq
        found: list[float] = []
        rejected: list[float] = []     # found, then dropped: never searched for again
        keep = list(range(n_dec))
        se_eq = np.zeros(n_dec)        # frequency standard errors (white noise) of eq's lines
        fit = self.fit0
        for rnd in range(_MAX_ROUNDS):
            if rnd > 0:  # the residual of every line fitted so far
                self._residual_power(fit)
            # the fit removed each fitted line's power from its own bin and its neighbours: leave
            # those bins out of the noise level, or it reads low
            fitted_mask = np.zeros(self.nbin, bool)
            for f0 in fit.frequency:
                fitted_mask[self.grid.within(f0, 1.0 / span)] = True
            self.noise_model = _LocalNoise(self.power, width=int(100 * oversample), min_width=int(20 * oversample),
                                           mask=fitted_mask, enbw=self.enbw)
            if rnd == 0:
                self.noise0 = self.noise_model
            del fitted_mask
            room = self.max_peaks - len(found)
            new = (_search(self.power, self.grid, self.noise_model, self.declared_f, found + rejected, span, guard,
                           self.f_found_min, self.fap_threshold, self.m_eff, oversample, room)
                   if room > 0 and self.nbin >= 3 else [])
            if not new:
                break
            # 4. joint fit, found frequencies refined by Gauss-Newton (the declared lines' equations
            # reused); a found peak stays while its amplitude is significant (a sidelobe is not,
            # once its line is fitted)
            f_all, se_eq, eq = refine_frequencies(self.theta, self.y, self.declared_f + found + new,
                                                  range(n_dec, n_dec + len(found) + len(new)), degree=self.deg,
                                                  iterations=3, base=eq_dec)
            keep, fit, _, _ = _significant(eq, list(range(len(f_all))), self.noise_model, self.grid, self.n,
                                           self.enbw, n_dec, self.fap_threshold, self.m_eff, oversample,
                                           self.f_found_min)
            rejected += [float(f_all[j]) for j in range(n_dec, len(f_all)) if j not in keep]
            found = [float(f_all[j]) for j in keep if j >= n_dec]
        if self.fft_res is not None:
            self.fft_res.release()
        self.eq, self.keep, self.se_eq = eq, keep, se_eq

    def peaks(self, noise: str) -> tuple[list[Peak], HarmonicFit]:
        """The peaks of the final joint fit and the fit: false-alarm probabilities and error scaling
        from the noise of the last residual searched; labels from the gear."""
        keep, fit, z_fit, fap_fit = _significant(self.eq, self.keep, self.noise_model, self.grid, self.n, self.enbw,
                                                 self.n_dec, self.fap_threshold, self.m_eff, self.oversample,
                                                 self.f_found_min)
        f_se = np.asarray(self.se_eq, dtype=float)[keep] if len(keep) else np.zeros(0)
        if noise == "local" and len(keep):
            s_at = self.grid.interp(fit.frequency, self.noise_model.level)
            factor = np.clip(s_at / self.enbw / max(fit.sigma**2, 1e-300), 0.05, 1e6)
            fit = fit.scaled(factor)
            f_se = f_se * np.sqrt(factor)
        amp, amp_se, ph, ph_se = fit.amplitude, fit.amplitude_se, fit.phase, fit.phase_se
        # a found line's phase at theta = 0, away from the segment's centre, carries its frequency
        # error: 2 pi centre f_se (0 for declared lines)
        ph_se = np.hypot(ph_se, 2 * np.pi * 0.5 * (self.lo + self.hi) * f_se) if len(f_se) else ph_se
        gear, span, nyquist = self.gear, self.span, self.nyquist
        spacing = span / (self.n - 1)  # mean position spacing: where lines above the Nyquist frequency alias
        staircase = self.staircase_labels([f if j >= self.n_dec else math.nan for j, f in zip(keep, fit.frequency)],
                                          [max(1.0 / span, 3 * e) for e in f_se])
        peaks = []
        for k, (j, f) in enumerate(zip(keep, fit.frequency)):
            aliased = exact = q_m = None
            if j < self.n_dec:
                label, declared = self.fitted[j].label, True
            else:
                declared, line = False, None
                if gear is not None:
                    line = gear.label(f, max(0.5 / span, 1e-6 * f))
                    if line is None:  # a line above the position Nyquist frequency, seen at its alias
                        line = gear.label(f, max(0.5 / span, 3 * f_se[k]), spacing=spacing, nyquist=nyquist)
                label = line.label if line is not None else None
                if label is None and staircase[k] is not None:  # the encoder staircase's line, or its sideband
                    q_m, label = staircase[k]
                if line is not None and line.kind == "alias":
                    aliased = {"label": line.parents[0], "frequency": line.frequency, "order": line.order}
                elif label is None and gear is not None:
                    # an integer order when the frequency's uncertainty (3 se, at least 0.05 resolution
                    # steps: a shaft turns once in the segment, Rayleigh) tells neighbouring multiples apart
                    exact = integer_order(gear, f, max(3 * f_se[k], 0.05 / span, 1e-6 * f))
            peaks.append(Peak(frequency=float(f), amplitude=float(amp[k]), amplitude_se=float(amp_se[k]),
                              phase=float(ph[k]), phase_se=float(ph_se[k]), fap=float(fap_fit[k]),
                              order=None if gear is None else gear.order(f), label=label, declared=declared,
                              snr=float(z_fit[k]), hint=None if exact is None else exact.hint,
                              frequency_se=float(f_se[k]),
                              frequency_exact=None if exact is None else exact.frequency,
                              order_exact=None if exact is None else exact.order, aliased_from=aliased,
                              quantisation_harmonic=q_m))
        return peaks, fit

    def staircase_labels(self, freqs, tolerances) -> list[tuple[int, str] | None]:
        """For each frequency: ``(m, label)`` when it is within its tolerance of a line of the segment's
        encoder staircase (:func:`quantisation_lines`, the lowest harmonic ``m`` of the count rate), or
        of a sideband ``j = +-1 .. +-_Q_SIDEBANDS`` times a declared line fitted in the segment around
        such a line found here, or predicted at or above the highest frequency searched (the speed
        ripple at a shaft's frequency modulates the count rate); else None."""
        out: list[tuple[int, str] | None] = [None] * len(freqs)
        if not self.step > 0:
            return out
        lines = sorted(quantisation_lines(self.step, _travel_per_sample(self.theta)), key=lambda x: x[1])
        # a staircase line at or above the highest frequency searched is not found there: its leakage into
        # the last _GUARD resolution steps searched, and its lower sidebands, are
        edge = self.f_search_max - 1.0 / self.span
        carriers = [(g, m) for g, m in lines if g >= edge]
        for i, (f, tol) in enumerate(zip(freqs, tolerances)):
            m = next((m for g, m in lines if abs(g - f) <= (max(tol, _GUARD / self.span) if g >= edge else tol)), None)
            if m is not None:
                out[i] = (m, f"encoder counts x{m}, folded")  # the count rate's harmonic, folded by the sampling
                carriers.append((f, m))
        for i, (f, tol) in enumerate(zip(freqs, tolerances)):
            if not math.isfinite(f):
                continue
            for (g, m), ln in ((c, ln) for c in carriers for ln in self.fitted if ln.frequency > tol):
                j = round((f - g) / ln.frequency)
                if out[i] is None and 1 <= abs(j) <= _Q_SIDEBANDS and abs(g + j * ln.frequency - f) <= tol:
                    out[i] = (m, f"encoder counts x{m}, folded, {j:+d}x {ln.label}")
        return out

    def spectra_for_figures(self, out: SegmentSpectrum, grid: _Grid, nbin: int, enbw: float, power_first) -> None:
        """Step 5: the spectra of the figures into ``out``, on the first round's ``grid``."""
        theta, y, n = self.theta, self.y, self.n
        noise_fig = self.noise_model if self.grid is grid else self.noise0
        freqs = grid.frequencies()
        if out.fft_frequency is None:
            _fft_residual_power(theta, y, self.fit0, self.oversample, self.f_search_max, out, lo=self.lo, hi=self.hi)
        ls_sig = LombScargle(theta, y, method=self.method, nthreads=_ls_threads())
        out.ls_frequency = freqs.astype(np.float32)
        p_sig = ls_sig.power_grid(freqs[0], freqs[1] - freqs[0], len(freqs)) if len(freqs) > 1 else self.power
        out.ls_amplitude = ls_sig.amplitude(power=p_sig).astype(np.float32)
        # the residual of the declared lines (the found peaks stand out in it), against the noise
        # level of the last round (the residual of every line found)
        out.ls_residual_amplitude = np.sqrt(4.0 * np.maximum(power_first, 0) / enbw / n).astype(np.float32)
        out.noise_amplitude = np.sqrt(4.0 * noise_fig.level(np.arange(nbin)) / enbw / n).astype(np.float32)


_local = threading.local()  # .in_pool: this thread analyses one segment of several at once


def _ls_threads() -> int | None:
    """finufft's threads: one inside analyze's worker threads (no oversubscription), else its default."""
    return 1 if getattr(_local, "in_pool", False) else None


#: a line is measurable below this fraction of a segment's position Nyquist frequency: the one
#: margin of spectrum, identify and diagnose
MEASURABLE_FRACTION = 0.8


def position_nyquist(theta: np.ndarray) -> float:
    """The position Nyquist frequency of samples at ``theta`` (cycles per unit of theta), for every
    stage: half the inverse of the 95th percentile of the nonzero spacings (as ``np.percentile``),
    selected in single precision (rounded to 1e-7, a third of the time)."""
    sp = np.empty(len(theta) - 1, np.float32)
    np.subtract(theta[1:], theta[:-1], out=sp, casting="unsafe")
    np.abs(sp, out=sp)
    n_zero = len(sp) - int(np.count_nonzero(sp))
    m = len(sp) - n_zero
    if m == 0:
        return 0.0
    pos = 0.95 * (m - 1)
    i = int(np.floor(pos))
    frac = pos - i
    k = n_zero + i
    kth = [k, k + 1] if (frac > 0 and k + 1 < len(sp)) else [k]
    sp.partition(kth)
    a = float(sp[k])
    b = float(sp[k + 1]) if len(kth) == 2 else a
    return 0.5 / (a + (b - a) * frac)


#: the quantisation limit is this fraction of the inverse encoder step: 1 / (8 step), see quantisation_limit
QUANTISATION_FRACTION = 0.125
#: a position is quantised when at least this fraction of its nonzero steps are whole multiples of one step
_LATTICE_SHARE = 0.99
#: ... within this fraction of the step (plus the rounding of the values)
_LATTICE_TOL = 0.02
#: ... and changes of other sizes than the commonest (in counts, 0 included) are at least this share
_OTHER_SIZES = 0.005


def quantisation_step(theta: np.ndarray) -> float:
    """The encoder step of positions ``theta`` (unit of theta), 0 when they are not quantised.

    The positions are quantised with step ``q`` when at least 99 % of their nonzero changes are
    whole multiples of ``q`` (within 2 % of ``q`` plus the float rounding of the values): ``q`` is
    the smallest change divided by 1, 2, ..., 8 (a fine encoder moves several counts per sample),
    the first that fits, refined as the ratio of the changes' sum to their sum in counts.  The
    changes must take at least two sizes in counts (0 included; the rarer ones at least 0.5 % of
    them): a position sampled exactly at a uniform spacing has one size only, and no quantisation
    error.  Timing jitter and dithering by whole counts keep the lattice; a position in floating
    point (filtered, interpolated, simulated without encoder) has no lattice and gives 0.
    """
    theta = np.asarray(theta, dtype=float)
    if len(theta) < 3:
        return 0.0
    d = np.abs(np.diff(theta))
    rounding = 16 * np.finfo(float).eps * float(np.max(np.abs(theta)))
    n_zero = len(d)
    d = d[d > rounding]
    n_zero -= len(d)
    if len(d) < 16:
        return 0.0
    d_min = float(d.min())
    few = d[::max(1, len(d) // 4096)]  # a candidate is tried on a few thousand changes first
    for j in range(1, 9):
        qc = d_min / j
        r = few / qc
        if np.count_nonzero(np.abs(r - np.rint(r)) <= _LATTICE_TOL + rounding / qc) < _LATTICE_SHARE * len(few):
            continue
        counts = np.rint(d / qc)
        on = np.abs(d / qc - counts) <= _LATTICE_TOL + rounding / qc
        if np.count_nonzero(on) >= _LATTICE_SHARE * len(d):
            # a lattice is evidence of quantisation only when the changes take two or more sizes in
            # counts (0 and 1 on a staircase, 8 and 9 on a fine encoder): a uniformly sampled exact
            # position changes by one same amount every sample, and any spacing is its 'step'
            c = counts[on].astype(np.int64)
            lo_c, hi_c = int(c.min()), int(c.max())
            times = np.bincount(c - lo_c) if hi_c - lo_c < 65536 else np.unique(c, return_counts=True)[1]
            times = np.append(times, n_zero)
            others = int(times.sum() - times.max())
            if others < max(2, _OTHER_SIZES * times.sum()):
                return 0.0
            return float(np.sum(d[on]) / np.sum(counts[on]))
    return 0.0


def quantisation_limit(step: float) -> float:
    """The highest frequency (cycles per unit of theta) a position quantised with ``step`` measures:
    ``QUANTISATION_FRACTION / step`` (inf when ``step`` is 0: not quantised).

    Each quantised position is off the true one by up to half a step.  A line at frequency ``f`` is
    then seen through the phase error ``2 pi f e``, with ``e`` spread over ``[-step/2, step/2]``: its
    amplitude shrinks by ``sinc(f step)`` and the rest of its power goes to sidebands at ``f +- m /
    step``; at ``1 / (8 step)`` the loss is 2.6 % (``sinc(1/8) = 0.974``), at ``1 / (4 step)`` already
    10 %.  And the staircase has lines of its own in the torque: a closed loop on the encoder reacts
    to every count, a signal periodic at the count rate ``v / step`` whose harmonics the sampling
    folds to ``|m / step - k / spacing|`` per unit of theta (``spacing`` the travel per sample): on
    the SILO4 twin at 2 rpm (a 2000-count encoder, 3.75 samples per count) at ``1 / (4 step)`` and
    ``1 / (2 step)``, significant in every segment (false-alarm probabilities 1e-7 to 1e-15).
    Below ``1 / (8 step)`` the analysis measures lines; above it neither searches nor fits.  Folded
    harmonics of the count rate can still fall lower when the samples per count are close to a
    whole number (e.g. 2.05 samples per count: at 0.05 / step); see the README's limits.
    """
    return QUANTISATION_FRACTION / step if step > 0 else math.inf


#: harmonics of the encoder's count rate whose folds :func:`quantisation_lines` lists (a sawtooth's
#: m-th harmonic has 1/m of its fundamental's amplitude)
QUANTISATION_HARMONICS = 8


def quantisation_lines(step: float, spacing: float, harmonics: int = QUANTISATION_HARMONICS) -> list[tuple[float, int]]:
    """Where an encoder's staircase puts lines of its own in a segment: ``(frequency, m)``, frequency in
    cycles per unit of theta of the ``m``-th harmonic of the count rate, ``m = 1 .. harmonics``.

    A closed loop on a quantised position reacts to every count: a torque periodic in time at the
    count rate, ``spacing / step`` counts per sample (``spacing``: travel per sample, unit of theta).
    Its ``m``-th harmonic, ``m spacing / step`` cycles per sample, is folded by the sampling to its
    distance ``x`` to the nearest whole number, ``x / spacing`` per unit of theta, and once more onto
    the positions' lattice of ``step`` (``f`` and ``1 / step - f`` look the same there).  At constant
    speed these are fixed frequencies over position in one segment (a position-locked line looks the
    same) that move with the speed from segment to segment.  Empty when ``step`` or ``spacing`` is 0.
    """
    if not (step > 0 and spacing > 0):
        return []
    out = []
    for m in range(1, int(harmonics) + 1):
        c = m * spacing / step
        f = abs(c - round(c)) / spacing
        lattice = abs(f - round(f * step) / step)
        out += [(f, m)] + ([(lattice, m)] if abs(lattice - f) > 1e-9 * (f + lattice) else [])
    return out


def _travel_per_sample(theta: np.ndarray) -> float:
    """Mean travel per sample (unit of theta): the least-squares slope of ``theta`` over the sample
    index (a quantised segment's end points are off by up to a step; its slope is not)."""
    n = len(theta)
    i = np.arange(n, dtype=float) - 0.5 * (n - 1)
    return abs(float(np.dot(i, theta - theta.mean()) / np.dot(i, i))) if n > 1 else 0.0


def rows_position_nyquist(rows: np.ndarray, length: np.ndarray) -> np.ndarray:
    """:func:`position_nyquist` of many pieces at once, from their absolute spacings as the rows of
    one float32 array (the first ``length`` of each row; NaN after them, sorted last), sorted here in
    place: the same numbers as the rule piece by piece; 0 when no spacing is nonzero, inf for a row
    without any spacing."""
    rows.sort(axis=1)
    width = rows.shape[1]
    n_zero = np.count_nonzero(rows == 0, axis=1)
    m = length - n_zero
    pos = 0.95 * (m - 1)
    i = np.floor(pos).astype(np.int64)
    frac = pos - i
    k = np.clip(n_zero + i, 0, width - 1)
    r = np.arange(len(rows))
    a = rows[r, k].astype(float)
    has_b = (frac > 0) & (k + 1 < length)
    b = np.where(has_b, rows[r, np.minimum(k + 1, width - 1)], a).astype(float)
    with np.errstate(divide="ignore", invalid="ignore"):
        nyq = np.where(m > 0, 0.5 / (a + (b - a) * frac), 0.0)
    nyq[length == 0] = np.inf  # no spacing at all: nothing limits it
    return nyq


#: groups with fewer spacings than this are sorted together as the rows of one array
_ROWS_BELOW = 256


def group_position_nyquist(theta: np.ndarray, starts, stops) -> np.ndarray:
    """:func:`position_nyquist` of every contiguous group ``[starts[g], stops[g])`` of the samples (the
    same numbers; 0 for a group without a nonzero spacing or of one sample): short groups together
    (:func:`rows_position_nyquist`), long ones one by one."""
    starts, stops = np.asarray(starts, dtype=np.int64), np.asarray(stops, dtype=np.int64)
    out = np.zeros(len(starts))
    nd = np.maximum(stops - starts - 1, 0)
    for g in np.flatnonzero(nd >= _ROWS_BELOW):
        out[g] = position_nyquist(theta[starts[g]:stops[g]])
    small = np.flatnonzero((nd > 0) & (nd < _ROWS_BELOW))
    if len(small):
        sp = np.empty(max(len(theta) - 1, 0), np.float32)  # as position_nyquist: a double difference, rounded
        np.subtract(theta[1:], theta[:-1], out=sp, casting="unsafe")
        np.abs(sp, out=sp)
        for c in range(0, len(small), 16384):  # rows of at most 4 MB x 16 at a time
            grp = small[c:c + 16384]
            cols = np.arange(int(nd[grp].max()))
            idx = np.minimum(starts[grp, None] + cols[None, :], len(sp) - 1)
            rows = np.where(cols[None, :] < nd[grp, None], sp[idx], np.float32(np.nan))
            out[grp] = rows_position_nyquist(rows, nd[grp])
    return out


# the whole-recording analysis lives in .pipeline, which calls analyze_segment: imported last
from .pipeline import _n_workers, analyze, relabel_aliases  # noqa: E402,F401  (_n_workers: benchmarks)
