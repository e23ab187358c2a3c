"""A design held as its blocks' columns side by side, never stacked (:class:`Design`): what the
fits of the closed loop read from a round's design (its normal equations, predictions, the rows
of a group) computed block by block or a chunk of rows at a time (:mod:`.gram`), so that no rows x
terms copy of the blocks' columns is made (issue 13: memory bounded on long recordings).  The
blocks' arrays are those :meth:`~.design.Block.columns` returns (shared with the data's cache of
columns while it holds them; on a long recording lazy columns, :class:`~.rowcols.Columns`, whose
rows are computed when a chunk asks for them).  The numbers are those of the stacked design up to the order of the
floating-point additions (about 1e-16 relative per entry)."""

from __future__ import annotations

import numpy as np

from ..core.reduction import one_blas_thread
from . import gram

__all__ = ["Design", "design_of"]


class _Rows:
    """The rows ``[a, z)`` of a :class:`Design`: ``rows @ beta`` a chunk of rows stacked at a time,
    ``rows.T @ C`` block by block on views of the blocks (no copy of the rows); ``np.asarray(rows)``
    stacks them (one group's rows)."""

    def __init__(self, blocks, at, a: int, z: int):
        self.blocks, self.at, self.a, self.z = blocks, at, a, z

    @property
    def shape(self) -> tuple[int, int]:
        return self.z - self.a, self.at[-1]

    def __matmul__(self, beta):
        # a chunk of rows stacked at a time (in cache): the arithmetic of the stacked design's rows
        out = np.empty(self.z - self.a)
        return gram.predict([B[self.a:self.z] for B in self.blocks], np.asarray(beta, dtype=float),
                            gram.every_row(self.z - self.a), out=out)

    @property
    def T(self) -> "_RowsT":
        return _RowsT(self)

    def __array__(self, dtype=None, copy=None):
        out = gram._rows(self.blocks, self.a, self.z)
        return out if dtype is None else out.astype(dtype)


class _RowsT:
    """The transpose of :class:`_Rows`: ``rows.T @ C`` (columns ``C`` over the same rows)."""

    def __init__(self, rows: _Rows):
        self.rows = rows

    def __matmul__(self, C):
        C = np.asarray(C)
        r = self.rows
        if C.ndim == 1:
            return np.concatenate([B[r.a:r.z].T @ C for B in r.blocks], axis=0)
        with one_blas_thread():     # matrix products: BLAS threads split only their results
            return np.concatenate([B[r.a:r.z].T @ C for B in r.blocks], axis=0)


class Design:
    """The design whose columns are the 2-d arrays ``blocks`` side by side (``n`` rows).

    ``X[a:z]`` (a row range) gives its rows lazily (:class:`_Rows`); ``X @ beta`` and ``X.T @ X``,
    ``X.T @ y`` (through :attr:`T`) are computed a chunk of rows at a time; ``X.masked(keep)`` is the
    column list of the columns ``keep`` for :func:`.gram.normals` / :func:`.gram.predict`."""

    def __init__(self, blocks, n: int):
        self.blocks = [b.reshape(n, -1) for b in blocks]
        self.n = n
        self.at = np.concatenate(([0], np.cumsum([b.shape[1] for b in self.blocks]))).astype(int)

    @property
    def shape(self) -> tuple[int, int]:
        return self.n, int(self.at[-1])

    @property
    def nbytes(self) -> int:
        return sum(int(b.nbytes) for b in self.blocks)

    def __len__(self) -> int:
        return self.n

    def __getitem__(self, key):
        """Rows ``a:z``: lazily (:class:`_Rows`); any other index of rows (a mask, indices): those
        rows stacked (a copy)."""
        if isinstance(key, slice) and key.step in (None, 1):
            a, z, _ = key.indices(self.n)
            return _Rows(self.blocks, self.at, a, max(a, z))
        parts = [B[key] for B in self.blocks]
        return np.concatenate(parts, axis=1) if parts else np.zeros((len(np.arange(self.n)[key]), 0))

    def __array__(self, dtype=None, copy=None):
        """The stacked design (a rows x columns copy: for checks, not for the loop)."""
        out = gram.hstack(self.blocks) if self.blocks else np.zeros((self.n, 0))
        return out if dtype is None else out.astype(dtype)

    def __matmul__(self, beta):
        beta = np.asarray(beta, dtype=float)
        if beta.ndim != 1:
            raise ValueError("a design multiplies a vector of coefficients")
        return gram.predict(self.blocks, beta, gram.every_row(self.n), n=self.n)

    @property
    def T(self) -> "_DesignT":
        return _DesignT(self)

    def masked(self, keep: np.ndarray) -> list:
        """The columns where ``keep`` (boolean over the design's columns) is true, as a column list of
        :mod:`.gram` (``(block, mask)`` pairs; whole blocks as they are)."""
        out = []
        for B, j, k in zip(self.blocks, self.at[:-1], self.at[1:]):
            m = keep[j:k]
            if m.all():
                out.append(B)
            elif m.any():
                out.append((B, m))
        return out


class _DesignT:
    """The transpose of a :class:`Design`: ``X.T @ X`` (its normal matrix) and ``X.T @ y``."""

    def __init__(self, X: Design):
        self.X = X

    def __matmul__(self, other):
        X = self.X
        ranges = gram.every_row(X.n)
        if other is X:
            return gram.normals(X.blocks, None, ranges)[0]
        other = np.asarray(other, dtype=float)
        out = np.zeros((X.shape[1],) + other.shape[1:])
        for a, z in ranges:
            out += gram._rows(X.blocks, a, z, scratch=True).T @ other[a:z]
        return out


def design_of(state, dd, taylor: bool = False) -> Design:
    """The design of a state's blocks on the data ``dd`` (with ``taylor``: each block's Taylor columns
    after its own), as a :class:`Design` of the blocks' columns (not stacked)."""
    return Design([b.columns(dd, taylor) for b in state.blocks], len(dd))
