"""Torque over position on a uniform grid (anti-aliased), from samples at arbitrary positions."""

from __future__ import annotations

import numpy as np
from scipy.signal import resample_poly

__all__ = ["resample_over_position", "resample_uniform", "grid_size"]


def resample_over_position(theta: np.ndarray, y: np.ndarray, spacing: float | None = None,
                           max_frequency: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Resample ``y(theta)`` (positions in rad or m, any order, may move backwards) onto a uniform
    position grid: ``(grid, values)``, the grid ascending.

    Samples are averaged per grid cell (a boxcar anti-aliasing filter where they are denser than
    the grid), and the cell means interpolated linearly onto the cell centres.  ``spacing``:
    default travel / (samples - 1), as many grid points as samples.  ``max_frequency`` (cycles per
    unit): when the grid resolves far more, it is decimated by an integer factor with
    ``scipy.signal.resample_poly`` (Kaiser FIR), keeping Nyquist at least 2.5 x ``max_frequency``.
    """
    theta = np.asarray(theta, dtype=float)
    y = np.asarray(y, dtype=float)
    lo, h, values = resample_uniform(theta, y, spacing)
    grid = lo + h * np.arange(len(values))
    if max_frequency is not None and max_frequency > 0:
        q = int(np.floor(1.0 / (2.5 * max_frequency * 2 * h)))
        if q >= 2:
            values = resample_poly(values, 1, q, padtype="line")
            grid = lo + h * q * np.arange(len(values))
    return grid, values


def grid_size(n: int, lo: float, hi: float, spacing: float | None = None) -> tuple[float, int]:
    """``(spacing, number of grid points)`` of :func:`resample_uniform` for n samples in [lo, hi]."""
    span = hi - lo
    h = span / (n - 1) if spacing is None else float(spacing)
    return h, int(np.floor(span / h)) + 1


def resample_uniform(theta: np.ndarray, y: np.ndarray, spacing: float | None = None, lo: float | None = None,
                     hi: float | None = None, chunk: int = 1 << 16, out: np.ndarray | None = None,
                     shift: float = 0.0) -> tuple[float, float, np.ndarray]:
    """The cell averaging and interpolation of :func:`resample_over_position` (no decimation):
    ``(first grid position, spacing, values)``; ``lo`` and ``hi`` (theta's extremes) when known.
    The grid is made in chunks (peak memory about four arrays of the samples).  With ``out``
    (e.g. a float32 buffer, :func:`grid_size`) the values minus ``shift`` are written there."""
    theta = np.asarray(theta, dtype=float)
    y = np.asarray(y, dtype=float)
    n = len(theta)
    if n < 4:
        raise ValueError("at least four samples are needed to resample over position")
    lo = float(theta.min()) if lo is None else float(lo)
    hi = float(theta.max()) if hi is None else float(hi)
    span = hi - lo
    if span <= 0:
        raise ValueError("position does not change: nothing to resample over")
    h, m = grid_size(n, lo, hi, spacing)
    values = np.empty(m) if out is None else out[:m]

    def store(i, j, v):
        if shift:
            v -= shift
        values[i:j] = v

    if m == n:
        # the common case of steady motion: one sample per cell, in order (every sample within
        # 0.49 cells of its grid point); the cell averages are then the samples themselves, and
        # the bincounts below would return them unchanged
        th, yy = (theta, y) if theta[-1] >= theta[0] else (theta[::-1], y[::-1])
        dev = np.empty(min(n, chunk))
        for i in range(0, n, chunk):
            j = min(n, i + chunk)
            d = dev[: j - i]
            np.multiply(np.arange(i, j), h, out=d)
            d += lo
            np.subtract(th[i:j], d, out=d)
            if not np.all(np.abs(d, out=d) < 0.49 * h):
                break
        else:
            # grid point k lies between samples k - 1 and k + 1: each chunk of the grid needs only
            # its own stretch of samples (np.interp copies read-only inputs, as a recording's
            # columns are: whole arrays per chunk would cost far more than the interpolation)
            for i in range(0, m, chunk):
                j = min(m, i + chunk)
                a, b = max(0, i - 1), min(n, j + 1)
                store(i, j, np.interp(lo + h * np.arange(i, j), th[a:b], yy[a:b]))
            return lo, h, values
    t = np.subtract(theta, lo)
    t /= h
    t += 0.5
    cell = t.astype(np.intp)
    del t
    np.minimum(cell, m - 1, out=cell)
    counts = np.bincount(cell, minlength=m)
    xs = np.bincount(cell, weights=theta, minlength=m)
    ys = np.bincount(cell, weights=y, minlength=m)
    del cell
    filled = counts > 0
    xs = xs[filled] / counts[filled]
    ys = ys[filled] / counts[filled]
    del counts, filled
    for i in range(0, m, chunk):
        j = min(m, i + chunk)
        store(i, j, np.interp(lo + h * np.arange(i, j), xs, ys))
    return lo, h, values
