"""The exact per-group reduction the three engines share: a group's (segment's, run's, move's)
samples become the normal equations of its columns, so that a fit's cost does not grow with the
samples (:mod:`gearspec.identify` ``SegmentStats``, :mod:`gearspec.diagnose.design` ``Grams``,
:mod:`gearspec.discover.moments` ``Moments``), with the lines' columns phased about the group's
mean position.
"""

from __future__ import annotations

import numpy as np

__all__ = ["harmonic_columns", "normal_equations", "group_normal_equations"]

_TWO_PI = 2.0 * np.pi


def normal_equations(X, y) -> tuple[np.ndarray, np.ndarray, float]:
    """``(X^T X, X^T y, y^T y)`` of one group's columns ``X`` (n, p) and observations ``y`` (n,):
    everything a least-squares fit of the group needs (the residual sum of squares of any
    coefficients ``b`` is ``y^T y - 2 b^T X^T y + b^T X^T X b``)."""
    X = np.asarray(X, dtype=float)
    y = np.asarray(y, dtype=float)
    return X.T @ X, X.T @ y, float(y @ y)


def group_normal_equations(X, y, starts, stops) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`normal_equations` of every contiguous group ``[starts[g], stops[g])`` of the rows:
    ``G`` (groups, p, p), ``b`` (groups, p), ``yy`` (groups,)."""
    X = np.asarray(X, dtype=float)
    ng, p = len(starts), X.shape[1]
    G, b, yy = np.empty((ng, p, p)), np.empty((ng, p)), np.empty(ng)
    for g, (a, z) in enumerate(zip(starts, stops)):
        G[g], b[g], yy[g] = normal_equations(X[a:z], y[a:z])
    return G, b, yy


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
