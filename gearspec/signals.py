"""Signal helpers over uniformly sampled series, written once: zero-phase low-pass, central
differences and MATLAB-compatible decimation (the EMPS reference procedure's inverse dynamic model:
filter the position, differentiate twice, decimate every column of the observation matrix)."""

from __future__ import annotations

import math

import numpy as np
from scipy import signal

from .errors import InputError

__all__ = ["butter_filtfilt", "central_difference", "decimation_index", "decimate"]


def butter_filtfilt(x, cutoff: float, fs: float, order: int = 4) -> np.ndarray:
    """Zero-phase Butterworth low-pass of ``x`` (any unit) with MATLAB's edge padding (``3 * order``
    samples, odd reflection): MATLAB's ``filtfilt(butter(order, cutoff / (fs/2)), x)`` to rounding.
    ``cutoff`` Hz (gain 1/2 there: -3 dB applied twice), ``fs`` sample rate Hz, ``order`` of the
    filter applied each way."""
    if not 0 < cutoff < fs / 2:
        raise InputError(f"filter cut-off must lie between 0 and half the sample rate ({fs / 2:g} Hz), got {cutoff:g}")
    b, a = signal.butter(order, cutoff / (fs / 2))
    return signal.filtfilt(b, a, np.asarray(x, dtype=float), padlen=3 * (max(len(a), len(b)) - 1))


def central_difference(x, dt: float) -> np.ndarray:
    """Derivative (unit of ``x`` per s) by central differences ``(x[k+1] - x[k-1]) / (2 dt)``,
    one-sided at the ends (as ``numpy.gradient(x, dt)``); ``dt`` sample interval, s; zeros for
    fewer than two samples."""
    x = np.asarray(x, dtype=float)
    d = np.empty_like(x)
    if len(x) < 2:
        return np.zeros_like(x)
    d[1:-1] = (x[2:] - x[:-2]) / (2 * dt)
    d[0] = (x[1] - x[0]) / dt
    d[-1] = (x[-1] - x[-2]) / dt
    return d


def decimation_index(n: int, q: int) -> np.ndarray:
    """The 0-based indices MATLAB's ``decimate(x, q)`` keeps of ``n`` samples: every q-th, the last
    one ``n - 1`` (``nbeg = q - (q * nout - n)``, 1-based), ``ceil(n / q)`` of them."""
    nout = int(math.ceil(n / q))
    nbeg = q - (q * nout - n)
    return np.arange(nbeg - 1, n, q)


def decimate(x, q: int) -> np.ndarray:
    """MATLAB-compatible ``decimate(x, q)`` (``q`` = 1: a copy): 8th-order Chebyshev type I low-pass
    at 0.8 of the new Nyquist frequency (0.05 dB ripple), zero-phase with MATLAB's padding, then the
    samples of :func:`decimation_index`.  Linear, so it commutes with combining design columns."""
    x = np.asarray(x, dtype=float)
    if q == 1:
        return x.copy()
    b, a = signal.cheby1(8, 0.05, 0.8 / q)
    y = signal.filtfilt(b, a, x, padlen=3 * (max(len(a), len(b)) - 1))
    return y[decimation_index(len(x), q)]
