"""The chunk products of :mod:`gearspec.diagnose.gram` (normals, bordered, rss, predict) stack a
chunk's rows into one reused buffer and run their matrix products on one BLAS thread: the numbers
are those of the stacked design, bit for bit, whatever the widths of the designs before."""

from __future__ import annotations

import contextlib

import numpy as np

from gearspec.diagnose import gram
from gearspec.diagnose.chunked import Design


def _blocks(rng, n, widths):
    return [rng.standard_normal((n, k)) for k in widths]


def test_products_are_those_of_the_stacked_design_through_a_reused_buffer():
    rng = np.random.default_rng(3)
    n = 3 * gram.CHUNK_ROWS + 123
    y = rng.standard_normal(n)
    R = gram.every_row(n)
    for widths in ((1, 2), (3, 4, 2, 5), (2, 1)):       # narrow, wider (the buffer grows), narrow again
        cols = _blocks(rng, n, widths)
        X = np.concatenate(cols, axis=1)
        G, b = gram.normals(cols, y, R)
        # the stacked design's sums chunk by chunk, as a direct computation
        G0 = sum(X[a:z].T @ X[a:z] for a, z in R)
        b0 = sum(X[a:z].T @ y[a:z] for a, z in R)
        assert np.array_equal(G, G0) and np.array_equal(b, b0)
        beta = rng.standard_normal(X.shape[1])
        assert np.array_equal(gram.predict(cols, beta, R, n=n), np.concatenate([X[a:z] @ beta for a, z in R]))
        r = y - np.concatenate([X[a:z] @ beta for a, z in R])
        assert gram.rss(cols, beta, y, R) == sum(float(r[a:z] @ r[a:z]) for a, z in R)
        new = _blocks(rng, n, (2, 1))
        C = np.concatenate(new, axis=1)
        CX, CC, Cy = gram.bordered(cols, new, y, R)
        assert np.array_equal(CC, sum(C[a:z].T @ C[a:z] for a, z in R))
        assert np.allclose(CX, C.T @ X, rtol=1e-12, atol=1e-9) and np.allclose(Cy, C.T @ y, rtol=1e-12, atol=1e-9)
        D = Design(cols, n)
        assert np.array_equal(D.T @ D, G0)
        assert np.allclose(D.T @ y, X.T @ y, rtol=1e-12, atol=1e-9)


def test_chunk_rows_reuse_one_buffer():
    rng = np.random.default_rng(4)
    cols = _blocks(rng, 1000, (2, 3))
    first = gram._rows(cols, 0, 500, scratch=True)
    second = gram._rows(cols, 500, 1000, scratch=True)
    assert np.shares_memory(first, second)          # no new array per chunk
    assert np.array_equal(second, np.concatenate([c[500:] for c in cols], axis=1))
    plain = gram._rows(cols, 0, 500)
    assert not np.shares_memory(plain, second)      # without scratch: an array of its own


def test_matrix_products_on_one_blas_thread(monkeypatch):
    entered = []

    @contextlib.contextmanager
    def counting():
        entered.append(1)
        yield

    monkeypatch.setattr(gram, "one_blas_thread", counting)
    rng = np.random.default_rng(5)
    n = 2 * gram.CHUNK_ROWS
    cols, y = _blocks(rng, n, (2, 2)), rng.standard_normal(n)
    gram.normals(cols, y, gram.every_row(n))
    assert len(entered) == 2                        # once per chunk
    gram.bordered(cols, _blocks(rng, n, (1,)), y, gram.every_row(n))
    assert len(entered) == 4
