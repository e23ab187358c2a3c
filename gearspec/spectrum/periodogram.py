"""Lomb-Scargle periodogram of a signal over position, on the raw (non-uniform) samples.

One small class, :class:`LombScargle`, in front of interchangeable implementations chosen with
``method`` (as in ``astropy.timeseries.LombScargle``):

``"nifty"``    nifty-ls (finufft, a non-uniform FFT): O(N log N), for long segments; uniform
               frequency grids only.
``"astropy"``  astropy's exact ``"cython"`` method: O(N M), any frequencies.
``"scipy"``    ``scipy.signal.lombscargle`` with a floating mean: O(N M), any frequencies.
``"auto"``     nifty on uniform grids, astropy otherwise.

All return the same *power*: the floating-mean ("generalised") periodogram in PSD normalisation,
which equals ``N A^2 / 4`` at the frequency of a sinusoid of amplitude ``A`` and has mean
``sigma^2`` over white noise of variance ``sigma^2``.  :meth:`LombScargle.amplitude` turns it into
the amplitude spectrum ``sqrt(4 P / N)``.

Significance uses the noise level *around* each frequency (:func:`local_noise`), not a global
one: friction residuals are far from white (slow drifts, control-loop ripple), and a global level
would flag every low-frequency bump.  Under Gaussian noise of local level S the power at one
frequency is exponential with mean S, so the chance that noise alone reaches ``z = P/S`` at one
given frequency is ``exp(-z)``, and somewhere among ``M`` independent frequencies
``1 - (1 - exp(-z))**M`` (:func:`false_alarm_probability`; Scargle 1982, with a local S).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["LombScargle", "local_noise", "false_alarm_probability", "METHODS"]

METHODS = ("auto", "nifty", "astropy", "scipy")


class LombScargle:
    """Lomb-Scargle periodogram of ``y`` sampled at positions ``theta``.

    Parameters
    ----------
    theta : ndarray
        Positions (rad or m); any order.
    y : ndarray
        Values, shape (N,) or (B, N) for a batch of signals sampled at the same positions.
    method : {"auto", "nifty", "astropy", "scipy"}
    """

    def __init__(self, theta, y, method: str = "auto"):
        if method not in METHODS:
            raise ValueError(f"unknown periodogram method '{method}' (choose from {', '.join(METHODS)})")
        theta = np.asarray(theta, dtype=float)
        y = np.asarray(y, dtype=float)
        d = np.diff(theta)
        if np.all(d >= 0):
            self._sorted = True
        elif np.all(d <= 0):
            theta, y = theta[::-1], y[..., ::-1]
            self._sorted = True
        else:
            order = np.argsort(theta, kind="stable")
            theta, y = theta[order], y[..., order]
            self._sorted = True
        self.theta = theta
        self.y = y
        self.method = method
        self.n = theta.shape[0]

    # ------------------------------------------------------------------ grids
    def span(self) -> float:
        return float(self.theta[-1] - self.theta[0])

    def autogrid(self, oversample: float = 2.0, fmax: float | None = None, fmin: float | None = None):
        """A uniform grid from one cycle per span to ``fmax`` (default: the position Nyquist of the
        median sample spacing), ``oversample`` points per resolution step 1/span.

        Returns ``(fmin, df, nf)``.
        """
        span = self.span()
        df = 1.0 / (span * oversample)
        f_lo = 1.0 / span if fmin is None else max(fmin, df)
        if fmax is None:
            fmax = 0.5 * (self.n - 1) / span
        nf = max(1, int(np.floor((fmax - f_lo) / df)) + 1)
        return f_lo, df, nf

    # ------------------------------------------------------------------ power
    def power_grid(self, fmin: float, df: float, nf: int) -> np.ndarray:
        """Power on the uniform grid ``fmin + df * arange(nf)``; shape (nf,) or (B, nf)."""
        method = "nifty" if self.method == "auto" else self.method
        if method == "nifty":
            import nifty_ls

            res = nifty_ls.lombscargle(self.theta, self.y, fmin=fmin, fmax=fmin + df * (nf - 1), Nf=nf,
                                       normalization="psd", backend="finufft", assume_sorted_t=True,
                                       finufft_kwargs={"eps": 1e-7})
            return np.asarray(res.power)
        return self.power(fmin + df * np.arange(nf), method=method)

    def power(self, frequency, method: str | None = None) -> np.ndarray:
        """Power at arbitrary frequencies (cycles per unit); shape like frequency, or (B, M)."""
        method = method or self.method
        f = np.atleast_1d(np.asarray(frequency, dtype=float))
        ys = np.atleast_2d(self.y)
        if method in ("auto", "astropy"):
            from astropy.timeseries import LombScargle as _ALS

            out = np.array([_ALS(self.theta, yy, normalization="psd").power(f, method="cython") for yy in ys])
        elif method == "scipy":
            from scipy.signal import lombscargle

            out = np.array([lombscargle(self.theta, yy, 2 * np.pi * f, floating_mean=True) for yy in ys])
        elif method == "nifty":
            if len(f) > 1 and np.allclose(np.diff(f), f[1] - f[0], rtol=1e-9, atol=0):
                return self.power_grid(f[0], f[1] - f[0], len(f))
            raise ValueError("the nifty method needs a uniform frequency grid")
        else:
            raise ValueError(f"unknown periodogram method '{method}'")
        return out[0] if self.y.ndim == 1 else out

    def amplitude(self, frequency=None, power=None) -> np.ndarray:
        """Amplitude spectrum ``sqrt(4 P / N)`` (unit of y) at ``frequency`` or from ``power``."""
        p = self.power(frequency) if power is None else power
        return np.sqrt(4.0 * np.maximum(p, 0) / self.n)


def local_noise(power: np.ndarray, width: int, mask: np.ndarray | None = None) -> np.ndarray:
    """Local mean noise power around every bin: a running median over ``width`` bins / ln 2.

    The median of an exponential distribution is ln 2 times its mean, and a median ignores the
    few bins a line occupies.  Bins in ``mask`` (e.g. next to fitted lines) are left out.  The
    median is taken over blocks of ``width`` bins and interpolated: O(n), not O(n width).
    """
    p = np.asarray(power, dtype=float)
    n = len(p)
    width = max(5, int(width))
    if mask is not None:
        p = np.where(mask, np.nan, p)
    nb = max(1, n // width)
    edges = np.linspace(0, n, nb + 1).astype(int)
    centres = np.empty(nb)
    levels = np.empty(nb)
    for i in range(nb):
        blk = p[edges[i]:edges[i + 1]]
        centres[i] = 0.5 * (edges[i] + edges[i + 1] - 1)
        levels[i] = np.nanmedian(blk) if np.any(np.isfinite(blk)) else np.nan
    good = np.isfinite(levels)
    if not good.any():
        return np.full(n, np.nan)
    return np.interp(np.arange(n), centres[good], levels[good]) / math.log(2)


def false_alarm_probability(z, n_independent: float = 1.0):
    """Probability that noise alone reaches ``z = power / local noise`` at least once among
    ``n_independent`` frequencies (1 for a frequency chosen in advance)."""
    z = np.asarray(z, dtype=float)
    single = np.exp(-z)
    m = max(1.0, float(n_independent))
    with np.errstate(divide="ignore"):
        return -np.expm1(m * np.log1p(-np.minimum(single, 1 - 1e-16)))
