"""Lomb-Scargle periodogram of a signal over position, on the raw (non-uniform) samples.

:class:`LombScargle` fronts interchangeable implementations (``method``, as in astropy):
``"nifty"`` (nifty-ls, a non-uniform FFT, O(N log N), uniform frequency grids only), ``"astropy"``
(exact ``"cython"``, any frequencies), ``"scipy"`` (``scipy.signal.lombscargle``, floating mean),
``"auto"`` (nifty on uniform grids, astropy otherwise).  All return the floating-mean periodogram
in PSD normalisation: ``N A^2 / 4`` at a sinusoid of amplitude ``A``, mean ``sigma^2`` over white
noise of variance ``sigma^2``.

Significance uses the noise level *around* each frequency (:func:`local_noise`), not a global
one: friction residuals are far from white, and a global level would flag every low-frequency
bump (:func:`false_alarm_probability`; Scargle 1982, with a local level).
"""

from __future__ import annotations

import math
import sys
import threading
import warnings

import numpy as np

__all__ = ["LombScargle", "local_noise", "noise_blocks", "false_alarm_probability", "METHODS"]

METHODS = ("auto", "nifty", "astropy", "scipy")


#: the astropy module nifty-ls imports on import, only to register its own methods with astropy's
#: LombScargle (which gearspec never asks for): 0.45 s of CPU and 35 MB, most of nifty-ls's import
_NIFTY_ASTROPY_HOOK = "astropy.timeseries.periodograms.lombscargle.implementations.main"
_NIFTY_LOCK = threading.Lock()
_NIFTY = None  # the module, once imported


def _nifty_ls():
    """The ``nifty_ls`` module, imported without its astropy hook: while it is imported, the hook's
    module is marked missing (``sys.modules[name] = None``: the ``ImportError`` nifty-ls expects
    without astropy), then unmarked, so that astropy imports as usual afterwards (``method="astropy"``).
    The same functions; only the registration of nifty's methods inside astropy is left out.  Handed
    out once imported completely (segments run in threads: never a module half initialised)."""
    global _NIFTY
    if _NIFTY is None:
        with _NIFTY_LOCK:
            if _NIFTY is None:
                marked = _NIFTY_ASTROPY_HOOK not in sys.modules
                if marked:
                    sys.modules[_NIFTY_ASTROPY_HOOK] = None
                try:
                    import nifty_ls
                finally:
                    if marked and sys.modules.get(_NIFTY_ASTROPY_HOOK, 0) is None:
                        del sys.modules[_NIFTY_ASTROPY_HOOK]
                _NIFTY = nifty_ls
    return _NIFTY


class LombScargle:
    """Lomb-Scargle periodogram of ``y`` (shape (N,), or (B, N) for a batch) sampled at positions
    ``theta`` (rad or m, any order); ``method`` one of ``METHODS``; ``nthreads``: threads of the
    nifty (finufft) back end (default OpenMP's choice; one when periodograms run in threads)."""

    def __init__(self, theta, y, method: str = "auto", nthreads: int | None = None):
        if method not in METHODS:
            raise ValueError(f"unknown periodogram method '{method}' (choose from {', '.join(METHODS)})")
        theta = np.asarray(theta, dtype=float)
        y = np.asarray(y, dtype=float)
        d = np.diff(theta)
        if np.all(d <= 0):  # a segment in the negative direction: reversed, no copy
            theta, y = theta[::-1], y[..., ::-1]
        elif not np.all(d >= 0):  # stick-slip jitter: sort
            order = np.argsort(theta, kind="stable")
            theta, y = theta[order], y[..., order]
        self.theta = theta
        self.y = y
        self.method = method
        self.nthreads = nthreads
        self.n = theta.shape[0]

    def autogrid(self, oversample: float = 2.0, fmax: float | None = None, fmin: float | None = None):
        """``(fmin, df, nf)`` of a uniform grid from one cycle per span to ``fmax`` (default: the
        Nyquist of the mean sample spacing), ``oversample`` points per resolution step 1/span."""
        span = float(self.theta[-1] - self.theta[0])
        df = 1.0 / (span * oversample)
        f_lo = 1.0 / span if fmin is None else max(fmin, df)
        if fmax is None:
            fmax = 0.5 * (self.n - 1) / span
        nf = max(1, int(np.floor((fmax - f_lo) / df)) + 1)
        return f_lo, df, nf

    def power_grid(self, fmin: float, df: float, nf: int) -> np.ndarray:
        """Power on the uniform grid ``fmin + df * arange(nf)``; shape (nf,) or (B, nf)."""
        method = "nifty" if self.method == "auto" else self.method
        if method == "nifty":
            res = _nifty_ls().lombscargle(self.theta, self.y, fmin=fmin, fmax=fmin + df * (nf - 1), Nf=nf,
                                       normalization="psd", backend="finufft", assume_sorted_t=True,
                                       nthreads=self.nthreads, finufft_kwargs={"eps": 1e-7})
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

            # scipy holds several (N, M) arrays at once: feed it blocks of ~2e7 elements
            step = max(1, int(2e7 // max(self.n, 1)))
            out = np.array([np.concatenate([lombscargle(self.theta, yy, 2 * np.pi * f[i:i + step], floating_mean=True)
                                            for i in range(0, len(f), step)]) for yy in ys])
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


def local_noise(power: np.ndarray, width: int = 200, mask: np.ndarray | None = None, min_width: int = 40,
                relative: float = 0.3, return_bins: bool = False):
    """Local mean noise power around every bin.

    Bins are grouped in blocks whose width grows with frequency (``relative`` times the block's
    starting bin, between ``min_width`` and ``width``): a constant relative bandwidth where
    coloured noise is steep, a fixed width higher up.  A block's level is the mean power of its
    bins below ten times its median level (a line does not raise it), interpolated between block
    centres (O(n)).  Bins in ``mask`` are left out.  ``return_bins`` also returns how many bins
    each bin's level averaged (:func:`false_alarm_probability`).
    """
    n = len(power)
    centres, levels, counts = noise_blocks(power, width=width, mask=mask, min_width=min_width, relative=relative)
    idx = np.arange(n)
    out = np.interp(idx, centres, levels) if len(centres) else np.full(n, np.nan)
    if return_bins:
        return out, (np.interp(idx, centres, counts) if len(centres) else np.zeros(n))
    return out


def noise_blocks(power: np.ndarray, width: int = 200, mask: np.ndarray | None = None, min_width: int = 40,
                 relative: float = 0.3):
    """The blocks of :func:`local_noise`: ``(centres, levels, counts)`` (bin index, mean noise power,
    bins averaged) of every block with a finite level; float32 spectra in single precision."""
    p = np.asarray(power)
    if p.dtype != np.float32:
        p = p.astype(float, copy=False)
    n = len(p)
    width = max(int(min_width), int(width))
    if mask is not None:
        mask = np.asarray(mask, dtype=bool)
        if not mask.any():
            mask = None
    # growing blocks first (a few), then blocks of the full width (vectorised)
    edges = [0]
    while edges[-1] < n and relative * edges[-1] < width:
        i = edges[-1]
        edges.append(min(n, i + int(np.clip(relative * i, min_width, width))))
    start = edges[-1]
    n_full = (n - start) // width
    edges += [start + width * (j + 1) for j in range(n_full)]
    if edges[-1] < n:
        if n - edges[-1] < min_width // 2 and len(edges) > 1:
            edges[-1] = n  # fold a runt last block into its neighbour
        else:
            edges.append(n)
    edges = np.array(edges)
    centres = 0.5 * (edges[:-1] + edges[1:] - 1)
    levels = np.empty(len(edges) - 1)
    counts = np.empty(len(edges) - 1)

    def block_levels(blocks, masked=True):  # rows of equal width, NaN for masked bins
        # the rows' medians (nanmedian's numbers) from one vectorised sort: NaN sorts last
        ref = _row_medians(blocks, masked)[:, None] / math.log(2)
        below = blocks < 10 * ref
        cnt = np.sum(below, axis=1)
        with np.errstate(invalid="ignore"):
            lev = np.sum(np.where(below, blocks, 0.0), axis=1) / np.maximum(cnt, 1)
        lev = np.where(cnt > 0, lev, ref[:, 0])
        return lev, cnt

    def piece(a, b):
        if mask is None or not mask[a:b].any():
            return p[None, a:b], False
        return np.where(mask[None, a:b], np.nan, p[None, a:b]), True

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN (masked) blocks
        n_grow = int(np.searchsorted(edges, start))
        for k in [*range(n_grow), *range(n_grow + n_full, len(edges) - 1)]:  # the growing blocks, a last short one
            lev, cnt = block_levels(*piece(edges[k], edges[k + 1]))
            levels[k], counts[k] = lev[0], cnt[0]
        if n_full:
            stop = start + n_full * width
            rows = p[start:stop].reshape(n_full, width)
            mrows_all = mask[start:stop].reshape(n_full, width) if mask is not None else None
            dirty = mrows_all.any(axis=1) if mask is not None else np.zeros(n_full, bool)
            lev = np.empty(n_full)
            cnt = np.empty(n_full)
            # in groups of rows: the sorted copy and the temporaries stay small
            step = max(1, (1 << 18) // width)
            for i in range(0, n_full, step):
                r_, d_ = rows[i:i + step], dirty[i:i + step]
                lv, ct = lev[i:i + step], cnt[i:i + step]
                c_ = ~d_
                if c_.any():
                    lv[c_], ct[c_] = block_levels(r_[c_], masked=False)
                if d_.any():
                    lv[d_], ct[d_] = block_levels(np.where(mrows_all[i:i + step][d_], np.nan, r_[d_]))
            levels[n_grow:n_grow + n_full], counts[n_grow:n_grow + n_full] = lev, cnt
    good = np.isfinite(levels)
    return centres[good], levels[good], counts[good]


def _row_medians(rows: np.ndarray, masked: bool = True) -> np.ndarray:
    """The median of every row of ``rows`` leaving NaN out (``np.nanmedian(rows, axis=1)``, the same
    numbers in the rows' precision; NaN for a row of NaN only) from one sort, without the masked
    arrays ``nanmedian`` uses on short rows (most of its time); ``masked``: False when no NaN."""
    s = np.sort(rows, axis=1)
    w = s.shape[1]
    if not masked:
        return s[:, w // 2] if w % 2 else (s[:, w // 2 - 1] + s[:, w // 2]) / 2
    m = w - np.count_nonzero(np.isnan(s), axis=1)
    r = np.arange(len(s))
    lo = s[r, np.maximum(m - 1, 0) // 2]
    hi = s[r, np.minimum(m // 2, w - 1)]
    med = np.where(m % 2 == 1, lo, (lo + hi) / 2)
    return np.where(m > 0, med, np.nan)


#: the smallest positive normal double: a false-alarm probability below it is not 0 but unknown
_TINY = float(np.finfo(float).tiny)


def false_alarm_probability(z, n_independent: float = 1.0, noise_bins=None, oversample: float = 1.0):
    """Probability that noise alone reaches ``z = power / local noise`` at least once among
    ``n_independent`` frequencies (1 for a frequency chosen in advance).

    With a known noise level the power at one frequency is exponential: ``P(> z) = exp(-z)``.
    When the level is itself the mean of ``noise_bins`` periodogram bins (``noise_bins /
    oversample`` independent ones, k), the ratio follows an F(2, 2k) law instead:
    ``P(> z) = (1 + z/k)^(-k)``, which has the heavier tail that an estimated level deserves.
    A probability that underflows is returned as the smallest positive double (about 2.2e-308): 0
    only for an infinite ``z``.
    """
    z = np.asarray(z, dtype=float)
    if noise_bins is None:
        single = np.exp(-z)
    else:
        k = np.maximum(np.asarray(noise_bins, dtype=float) / max(oversample, 1.0), 1.0)
        single = np.exp(-k * np.log1p(z / k))
    m = max(1.0, float(n_independent))
    with np.errstate(divide="ignore"):
        fap = -np.expm1(m * np.log1p(-np.minimum(single, 1 - 1e-16)))
    # 0 only for an infinite ratio; a finite one whose probability underflows gets the smallest
    # positive double instead (the float precision of the estimate, not a certainty)
    return np.where(np.isfinite(z) & (fap < _TINY), _TINY, fap)[()]
