"""The search for peaks no declared line explains in the residual power spectrum of one segment
(internal to :func:`~gearspec.spectrum.analyze_segment`)."""

from __future__ import annotations

import math
from functools import cached_property

import numpy as np

from .fft import hann_fft_length, hann_sinusoid_dft, hann_spectrum32_buffer, legendre_constant
from .harmonic import HarmonicFit, NormalEquations
from .periodogram import false_alarm_probability, noise_blocks
from .resample import grid_size, resample_uniform


def _search(power, grid: "_Grid", noise_model: "_LocalNoise", declared_f, taken, span, guard, f_found_min,
            fap_threshold, m_eff, oversample, room) -> list[float]:
    """At most ``room`` peaks nothing fitted explains, strongest first: local maxima whose
    false-alarm probability (``m_eff`` frequencies searched) is below ``fap_threshold``; none within
    1.5 resolution steps of a declared line (not told apart), within ``guard`` of a line in
    ``taken`` or of a stronger new one, or below ``f_found_min`` (the nuisance could mimic it)."""
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
    # screened first by the power a known noise level (the lightest tail) would call significant,
    # against the lowest level anywhere; only those left get the exact (F) false-alarm probability
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


def _z_floor(fap_threshold: float, m_eff: float) -> float:
    """The least power ratio z whose false-alarm probability can be below ``fap_threshold`` (a known
    noise level, ``exp(-z)``, has the lightest tail of the F-family), a little below for rounding."""
    single = -math.expm1(math.log1p(-min(max(fap_threshold, 1e-300), 1.0)) / max(1.0, m_eff))
    if single <= 0:
        return math.inf
    return -math.log(min(single, 1.0)) * (1 - 1e-9) - 1e-12


class _Grid:
    """The frequencies ``base + df (k0 + i)`` of a uniform periodogram grid, computed only where
    needed."""

    def __init__(self, base: float, df: float, k0: int, n: int):
        self.base, self.df, self.k0, self.n = float(base), float(df), int(k0), int(n)

    def at(self, i):
        return self.base + self.df * (self.k0 + np.asarray(i))

    def frequencies(self) -> np.ndarray:
        return self.at(np.arange(self.n))

    def _index_near(self, f: float) -> int:
        return int(np.floor((f - self.base) / self.df)) - self.k0

    def within(self, f0: float, width: float) -> slice:
        """Bins with ``|f - f0| < width`` (a contiguous range)."""
        a = max(0, self._index_near(f0 - width) - 2)
        b = min(self.n, self._index_near(f0 + width) + 3)
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
    """:func:`~gearspec.spectrum.periodogram.local_noise` evaluated only at the bins asked for (the
    median power where the level is missing or not positive); ``bins``: bins averaged over the
    window's equivalent noise bandwidth."""

    def __init__(self, power, width, min_width, mask, enbw):
        self.power = power
        self.centres, self.levels, self.counts = noise_blocks(power, width=width, min_width=min_width, mask=mask)
        self.enbw = enbw

    @cached_property
    def fallback(self) -> float:
        p = self.power
        return float(np.nanmedian(p)) if np.any(np.isfinite(p)) else 1.0

    def level(self, idx) -> np.ndarray:
        idx = np.asarray(idx)
        v = np.interp(idx, self.centres, self.levels) if len(self.centres) else np.full(idx.shape, np.nan)
        bad = ~(np.isfinite(v) & (v > 0))
        if bad.any():
            v[bad] = self.fallback
        return v

    def lowest(self) -> float:
        """A lower bound of the level at every bin (0 when there is none)."""
        if not len(self.levels) or not np.all(np.isfinite(self.levels) & (self.levels > 0)):
            return 0.0
        return float(np.min(self.levels))

    def bins(self, idx) -> np.ndarray:
        idx = np.asarray(idx)
        return (np.interp(idx, self.centres, self.counts) if len(self.centres) else np.zeros(idx.shape)) / self.enbw


def _fft_residual_power(theta, y, fit0: HarmonicFit, oversample: float, f_max: float, keep_into=None,
                        lo: float | None = None, hi: float | None = None, keep_residual: bool = False):
    """Power of the residual of ``fit0`` from one single-precision Hann FFT of the signal resampled
    over position: the nuisance subtracted on the grid, the fitted lines in closed form within +-40
    bins (leakage beyond below 1e-7).  A sinusoid of amplitude A has power n A^2 / 4, white noise
    ``enbw * sigma^2``.  ``keep_into`` (a SegmentSpectrum) gets the signal's amplitude spectrum for
    the figures.  Returns ``(k_lo, k_hi, df, power, enbw, residual)``, ``residual`` (with
    ``keep_residual``) a :class:`_FFTResidual` for the power of another fit's residual.
    """
    n = len(theta)
    if lo is None:
        lo, hi = float(np.min(theta)), float(np.max(theta))
    h, m = grid_size(n, lo, hi)
    g0 = lo
    # x of the nuisance's Legendre series on the grid: x_k = a + b k (fit0 spans theta: hi > lo)
    b = 2.0 * h / (fit0.hi - fit0.lo)
    a = 2.0 * (g0 - fit0.lo) / (fit0.hi - fit0.lo) - 1.0
    # resampled straight into the float32 buffer (the transform pads it), the nuisance's constant
    # part taken off first in double precision (a segment has 16 samples or more: m >= 15)
    buf = np.empty(m, np.float32)
    resample_uniform(theta, y, lo=lo, hi=hi, out=buf, shift=legendre_constant(fit0.nuisance, a))
    spec, df, wsum, enbw = hann_spectrum32_buffer(buf, m, h, fit0.nuisance, a, b, nfft=hann_fft_length(m, oversample))
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
    """The complex residual spectrum of :func:`_fft_residual_power` (bins k_lo..k_hi), for the power
    of the residual of a fit with more lines: bins within +-40 of any line of either fit are
    recomputed in closed form, the rest copied; the nuisance's change is left in (lowest bins)."""

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
