"""Joint least-squares fit of sinusoids at known frequencies over position, on the raw samples.

Model, for positions ``theta`` in ``[lo, hi]``::

    y = sum_j c_j P_j(x) + sum_k A_k sin(2 pi f_k theta + phi_k) + noise,   x = 2 (theta - lo)/(hi - lo) - 1

with Legendre polynomials ``P_j`` as nuisance terms (the level, a slow trend, and any component
too slow to complete a cycle).  All terms are fitted together, so close frequencies do not leak
into each other.  One pass accumulates the normal equations (:class:`NormalEquations`) in chunks,
in single precision within sub-blocks of a few thousand samples (phases reduced to one cycle in
double precision at each sub-block's start) and double precision across them; any subset of the
frequencies is then solved without another pass.

Standard errors are ``sigma^2 (X'X)^-1`` for white noise; :meth:`HarmonicFit.scaled` rescales
them per frequency by the local noise level, which makes them honest for coloured noise.
Amplitude and phase errors follow by the delta method (biased upwards below SNR ~3, Rice).
Phase convention: ``A sin(2 pi f theta + phi)`` (SILO4's ``A sin(omega theta + phi)``), theta
from the recording's zero.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy import linalg

__all__ = ["HarmonicFit", "NormalEquations", "harmonic_fit", "refine_frequencies", "min_degree_for_cycles"]

_TWO_PI = 2.0 * np.pi
_CHUNK = 1 << 16
#: relative precision of a double: the least standard error a fitted amplitude (relative) or phase (rad) has
_EPS = float(np.finfo(float).eps)


def min_degree_for_cycles(cycles: float) -> int:
    """Legendre degree that represents a sinusoid of ``cycles`` cycles over the span to ~1e-4.

    A sinusoid over a phase range of 2 pi c is matched by a Chebyshev/Legendre series whose error
    falls like (pi c)^(d+1) / (2^d (d+1)!); ``ceil(2 pi c) + 3`` terms bring it below ~1e-4 for
    c <= 1.
    """
    return int(np.ceil(_TWO_PI * max(cycles, 0.0))) + 3


@dataclass(frozen=True)
class HarmonicFit:
    """Result of :func:`harmonic_fit` (all arrays have one entry per frequency)."""

    frequency: np.ndarray
    coef_cos: np.ndarray
    coef_sin: np.ndarray
    cov: np.ndarray          # covariance of [cos_0, sin_0, cos_1, sin_1, ...]
    nuisance: np.ndarray     # Legendre coefficients
    lo: float
    hi: float
    sigma: float             # residual standard deviation (white-noise estimate)
    n: int
    dof: int
    noise_factor: np.ndarray  # variance scale applied per frequency (1 = white)

    @property
    def amplitude(self) -> np.ndarray:
        return np.hypot(self.coef_cos, self.coef_sin)

    @property
    def phase(self) -> np.ndarray:
        """phi in ``A sin(2 pi f theta + phi)``, in (-pi, pi]."""
        return np.arctan2(self.coef_cos, self.coef_sin)

    @property
    def amplitude_se(self) -> np.ndarray:
        a, b = self.coef_cos, self.coef_sin
        amp = np.maximum(self.amplitude, 1e-300)
        vcc, vss, vcs = self._blocks()
        var = (a * a * vcc + b * b * vss + 2 * a * b * vcs) / amp**2
        # never 0 by rounding: at least the float precision of the amplitude itself
        return np.maximum(np.sqrt(np.maximum(var, 0)), _EPS * self.amplitude)

    @property
    def phase_se(self) -> np.ndarray:
        a, b = self.coef_cos, self.coef_sin
        amp2 = np.maximum(a * a + b * b, 1e-300)
        vcc, vss, vcs = self._blocks()
        var = (b * b * vcc + a * a * vss - 2 * a * b * vcs) / amp2**2
        return np.maximum(np.sqrt(np.maximum(var, 0)), _EPS * np.pi)  # at least the precision of a phase

    def _blocks(self):
        """Per frequency: var(cos), var(sin), cov(cos, sin)."""
        return np.diagonal(self.cov)[0::2], np.diagonal(self.cov)[1::2], np.diagonal(self.cov, 1)[0::2]

    def scaled(self, factor) -> HarmonicFit:
        """The same fit with the variance of frequency k scaled by ``factor[k]`` (local noise)."""
        f = np.repeat(np.asarray(factor, dtype=float), 2)
        s = np.sqrt(f)
        return replace(self, cov=self.cov * np.outer(s, s), noise_factor=np.asarray(factor, dtype=float))

    def predict(self, theta, nuisance: bool = True, chunk: int = _CHUNK) -> np.ndarray:
        """Model values at ``theta`` (with or without the nuisance polynomial)."""
        theta = np.asarray(theta, dtype=float)
        n = len(theta)
        out = np.empty(n)
        if n == 0:
            return out
        d, k = len(self.nuisance) - 1, len(self.frequency)
        beta = np.concatenate([self.nuisance if nuisance else np.zeros(d + 1), self.coef_cos, self.coef_sin])
        b32 = beta.astype(np.float32)
        q = len(beta)
        design, rows = _make_design(n, d, self.lo, self.hi, [(self.frequency, d + 1, d + 1 + k)], [], q, q,
                                    chunk)
        acc = np.empty((design.blocks, design.rows), np.float32)
        tmp = np.empty_like(acc)
        for i in range(0, n, rows):
            th = theta[i:i + rows]
            nb = design.fill(th)
            D, a = design.D[:nb], acc[:nb]
            np.multiply(D[:, 0], b32[0], out=a)
            for j in range(1, q):
                a += np.multiply(D[:, j], b32[j], out=tmp[:nb])
            out[i:i + len(th)] = a.reshape(-1)[: len(th)]
        return out


_SUB_ELEMS = 1 << 18  # rows x rows-of-X'X x columns of one sub-block product (see _sub_rows)


def _sub_rows(q_rows: int, q: int, n: int) -> int:
    """Rows per sub-block product: a power of two (128 to 8192, at most ``n``) keeping rows x
    q_rows x q within 2^18, so that OpenBLAS runs each product on one thread with its
    small-matrix kernels (splitting such tall, narrow products across threads costs more than it
    gains, a great deal on a busy machine)."""
    r = 1 << max(0, int(np.floor(np.log2(max(_SUB_ELEMS / max(q_rows * q, 1), 1.0)))))
    r = int(np.clip(r, 128, 8192))
    return max(1, min(r, n))


class _Design:
    """The single-precision design matrix of one chunk of samples, with ``y - y0`` as column ``q``.

    Columns: Legendre 0..degree, per group of lines (``groups``: frequencies, first cosine column,
    first sine column) its cosines and sines, then derivative columns ``2 pi (theta - centre) *
    (cos, sin)`` (``deriv``: source columns per free line).  ``D[b, j, :]`` is column j of
    sub-block b, so one batched product ``D[:, a:q] @ D[:].T`` gives rows ``a:`` of ``X'X`` and
    ``X'y``.  Phases are taken from each sub-block's first position (reduced to one cycle in
    double precision): the float32 argument stays below 4096 cycles, rounding < 1e-5 of amplitude,
    and float32 trigonometry runs many times faster.
    """

    def __init__(self, degree, lo, hi, groups, deriv, q, rows, blocks):
        self.degree, self.lo, self.hi = int(degree), float(lo), float(hi)
        self.groups = [(np.asarray(f, dtype=float), int(c), int(s)) for f, c, s in groups]
        self.deriv = list(deriv)
        self.q, self.rows, self.blocks = int(q), int(rows), int(blocks)
        self.centre = 0.5 * (self.lo + self.hi)
        self.xscale = 2.0 / (self.hi - self.lo) if self.hi > self.lo else 0.0
        kmax = max([len(f) for f, _, _ in self.groups] + [1])
        self.D = np.empty((blocks, q + 1, rows), np.float32)
        self.U = np.empty((blocks, rows), np.float32)
        self.T64 = np.empty((blocks, rows))
        self.P = np.empty((kmax, blocks, rows), np.float32)
        self.W = np.empty((blocks, rows), np.float32)

    def fill(self, theta: np.ndarray, y: np.ndarray | None = None, y0: float = 0.0):
        """Fill the design for the samples ``theta`` (at most rows x blocks of them), and column
        q with ``y - y0`` when y is given; returns the number of sub-blocks used.  Rows past the
        samples are zero (they add nothing to any product)."""
        m = len(theta)
        r = self.rows
        nb = -(-m // r)
        full = nb * r
        U = self.U[:nb]
        if full == m:  # a whole number of sub-blocks: straight from theta
            T = theta.reshape(nb, r)
        else:  # the last, partial chunk: padded with its last position
            T = self.T64[:nb]
            flat = T.reshape(-1)
            flat[:m] = theta
            flat[m:] = theta[-1]
        ref = T[:, 0].copy()
        np.subtract(T, ref[:, None], out=U, casting="same_kind")
        D = self.D[:nb]
        d = self.degree
        # Legendre polynomials of x = 2 (theta - lo) / (hi - lo) - 1, Bonnet recurrence
        D[:, 0] = 1.0
        if d >= 1:
            x = D[:, 1]
            np.multiply(U, np.float32(self.xscale), out=x)
            x += ((ref - self.lo) * self.xscale - 1.0).astype(np.float32)[:, None]
            W = self.W[:nb]
            for j in range(2, d + 1):
                np.multiply(x, D[:, j - 1], out=D[:, j])
                D[:, j] *= np.float32((2 * j - 1) / j)
                np.multiply(D[:, j - 2], np.float32((j - 1) / j), out=W)
                D[:, j] -= W
        # cosines and sines, group by group
        for freq, c0, s0 in self.groups:
            k = len(freq)
            if not k:
                continue
            P = self.P[:k, :nb]
            np.multiply(U[None, :, :], (_TWO_PI * freq).astype(np.float32)[:, None, None], out=P)
            P += (np.mod(np.multiply.outer(freq, ref), 1.0) * _TWO_PI).astype(np.float32)[:, :, None]
            np.cos(P, out=D[:, c0:c0 + k].transpose(1, 0, 2))
            np.sin(P, out=D[:, s0:s0 + k].transpose(1, 0, 2))
        # derivative columns
        if self.deriv:
            W = self.W[:nb]
            np.multiply(U, np.float32(_TWO_PI), out=W)
            W += (_TWO_PI * (ref - self.centre)).astype(np.float32)[:, None]
            col = self.q - 2 * len(self.deriv)
            for cs, ss in self.deriv:
                np.multiply(D[:, cs], W, out=D[:, col])
                np.multiply(D[:, ss], W, out=D[:, col + 1])
                col += 2
        if y is not None:
            if full == m:
                np.subtract(y.reshape(nb, r), y0, out=D[:, self.q], casting="same_kind")
            else:
                Y = self.U.reshape(-1)  # U is used up: its buffer takes y - y0 on its way into column q
                np.subtract(y, y0, out=Y[:m], casting="same_kind")
                D[:, self.q] = Y[:full].reshape(nb, r)
        if full > m:
            D[nb - 1, :, m - (nb - 1) * r:] = 0.0
        return nb


def _pass(theta, y, y0, design: _Design, first_row: int, chunk_rows: int, want_yy: bool):
    """One pass over the samples: rows ``first_row:`` of X'X and X'(y - y0) (float64 sums of
    float32 sub-block products, :func:`_sub_rows`), and (y - y0)'(y - y0) when asked."""
    q = design.q
    GH = np.zeros((q - first_row, q + 1))
    yy = 0.0
    n = len(theta)
    for i in range(0, n, chunk_rows):
        th = theta[i:i + chunk_rows]
        m = len(th)
        nb = design.fill(th, y[i:i + m], y0)
        D = design.D[:nb]
        if want_yy:
            yc = y[i:i + m] - y0
            yy += float(np.sum(np.square(yc, out=yc)))
        GH += np.matmul(D[:, first_row:q], D.transpose(0, 2, 1)).sum(axis=0, dtype=np.float64)
    return GH[:, :q], GH[:, q], yy


def _make_design(n, degree, lo, hi, groups, deriv, q, first_row, chunk):
    r = _sub_rows(q - first_row, q + 1, n)
    blocks = max(1, min(max(chunk, r) // r, -(-n // r)))
    return _Design(degree, lo, hi, groups, deriv, q, r, blocks), r * blocks


@dataclass
class NormalEquations:
    """``X'X``, ``X'y`` and ``y'y`` of one pass over the samples, for any subset of frequencies.

    Columns: Legendre 0..degree, the cosines, the sines, then (optionally) the Gauss-Newton
    derivative columns ``2 pi (theta - centre) * (cos, sin)`` of the ``free`` lines.
    """

    G: np.ndarray
    h: np.ndarray
    yy: float
    y0: float
    n: int
    frequency: np.ndarray
    degree: int
    lo: float
    hi: float
    free: tuple = ()

    @classmethod
    def accumulate(cls, theta, y, frequency, degree: int = 1, free=(), chunk: int = _CHUNK) -> NormalEquations:
        theta = np.asarray(theta, dtype=float)
        y = np.asarray(y, dtype=float)
        freq = np.array(frequency, dtype=float, ndmin=1)  # a copy: callers go on changing theirs
        n, k, d = len(theta), len(freq), int(degree)
        free = tuple(int(j) for j in free)
        p = d + 1 + 2 * k
        q = p + 2 * len(free)
        if n <= q:
            raise ValueError(f"{n} samples cannot fit {q} terms")
        lo, hi = float(theta.min()), float(theta.max())
        y0 = float(np.mean(y))
        deriv = [(d + 1 + j, d + 1 + k + j) for j in free]
        design, rows = _make_design(n, d, lo, hi, [(freq, d + 1, d + 1 + k)], deriv, q, 0, chunk)
        G, h, yy = _pass(theta, y, y0, design, 0, rows, True)
        return cls(0.5 * (G + G.T), h, yy, y0, n, freq, d, lo, hi, free)

    def extend(self, theta, y, frequency, chunk: int = _CHUNK) -> NormalEquations:
        """The equations with the lines ``frequency`` added, free, from one pass over the samples
        these (no free lines) came from, computing only the new rows of ``X'X``."""
        if self.free:
            raise ValueError("extend() needs equations without free lines")
        theta = np.asarray(theta, dtype=float)
        y = np.asarray(y, dtype=float)
        new = np.array(frequency, dtype=float, ndmin=1)
        d, k0, k1 = self.degree, len(self.frequency), len(new)
        n = len(theta)
        if n != self.n:
            raise ValueError("extend() needs the samples the equations came from")
        p0 = d + 1 + 2 * k0
        q = p0 + 4 * k1
        if n <= q:
            raise ValueError(f"{n} samples cannot fit {q} terms")
        # work order: [Legendre | cos old | sin old | cos new | sin new | derivatives of the new]
        groups = [(self.frequency, d + 1, d + 1 + k0), (new, p0, p0 + k1)]
        deriv = [(p0 + j, p0 + k1 + j) for j in range(k1)]
        design, rows = _make_design(n, d, self.lo, self.hi, groups, deriv, q, p0, chunk)
        Gn, hn, _ = _pass(theta, y, self.y0, design, p0, rows, False)
        Gw = np.empty((q, q))
        Gw[:p0, :p0] = self.G
        Gw[p0:, :] = Gn
        Gw[:p0, p0:] = Gn[:, :p0].T
        Gw[p0:, p0:] = 0.5 * (Gn[:, p0:] + Gn[:, p0:].T)
        hw = np.concatenate([self.h, hn])
        # to the standard order: [Legendre | all cosines | all sines | derivatives]
        k = k0 + k1
        perm = np.concatenate([np.arange(d + 1), d + 1 + np.arange(k0), p0 + np.arange(k1),
                               d + 1 + k0 + np.arange(k0), p0 + k1 + np.arange(k1), p0 + 2 * k1 + np.arange(2 * k1)])
        freq = np.concatenate([self.frequency, new])
        assert len(perm) == q and d + 1 + 2 * k + 2 * k1 == q
        return NormalEquations(Gw[np.ix_(perm, perm)], hw[perm], self.yy, self.y0, self.n, freq, d, self.lo,
                               self.hi, tuple(range(k0, k)))

    def _solve(self, cols: np.ndarray):
        G = self.G[np.ix_(cols, cols)]
        h = self.h[cols]
        scale = np.sqrt(np.maximum(np.diag(G), 1e-300))
        Gs = G / np.outer(scale, scale)
        try:
            cho = linalg.cho_factor(Gs, check_finite=False)
            beta = linalg.cho_solve(cho, h / scale, check_finite=False) / scale
            Ginv = linalg.cho_solve(cho, np.eye(len(cols)), check_finite=False) / np.outer(scale, scale)
        except linalg.LinAlgError:
            Ginv_s = linalg.pinvh(Gs)
            beta = Ginv_s @ (h / scale) / scale
            Ginv = Ginv_s / np.outer(scale, scale)
        rss = max(self.yy - float(beta @ h), 0.0)
        return beta, Ginv, rss

    def fit(self, keep=None) -> HarmonicFit:
        """The joint fit of the frequencies ``keep`` (indices; default all), no new pass."""
        d, k = self.degree, len(self.frequency)
        keep = list(range(k)) if keep is None else [int(j) for j in keep]
        cols = np.array(list(range(d + 1)) + [c for j in keep for c in (d + 1 + j, d + 1 + k + j)], dtype=int)
        beta, Ginv, rss = self._solve(cols)
        dof = self.n - len(cols)
        sigma = float(np.sqrt(rss / dof))
        nuis = beta[: d + 1].copy()
        nuis[0] += self.y0
        return HarmonicFit(frequency=self.frequency[keep].copy(), coef_cos=beta[d + 1::2].copy(),
                           coef_sin=beta[d + 2::2].copy(), cov=sigma**2 * Ginv[d + 1:, d + 1:], nuisance=nuis,
                           lo=self.lo, hi=self.hi, sigma=sigma, n=self.n, dof=dof,
                           noise_factor=np.ones(len(keep)))

    def frequency_step(self):
        """Gauss-Newton corrections of the free frequencies (and their white-noise standard errors)
        from the fit with derivative columns: ``delta = (c1 b - c2 a) / (2 pi (a^2 + b^2))``."""
        d, k = self.degree, len(self.frequency)
        p = d + 1 + 2 * k
        cols = np.arange(len(self.h))
        beta, Ginv, rss = self._solve(cols)
        sigma2 = rss / max(self.n - len(cols), 1)
        steps, ses = [], []
        for m, j in enumerate(self.free):
            a, b = beta[d + 1 + j], beta[d + 1 + k + j]
            c1, c2 = beta[p + 2 * m], beta[p + 2 * m + 1]
            amp2 = max(a * a + b * b, 1e-300)
            delta = (c1 * b - c2 * a) / amp2  # the 2 pi is inside the derivative columns
            grad = np.zeros(len(cols))
            grad[p + 2 * m], grad[p + 2 * m + 1] = b / amp2, -a / amp2
            steps.append(delta)
            ses.append(float(np.sqrt(max(sigma2 * grad @ Ginv @ grad, 0.0))))
        return np.array(steps), np.array(ses)


def harmonic_fit(theta, y, frequency, degree: int = 1, chunk: int = _CHUNK, residual: bool = False):
    """Fit sinusoids at ``frequency`` (cycles/rad or cycles/m, may be empty) plus a Legendre
    nuisance of ``degree`` (0: a mean only) to raw samples ``theta, y`` (any order); ``chunk``
    rows per block of the normal equations.  Returns the :class:`HarmonicFit`, and with
    ``residual`` also ``y - model`` at every sample (a second pass)."""
    ne = NormalEquations.accumulate(theta, y, frequency, degree, chunk=chunk)
    fit = ne.fit()
    if not residual:
        return fit
    r = np.asarray(y, dtype=float) - fit.predict(theta, chunk=chunk)
    return fit, r


def refine_frequencies(theta, y, frequency, free, degree: int = 1, iterations: int = 4,
                       chunk: int = _CHUNK, base: NormalEquations | None = None):
    """Refine the frequencies listed in ``free`` (indices) by Gauss-Newton on the joint model.

    A periodogram's frequency is good to a fraction of 1/span, but the phase at theta = 0 of a
    line far from the origin needs it far better.  Each iteration is one pass: the joint fit plus
    derivative columns ``2 pi (theta - centre) (cos, sin)`` per free line, whose coefficients give
    the correction (at most half a resolution step); it stops below 1e-3 of that, or after
    ``iterations`` passes.  ``base``, the equations of the fixed lines (the first ones of
    ``frequency``, the same degree), makes every pass compute only the free lines' rows.

    Returns ``(frequency, frequency_se, equations)``: all frequencies (the free ones refined),
    white-noise standard errors of the free ones (0 for the others), and the last pass's
    :class:`NormalEquations`, whose ``fit()`` is the joint fit at those frequencies.
    """
    theta = np.asarray(theta, dtype=float)
    freq = np.array(frequency, dtype=float)
    free = list(free)
    se = np.zeros(len(freq))
    step_max = 0.5 / float(np.ptp(theta))
    k0 = len(base.frequency) if base is not None else 0
    use_base = (base is not None and free and not base.free and base.degree == int(degree)
                and sorted(free) == list(range(k0, len(freq))) and np.array_equal(base.frequency, freq[:k0]))
    for it in range(max(1, iterations)):
        if use_base:
            ne = base.extend(theta, y, freq[k0:], chunk=chunk)
            order = list(range(k0, len(freq)))  # extend() makes the new lines free in this order
        else:
            ne = NormalEquations.accumulate(theta, y, freq, degree, free=free, chunk=chunk)
            order = free
        if not free:
            break
        delta, dse = ne.frequency_step()
        se[order] = dse
        # converged, or out of iterations: stop where the fit was taken, so that frequencies,
        # amplitudes and phases returned belong together
        if np.all(np.abs(delta) < 1e-3 * step_max) or it == iterations - 1:
            break
        freq[order] += np.clip(delta, -step_max, step_max)
    return freq, se, ne
