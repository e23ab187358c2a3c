"""The per-segment spectral analysis of a recording: what ``gearspec spectrum`` runs.

For every constant-speed segment, on ``y = direction * (torque - J thetadd)`` (the friction
magnitude, so that levels and phases mean the same in both directions, as in SILO4 eq. 11):

1. Joint least-squares fit, on the raw samples, of a sinusoid at every declared line that fits
   in the segment (at least ``min_cycles`` cycles, below the position Nyquist), plus a Legendre
   nuisance polynomial whose degree grows with the slowest declared line that does *not*
   complete ``min_cycles`` (so that it cannot bias the others).  One pass over the samples.
2. Periodogram of the residual: Lomb-Scargle on the raw samples for segments up to
   ``LS_MAX_SAMPLES`` samples; beyond, the Hann spectrum of the signal resampled over position
   (anti-aliased), with the fitted nuisance and lines taken out in closed form -- one FFT.  Its
   local noise level (constant relative bandwidth at low frequency) calibrates everything after.
3. Search for peaks that no declared line explains: local maxima whose false-alarm probability
   (local noise, F-distributed for an estimated level, all independent frequencies searched) is
   below ``fap_threshold``, strongest first, none within 1.5 resolution steps (1.5/span) of a
   declared line or within three of a stronger peak, none so slow that the nuisance polynomial
   could mimic it (at least 2 cycles, and (degree+1)/pi).
4. Joint fit of declared and found lines, the found frequencies refined by Gauss-Newton (a phase
   at theta = 0 needs the frequency far more precisely than a periodogram bin gives it; each
   iteration one pass that computes only the found lines' rows of the equations); a found
   peak whose fitted amplitude is no longer significant (a sidelobe of a stronger line) is
   dropped.  Standard errors are rescaled by the local noise level (honest for coloured noise).
   Without found peaks the whole analysis is one pass over the samples plus one spectrum.
5. Steps 3-4 repeat on the residual of every line found so far (the noise level re-estimated
   from it: a dense comb of lines no longer raises the level around its weaker members), until a
   round finds nothing; the later rounds search the Hann spectrum of the resampled signal with
   every fitted line taken out in closed form (no new transform, no new periodogram).

Nothing above the segment's position Nyquist frequency (:func:`position_nyquist`) is searched,
fitted or reported as measured: such declared lines are listed (``above_nyquist``) with the
frequency where they alias, and a peak found there is labelled ``alias of <label>``
(:func:`gearspec.gears.alias_of`; across segments, :func:`relabel_aliases`).  An unlabelled
peak gets an integer-order ``hint`` (with ``order_exact``) only when its frequency uncertainty
tells neighbouring multiples of the shaft apart (:func:`gearspec.gears.integer_order`).

Every declared line that fits is reported as a peak whether it is strong or not (its ``fap`` is
the chance that noise alone gives that much fitted power at that one frequency); a found peak's
``fap`` counts every independent frequency searched.  Lines that do not fit are listed with the
reason.  Peaks found in step 3 carry the label of the harmonic or sideband of declared lines
that explains them, or ``None`` (and perhaps an integer-multiple ``hint``).
"""

from __future__ import annotations

import json
import math
import sys
import threading
from collections import Counter
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import InputError
from ..jsonsafe import plain
from ..gears import GearTrain, alias_frequency, alias_of, integer_order, load_gear
from ..recording import Recording
from ..segment import FrictionTorque, Segment, Segmentation, find_segments
from .fft import (
    hann_fft_length,
    hann_sinusoid_dft,
    hann_spectrum32,
    hann_spectrum32_buffer,
    legendre_constant,
)
from .harmonic import (
    HarmonicFit,
    NormalEquations,
    min_degree_for_cycles,
    refine_frequencies,
)
from .periodogram import LombScargle, false_alarm_probability, noise_blocks
from .resample import grid_size, resample_uniform

__all__ = ["Peak", "SegmentSpectrum", "SpectrumResult", "analyze_segment", "analyze"]

_GUARD = 3.0  # resolution steps kept clear around fitted lines when searching for peaks
_MAX_ROUNDS = 6  # search -> joint fit -> search the residual of all lines found, at most this often


@dataclass(frozen=True)
class Peak:
    """A sinusoidal component of one segment (``CONTRACTS.md`` section 4, ``peaks``)."""

    frequency: float
    amplitude: float
    amplitude_se: float
    phase: float
    phase_se: float
    fap: float
    order: float | None
    label: str | None
    declared: bool
    snr: float  # power over local noise power at the frequency
    hint: str | None = None  # for an unlabelled peak: an integer multiple of a shaft it sits on
    frequency_se: float = 0.0  # standard error of a found peak's frequency (0: declared, fixed)
    frequency_exact: float | None = None  # with a hint: the exact frequency of that multiple
    order_exact: float | None = None      # ... and its exact order
    aliased_from: dict | None = None  # a peak labelled 'alias of X': X's label, frequency and order

    def to_dict(self) -> dict:
        return {"frequency": self.frequency, "amplitude": self.amplitude, "amplitude_se": self.amplitude_se,
                "phase": self.phase, "phase_se": self.phase_se, "fap": self.fap, "order": self.order,
                "label": self.label, "declared": self.declared, "snr": self.snr, "hint": self.hint,
                "frequency_se": self.frequency_se, "frequency_exact": self.frequency_exact,
                "order_exact": self.order_exact, "aliased_from": self.aliased_from}


@dataclass
class SegmentSpectrum:
    """Spectral analysis of one segment."""

    segment: Segment
    peaks: list[Peak]
    level: float            # mean friction magnitude over the segment (Nm or N)
    sigma: float            # residual standard deviation after the fit
    span: float             # travel, rad or m
    nyquist: float          # highest frequency the sampling resolves, cycles per unit
    degree: int             # nuisance polynomial degree
    skipped: list[dict]     # declared lines not fitted, with the reason
    fit: HarmonicFit | None
    fft_frequency: np.ndarray | None = None
    fft_amplitude: np.ndarray | None = None
    ls_frequency: np.ndarray | None = None
    ls_amplitude: np.ndarray | None = None
    ls_residual_amplitude: np.ndarray | None = None
    noise_amplitude: np.ndarray | None = None
    note: str = ""

    @property
    def direction(self) -> int:
        return self.segment.direction

    @property
    def speed(self) -> float:
        return self.segment.speed

    def peak(self, label: str) -> Peak | None:
        """The peak labelled ``label`` (or with ``label`` among its ' = '-joined names), or None."""
        for p in self.peaks:
            if p.label is not None and (p.label == label or label in p.label.split(" = ")):
                return p
        return None

    def to_dict(self) -> dict:
        s = self.segment
        return {"direction": s.direction, "speed": s.speed, "n": s.n, "run": s.run, "kind": s.kind,
                "start": s.start, "stop": s.stop, "level": self.level, "sigma": self.sigma,
                "span": self.span, "nyquist": self.nyquist, "nuisance_degree": self.degree,
                "peaks": [p.to_dict() for p in self.peaks], "skipped_lines": self.skipped,
                "above_nyquist": [d["label"] for d in self.skipped if d.get("kind") == "above_nyquist"],
                **({"note": self.note} if self.note else {})}


@dataclass
class SpectrumResult:
    """All segments of a recording with their spectra, and the ledger of excluded rows."""

    segments: list[SegmentSpectrum]
    excluded: Counter
    n_rows: int
    unit: str
    gear: GearTrain | None
    notes: list[str] = field(default_factory=list)
    settings: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {"unit": self.unit, "torque_unit": "Nm" if self.unit == "rad" else "N",
                "frequency_unit": f"cycles/{self.unit}", "n_rows": self.n_rows,
                "gear": None if self.gear is None else self.gear.to_dict(),
                "segments": [s.to_dict() for s in self.segments],
                "excluded": dict(sorted(self.excluded.items())), "notes": self.notes,
                "settings": {k: v for k, v in self.settings.items() if _jsonable(v)}}

    def to_json(self, path: str | Path) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(plain(self.to_dict()), indent=1))
        return path

    def peaks_table(self) -> pd.DataFrame:
        """One row per (segment, peak)."""
        rows = []
        for i, s in enumerate(self.segments):
            for p in s.peaks:
                rows.append({"segment": i, "run": s.segment.run, "direction": s.direction, "speed": s.speed,
                             "level": s.level, **p.to_dict()})
        return pd.DataFrame(rows)

    def amplitude_vs_speed(self, label: str) -> pd.DataFrame:
        """Amplitude of the peak labelled ``label`` in every segment where it was fitted."""
        rows = []
        for i, s in enumerate(self.segments):
            p = s.peak(label)
            if p is not None:
                rows.append({"segment": i, "direction": s.direction, "speed": s.speed, "level": s.level,
                             "amplitude": p.amplitude, "amplitude_se": p.amplitude_se, "phase": p.phase,
                             "frequency": p.frequency})
        return pd.DataFrame(rows)

    def unexplained(self, max_fap: float = 0.01) -> pd.DataFrame:
        """Peaks found that no declared line, harmonic or sideband explains."""
        t = self.peaks_table()
        if t.empty:
            return t
        return t[(~t["declared"]) & t["label"].isna() & (t["fap"] <= max_fap)].reset_index(drop=True)


def _jsonable(v) -> bool:
    try:
        json.dumps(plain(v))
        return True
    except TypeError:
        return False


# ---------------------------------------------------------------------- one segment
#: segments up to this many samples search the Lomb-Scargle periodogram of the raw residual;
#: longer ones the Hann spectrum of the residual resampled over position (see analyze_segment)
LS_MAX_SAMPLES = 200_000


def analyze_segment(theta: np.ndarray, y: np.ndarray, gear: GearTrain | None = None, *,
                    segment: Segment | None = None, max_frequency: float | None = None,
                    min_cycles: float = 1.0, harmonics: int = 1, degree: int | str = "auto",
                    fap_threshold: float = 0.01, max_peaks: int = 8, oversample: float = 2.0,
                    noise: str = "local", periodogram: str = "auto", method: str = "auto",
                    keep_spectra: bool = False) -> SegmentSpectrum:
    """Analyse one stretch of friction ``y`` over position ``theta`` (see the module docstring).

    ``y`` should already be the friction magnitude (direction times torque).  Frequencies are in
    cycles per unit of theta; amplitudes in the unit of ``y``.

    ``periodogram`` chooses the spectrum searched for undeclared peaks: ``"lombscargle"`` (of the
    residual on the raw samples; exact for any sampling, O(N log N) with a large constant),
    ``"fft"`` (Hann spectrum of the signal resampled over position, with the fitted declared
    lines and nuisance taken out in closed form: one FFT), or ``"auto"`` (Lomb-Scargle up to
    ``LS_MAX_SAMPLES`` samples).  Either way amplitudes, phases and errors come from the joint fit
    on the raw samples.  ``keep_spectra`` keeps the order spectrum and the Lomb-Scargle of the
    signal for figures.
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
    # nothing above the position Nyquist frequency is searched (nor fitted, nor reported as
    # measured): with jittered spacing it is below the mean spacing's 0.5 (n - 1) / span
    f_search_max = min(0.5 * (n - 1) / span, nyquist)
    if max_frequency is not None:
        f_search_max = min(f_search_max, float(max_frequency))
    # declared lines: fit, too slow, or too fast
    fitted, skipped, slow_cycles = [], [], []
    for ln in (gear.declared_lines(max_harmonic=harmonics) if gear is not None else []):
        cycles = ln.frequency * span
        if cycles < min_cycles:
            skipped.append({"label": ln.label, "frequency": ln.frequency, "kind": "too_slow",
                            "reason": f"{cycles:.3g} cycles in the segment (< {min_cycles:g}); absorbed by the nuisance polynomial"})
            slow_cycles.append(cycles)
        elif ln.frequency >= MEASURABLE_FRACTION * nyquist:
            # not measurable here: never fitted; where it shows up (its alias at the mean spacing)
            # is said, and a peak found there is labelled 'alias of <label>'
            skipped.append({"label": ln.label, "frequency": ln.frequency, "kind": "above_nyquist",
                            "alias": alias_frequency(ln.frequency, span / (n - 1)) if ln.frequency > nyquist else None,
                            "reason": f"above {MEASURABLE_FRACTION:g} x the position Nyquist frequency ({nyquist:.4g}): "
                                      "not measured"})
        else:
            fitted.append(ln)
    deg = (max(1, min_degree_for_cycles(max(slow_cycles))) if slow_cycles else 1) if degree == "auto" else int(degree)
    declared_f = [ln.frequency for ln in fitted]
    n_terms = deg + 1 + 2 * len(declared_f)
    if n <= n_terms + 8:
        return SegmentSpectrum(segment, [], float(np.mean(y)), float("nan"), span, nyquist, deg, skipped, None,
                               note=f"{n} samples are too few for {n_terms} terms")
    # 1. the declared lines: one pass over the samples
    eq = NormalEquations.accumulate(theta, y, declared_f, deg)
    fit0 = eq.fit()
    # 2. periodogram of the residual, in units where a sinusoid of amplitude A has power n A^2/4,
    # on the uniform grid freq(i) = f_first + df i (kept as an index map, not an array)
    use_ls = periodogram == "lombscargle" or (periodogram == "auto" and n <= LS_MAX_SAMPLES)
    out = SegmentSpectrum(segment, [], level=eq.y0, sigma=fit0.sigma, span=span, nyquist=nyquist,
                          degree=deg, skipped=skipped, fit=fit0)
    fft_res = None
    if use_ls:
        ls = LombScargle(theta, y - fit0.predict(theta), method=method, nthreads=_ls_threads())
        fmin, df, nf = ls.autogrid(oversample=oversample, fmax=f_search_max)
        power = np.atleast_1d(ls.power_grid(fmin, df, nf))
        grid = _Grid(fmin, df, 0, len(power))
        enbw = 1.0
        del ls
    else:
        k_lo, _, df, power, enbw, fft_res = _fft_residual_power(
            theta, y, fit0, oversample, f_search_max, out if keep_spectra else None, lo=lo, hi=hi,
            keep_residual=max_peaks > 0)
        grid = _Grid(0.0, df, k_lo, len(power))
    nbin = len(power)
    power_first = power if keep_spectra else None
    grid0, nbin0, enbw0 = grid, nbin, enbw
    m_eff = max(1.0, nbin / oversample)  # independent frequencies searched: the same in every round
    # 3. peaks no declared line explains (see _search), found iteratively: a dense comb of lines
    # raises the local noise level around each of them, so after every search the lines found so
    # far are fitted jointly (frequencies refined), the ones no longer significant dropped, and
    # the residual of all of them searched again -- its noise level re-estimated without their
    # power and sidelobes -- until a round finds nothing (at most _MAX_ROUNDS rounds).  Every
    # round searches the same frequencies: m_eff stays the count in every false-alarm probability.
    guard = _GUARD / span
    f_found_min = max(2.0, min_cycles, (deg + 1) / math.pi) / span
    n_dec = len(declared_f)
    eq_dec = eq
    found: list[float] = []
    rejected: list[float] = []     # found, then dropped: never searched for again
    keep = list(range(n_dec))
    se_eq = np.zeros(n_dec)        # frequency standard errors (white noise) of eq's lines
    fit = fit0
    for rnd in range(_MAX_ROUNDS):
        if rnd > 0:  # the residual of every line fitted so far
            if fft_res is None and nbin >= 3:
                # a Lomb-Scargle segment: the later rounds search the Hann spectrum of the signal
                # resampled over position, every fitted line taken out in closed form -- one
                # transform for all of them, a fraction of a periodogram's cost (the search's
                # frequencies and their count m_eff stay those of the first round's range)
                k_lo, _, df, p1, enbw1, fft_res = _fft_residual_power(theta, y, fit0, oversample, f_search_max,
                                                                      lo=lo, hi=hi, keep_residual=True)
                if fft_res is not None:
                    grid, enbw, nbin = _Grid(0.0, df, k_lo, len(p1)), enbw1, len(p1)
                del p1
            if fft_res is not None:
                power = fft_res.power(fit)
            else:
                ls = LombScargle(theta, y - fit.predict(theta), method=method, nthreads=_ls_threads())
                power = np.atleast_1d(ls.power_grid(grid.base, grid.df, nbin))
                del ls
        # the fit removed each fitted line's power from its own bin and its neighbours: leave
        # those bins out of the noise level, or it reads low
        fitted_mask = np.zeros(nbin, bool)
        for f0 in fit.frequency:
            fitted_mask[grid.within(f0, 1.0 / span)] = True
        noise_model = _LocalNoise(power, width=int(100 * oversample), min_width=int(20 * oversample),
                                  mask=fitted_mask, enbw=enbw)
        if rnd == 0:
            noise0 = noise_model
        del fitted_mask
        room = max_peaks - len(found)
        new = (_search(power, grid, noise_model, declared_f, found + rejected, span, guard, f_found_min,
                       fap_threshold, m_eff, oversample, room) if room > 0 and nbin >= 3 else [])
        if not new:
            break
        # 4. joint fit; the found frequencies refined by Gauss-Newton (each iteration one pass that
        # computes only the rows of the found lines -- the declared lines' equations are reused --
        # the last one also the joint fit); a found peak stays only while its fitted amplitude is
        # significant (a sidelobe of a stronger line is not, once that line is fitted): dropping
        # one is a smaller solve of the same normal equations, not another pass
        f_all, se_eq, eq = refine_frequencies(theta, y, declared_f + found + new,
                                              range(n_dec, n_dec + len(found) + len(new)), degree=deg,
                                              iterations=3, base=eq_dec)
        keep, fit, _, _ = _significant(eq, list(range(len(f_all))), noise_model, grid, n, enbw, n_dec,
                                       fap_threshold, m_eff, oversample, f_found_min)
        rejected += [float(f_all[j]) for j in range(n_dec, len(f_all)) if j not in keep]
        found = [float(f_all[j]) for j in keep if j >= n_dec]
    if fft_res is not None:
        fft_res.release()
    # the false-alarm probabilities and error scaling from the noise of the last residual searched
    keep, fit, z_fit, fap_fit = _significant(eq, keep, noise_model, grid, n, enbw, n_dec, fap_threshold, m_eff,
                                             oversample, f_found_min)
    f_se = np.asarray(se_eq, dtype=float)[keep] if len(keep) else np.zeros(0)
    if noise == "local" and len(keep):
        s_at = grid.interp(fit.frequency, noise_model.level)
        factor = np.clip(s_at / enbw / max(fit.sigma**2, 1e-300), 0.05, 1e6)
        fit = fit.scaled(factor)
        f_se = f_se * np.sqrt(factor)
    amp, amp_se, ph, ph_se = fit.amplitude, fit.amplitude_se, fit.phase, fit.phase_se
    # a found line's phase is given at theta = 0, away from the segment's centre where the
    # Gauss-Newton step decouples it from the frequency: its frequency error adds
    # 2 pi (centre - 0) f_se to the phase's (0 for declared lines, whose frequency is fixed)
    ph_se = np.hypot(ph_se, 2 * np.pi * 0.5 * (lo + hi) * f_se) if len(f_se) else ph_se
    spacing = span / (n - 1)  # mean position spacing: where lines above the Nyquist frequency alias
    peaks = []
    for k, (j, f) in enumerate(zip(keep, fit.frequency)):
        aliased = exact = None
        if j < n_dec:
            label, declared = fitted[j].label, True
        else:
            declared, line = False, None
            if gear is not None:
                line = gear.label(f, max(0.5 / span, 1e-6 * f))
                if line is None:  # a line above the position Nyquist frequency, seen at its alias
                    line = gear.label(f, max(0.5 / span, 3 * f_se[k]), spacing=spacing, nyquist=nyquist)
            label = line.label if line is not None else None
            if line is not None and line.kind == "alias":
                aliased = {"label": line.parents[0], "frequency": line.frequency, "order": line.order}
            elif label is None and gear is not None:
                # an integer order: the frequency's uncertainty (three standard errors, and no less
                # than 0.05 resolution steps, so that the resolution bound of integer_order asks a
                # shaft to turn at least once in the segment -- the Rayleigh criterion) must tell
                # neighbouring multiples apart
                exact = integer_order(gear, f, max(3 * f_se[k], 0.05 / span, 1e-6 * f))
        peaks.append(Peak(frequency=float(f), amplitude=float(amp[k]), amplitude_se=float(amp_se[k]),
                          phase=float(ph[k]), phase_se=float(ph_se[k]), fap=float(fap_fit[k]),
                          order=None if gear is None else gear.order(f), label=label, declared=declared,
                          snr=float(z_fit[k]), hint=None if exact is None else exact.hint,
                          frequency_se=float(f_se[k]),
                          frequency_exact=None if exact is None else exact.frequency,
                          order_exact=None if exact is None else exact.order, aliased_from=aliased))
    out.peaks, out.fit, out.sigma = peaks, fit, fit.sigma
    # 5. spectra for the figures
    if keep_spectra:
        # on the first round's grid; the noise level of the last round when it searched that grid
        noise_fig = noise_model if grid is grid0 else noise0
        grid, nbin, enbw = grid0, nbin0, enbw0
        freqs = grid.frequencies()
        if out.fft_frequency is None:
            _fft_residual_power(theta, y, fit0, oversample, f_search_max, out, lo=lo, hi=hi)
        ls_sig = LombScargle(theta, y, method=method, nthreads=_ls_threads())
        out.ls_frequency = freqs.astype(np.float32)
        p_sig = ls_sig.power_grid(freqs[0], freqs[1] - freqs[0], len(freqs)) if len(freqs) > 1 else power
        out.ls_amplitude = ls_sig.amplitude(power=p_sig).astype(np.float32)
        # the residual of the declared lines (the found peaks stand out in it), against the noise
        # level of the last round (the residual of every line found)
        out.ls_residual_amplitude = np.sqrt(4.0 * np.maximum(power_first, 0) / enbw / n).astype(np.float32)
        out.noise_amplitude = np.sqrt(4.0 * noise_fig.level(np.arange(nbin)) / enbw / n).astype(np.float32)
    return out


def _search(power, grid: "_Grid", noise_model: "_LocalNoise", declared_f, taken, span, guard, f_found_min,
            fap_threshold, m_eff, oversample, room) -> list[float]:
    """Peaks of a residual power spectrum that nothing fitted explains, strongest first: local
    maxima whose false-alarm probability (local noise, F-distributed for an estimated level,
    ``m_eff`` independent frequencies searched) is below ``fap_threshold``; none within 1.5
    resolution steps of a declared line (the two could not be told apart), within ``guard`` of a
    line in ``taken`` (found or rejected before) or of a stronger new one, or below
    ``f_found_min`` (where the nuisance polynomial could mimic it).  At most ``room``."""
    nbin = len(power)
    is_max = np.zeros(nbin, bool)
    np.greater(power[1:-1], power[:-2], out=is_max[1:-1])
    is_max[1:-1] &= power[1:-1] >= power[2:]
    for f0 in declared_f:
        is_max[grid.within(f0, 1.5 / span)] = False
    for f0 in taken:
        is_max[grid.within(f0, guard)] = False
    is_max[:grid.first_at_least(f_found_min)] = False
    cand = np.flatnonzero(is_max)
    del is_max
    # a candidate needs at least the power that a known noise level (the lightest tail) would
    # call significant; only those get the exact (F-distributed) false-alarm probability.  The
    # lowest noise level anywhere screens out most of them without evaluating the level.
    z_floor = _z_floor(fap_threshold, m_eff)
    floor = noise_model.lowest()
    if floor > 0:
        cand = cand[power[cand] > z_floor * floor * (1 - 1e-6)]
    z_c = power[cand] / noise_model.level(cand)
    keep_c = z_c > z_floor
    cand, z_c = cand[keep_c], z_c[keep_c]
    fap_c = false_alarm_probability(z_c, m_eff, noise_model.bins(cand), oversample)
    sig = fap_c < fap_threshold
    cand, z_c = cand[sig], z_c[sig]
    new: list[float] = []
    for i in cand[np.argsort(-z_c)]:
        f_pk = _refine(grid, power, i)
        if any(abs(f_pk - f0) < guard for f0 in new):
            continue
        new.append(f_pk)
        if len(new) >= room:
            break
    return new


def _significant(eq: NormalEquations, keep, noise_model: "_LocalNoise", grid: "_Grid", n, enbw, n_dec,
                 fap_threshold, m_eff, oversample, f_found_min):
    """The joint fit of the lines ``keep`` of ``eq``, found lines (index >= ``n_dec``) dropped while
    one is not significant against ``noise_model`` or too slow.  Returns ``(keep, fit, z, fap)``;
    a declared line's fap is for one frequency, a found one's counts the ``m_eff`` searched."""
    keep = list(keep)
    while True:
        fit = eq.fit(keep)
        s_at = grid.interp(fit.frequency, noise_model.level) if len(keep) else np.array([])
        k_at = grid.interp(fit.frequency, noise_model.bins) if len(keep) else np.array([])
        z_fit = n * fit.amplitude**2 / 4.0 / np.maximum(s_at / enbw, 1e-300)
        is_dec = np.array([j < n_dec for j in keep], bool)
        fap_fit = np.where(is_dec, false_alarm_probability(z_fit, 1.0, k_at, oversample),
                           false_alarm_probability(z_fit, m_eff, k_at, oversample))
        bad = [j for j, dec, fp, f in zip(keep, is_dec, fap_fit, fit.frequency)
               if not dec and (fp >= fap_threshold or f < f_found_min)]
        if not bad:
            return keep, fit, z_fit, fap_fit
        keep = [j for j in keep if j not in bad]


_local = threading.local()  # .in_pool: this thread analyses one segment of several at once


def _ls_threads() -> int | None:
    """finufft's threads for a periodogram: one inside analyze's worker threads (the workers
    already share the CPUs; OpenMP teams on top would oversubscribe them), else its default."""
    return 1 if getattr(_local, "in_pool", False) else None


#: a line is measurable in a segment when it lies below this fraction of the segment's position
#: Nyquist frequency (:func:`position_nyquist`): the one margin of the spectrum, the joint fit
#: (``identify``) and the closed loop (``diagnose``), so that a line is "measured" in one place
#: exactly where its amplitude law may be fitted in the others
MEASURABLE_FRACTION = 0.8


def position_nyquist(theta: np.ndarray) -> float:
    """The position Nyquist frequency of samples at positions ``theta`` (cycles per unit of theta):
    the one source of this fact for every stage (spectrum, identification, the closed loop).

    Half the inverse of the 95th percentile of the nonzero sample spacings (linear
    interpolation, as ``np.percentile``), from a selection in single precision: the spacing is
    rounded to 1e-7 of itself, and the selection takes a third of the time."""
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


def _z_floor(fap_threshold: float, m_eff: float) -> float:
    """The least power ratio z whose false-alarm probability can be below ``fap_threshold``:
    that of an exactly known noise level (``exp(-z)`` per frequency), whose tail is the lightest
    of the F-family; a little below, for rounding."""
    single = -math.expm1(math.log1p(-min(max(fap_threshold, 1e-300), 1.0)) / max(1.0, m_eff))
    if single <= 0:
        return math.inf
    return -math.log(min(single, 1.0)) * (1 - 1e-9) - 1e-12


class _Grid:
    """The frequencies of a uniform periodogram grid, ``f(i) = base + df (k0 + i)``, computed
    exactly as the array ``base + df * arange(k0, k0 + n)`` would hold them, but only where
    needed."""

    def __init__(self, base: float, df: float, k0: int, n: int):
        self.base, self.df, self.k0, self.n = float(base), float(df), int(k0), int(n)

    def at(self, i):
        i = np.asarray(i)
        if self.base == 0.0:
            return self.df * (self.k0 + i)
        return self.base + self.df * (self.k0 + i)

    def frequencies(self) -> np.ndarray:
        return self.at(np.arange(self.n))

    def _index_near(self, f: float) -> int:
        return int(np.floor((f - self.base) / self.df)) - self.k0

    def within(self, f0: float, width: float) -> slice:
        """Bins with ``|f - f0| < width`` (a contiguous range)."""
        a = max(0, self._index_near(f0 - width) - 2)
        b = min(self.n, self._index_near(f0 + width) + 3)
        if b <= a:
            return slice(0, 0)
        idx = np.arange(a, b)
        hit = idx[np.abs(self.at(idx) - f0) < width]
        return slice(int(hit[0]), int(hit[-1]) + 1) if len(hit) else slice(0, 0)

    def first_at_least(self, f: float) -> int:
        """The first bin with frequency >= f."""
        i = min(max(0, self._index_near(f) - 2), self.n)
        while i < self.n and self.at(i) < f:
            i += 1
        return i

    def interp(self, f, values_at) -> np.ndarray:
        """``np.interp(f, frequencies, values)``, with ``values_at(indices)`` giving values only
        at the bins around each f."""
        f = np.atleast_1d(np.asarray(f, dtype=float))
        out = np.empty(len(f))
        for j, x in enumerate(f):
            c = self._index_near(x)
            idx = np.arange(max(0, min(c, self.n - 1) - 2), min(self.n, max(c, 0) + 4))
            out[j] = np.interp(x, self.at(idx), values_at(idx))
        return out


class _LocalNoise:
    """:func:`~gearspec.spectrum.periodogram.local_noise` of a power spectrum, evaluated only at
    the bins asked for (the same values: linear interpolation between block levels, and the
    median power wherever the level is missing or not positive); ``bins`` is the number of
    bins averaged, over the window's equivalent noise bandwidth."""

    def __init__(self, power, width, min_width, mask, enbw):
        self.power = power
        self.centres, self.levels, self.counts = noise_blocks(power, width=width, min_width=min_width, mask=mask)
        self.enbw = enbw
        self._fallback = None

    def fallback(self) -> float:
        if self._fallback is None:
            p = self.power
            self._fallback = float(np.nanmedian(p)) if np.any(np.isfinite(p)) else 1.0
        return self._fallback

    def level(self, idx) -> np.ndarray:
        idx = np.asarray(idx)
        if len(self.centres):
            v = np.interp(idx, self.centres, self.levels)
        else:
            v = np.full(idx.shape, np.nan)
        bad = ~(np.isfinite(v) & (v > 0))
        if bad.any():
            v[bad] = self.fallback()
        return v

    def lowest(self) -> float:
        """A lower bound of the level at every bin (0 when there is none)."""
        if not len(self.levels) or not np.all(np.isfinite(self.levels) & (self.levels > 0)):
            return 0.0
        return float(np.min(self.levels))

    def bins(self, idx) -> np.ndarray:
        idx = np.asarray(idx)
        if len(self.centres):
            return np.interp(idx, self.centres, self.counts) / self.enbw
        return np.zeros(idx.shape) / self.enbw


def _fft_residual_power(theta, y, fit0: HarmonicFit, oversample: float, f_max: float, keep_into=None,
                        lo: float | None = None, hi: float | None = None, keep_residual: bool = False):
    """Power of the residual of ``fit0`` from one Hann-windowed FFT of the signal resampled over
    position: the nuisance polynomial is subtracted on the grid, the fitted lines in closed form
    near their bins (:func:`~gearspec.spectrum.fft.hann_sinusoid_dft`; beyond +-40 bins the
    window's leakage is below 1e-7).  Scaled so that a sinusoid of amplitude A has power
    n A^2 / 4; white noise then has power ``enbw * sigma^2``.

    The resampled signal, once the nuisance is off, is windowed and transformed in single
    precision (:func:`~gearspec.spectrum.fft.hann_spectrum32`): its rounding (~1e-7 of the
    signal) is far below any noise floor the search could use, and it halves the FFT's time and
    memory.

    With ``keep_into`` (a SegmentSpectrum) the calibrated amplitude spectrum of the signal (line
    included, nuisance removed) is stored there for the figures.

    Returns ``(k_lo, k_hi, df, power, enbw, residual)``: ``residual`` (with ``keep_residual``,
    else None) is a :class:`_FFTResidual` that gives the power of the residual of another fit
    (more lines) without another transform.
    """
    n = len(theta)
    if lo is None:
        lo, hi = float(np.min(theta)), float(np.max(theta))
    h, m = grid_size(n, lo, hi)
    g0 = lo
    # x of the nuisance's Legendre series on the grid: x_k = a + b k
    if fit0.hi > fit0.lo:
        b = 2.0 * h / (fit0.hi - fit0.lo)
        a = 2.0 * (g0 - fit0.lo) / (fit0.hi - fit0.lo) - 1.0
    else:
        a = b = 0.0
    if m < 4:  # degenerate: the general function
        _, _, vals = resample_uniform(theta, y, lo=lo, hi=hi)
        spec, df, wsum, enbw = hann_spectrum32(vals, h, pad=oversample, legendre=(fit0.nuisance, a, b))
    else:
        # resampled straight into the transform's float32 buffer, the nuisance's constant part
        # taken off first in double precision: no double-precision copy of the grid
        buf = np.empty(m, np.float32)  # the transform pads it (in its own work buffer)
        resample_uniform(theta, y, lo=lo, hi=hi, out=buf, shift=legendre_constant(fit0.nuisance, a))
        spec, df, wsum, enbw = hann_spectrum32_buffer(buf, m, h, fit0.nuisance, a, b,
                                                      nfft=hann_fft_length(m, oversample))
        del buf
    nfft = 2 * (len(spec) - 1) if len(spec) > 1 else 1
    if keep_into is not None:
        keep_into.fft_frequency = (df * np.arange(len(spec))).astype(np.float32)
        keep_into.fft_amplitude = (np.abs(spec) * np.float32(2.0 / wsum)).astype(np.float32)
    for f, ca, cb in zip(fit0.frequency, fit0.coef_cos, fit0.coef_sin):
        k0 = int(round(f / df))
        k = np.arange(max(0, k0 - 40), min(len(spec), k0 + 41))
        spec[k] -= hann_sinusoid_dft(k, nfft, m, g0, h, f, ca, cb).astype(spec.dtype)
    k_lo = max(1, int(np.ceil((1.0 / (hi - lo)) / df)))
    k_hi = min(len(spec) - 1, int(np.floor(f_max / df)))
    sel = spec[k_lo:k_hi + 1]
    power = np.square(sel.real)      # single precision, as the spectrum: ~1e-7 of each bin's power
    power += np.square(sel.imag)
    power *= np.float32(n / wsum**2)
    res = (_FFTResidual(sel, k_lo, df, nfft, m, g0, h, np.float32(n / wsum**2), fit0, power)
           if keep_residual and len(sel) else None)
    return k_lo, k_hi, df, power, enbw, res


class _FFTResidual:
    """The complex residual spectrum of :func:`_fft_residual_power` (a view of its bins k_lo..k_hi),
    kept to give the power of the residual of a fit with more lines: the bins within +-40 of
    every line of either fit are recomputed in closed form (the first fit's lines put back, the
    new fit's taken out, as the first were), the rest copied.  The change of the nuisance
    polynomial between the two fits is left in (it is slow: it touches the lowest bins only)."""

    _HALF = 40  # bins either side of a line (the Hann window's leakage beyond is below 1e-7)

    def __init__(self, sel, k_lo, df, nfft, m, g0, h, scale, fit0: HarmonicFit, power0):
        self.sel, self.k_lo, self.df, self.nfft, self.m, self.g0, self.h = sel, int(k_lo), df, nfft, m, g0, h
        self.scale, self.power0 = scale, power0
        self.lines0 = list(zip(fit0.frequency, fit0.coef_cos, fit0.coef_sin))

    def _window(self, f):
        k0 = int(round(f / self.df))
        a = max(self.k_lo, k0 - self._HALF)
        b = min(self.k_lo + len(self.sel) - 1, k0 + self._HALF)
        return a, b

    def power(self, fit: HarmonicFit):
        p = self.power0.copy()
        lines1 = list(zip(fit.frequency, fit.coef_cos, fit.coef_sin))
        spans = [self._window(f) for f, _, _ in self.lines0 + lines1]
        idx = np.unique(np.concatenate([np.arange(a, b + 1) for a, b in spans if b >= a] or [np.zeros(0, int)]))
        if not len(idx):
            return p
        val = self.sel[idx - self.k_lo].astype(np.complex128)
        for sign, lines in ((1.0, self.lines0), (-1.0, lines1)):
            for f, ca, cb in lines:
                a, b = self._window(f)
                w = (idx >= a) & (idx <= b)
                if w.any():
                    val[w] += sign * hann_sinusoid_dft(idx[w], self.nfft, self.m, self.g0, self.h, f, ca, cb)
        p[idx - self.k_lo] = (np.square(val.real) + np.square(val.imag)) * float(self.scale)
        return p

    def release(self):
        self.sel = self.power0 = None


def _refine(grid: _Grid, power, i):
    """Peak frequency by a parabola through the log power of the three bins around bin i."""
    if i <= 0 or i >= len(power) - 1:
        return float(grid.at(i))
    a, b, c = np.log(np.maximum(power[i - 1:i + 2].astype(float), 1e-300))
    den = a - 2 * b + c
    shift = 0.5 * (a - c) / den if den < 0 else 0.0
    return float(grid.at(i) + np.clip(shift, -0.5, 0.5) * (grid.at(1) - grid.at(0)))


# ---------------------------------------------------------------------- a whole recording
def analyze(rec: Recording, gear=None, *, segmentation: Segmentation | None = None,
            window: float | str = "auto", rel_tol: float = 0.15, min_speed: float | None = None,
            min_duration: float | None = None, inertia: bool = True, progress: bool | None = None,
            workers: int | str = "auto", **options) -> SpectrumResult:
    """Segment a recording and analyse every segment (``gearspec spectrum``).

    Parameters
    ----------
    rec : Recording
    gear : GearTrain, preset name or path, optional
        Defaults to the recording's own gear spec.
    segmentation : Segmentation, optional
        Precomputed segments; otherwise :func:`~gearspec.segment.find_segments` runs with
        ``window``, ``rel_tol``, ``min_speed`` and ``min_duration``.
    inertia : bool
        Subtract ``J * thetadd`` when the gear spec gives an inertia.
    progress : bool, optional
        Show a progress bar (default: when stderr is a terminal and there are many segments).
    workers : int or "auto"
        Segments analysed at once, in threads (numpy, the BLAS and the FFT release the GIL for
        the bulk of the work).  The results are the same whatever the number.  ``"auto"``: two
        on a machine with two or more CPUs when at least two segments are long (more than
        ``LS_MAX_SAMPLES`` samples), else one.  Each segment in flight holds its own
        temporaries, so two workers need about twice the memory of one.
    **options
        Passed to :func:`analyze_segment` (``max_frequency``, ``min_cycles``, ``harmonics``,
        ``degree``, ``fap_threshold``, ``max_peaks``, ``oversample``, ``noise``, ``method``,
        ``keep_spectra``).
    """
    gear = load_gear(gear) if gear is not None else rec.gear
    if gear is not None and gear.unit != rec.unit:
        raise InputError(f"gear spec '{gear.name}' is for theta in {gear.unit}, the recording's theta is in {rec.unit}")
    # `is None`, not `or`: an empty Segmentation is falsy, and the user's segmentation (with its
    # options) must be honoured -- refused below when it holds no segment -- never replaced
    seg = segmentation if segmentation is not None else find_segments(
        rec, window=window, rel_tol=rel_tol, min_speed=min_speed, min_duration=min_duration)
    if len(seg) == 0:
        raise InputError(f"{', '.join(rec.sources)}: no constant-speed segment found "
                         f"(rows: {dict(seg.excluded)}); try a larger --rel-tol or a fixed --window")
    J = gear.inertia if (inertia and gear is not None) else None
    # the friction torque segment by segment (tau - J thetadd), never the whole recording at once
    tau = FrictionTorque(rec, inertia=J) if J else rec.tau
    theta = rec.theta
    notes = list(rec.notes)
    if J:
        notes.append(f"inertia removed: tau - {J:g} x thetadd (Savitzky-Golay derivative)")
    if progress is None:
        progress = sys.stderr.isatty() and len(seg) > 5
    n_workers = _n_workers(workers, seg)

    def one(s: Segment) -> SegmentSpectrum:
        # a quasi-static sweep was taken at rest: its torque is analysed as measured (no J thetadd)
        y = (rec.tau if s.kind == "quasi_static" else tau)[s.rows]
        if s.direction < 0:  # the friction magnitude (a view of the torque when it is the torque)
            y = -y
        return analyze_segment(theta[s.rows], y, gear, segment=s, **options)

    def one_in_pool(s: Segment) -> SegmentSpectrum:
        _local.in_pool = True
        try:
            return one(s)
        finally:
            _local.in_pool = False

    if n_workers > 1:
        from concurrent.futures import ThreadPoolExecutor

        with ThreadPoolExecutor(max_workers=n_workers, thread_name_prefix="gearspec-segment") as pool:
            it = pool.map(one_in_pool, seg.segments)
            if progress:
                from tqdm import tqdm

                it = tqdm(it, total=len(seg), desc="segments", unit="seg", file=sys.stderr)
            results = list(it)
    else:
        iterator = seg.segments
        if progress:
            from tqdm import tqdm

            iterator = tqdm(iterator, desc="segments", unit="seg", file=sys.stderr)
        results = [one(s) for s in iterator]
    relabel_aliases(results, gear, unit=rec.unit)
    excluded = Counter(rec.excluded) + Counter(seg.excluded)
    return SpectrumResult(results, excluded, rec.n_read, rec.unit, gear, notes,
                          settings={**seg.settings, **options, "inertia": inertia})


def relabel_aliases(segments: list[SegmentSpectrum], gear: GearTrain | None = None, unit: str = "rad") -> int:
    """Label ``alias of <line>`` the unexplained peaks of a segment that sit where a line found
    in *another* segment (measured there, below its position Nyquist frequency) aliases in this
    one -- the same ripple seen at a slow speed and, above the Nyquist frequency, at a fast one
    (:func:`gearspec.gears.alias_of`, the rule the per-segment labels use).  Changes the peaks in
    place; returns how many were relabelled."""
    known: list[tuple[float, str]] = []
    for s in segments:
        for p in s.peaks:
            if p.declared or p.aliased_from is not None or p.fap >= 0.01:
                continue
            name = (p.label.split(" = ")[0] if p.label else p.hint) or f"line at {p.frequency:.6g} cycles/{unit}"
            if not any(abs(f - p.frequency) <= 1e-4 * p.frequency for f, _ in known):
                known.append((p.frequency, name))
    changed = 0
    for s in segments:
        n = s.segment.n
        if not s.peaks or n < 2 or not (s.span > 0):
            continue
        spacing = s.span / (n - 1)
        for i, p in enumerate(s.peaks):
            if p.declared or p.label is not None:
                continue
            others = [(f, lab) for f, lab in known if f > s.nyquist]  # only lines this segment cannot measure
            if not others:
                continue
            ln = alias_of(None, p.frequency, max(0.5 / s.span, 3 * p.frequency_se), spacing, nyquist=s.nyquist,
                          known=others, max_harmonic=1)
            if ln is not None:
                s.peaks[i] = replace(p, label=ln.label, hint=None, frequency_exact=None, order_exact=None,
                                     aliased_from={"label": ln.parents[0], "frequency": ln.frequency,
                                                   "order": None if gear is None else gear.order(ln.frequency)})
                changed += 1
    return changed


def _n_workers(workers, seg: Segmentation) -> int:
    if workers == "auto":
        import os

        long_ = sum(s.n > LS_MAX_SAMPLES for s in seg)
        return 2 if (os.cpu_count() or 1) >= 2 and long_ >= 2 else 1
    try:
        n = int(workers)
    except (TypeError, ValueError):
        raise InputError(f"workers must be a positive integer or 'auto', got {workers!r}") from None
    if n < 1:
        raise InputError(f"workers must be a positive integer or 'auto', got {workers!r}")
    return min(n, max(1, len(seg)))
