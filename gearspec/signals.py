"""Signal helpers over uniformly sampled time series: zero-phase low-pass filtering, central
differences and MATLAB-compatible decimation.

These are the inverse-dynamic-model (IDIM) practice of the EMPS reference procedure (filter the
position, differentiate twice, decimate every column of the observation matrix); they live here
once so that the closed loop (:func:`gearspec.diagnose.trajectory_data`), the twins and any user
script share one implementation.  Plain functions over arrays, as :mod:`scipy.signal`.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import signal

from .errors import InputError

__all__ = ["butter_filtfilt", "central_difference", "decimation_index", "decimate"]


def butter_filtfilt(x, cutoff: float, fs: float, order: int = 4) -> np.ndarray:
    """Zero-phase Butterworth low-pass (``scipy.signal.butter`` + ``filtfilt``), with MATLAB's edge
    padding (``3 * (order)`` samples, odd reflection), so that results match MATLAB's
    ``filtfilt(butter(order, cutoff / (fs/2)), x)`` to rounding.

    Parameters
    ----------
    x : ndarray
        Uniformly sampled signal (any unit).
    cutoff : float
        Cut-off frequency, Hz (the gain there is 1/2: the Butterworth's -3 dB, applied twice).
    fs : float
        Sample rate, Hz.
    order : int
        Order of the Butterworth filter (applied forwards and backwards: twice the order).

    Returns
    -------
    ndarray
        The filtered signal, same length and unit as ``x``, without phase shift.
    """
    if not 0 < cutoff < fs / 2:
        raise InputError(f"filter cut-off must lie between 0 and half the sample rate ({fs / 2:g} Hz), got {cutoff:g}")
    b, a = signal.butter(order, cutoff / (fs / 2))
    return signal.filtfilt(b, a, np.asarray(x, dtype=float), padlen=3 * (max(len(a), len(b)) - 1))


def central_difference(x, dt: float) -> np.ndarray:
    """Derivative by central differences ``(x[k+1] - x[k-1]) / (2 dt)``, one-sided at the ends
    (the same numbers as ``numpy.gradient(x, dt)``).

    Parameters
    ----------
    x : ndarray
        Uniformly sampled signal (e.g. position in rad).
    dt : float
        Sample interval, s.

    Returns
    -------
    ndarray
        The derivative (unit of ``x`` per second); zeros for fewer than two samples.
    """
    x = np.asarray(x, dtype=float)
    d = np.empty_like(x)
    if len(x) < 2:
        return np.zeros_like(x)
    d[1:-1] = (x[2:] - x[:-2]) / (2 * dt)
    d[0] = (x[1] - x[0]) / dt
    d[-1] = (x[-1] - x[-2]) / dt
    return d


def decimation_index(n: int, q: int) -> np.ndarray:
    """Indices MATLAB's ``decimate(x, q)`` keeps: every q-th sample, aligned so that the last
    sample is kept (``nbeg = q - (q * nout - n)``, 1-based).

    Parameters
    ----------
    n : int
        Number of samples.
    q : int
        Decimation factor.

    Returns
    -------
    ndarray of int
        The 0-based indices kept, ``ceil(n / q)`` of them, the last one ``n - 1``.
    """
    nout = int(math.ceil(n / q))
    nbeg = q - (q * nout - n)
    return np.arange(nbeg - 1, n, q)


def decimate(x, q: int) -> np.ndarray:
    """MATLAB-compatible ``decimate(x, q)``: 8th-order Chebyshev type I low-pass at 0.8 of the new
    Nyquist frequency (0.05 dB ripple), zero-phase (``filtfilt`` with MATLAB's padding), then the
    samples of :func:`decimation_index`.  Linear: decimating every column of a design matrix and
    then combining them equals decimating the combination.

    Parameters
    ----------
    x : ndarray
        Uniformly sampled signal (any unit).
    q : int
        Decimation factor (1: a copy of ``x``).

    Returns
    -------
    ndarray
        ``ceil(len(x) / q)`` samples, same unit as ``x``.
    """
    x = np.asarray(x, dtype=float)
    if q == 1:
        return x.copy()
    b, a = signal.cheby1(8, 0.05, 0.8 / q)
    y = signal.filtfilt(b, a, x, padlen=3 * (max(len(a), len(b)) - 1))
    return y[decimation_index(len(x), q)]
