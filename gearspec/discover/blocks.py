"""A library's columns on the segments' pseudo rows, reduced a block of segments at a time.

The sparse-regression path and its bootstrap need only the normal equations of the library's
columns over all segments (``X^T X``, ``X^T q``): ridge regression, thresholding and least squares
all depend on the data through them.  :class:`SegmentDesign` holds what builds the design of any
block of segments (per-segment multipliers and the pseudo rows of :mod:`.moments`) and
:meth:`SegmentDesign.reduce` folds the blocks into one triangular factor ``R`` (p x p) with
``R^T R = X^T X`` and ``R^T t = X^T q`` by a running QR (numerically as good as a QR of the whole
design, better than forming ``X^T X``).  Memory: one block of segments by the columns plus
``p x p``, never the whole ``(S*K, p)`` design of a long recording; cost linear in the segments.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .moments import Moments

__all__ = ["SegmentDesign", "running_qr"]

#: pseudo rows x columns of design built at once
_BLOCK_CELLS = 2_000_000


def running_qr(blocks) -> tuple[np.ndarray, np.ndarray]:
    """``(R, t)`` of the rows given block by block (``blocks``: iterable of ``(X_b, y_b)``), such
    that ``R^T R = sum X_b^T X_b`` and ``R^T t = sum X_b^T y_b``: each block stacked under the
    current ``R`` and factored again (``R`` has at most as many rows as columns)."""
    R, t = None, None
    for Xb, yb in blocks:
        if R is not None:
            Xb, yb = np.vstack([R, Xb]), np.concatenate([t, yb])
        Q, R = np.linalg.qr(Xb, mode="reduced")
        t = Q.T @ yb
    return R, t


@dataclass
class SegmentDesign:
    """The design ``[fixed | A_s * P_s[:, basis]]`` on the pseudo rows of ``M``, segment by segment.

    Attributes
    ----------
    M : Moments
    A : ndarray, (S, p)
        Per-segment multiplier of every library column.
    kidx : ndarray, (p,)
        Sample basis of every library column (index into ``M.basis``).
    fixed : ndarray, (S*K, nf) or None
        Columns held in (never thresholded), first in the design.
    """

    M: Moments
    A: np.ndarray
    kidx: np.ndarray
    fixed: np.ndarray | None = None

    @classmethod
    def of(cls, lib, M: Moments, fixed: np.ndarray | None = None) -> "SegmentDesign":
        """The design of the library ``lib`` on ``M`` with the columns ``fixed`` (S*K, nf) first."""
        return cls(M, lib.multipliers(M), lib.basis_index(M), fixed)

    @property
    def nf(self) -> int:
        return 0 if self.fixed is None else self.fixed.shape[1]

    @property
    def shape(self) -> tuple[int, int]:
        return self.M.S * self.M.K, self.nf + self.A.shape[1]

    def block(self, idx) -> np.ndarray:
        """The design's pseudo rows of the segments ``idx`` (len(idx)*K, nf + p)."""
        idx = np.asarray(idx, dtype=int)
        M = self.M
        Pk = np.ascontiguousarray(M.P[idx][:, :, self.kidx])    # C-ordered: the product reshapes without a copy
        X = (self.A[idx][:, None, :] * Pk).reshape(len(idx) * M.K, self.A.shape[1])
        if self.nf:
            F = self.fixed.reshape(M.S, M.K, self.nf)[idx].reshape(len(idx) * M.K, self.nf)
            X = np.hstack([F, X])
        return X

    def dense(self) -> np.ndarray:
        """The whole design (S*K, nf + p): for checks; the search uses :meth:`reduce`."""
        return self.block(np.arange(self.M.S))

    def reduce(self, segments=None):
        """``(R, t, N, yy)``: the triangular factor and target of the design's normal equations
        over ``segments`` (indices, repeats allowed as in a bootstrap: a segment drawn ``c`` times
        counts ``c`` times; default all), with the number of samples and sum of squared friction
        they stand for (what :class:`~.search.Scaled` scales by)."""
        M = self.M
        idx = np.arange(M.S) if segments is None else np.asarray(segments, dtype=int)
        seg, count = np.unique(idx, return_counts=True)
        w = np.sqrt(count.astype(float))
        per = max(1, _BLOCK_CELLS // max(M.K * self.shape[1], 1))

        def blocks():
            for a in range(0, len(seg), per):
                s, ws = seg[a:a + per], np.repeat(w[a:a + per], M.K)
                yield self.block(s) * ws[:, None], M.q[s].reshape(-1) * ws

        R, t = running_qr(blocks())
        if R is None:
            p = self.shape[1]
            R, t = np.zeros((0, p)), np.zeros(0)
        return R, t, float(np.sum(M.n[seg] * count)), float(np.sum(M.yy[seg] * count))
