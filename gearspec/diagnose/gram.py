"""Normal equations and predictions of a design given as a list of column blocks, a bounded number
of rows at a time: the fits of the closed loop never stack a rows x terms matrix of a long
recording (memory: one chunk of :data:`CHUNK_ROWS` rows; the sums are those of the stacked design
up to the order of the floating-point additions, about 1e-16 relative per entry)."""

from __future__ import annotations

import numpy as np

from ..core.reduction import one_blas_thread

__all__ = ["CHUNK_ROWS", "COPY_ROWS", "spans", "every_row", "width", "normals", "bordered", "rss", "predict",
           "hstack", "stack"]

#: rows per chunk: 16384 rows x 40 columns are 5 MB, a few cache-sized BLAS products each
CHUNK_ROWS = 16384


def spans(starts, stops, mask=None, chunk: int | None = None) -> list[tuple[int, int]]:
    """Row ranges ``[a, z)`` covering the groups ``[starts[g], stops[g])`` where ``mask`` (default:
    all) is true: neighbouring groups merged, each range at most ``chunk`` rows (default
    :data:`CHUNK_ROWS`; longer groups split)."""
    chunk = CHUNK_ROWS if chunk is None else chunk
    starts, stops = np.asarray(starts), np.asarray(stops)
    sel = np.arange(len(starts)) if mask is None else np.flatnonzero(mask)
    out: list = []
    for g in sel:
        a, z = int(starts[g]), int(stops[g])
        if out and out[-1][1] == a and z - out[-1][0] <= chunk:
            out[-1] = (out[-1][0], z)
            continue
        while z - a > chunk:
            out.append((a, a + chunk))
            a += chunk
        if z > a:
            out.append((a, z))
    return out


def every_row(n: int, chunk: int | None = None) -> list[tuple[int, int]]:
    """Row ranges of at most ``chunk`` rows (default :data:`CHUNK_ROWS`) covering ``[0, n)``."""
    chunk = CHUNK_ROWS if chunk is None else chunk
    return [(a, min(a + chunk, n)) for a in range(0, n, chunk)]


def _rows(cols, a: int, z: int, scratch: bool = False) -> np.ndarray:
    """The rows ``[a, z)`` of the stacked design: every block's slice side by side.  A block is an
    array (n, k) or ``(array, columns)`` (only those columns: an index or a boolean mask).  With
    ``scratch`` they are copied into this process's chunk buffer (:func:`_scratch`), valid until
    the next such call: for a product used at once (no new array, and no fresh pages, per chunk)."""
    parts = [_block(c, a, z) for c in cols]
    if not parts:
        return np.zeros((z - a, 0))
    if len(parts) == 1:
        return parts[0]
    if not scratch:
        return np.concatenate(parts, axis=1)
    out = _scratch(z - a, sum(q.shape[1] for q in parts))
    return np.concatenate(parts, axis=1, out=out)


#: the chunk buffer of :func:`_rows` (one per process: a forked worker copies it on first write)
_SCRATCH = [np.empty(0)]


def _scratch(m: int, p: int) -> np.ndarray:
    """An uninitialised C-ordered (m, p) view of the chunk buffer, grown when too small (a chunk of
    :data:`CHUNK_ROWS` rows of the widest design so far: a few MB)."""
    if _SCRATCH[0].size < m * p:
        _SCRATCH[0] = np.empty(max(m * p, CHUNK_ROWS * max(p, 1)))
    return _SCRATCH[0][:m * p].reshape(m, p)


def _block(c, a: int, z: int) -> np.ndarray:
    """The rows ``[a, z)`` of one block of a column list (2-d)."""
    part = c[0][a:z][:, c[1]] if isinstance(c, tuple) else c[a:z]
    return part.reshape(z - a, -1)


def width(cols) -> int:
    """Columns of the stacked design."""
    n = 0
    for c in cols:
        if not isinstance(c, tuple):      # an array, or lazy columns (:class:`~.rowcols.Columns`)
            n += c.shape[1] if c.ndim > 1 else 1
        else:
            idx = np.asarray(c[1])
            n += int(idx.sum()) if idx.dtype == bool else len(idx)
    return n


def normals(cols, y: np.ndarray | None, ranges) -> tuple[np.ndarray, np.ndarray | None]:
    """``(X^T X, X^T y)`` of the stacked design ``X`` (:func:`_rows`) over the row ranges ``ranges``
    (``X^T y`` None when ``y`` is)."""
    p = width(cols)
    G, b = np.zeros((p, p)), (None if y is None else np.zeros(p))
    for a, z in ranges:
        Xc = _rows(cols, a, z, scratch=True)
        with one_blas_thread():     # threads split only the result: the same bits, without their contention
            G += Xc.T @ Xc
        if y is not None:
            b += Xc.T @ y[a:z]
    return G, b


def bordered(cols, new, y: np.ndarray, ranges) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(C^T X, C^T C, C^T y)`` of new columns ``C`` (the stacked design of the blocks ``new``)
    against the stacked design ``X`` of ``cols``: the border of the normal equations of
    ``[X | C]`` whose ``X`` part is known (a bounded search that changes only ``C``)."""
    p, q = width(cols), width(new)
    CX, CC, Cy = np.zeros((q, p)), np.zeros((q, q)), np.zeros(q)
    for a, z in ranges:
        Cc = _rows(new, a, z, scratch=True)
        j = 0
        with one_blas_thread():     # matrix products: threads would split only their results
            for c in cols:          # block by block on views of the rows (no copy of X's)
                part = _block(c, a, z)
                CX[:, j:j + part.shape[1]] += Cc.T @ part
                j += part.shape[1]
            CC += Cc.T @ Cc
        Cy += Cc.T @ y[a:z]
    return CX, CC, Cy


def rss(cols, beta: np.ndarray, y: np.ndarray, ranges) -> float:
    """``|y - X beta|^2`` over the row ranges ``ranges`` (the residual a chunk at a time)."""
    out = 0.0
    for a, z in ranges:
        r = y[a:z] - _rows(cols, a, z, scratch=True) @ beta
        out += float(r @ r)
    return out


def predict(cols, beta: np.ndarray, ranges, out: np.ndarray | None = None, n: int | None = None) -> np.ndarray:
    """``X beta`` at the rows of ``ranges`` (into ``out``, created with ``n`` rows when None): each
    chunk's rows stacked (in cache) and multiplied at once, row by row the arithmetic of ``X @ beta``
    on the stacked design (a sum over the blocks in another order moves the predictions of an
    ill-conditioned fit, whose coefficients cancel, far above round-off)."""
    out = np.zeros(n) if out is None else out
    for a, z in ranges:
        out[a:z] = _rows(cols, a, z, scratch=True) @ beta
    return out


#: rows copied at a time by :func:`hstack`: a chunk of every block stays in cache while it is copied
COPY_ROWS = 4096


def hstack(cols, out: np.ndarray | None = None) -> np.ndarray:
    """``np.column_stack`` of 2-d blocks with the same rows (the same array), copied a chunk of
    :data:`COPY_ROWS` rows at a time (into ``out`` when given): about half the time of one copy
    of narrow blocks into a wide array."""
    n = cols[0].shape[0]
    p = sum(c.shape[1] for c in cols)
    out = np.empty((n, p)) if out is None else out
    for a in range(0, n, COPY_ROWS):
        np.concatenate([c[a:a + COPY_ROWS] for c in cols], axis=1, out=out[a:a + COPY_ROWS])
    return out


def stack(parts, n: int, p: int, out: np.ndarray | None = None) -> np.ndarray:
    """``np.column_stack`` of the 2-d blocks (``n`` rows, ``p`` columns in all) that the iterable
    ``parts`` yields, each copied into the result as it comes and let go: the peak is the result and
    one block (with a list of blocks, the result and every block).  The same array, bit for bit:
    products of it are those of the stacked design."""
    out = np.empty((n, p)) if out is None else out
    j = 0
    for c in parts:
        k = c.shape[1] if c.ndim > 1 else 1
        for a, z in ([(0, n)] if isinstance(c, np.ndarray) else every_row(n)):   # lazy columns: by rows
            out[a:z, j:j + k] = c[a:z].reshape(z - a, k)
        j += k
        del c          # the generator computes the next block without this one held
    if j != p:
        raise ValueError(f"stacked {j} columns where {p} were announced")
    return out
