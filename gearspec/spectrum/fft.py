"""Amplitude-calibrated order spectrum of a signal on a uniform position grid, and the exact
windowed DFT of a sinusoid (to take known lines out of a spectrum without another pass)."""

from __future__ import annotations

import numpy as np
import scipy.fft
from scipy.signal import get_window

__all__ = ["order_spectrum", "hann_spectrum", "hann_spectrum32", "hann_sinusoid_dft"]


def order_spectrum(values: np.ndarray, spacing: float, window: str = "hann", detrend: bool = True,
                   pad: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Single-sided amplitude spectrum over position: ``(frequency, amplitude)`` in cycles per unit
    of theta and the unit of ``values``.

    ``values`` on a uniform grid of ``spacing`` (rad or m; :func:`resample_over_position`);
    ``window`` any name of ``scipy.signal.get_window``; ``detrend`` removes the least-squares line
    first (the mean and a slow trend do not leak); ``pad`` (>= 1) zero-pads for a finer grid.  A
    sinusoid of amplitude ``A`` on a bin peaks at ``A``; between bins Hann reads up to 15 % low
    (use ``window="flattop"``, or the harmonic fit for exact amplitudes).
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
    """Hann-windowed complex spectrum of ``values`` (free of its mean), padded to a fast length of
    at least ``pad`` times the samples: ``(spectrum, df, window_sum, enbw)``.  Bin k is at ``k df``;
    a sinusoid of amplitude A on a bin has ``|spectrum| = A window_sum / 2``; white noise has
    ``enbw = n sum(w^2) / sum(w)^2`` (1.5 for Hann) times a rectangular window's power.
    """
    v = np.asarray(values, dtype=float)
    n = len(v)
    w = get_window("hann", n, fftbins=False)
    nfft = hann_fft_length(n, pad)
    spec = scipy.fft.rfft(v * w, nfft)
    wsum = float(w.sum())
    enbw = n * float(w @ w) / wsum**2
    return spec, 1.0 / (nfft * spacing), wsum, enbw


def hann_spectrum32(values: np.ndarray, spacing: float, pad: float = 2.0, legendre=None):
    """:func:`hann_spectrum` in single precision (complex64), ``legendre = (coef, a, b)`` (a fitted
    nuisance, ``sum_j coef_j P_j(a + b m)`` at grid index m) subtracted first, its constant term in
    double precision so that a large mean level costs no precision.  The float32 rounding (~1e-7
    of the signal) is far below any noise floor, and time and memory are about halved.
    """
    v = np.asarray(values, dtype=float)
    n = len(v)
    if n < 4:
        spec, df, wsum, enbw = hann_spectrum(v - (legendre[0][0] if legendre is not None and len(legendre[0]) else 0),
                                             spacing, pad)
        return spec.astype(np.complex64), df, wsum, enbw
    nfft = hann_fft_length(n, pad)
    buf = np.zeros(nfft, np.float32)
    coef = np.asarray(legendre[0], dtype=float) if legendre is not None else np.zeros(0)
    a, b = (legendre[1], legendre[2]) if legendre is not None else (0.0, 0.0)
    np.subtract(v, legendre_constant(coef, a), out=buf[:n], casting="unsafe")
    return hann_spectrum32_buffer(buf, n, spacing, coef, a, b)


def hann_fft_length(n: int, pad: float = 2.0) -> int:
    """The transform length of :func:`hann_spectrum`: a fast length of at least ``pad`` times n."""
    return int(scipy.fft.next_fast_len(int(np.ceil(n * max(1.0, pad))), real=True))


def legendre_constant(coef, a: float) -> float:
    """The part of ``sum_j coef_j P_j(a + b m)`` that :func:`hann_spectrum32_buffer` expects
    subtracted in double precision: the constant term (a straight line: its value at m = 0)."""
    coef = np.asarray(coef, dtype=float)
    if len(coef) == 0:
        return 0.0
    if len(coef) == 2:
        return float(coef[0] + coef[1] * a)
    return float(coef[0])


def hann_spectrum32_buffer(buf: np.ndarray, n: int, spacing: float, coef=(), a: float = 0.0, b: float = 0.0,
                           nfft: int | None = None):
    """The work of :func:`hann_spectrum32` on a float32 buffer (used up) whose first n values hold
    the signal minus ``legendre_constant(coef, a)``; its length is the transform length unless
    ``nfft`` is given.  The window's sums are the closed forms of the symmetric Hann window."""
    coef = np.asarray(coef, dtype=float)
    nfft = len(buf) if nfft is None else int(nfft)
    x = buf[:n]
    m = np.arange(n, dtype=np.float32)  # exact below 2^24
    if len(coef) == 2:  # a straight line: its slope
        x -= np.float32(coef[1] * b) * m
    if len(coef) > 2:
        t = m * np.float32(b)
        t += np.float32(a)
        p0, p1 = np.float32(1.0), t
        x -= np.float32(coef[1]) * p1
        for j in range(2, len(coef)):
            p2 = t * p1
            p2 *= np.float32((2 * j - 1) / j)
            p2 -= np.float32((j - 1) / j) * p0
            p0, p1 = p1, p2
            x -= np.float32(coef[j]) * p2
        del t, p0, p1
    # symmetric Hann window: 0.5 - 0.5 cos(2 pi m / (n - 1))
    m *= np.float32(2 * np.pi / (n - 1))
    np.cos(m, out=m)
    m *= np.float32(-0.5)
    m += np.float32(0.5)
    x *= m
    del m
    spec = scipy.fft.rfft(buf if len(buf) == nfft else x, nfft, overwrite_x=True)
    del x
    wsum = 0.5 * (n - 1)            # sum of the window
    w2 = 0.375 * (n - 1)            # sum of its squares
    return spec, 1.0 / (nfft * spacing), wsum, n * w2 / wsum**2


def hann_sinusoid_dft(k: np.ndarray, nfft: int, n: int, x0: float, spacing: float, frequency: float,
                      coef_cos: float, coef_sin: float) -> np.ndarray:
    """Exact bins ``k`` of the Hann-windowed ``nfft``-point DFT of ``coef_cos cos(2 pi f x) +
    coef_sin sin(2 pi f x)`` at ``x = x0 + m spacing``, ``m < n`` (closed-form geometric sums):
    subtracted from :func:`hann_spectrum`, it removes a fitted line without evaluating it."""
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
