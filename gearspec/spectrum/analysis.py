"""The per-segment spectral analysis of a recording: what ``gearspec spectrum`` runs.

For every constant-speed segment, on ``y = direction * (torque - J thetadd)`` (the friction
magnitude, so that levels and phases mean the same in both directions, as in SILO4 eq. 11):

1. Joint fit of the declared lines (see 3), and the Lomb-Scargle periodogram of its residual on
   the raw samples over position, from one cycle per segment up to the position Nyquist (or
   ``max_frequency``), with its local noise level.
2. Search for peaks that no declared line explains: local maxima of the residual periodogram
   whose false-alarm probability (local noise, all independent frequencies searched) is below
   ``fap_threshold``, strongest first, none within 1.5 resolution steps (1.5/span) of a declared
   line or within three of a stronger peak, and none so slow that the nuisance polynomial could
   mimic it (at least 2 cycles, and (degree+1)/pi).
3. Joint least-squares fit, on the raw samples, of a sinusoid at every declared line that fits in
   the segment (at least ``min_cycles`` cycles, below the position Nyquist) and at every peak
   found, plus a Legendre nuisance polynomial whose degree grows with the slowest declared line
   that does *not* complete ``min_cycles`` (so that it cannot bias the others).  Standard errors
   are rescaled by the local noise level of step 1 (honest for coloured noise).  A peak of step 2
   whose fitted amplitude is no longer significant (a sidelobe of a stronger line) is dropped and
   the fit repeated.  The frequencies of found peaks are refined by Gauss-Newton on the joint
   model first (a phase at theta = 0 needs the frequency far more precisely than a periodogram
   bin gives it).
4. Calibrated order spectrum: torque resampled over position (anti-aliased), Hann-windowed FFT.

Every declared line that fits is reported as a peak whether it is strong or not (its ``fap`` is
the chance that noise alone gives that much fitted power at that one frequency); a found peak's
``fap`` counts every independent frequency searched.  Lines that do not fit are listed with the
reason.  Peaks found in step 2 carry the label of the harmonic or sideband of
declared lines that explains them, or ``None``.
"""

from __future__ import annotations

import json
import math
import sys
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import InputError
from ..gears import GearTrain, load_gear
from ..recording import Recording
from ..segment import Segment, Segmentation, find_segments, friction_torque
from .fft import order_spectrum
from .harmonic import HarmonicFit, harmonic_fit, min_degree_for_cycles, refine_frequencies
from .periodogram import LombScargle, false_alarm_probability, local_noise
from .resample import resample_over_position

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
        return {"direction": s.direction, "speed": s.speed, "n": s.n, "run": s.run,
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
def analyze_segment(theta: np.ndarray, y: np.ndarray, gear: GearTrain | None = None, *,
                    segment: Segment | None = None, max_frequency: float | None = None,
                    min_cycles: float = 1.0, harmonics: int = 1, degree: int | str = "auto",
                    fap_threshold: float = 0.01, max_peaks: int = 8, oversample: float = 2.0,
                    noise: str = "local", method: str = "auto", keep_spectra: bool = True) -> SegmentSpectrum:
    """Analyse one stretch of friction ``y`` over position ``theta`` (see the module docstring).

    ``y`` should already be the friction magnitude (direction times torque).  Frequencies are in
    cycles per unit of theta; amplitudes in the unit of ``y``.
    """
    theta = np.asarray(theta, dtype=float)
    y = np.asarray(y, dtype=float)
    n = len(theta)
    if segment is None:
        d = int(np.sign(theta[-1] - theta[0])) or 1
        segment = Segment(run=0, start=0, stop=n, direction=d, speed=float("nan"))
    span = float(np.ptp(theta))
    if n < 16 or span <= 0:
        return SegmentSpectrum(segment, [], float(np.mean(y)) if n else float("nan"), float("nan"), span,
                               float("nan"), 0, [], None, note="too few samples to analyse")
    spacing = np.abs(np.diff(theta))
    moving = spacing[spacing > 0]
    nyquist = 0.5 / float(np.percentile(moving, 95)) if len(moving) else 0.0
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
    if degree == "auto":
        deg = max(1, min_degree_for_cycles(max(slow_cycles))) if slow_cycles else 1
    else:
        deg = int(degree)
    declared_f = [ln.frequency for ln in fitted]
    # 1. declared lines first; periodogram of the residual (of the signal too, for the figures)
    fit0, resid = harmonic_fit(theta, y, declared_f, degree=deg, residual=True)
    ls = LombScargle(theta, np.vstack([resid, y]) if keep_spectra else resid, method=method)
    fmin, df, nf = ls.autogrid(oversample=oversample, fmax=f_search_max)
    power_all = np.atleast_2d(ls.power_grid(fmin, df, nf))
    power = power_all[0]
    freqs = fmin + df * np.arange(len(power))
    # the fit removed each declared line's power from its own bin and its neighbours: leave those
    # bins out of the noise level, or it reads low
    fitted_mask = np.zeros(len(freqs), bool)
    for f0 in declared_f:
        fitted_mask |= np.abs(freqs - f0) < 1.0 / span
    noise_power, noise_bins = local_noise(power, width=int(100 * oversample), min_width=int(20 * oversample),
                                          mask=fitted_mask, return_bins=True)
    fallback = float(np.nanmedian(power)) / math.log(2) if np.any(np.isfinite(power)) else 1.0
    noise_power = np.where(np.isfinite(noise_power) & (noise_power > 0), noise_power, fallback)
    z = power / noise_power
    m_eff = max(1.0, len(freqs) / oversample)
    # 2. peaks no declared line explains: not where the nuisance polynomial could mimic them, and
    # not within 1.5 resolution steps of a declared line (the two could not be told apart)
    guard = _GUARD / span
    f_found_min = max(2.0, min_cycles, (deg + 1) / math.pi) / span
    near_declared = np.zeros(len(freqs), bool)
    for f0 in declared_f:
        near_declared |= np.abs(freqs - f0) < 1.5 / span
    found = []
    if max_peaks > 0 and len(power) >= 3:
        is_max = np.zeros(len(power), bool)
        is_max[1:-1] = (power[1:-1] > power[:-2]) & (power[1:-1] >= power[2:])
        fap_all = false_alarm_probability(z, m_eff, noise_bins, oversample)
        cand = np.flatnonzero(is_max & ~near_declared & (fap_all < fap_threshold) & (freqs >= f_found_min))
        for i in cand[np.argsort(-z[cand])]:
            f_pk = _refine(freqs, power, i)
            if any(abs(f_pk - f0) < guard for f0 in found):
                continue
            found.append(f_pk)
            if len(found) >= max_peaks:
                break
    # 3. joint fit; a peak found in the periodogram stays only if its amplitude in the joint fit
    # is still significant (a sidelobe of a stronger line is not, once that line is fitted)
    declared_f = [ln.frequency for ln in fitted]
    if found:
        f_all, _ = refine_frequencies(theta, y, declared_f + found, range(len(declared_f), len(declared_f) + len(found)),
                                      degree=deg)
        # keep a refinement only if it stayed within a resolution step and out of the polynomial's reach
        found = [float(fr) if (abs(fr - f0) <= 1.0 / span and fr >= f_found_min) else f0
                 for f0, fr in zip(found, f_all[len(declared_f):])]
    while True:
        all_freq = declared_f + found
        n_terms = deg + 1 + 2 * len(all_freq)
        if n <= n_terms + 8:
            return SegmentSpectrum(segment, [], float(np.mean(y)), float("nan"), span, nyquist, deg, skipped,
                                   None, note=f"{n} samples are too few for {n_terms} terms")
        fit = harmonic_fit(theta, y, all_freq, degree=deg)
        s_at = np.interp(all_freq, freqs, noise_power) if len(all_freq) else np.array([])
        k_at = np.interp(all_freq, freqs, noise_bins) if len(all_freq) else np.array([])
        z_fit = n * fit.amplitude**2 / 4.0 / np.maximum(s_at, 1e-300)
        fap_fit = np.where(np.arange(len(all_freq)) < len(declared_f),
                           false_alarm_probability(z_fit, 1.0, k_at, oversample),
                           false_alarm_probability(z_fit, m_eff, k_at, oversample))
        keep = [f for j, f in enumerate(found) if fap_fit[len(declared_f) + j] < fap_threshold]
        if len(keep) == len(found):
            break
        found = keep
    if noise == "local" and len(all_freq):
        factor = np.clip(s_at / max(fit.sigma**2, 1e-300), 0.05, 1e6)
        fit = fit.scaled(factor)
    elif noise not in ("local", "white"):
        raise InputError(f"noise must be 'local' or 'white', got '{noise}'")
    amp, amp_se, ph, ph_se = fit.amplitude, fit.amplitude_se, fit.phase, fit.phase_se
    peaks = []
    for k, f in enumerate(all_freq):
        if k < len(fitted):
            label, declared = fitted[k].label, True
        else:
            tol = max(0.5 / span, 1e-6 * f)
            line = gear.label(f, tol) if gear is not None else None
            label, declared = (line.label if line is not None else None), False
        hint = _integer_hint(gear, f, max(0.5 / span, 1e-6 * f)) if (label is None and gear is not None) else None
        peaks.append(Peak(frequency=float(f), amplitude=float(amp[k]), amplitude_se=float(amp_se[k]),
                          phase=float(ph[k]), phase_se=float(ph_se[k]), fap=float(fap_fit[k]),
                          order=None if gear is None else gear.order(f), label=label, declared=declared,
                          snr=float(z_fit[k]), hint=hint))
    out = SegmentSpectrum(segment, peaks, level=float(np.mean(y)), sigma=fit.sigma, span=span, nyquist=nyquist,
                          degree=deg, skipped=skipped, fit=fit)
    # 4. order spectrum
    if keep_spectra:
        grid, vals = resample_over_position(theta, y, max_frequency=max_frequency)
        out.fft_frequency, out.fft_amplitude = order_spectrum(vals, grid[1] - grid[0])
        out.ls_frequency = freqs
        out.ls_amplitude = ls.amplitude(power=power_all[1])
        out.ls_residual_amplitude = ls.amplitude(power=power)
        out.noise_amplitude = ls.amplitude(power=noise_power)
    return out


def _integer_hint(gear: GearTrain, f: float, tol: float) -> str | None:
    """'7x motor shaft' when f sits within tol of an integer multiple (>= 2) of a shaft line.

    Not a label: a high multiple of a slow shaft matches almost anything, so only multiples up to
    64 are tried, fastest shaft (smallest multiple) first, and only shafts whose frequency is ten
    times the tolerance (so that neighbouring multiples are distinguishable).  A motor pole-pair or cogging order
    shows up this way.
    """
    shafts = sorted((ln for ln in gear.declared_lines() if ln.kind == "shaft"), key=lambda x: -x.frequency)
    for ln in shafts:
        if tol > 0.1 * ln.frequency:  # neighbouring multiples cannot be told apart
            continue
        m = round(f / ln.frequency)
        if 2 <= m <= 64 and abs(f - m * ln.frequency) <= tol:
            return f"{m}x {ln.label}"
    return None


def _refine(freqs, power, i):
    """Peak frequency by a parabola through the log power of the three bins around bin i."""
    if i <= 0 or i >= len(power) - 1:
        return float(freqs[i])
    a, b, c = np.log(np.maximum(power[i - 1:i + 2], 1e-300))
    den = a - 2 * b + c
    shift = 0.5 * (a - c) / den if den < 0 else 0.0
    return float(freqs[i] + np.clip(shift, -0.5, 0.5) * (freqs[1] - freqs[0]))


# ---------------------------------------------------------------------- a whole recording
def analyze(rec: Recording, gear=None, *, segmentation: Segmentation | None = None,
            window: float | str = "auto", rel_tol: float = 0.15, min_speed: float | None = None,
            min_duration: float | None = None, inertia: bool = True, progress: bool | None = None,
            **options) -> SpectrumResult:
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
    tau = friction_torque(rec) if inertia else rec.tau
    theta = rec.theta
    notes = list(rec.notes)
    if inertia and gear is not None and gear.inertia:
        notes.append(f"inertia removed: tau - {gear.inertia:g} x thetadd (Savitzky-Golay derivative)")
    if progress is None:
        progress = sys.stderr.isatty() and len(seg) > 5
    iterator = seg.segments
    if progress:
        from tqdm import tqdm

        iterator = tqdm(iterator, desc="segments", unit="seg", file=sys.stderr)
    results = []
    for s in iterator:
        y = s.direction * tau[s.rows]
        results.append(analyze_segment(theta[s.rows], y, gear, segment=s, **options))
    excluded = Counter(rec.excluded) + Counter(seg.excluded)
    return SpectrumResult(results, excluded, rec.n_read, rec.unit, gear, notes,
                          settings={**seg.settings, **options, "inertia": inertia})
