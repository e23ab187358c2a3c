"""Shared pieces of the exact per-group reductions of :mod:`gearspec.identify` (``SegmentStats``)
and :mod:`gearspec.discover.moments` (``Moments``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["harmonic_columns"]

_TWO_PI = 2.0 * np.pi


def harmonic_columns(theta, frequencies) -> tuple[np.ndarray, np.ndarray]:
    """``sin`` and ``cos`` of ``2 pi f theta`` for the positions of one group, phases about the
    group's mean position.

    The phase is computed from positions centred on the group (``theta - m``, exact in double
    precision even far from the origin) and rotated back to ``theta = 0``:
    ``sin(w(th - m) + wm) = sin(w(th - m)) cos(wm) + cos(w(th - m)) sin(wm)``, so the columns are
    those of ``theta`` itself without the rounding of ``2 pi f theta`` at large ``theta``.

    Parameters
    ----------
    theta : array_like, (n,)
        Positions of the group's samples (rad or m).
    frequencies : array_like, (K,)
        Frequencies in cycles per unit of ``theta``.

    Returns
    -------
    sin, cos : ndarray, (n, K)
    """
    th = np.asarray(theta, dtype=float)
    freqs = np.asarray(frequencies, dtype=float)
    m = th.mean()
    ph = _TWO_PI * np.outer(th - m, freqs)
    sn, cs = np.sin(ph), np.cos(ph)
    rot = _TWO_PI * freqs * m
    c, s = np.cos(rot), np.sin(rot)
    return sn * c + cs * s, cs * c - sn * s
