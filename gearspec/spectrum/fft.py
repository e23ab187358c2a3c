"""Amplitude-calibrated order spectrum of a signal on a uniform position grid, and the exact
windowed DFT of a sinusoid (to take known lines out of a spectrum without another pass)."""

from __future__ import annotations

import numpy as np
import scipy.fft
from scipy.signal import get_window

__all__ = ["order_spectrum", "hann_spectrum", "hann_sinusoid_dft"]


def order_spectrum(values: np.ndarray, spacing: float, window: str = "hann", detrend: bool = True,
                   pad: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Single-sided amplitude spectrum over position.

    A sinusoid ``A sin(2 pi f theta + phi)`` whose frequency falls on a bin shows as a peak of
    height ``A`` (the window's coherent gain is divided out).  Between bins the Hann window reads
    up to 15 % low (scalloping); use ``window="flattop"`` for amplitudes read off the plot, or the
    harmonic fit for exact ones.  The transform length is padded to a fast FFT size.

    Parameters
    ----------
    values : ndarray
        Signal on a uniform grid (see :func:`resample_over_position`).
    spacing : float
        Grid spacing, rad or m.
    window : str
        Any window name of ``scipy.signal.get_window``.
    detrend : bool
        Remove the least-squares line first, so that the mean and a slow trend do not leak.
    pad : int
        Zero-padding factor (>= 1) for a finer frequency grid.

    Returns
    -------
    frequency : ndarray
        Cycles per unit of theta.
    amplitude : ndarray
        In the unit of ``values``.
    """
    v = np.asarray(values, dtype=float)
    n = len(v)
    if detrend:
        x = np.arange(n) - (n - 1) / 2
        v = v - v.mean() - x * (x @ v) / (x @ x)
    w = get_window(window, n, fftbins=False)
    nfft = scipy.fft.next_fast_len(int(n * max(1, pad)), real=True)
    spec = scipy.fft.rfft(v * w, nfft)
    amp = np.abs(spec) * (2.0 / w.sum())
    amp[0] /= 2
    freq = np.fft.rfftfreq(nfft, d=spacing)
    return freq, amp


def hann_spectrum(values: np.ndarray, spacing: float, pad: float = 2.0):
    """Hann-windowed complex spectrum of ``values`` (already free of its mean), padded to a fast
    length of at least ``pad`` times the samples.

    Returns ``(spectrum, df, window_sum, enbw)``: bin k is at ``k * df`` cycles per unit; a
    sinusoid of amplitude A on a bin has ``|spectrum| = A window_sum / 2``; white noise of
    variance s^2 has ``E|spectrum|^2 = s^2 sum(w^2)``, i.e. ``enbw = n sum(w^2) / sum(w)^2`` (1.5
    for Hann) times what a rectangular window gives.
    """
    v = np.asarray(values, dtype=float)
    n = len(v)
    w = get_window("hann", n, fftbins=False)
    nfft = scipy.fft.next_fast_len(int(np.ceil(n * max(1.0, pad))), real=True)
    spec = scipy.fft.rfft(v * w, nfft)
    wsum = float(w.sum())
    enbw = n * float(w @ w) / wsum**2
    return spec, 1.0 / (nfft * spacing), wsum, enbw


def hann_sinusoid_dft(k: np.ndarray, nfft: int, n: int, x0: float, spacing: float, frequency: float,
                      coef_cos: float, coef_sin: float) -> np.ndarray:
    """Exact bins ``k`` of the Hann-windowed, ``nfft``-point DFT of
    ``coef_cos cos(2 pi f x) + coef_sin sin(2 pi f x)`` sampled at ``x = x0 + m spacing``,
    ``m = 0 .. n-1`` (closed-form geometric sums; the symmetric Hann window of scipy).

    Subtracting it from :func:`hann_spectrum` removes a fitted line from the spectrum without
    evaluating it at every grid point.
    """
    k = np.asarray(k, dtype=float)
    alpha = 2 * np.pi / (n - 1)

    def dsum(psi):
        # sum_{m<n} exp(i m psi), with the limit n where exp(i psi) = 1
        e1 = np.exp(1j * psi)
        num = 1 - np.exp(1j * n * psi)
        den = 1 - e1
        small = np.abs(den) < 1e-12
        return np.where(small, n, num / np.where(small, 1, den))

    def wsum(psi):
        return 0.5 * dsum(psi) - 0.25 * dsum(psi + alpha) - 0.25 * dsum(psi - alpha)

    c = coef_cos - 1j * coef_sin                 # a cos + b sin = Re(c exp(i phase))
    phase0 = 2 * np.pi * ((frequency * x0) % 1.0)
    step = 2 * np.pi * ((frequency * spacing) % 1.0)
    bin_phase = 2 * np.pi * k / nfft
    plus = 0.5 * c * np.exp(1j * phase0) * wsum(step - bin_phase)
    minus = 0.5 * np.conj(c) * np.exp(-1j * phase0) * wsum(-step - bin_phase)
    return plus + minus
