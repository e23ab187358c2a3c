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
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import InputError
from ..gears import GearTrain, integer_hint, load_gear
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

    def to_dict(self) -> dict:
        return {"frequency": self.frequency, "amplitude": self.amplitude, "amplitude_se": self.amplitude_se,
                "phase": self.phase, "phase_se": self.phase_se, "fap": self.fap, "order": self.order,
                "label": self.label, "declared": self.declared, "snr": self.snr, "hint": self.hint}


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
        path.write_text(json.dumps(_clean(self.to_dict()), indent=1))
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
        json.dumps(_clean(v))
        return True
    except TypeError:
        return False


def _clean(obj):
    """NaN/inf -> None and numpy scalars -> Python, recursively, for strict JSON."""
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        x = float(obj)
        return x if math.isfinite(x) else None
    if isinstance(obj, np.ndarray):
        return _clean(obj.tolist())
    return obj


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
    f_search_max = 0.5 * (n - 1) / span
    if max_frequency is not None:
        f_search_max = min(f_search_max, float(max_frequency))
    # declared lines: fit, too slow, or too fast
    fitted, skipped, slow_cycles = [], [], []
    for ln in (gear.declared_lines(max_harmonic=harmonics) if gear is not None else []):
        cycles = ln.frequency * span
        if cycles < min_cycles:
            skipped.append({"label": ln.label, "frequency": ln.frequency,
                            "reason": f"{cycles:.3g} cycles in the segment (< {min_cycles:g}); absorbed by the nuisance polynomial"})
            slow_cycles.append(cycles)
        elif ln.frequency > 0.9 * nyquist:
            skipped.append({"label": ln.label, "frequency": ln.frequency,
                            "reason": f"above 0.9 x the position Nyquist frequency ({nyquist:.4g})"})
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
    if use_ls:
        ls = LombScargle(theta, y - fit0.predict(theta), method=method, nthreads=_ls_threads())
        fmin, df, nf = ls.autogrid(oversample=oversample, fmax=f_search_max)
        power = np.atleast_1d(ls.power_grid(fmin, df, nf))
        grid = _Grid(fmin, df, 0, len(power))
        enbw = 1.0
        del ls
    else:
        k_lo, _, df, power, enbw = _fft_residual_power(theta, y, fit0, oversample, f_search_max,
                                                          out if keep_spectra else None, lo=lo, hi=hi)
        grid = _Grid(0.0, df, k_lo, len(power))
    nbin = len(power)
    # the fit removed each declared line's power from its own bin and its neighbours: leave those
    # bins out of the noise level, or it reads low
    fitted_mask = np.zeros(nbin, bool)
    for f0 in declared_f:
        fitted_mask[grid.within(f0, 1.0 / span)] = True
    noise_model = _LocalNoise(power, width=int(100 * oversample), min_width=int(20 * oversample),
                              mask=fitted_mask, enbw=enbw)
    del fitted_mask
    m_eff = max(1.0, nbin / oversample)
    # 3. peaks no declared line explains: not where the nuisance polynomial could mimic them, and
    # not within 1.5 resolution steps of a declared line (the two could not be told apart)
    guard = _GUARD / span
    f_found_min = max(2.0, min_cycles, (deg + 1) / math.pi) / span
    found: list[float] = []
    if max_peaks > 0 and nbin >= 3:
        is_max = np.zeros(nbin, bool)
        np.greater(power[1:-1], power[:-2], out=is_max[1:-1])
        is_max[1:-1] &= power[1:-1] >= power[2:]
        for f0 in declared_f:
            is_max[grid.within(f0, 1.5 / span)] = False
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
        for i in cand[np.argsort(-z_c)]:
            f_pk = _refine(grid, power, i)
            if any(abs(f_pk - f0) < guard for f0 in found):
                continue
            found.append(f_pk)
            if len(found) >= max_peaks:
                break
    # 4. joint fit; the found frequencies refined by Gauss-Newton (each iteration one pass that
    # computes only the rows of the found lines -- the declared lines' equations are reused --
    # the last one also the joint fit); a found peak stays only while its fitted amplitude is
    # significant (a sidelobe of a stronger line is not, once that line is fitted): dropping one
    # is a smaller solve of the same normal equations, not another pass
    if found:
        n_dec = len(declared_f)
        _, _, eq = refine_frequencies(theta, y, declared_f + found, range(n_dec, n_dec + len(found)), degree=deg,
                                      iterations=3, base=eq)
    all_f = eq.frequency
    keep = list(range(len(all_f)))
    while True:
        fit = eq.fit(keep)
        s_at = grid.interp(fit.frequency, noise_model.level) if len(keep) else np.array([])
        k_at = grid.interp(fit.frequency, noise_model.bins) if len(keep) else np.array([])
        z_fit = n * fit.amplitude**2 / 4.0 / np.maximum(s_at / enbw, 1e-300)
        is_dec = np.array([j < len(declared_f) for j in keep], bool)
        fap_fit = np.where(is_dec, false_alarm_probability(z_fit, 1.0, k_at, oversample),
                           false_alarm_probability(z_fit, m_eff, k_at, oversample))
        bad = [j for j, dec, fp, f in zip(keep, is_dec, fap_fit, fit.frequency)
               if not dec and (fp >= fap_threshold or f < f_found_min)]
        if not bad:
            break
        keep = [j for j in keep if j not in bad]
    if noise == "local" and len(keep):
        fit = fit.scaled(np.clip(s_at / enbw / max(fit.sigma**2, 1e-300), 0.05, 1e6))
    amp, amp_se, ph, ph_se = fit.amplitude, fit.amplitude_se, fit.phase, fit.phase_se
    peaks = []
    for k, (j, f) in enumerate(zip(keep, fit.frequency)):
        if j < len(declared_f):
            label, declared = fitted[j].label, True
        else:
            tol = max(0.5 / span, 1e-6 * f)
            line = gear.label(f, tol) if gear is not None else None
            label, declared = (line.label if line is not None else None), False
        hint = integer_hint(gear, f, max(0.5 / span, 1e-6 * f)) if (label is None and gear is not None) else None
        peaks.append(Peak(frequency=float(f), amplitude=float(amp[k]), amplitude_se=float(amp_se[k]),
                          phase=float(ph[k]), phase_se=float(ph_se[k]), fap=float(fap_fit[k]),
                          order=None if gear is None else gear.order(f), label=label, declared=declared,
                          snr=float(z_fit[k]), hint=hint))
    out.peaks, out.fit, out.sigma = peaks, fit, fit.sigma
    # 5. spectra for the figures
    if keep_spectra:
        freqs = grid.frequencies()
        if out.fft_frequency is None:
            _fft_residual_power(theta, y, fit0, oversample, f_search_max, out, lo=lo, hi=hi)
        ls_sig = LombScargle(theta, y, method=method, nthreads=_ls_threads())
        out.ls_frequency = freqs.astype(np.float32)
        p_sig = ls_sig.power_grid(freqs[0], freqs[1] - freqs[0], len(freqs)) if len(freqs) > 1 else power
        out.ls_amplitude = ls_sig.amplitude(power=p_sig).astype(np.float32)
        out.ls_residual_amplitude = np.sqrt(4.0 * np.maximum(power, 0) / enbw / n).astype(np.float32)
        out.noise_amplitude = np.sqrt(4.0 * noise_model.level(np.arange(nbin)) / enbw / n).astype(np.float32)
    return out


_local = threading.local()  # .in_pool: this thread analyses one segment of several at once


def _ls_threads() -> int | None:
    """finufft's threads for a periodogram: one inside analyze's worker threads (the workers
    already share the CPUs; OpenMP teams on top would oversubscribe them), else its default."""
    return 1 if getattr(_local, "in_pool", False) else None


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
                        lo: float | None = None, hi: float | None = None):
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
    return k_lo, k_hi, df, power, enbw


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
    seg = segmentation or find_segments(rec, window=window, rel_tol=rel_tol, min_speed=min_speed,
                                        min_duration=min_duration)
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
    excluded = Counter(rec.excluded) + Counter(seg.excluded)
    return SpectrumResult(results, excluded, rec.n_read, rec.unit, gear, notes,
                          settings={**seg.settings, **options, "inertia": inertia})


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
