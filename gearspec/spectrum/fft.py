"""Amplitude-calibrated order spectrum of a signal on a uniform position grid."""

from __future__ import annotations

import numpy as np
from scipy.signal import get_window

__all__ = ["order_spectrum"]


def order_spectrum(values: np.ndarray, spacing: float, window: str = "hann", detrend: bool = True,
                   pad: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Single-sided amplitude spectrum over position.

    A sinusoid ``A sin(2 pi f theta + phi)`` whose frequency falls on a bin shows as a peak of
    height ``A`` (the window's coherent gain is divided out).  Between bins the Hann window reads
    up to 15 % low (scalloping); use ``window="flattop"`` for amplitudes read off the plot, or the
    harmonic fit for exact ones.

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
    nfft = int(n * max(1, pad))
    spec = np.fft.rfft(v * w, nfft)
    amp = np.abs(spec) * (2.0 / w.sum())
    amp[0] /= 2
    freq = np.fft.rfftfreq(nfft, d=spacing)
    return freq, amp
