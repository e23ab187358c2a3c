"""The exact per-group reduction the three engines share: a group's (segment's, run's, move's)
samples become the normal equations of its columns (:class:`GroupNormals`), so that a fit's cost
does not grow with the samples, with the lines' columns phased about the group's mean position.
:mod:`gearspec.identify` ``SegmentStats`` and :mod:`gearspec.discover.moments` ``Moments`` are
:class:`GroupNormals` with their engine's metadata.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np

__all__ = ["GroupNormals", "harmonic_columns", "normal_equations", "group_normal_equations", "group_cross",
           "partial_out_last", "unique_ids", "group_rows", "gram", "one_blas_thread", "on_one_blas_thread"]

_TWO_PI = 2.0 * np.pi


def unique_ids(a, *, return_index: bool = False, return_inverse: bool = False):
    """``np.unique(a, return_index=..., return_inverse=...)`` of a 1-D array of ids (segments,
    runs, groups), the same arrays, in one pass without a sort when ``a`` is already in ascending
    order (the samples of a recording's segments are: 10^7 rows sorted again cost a second per call).

    Parameters
    ----------
    a : array_like, (n,)
        Ids (integers or floats; no NaN).
    return_index, return_inverse : bool
        Also return the index of each id's first row, and each row's position in the ids.

    Returns
    -------
    ids : ndarray
        The distinct ids, ascending; then ``first`` and ``inverse`` as asked (as :func:`numpy.unique`).
    """
    a = np.asarray(a)
    if a.ndim != 1 or (len(a) > 1 and not bool(np.all(a[1:] >= a[:-1]))):
        return np.unique(a, return_index=return_index, return_inverse=return_inverse)
    new = np.empty(len(a), bool)
    new[:1] = True
    np.not_equal(a[1:], a[:-1], out=new[1:])
    first = np.flatnonzero(new)
    out = [a[first]]
    if return_index:
        out.append(first)
    if return_inverse:
        out.append(np.cumsum(new, dtype=np.intp) - 1)
    return out[0] if len(out) == 1 else tuple(out)


def group_rows(ids) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The rows of every group, each group's in their order: ``(order, groups, bounds)`` with
    ``order = argsort(ids, kind="stable")``, ``groups`` the distinct ids ascending and group ``j``'s
    rows ``order[bounds[j]:bounds[j + 1]]``.  Ids already in ascending order (a recording's
    segments) need no sort: ``order`` is then ``arange``.

    Parameters
    ----------
    ids : array_like, (n,)
        Group id of every row.
    """
    ids = np.asarray(ids)
    if len(ids) > 1 and not bool(np.all(ids[1:] >= ids[:-1])):
        order = np.argsort(ids, kind="stable")
        ordered = ids[order]
    else:
        order, ordered = np.arange(len(ids)), ids
    groups, starts = unique_ids(ordered, return_index=True)
    return order, groups, np.append(starts, len(ids))


_CONTROLLER = None


def gram(X) -> np.ndarray:
    """``X^T X`` (p, p) of columns ``X`` (n, p), computed by BLAS on one thread.

    With OpenBLAS's threads on a busy machine this product of few columns and many rows cost up to
    three orders of magnitude more CPU than on one (measured on the shared 2-core machine:
    25000 x 21 rows x columns 0.77 s against 1.1 ms; 10^6 x 21: 3.2 s against 66 ms).  The
    threads split the p x p result, not the sums over the rows, so every entry is the same to the
    last bit (checked at 5000-10^6 rows, 3-41 columns).  Products with a vector (``X^T y``,
    ``y^T y``) keep the threads here: theirs do split the sums, and the last bits would change
    (callers whose products are all of few columns run on one thread: :func:`on_one_blas_thread`)."""
    X = np.asarray(X, dtype=float)
    with one_blas_thread():
        return X.T @ X


def _controller():
    """The process's ``threadpoolctl`` controller, made once (entering a limit then costs microseconds)."""
    global _CONTROLLER
    if _CONTROLLER is None:
        from threadpoolctl import ThreadpoolController

        _CONTROLLER = ThreadpoolController()
    return _CONTROLLER


def one_blas_thread():
    """A context in which BLAS runs on one thread (``threadpoolctl``)."""
    return _controller().limit(limits=1, user_api="blas")


def blas_on_one_thread() -> bool:
    """Whether BLAS runs on one thread here now (as in a forked worker of
    :func:`gearspec.core.parallel.forked_map`): work whose sums BLAS splits by thread count gives a
    worker's numbers only then, so a map that must equal the loop forks only then."""
    return all(c.num_threads == 1 for c in _controller().select(user_api="blas").lib_controllers)


def on_one_blas_thread(fn):
    """``fn`` run inside :func:`one_blas_thread` (a decorator): for work whose products are all of
    few columns (a fit's least squares on per-segment statistics, ``X^T y`` over a group's rows),
    where OpenBLAS's threads only contend for the cores."""

    @functools.wraps(fn)
    def run(*args, **kwargs):
        with one_blas_thread():
            return fn(*args, **kwargs)

    return run


def normal_equations(X, y) -> tuple[np.ndarray, np.ndarray, float]:
    """``(X^T X, X^T y, y^T y)`` of one group's columns ``X`` (n, p) and observations ``y`` (n,):
    everything a least-squares fit of the group needs (the residual sum of squares of any
    coefficients ``b`` is ``y^T y - 2 b^T X^T y + b^T X^T X b``).  ``X^T X`` by :func:`gram`."""
    X = np.asarray(X, dtype=float)
    y = np.asarray(y, dtype=float)
    return gram(X), X.T @ y, float(y @ y)


#: groups of at least this many rows are reduced one by one (BLAS); smaller ones together
_BATCH_BELOW = 4096
#: rows x p^2 products held at once when small groups are reduced together
_BATCH_CELLS = 4_000_000


def group_normal_equations(X, y, starts, stops) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`normal_equations` of every contiguous group ``[starts[g], stops[g])`` of the rows:
    ``G`` (groups, p, p), ``b`` (groups, p), ``yy`` (groups,).  Large groups one by one, small ones
    (free-motion blocks: thousands of a few rows each) summed together, a bounded number of rows
    at a time; empty groups give zeros."""
    X = np.asarray(X, dtype=float)
    y = np.asarray(y, dtype=float)
    starts, stops = np.asarray(starts, dtype=np.int64), np.asarray(stops, dtype=np.int64)
    ng, p = len(starts), X.shape[1]
    G, b, yy = np.zeros((ng, p, p)), np.zeros((ng, p)), np.zeros(ng)
    size = stops - starts
    for g in np.flatnonzero(size >= _BATCH_BELOW):
        a, z = starts[g], stops[g]
        G[g], b[g], yy[g] = normal_equations(X[a:z], y[a:z])
    small = np.flatnonzero((size > 0) & (size < _BATCH_BELOW))
    rows_per = max(_BATCH_CELLS // max(p * p, 1), _BATCH_BELOW)
    i = 0
    while i < len(small):
        # a run of small groups holding at most rows_per rows (at least one group)
        cum = np.cumsum(size[small[i:]])
        j = i + max(int(np.searchsorted(cum, rows_per, side="right")), 1)
        grp = small[i:j]
        idx = np.concatenate([np.arange(starts[g], stops[g]) for g in grp])
        at = np.concatenate(([0], np.cumsum(size[grp])[:-1]))
        Xg, yg = X[idx], y[idx]
        G[grp] = np.add.reduceat(Xg[:, :, None] * Xg[:, None, :], at, axis=0)
        b[grp] = np.add.reduceat(Xg * yg[:, None], at, axis=0)
        yy[grp] = np.add.reduceat(yg * yg, at)
        i = j
    return G, b, yy


def group_cross(X, C, starts, stops) -> np.ndarray:
    """Per-group cross products ``X_g^T C_g`` (groups, p, q) of two column sets over the same rows:
    how new columns ``C`` enter normal equations already reduced for ``X``."""
    out = np.empty((len(starts), X.shape[1], C.shape[1]))
    for g, (a, z) in enumerate(zip(starts, stops)):
        out[g] = X[a:z].T @ C[a:z]
    return out


@dataclass
class GroupNormals:
    """Normal equations of a least-squares problem per group of rows: ``G[g] = X_g^T X_g``
    (groups, p, p), ``b[g] = X_g^T y_g`` (groups, p), ``yy[g] = y_g^T y_g`` (groups,) and the
    group's number of rows ``n`` (groups,).  Any fit on any union of groups follows from them.

    Subclasses add per-group metadata: the names in :attr:`per_group` are taken along by
    :meth:`take`.
    """

    G: np.ndarray
    b: np.ndarray
    yy: np.ndarray
    n: np.ndarray

    #: attributes indexed by group (None allowed), taken along by :meth:`take`
    per_group: ClassVar[tuple] = ("G", "b", "yy", "n")

    @classmethod
    def of(cls, X, y, starts, stops) -> "GroupNormals":
        """The normal equations of the contiguous groups ``[starts[g], stops[g])`` of the rows of
        ``X`` (n, p) and ``y`` (n,)."""
        G, b, yy = group_normal_equations(X, y, starts, stops)
        return cls(G, b, yy, np.asarray(stops) - np.asarray(starts))

    def __len__(self) -> int:
        return len(self.yy)

    def take(self, idx):
        """The groups ``idx`` (indices, repeats allowed as in a bootstrap, or a boolean mask)."""
        idx = np.asarray(idx)
        return replace(self, **{k: getattr(self, k)[idx] for k in self.per_group if getattr(self, k) is not None})

    def sum(self, idx=None) -> tuple[np.ndarray, np.ndarray, float]:
        """``(X^T X, X^T y, y^T y)`` summed over the groups ``idx`` (default: all)."""
        sel = slice(None) if idx is None else np.asarray(idx)
        return self.G[sel].sum(0), self.b[sel].sum(0), float(self.yy[sel].sum())

    def rss(self, beta, idx=None) -> np.ndarray:
        """Residual sum of squares of every group (of ``idx``) for the coefficients ``beta`` (p,):
        ``yy - 2 b.beta + beta.G.beta``."""
        sel = slice(None) if idx is None else np.asarray(idx)
        beta = np.asarray(beta, dtype=float)
        return self.yy[sel] - 2.0 * self.b[sel] @ beta + np.einsum("p,gpq,q->g", beta, self.G[sel], beta)

    def columns(self, cols) -> tuple[np.ndarray, np.ndarray]:
        """``(G, b)`` of the columns ``cols`` alone (the others ignored)."""
        cols = np.asarray(cols, dtype=int)
        return self.G[:, cols][:, :, cols], self.b[:, cols]

    def pseudo_rows(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``p`` pseudo rows per group, ``P[g]`` (p x p, ``P^T P = G``), targets ``q[g]``
        (``P^T q = b``) and ``rest = yy - |q|^2``, so that for every ``w``
        ``|y_g - X_g w|^2 = |q_g - P_g w|^2 + rest_g``: a least-squares solver (or a sparse
        regression) on the pseudo rows gives exactly what it gives on the samples.  From the
        eigen-decomposition of each ``G[g]`` in columns scaled to unit RMS (a scale-free rank test)."""
        G, b = self.G, self.b
        S, K = b.shape
        diag = np.einsum("skk->k", G) if S else np.ones(K)
        scale = np.sqrt(np.maximum(diag / max(S, 1), 0.0))
        scale[scale == 0] = 1.0
        P = np.zeros((S, K, K))
        q = np.zeros((S, K))
        for s in range(S):
            lam, U = np.linalg.eigh(G[s] / np.outer(scale, scale))
            keep = lam > max(lam[-1], 0.0) * 1e-12
            r = int(keep.sum())
            if r == 0:
                continue
            lam, U = lam[keep], U[:, keep]
            P[s, :r] = (np.sqrt(lam)[:, None] * U.T) * scale[None, :]
            q[s, :r] = (U.T @ (b[s] / scale)) / np.sqrt(lam)
        return P, q, np.maximum(self.yy - np.sum(q * q, axis=1), 0.0)


def harmonic_columns(theta, frequencies, center=None) -> tuple[np.ndarray, np.ndarray]:
    """``sin`` and ``cos`` of ``2 pi f theta`` for the positions of one group, phases about the
    group's mean position (``center``: that position per sample, for many groups at once).

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
    center : array_like, (n,), optional
        The centre of each sample's group (default: the mean of ``theta``, one group).

    Returns
    -------
    sin, cos : ndarray, (n, K)
    """
    th = np.asarray(theta, dtype=float)
    freqs = np.asarray(frequencies, dtype=float)
    m = th.mean() if center is None else np.asarray(center, dtype=float)[:, None]
    ph = _TWO_PI * (np.outer(th - m, freqs) if center is None else (th[:, None] - m) * freqs)
    sn, cs = np.sin(ph), np.cos(ph)
    if center is None:
        rot = _TWO_PI * freqs * m
        c, s = np.cos(rot), np.sin(rot)
    else:   # the rotation once per run of equal centres (a group's), repeated: the same values
        first, runs = _runs(m[:, 0])
        rot = _TWO_PI * freqs * m[first]
        c, s = np.repeat(np.cos(rot), runs, axis=0), np.repeat(np.sin(rot), runs, axis=0)
    return sn * c + cs * s, cs * c - sn * s


def _runs(a) -> tuple[np.ndarray, np.ndarray]:
    """First index and length of every run of equal consecutive values of ``a`` (1-D)."""
    new = np.empty(len(a), bool)
    new[:1] = True
    np.not_equal(a[1:], a[:-1], out=new[1:])
    first = np.flatnonzero(new)
    return first, np.diff(np.append(first, len(a)))


def partial_out_last(G, g, yy):
    """Normal equations ``(G, g, yy)`` per group with their last column taken out by least squares
    (the Schur complement): exactly those of the other columns fitted together with it, its
    coefficient free in every group; a group where it is zero keeps its equations."""
    gnn = G[:, -1, -1]
    ok = gnn > 0
    inv = np.where(ok, 1.0 / np.where(ok, gnn, 1.0), 0.0)
    c = G[:, :-1, -1]
    G2 = G[:, :-1, :-1] - np.einsum("sp,sq,s->spq", c, c, inv)
    g2 = g[:, :-1] - c * (g[:, -1] * inv)[:, None]
    yy2 = yy - g[:, -1] ** 2 * inv
    return G2, g2, yy2
