"""The closed loop's designs held as their blocks' columns, never stacked (issue 13, "memory stays
bounded"): :class:`gearspec.diagnose.chunked.Design` (a round's design), and the refinement of the
nonlinear parameters (:func:`~gearspec.diagnose.nonlinear.refine`, ``polish``, their standard errors)
on normal equations reduced a chunk of rows at a time (:mod:`gearspec.diagnose.gram`).

Known answers: the products of the stacked design (numpy on the stacked array) to 1e-12 relative;
tracemalloc peaks on N and 4N rows whose growth per row stays below what one stacked copy of the
design would add.
"""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from gearspec.diagnose import budget, design, gram, loop
from gearspec.diagnose.chunked import Design
from gearspec.diagnose.context import Round, group_normals
from gearspec.diagnose.frommodel import state_from_model
from gearspec.diagnose.nonlinear import nonlinear_standard_errors, polish, refine

import test_diagnose_budget as tb


def _close(a, b, tol=1e-12):
    a, b = np.asarray(a, float), np.asarray(b, float)
    scale = max(float(np.max(np.abs(b))), 1e-300)
    return a.shape == b.shape and float(np.max(np.abs(a - b))) <= tol * scale


@pytest.fixture
def blocks():
    rng = np.random.default_rng(3)
    n = 3 * 16384 + 777                     # several chunks of gram.CHUNK_ROWS rows and a remainder
    return [rng.normal(size=(n, k)) * 10.0 ** rng.integers(-3, 4) for k in (3, 1, 4, 2, 5)], n


def test_a_designs_products_equal_the_stacked_designs(blocks):
    cols, n = blocks
    X = np.column_stack(cols)
    D = Design(cols, n)
    rng = np.random.default_rng(4)
    y, beta, C = rng.normal(size=n), rng.normal(size=X.shape[1]), rng.normal(size=(n, 2))
    assert D.shape == X.shape and D.nbytes == X.nbytes and np.array_equal(np.asarray(D), X)
    assert _close(D.T @ D, X.T @ X) and _close(D.T @ y, X.T @ y) and _close(D @ beta, X @ beta)
    a, z = 5000, 40000
    assert _close(D[a:z] @ beta, X[a:z] @ beta) and _close(D[a:z].T @ C[a:z], X[a:z].T @ C[a:z])
    assert np.array_equal(np.asarray(D[a:z]), X[a:z]) and np.array_equal(D[X[:, 0] > 0], X[X[:, 0] > 0])
    keep = np.ones(X.shape[1], bool)
    keep[[1, 3, 8, 10]] = False
    G, b = gram.normals(D.masked(keep), y, gram.every_row(n))
    assert _close(G, X[:, keep].T @ X[:, keep]) and _close(b, X[:, keep].T @ y)
    # the border of [X | C] and the residual sum of squares
    CX, CC, Cy = gram.bordered(cols, [C], y, gram.every_row(n))
    assert _close(CX, C.T @ X) and _close(CC, C.T @ C) and _close(Cy, C.T @ y)
    r = y - X @ beta
    assert gram.rss(cols, beta, y, gram.every_row(n)) == pytest.approx(float(r @ r), rel=1e-12)


@pytest.mark.parametrize("size", [40, 3000, 70000])
def test_group_normals_of_a_design_equal_those_of_the_stacked_design(blocks, size, monkeypatch):
    """Short groups (free motion: batched), plateau-sized groups (one product each) and groups longer
    than STACK_GROUP_CHUNKS chunks (summed a chunk at a time): the sums of the stacked array."""
    cols, n = blocks
    monkeypatch.setattr(gram, "CHUNK_ROWS", 8192)
    starts = np.arange(0, n, size)
    stops = np.minimum(starts + size, n)
    y = np.random.default_rng(5).normal(size=n)
    got = group_normals(Design(cols, n), y, starts, stops)
    want = group_normals(np.column_stack(cols), y, starts, stops)
    for a, b in ((got.G, want.G), (got.b, want.b), (got.yy, want.yy)):
        assert _close(a, b)
    assert np.array_equal(got.n, want.n)


def test_nonlinear_standard_errors_are_those_of_the_stacked_taylor_design():
    dd = tb._data(model=tb.MODEL)
    rnd = Round(dd, state_from_model(tb.MODEL, dd), loop.folds_of(dd, 4))
    X = np.asarray(rnd.X)                               # stacked: plain and Taylor columns of every block
    beta, *_ = np.linalg.lstsq(X, dd.y, rcond=None)
    r = dd.y - X @ beta
    cov = np.linalg.inv(X.T @ X) * float(r @ r) / (len(r) - X.shape[1])
    got = nonlinear_standard_errors(rnd.state, dd)
    assert got == rnd.fitted.nonlinear_se or all(
        v == pytest.approx(rnd.fitted.nonlinear_se[u][k], rel=1e-9) for u, d in got.items() for k, v in d.items())
    n_found = 0
    for blk, (a, z) in zip(rnd.state.blocks, rnd.taylor_spans()):
        for j, (key, se) in enumerate(got.get(blk.uid, {}).items()):
            k = a + len(blk.names) + j
            assert se == pytest.approx(np.sqrt(cov[k, k]), rel=1e-7), (blk.key, key)
            n_found += 1
    assert n_found == 2                                 # the Stribeck velocity and the line's decay


def _cached_bytes(dd) -> int:
    return sum(budget.nbytes(v) for v in dd.cache.get("columns", {}).values())


def _refine_peak(duration: float, monkeypatch, fn) -> tuple[float, int, int]:
    """tracemalloc peak of ``fn(state, dd)`` above the prepared round (whose blocks' columns the data's
    cache holds) less what the cache of columns grew by (the columns of the trials' blocks, kept for
    later calls: unbounded here, bounded in bytes on a long recording), the rows and the width of the
    round's design."""
    monkeypatch.setattr(gram, "CHUNK_ROWS", 1024)       # chunks far shorter than the data
    monkeypatch.setattr(budget, "CACHE_BYTES", 2 ** 40)
    monkeypatch.setattr(design, "_CACHE_COLUMNS", 10 ** 6)
    monkeypatch.setattr(design, "_CACHE_SIZE", 10 ** 6)
    dd = tb._data(duration=duration, model=tb.MODEL4)
    rnd = Round(dd, state_from_model(tb.MODEL4, dd), loop.folds_of(dd, 4))
    state, width = rnd.state, rnd.width
    del rnd
    held = _cached_bytes(dd)
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        tracemalloc.reset_peak()
        fn(state, dd)
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    return peak - (_cached_bytes(dd) - held), len(dd), width


@pytest.mark.parametrize("name", ["refine", "polish"])
def test_a_refinement_holds_no_stacked_design(name, monkeypatch):
    """On N and 4N rows a refinement's peak (less the columns it adds to the data's cache) grows per
    row by less than half its design would take stacked (16 columns, 128 bytes per row): the blocks'
    columns come from the data's cache and are reduced a chunk of rows at a time."""
    fn = {"refine": lambda st, dd: refine(st, dd, steps=2),
          "polish": lambda st, dd: polish(st, dd, sweeps=1)}[name]
    p1, n1, w = _refine_peak(1.0, monkeypatch, fn)
    p4, n4, w4 = _refine_peak(4.0, monkeypatch, fn)
    assert w == w4 == 16 and n4 > 3.5 * n1
    per_row = (p4 - p1) / (n4 - n1)
    print(name, per_row)
    assert per_row < 4 * w, f"{per_row:.0f} bytes per row; a stacked design of {w} columns takes {8 * w}"
