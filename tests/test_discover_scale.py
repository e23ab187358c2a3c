"""discover at scale (issue 13): the sparse-regression path and its bootstrap run on the normal
equations of the library's columns, folded a block of segments at a time
(:mod:`gearspec.discover.blocks`), and give what the dense pseudo-row design gives."""

from __future__ import annotations

import numpy as np
import pytest

from gearspec.discover import blocks
from gearspec.discover.blocks import SegmentDesign, running_qr
from gearspec.discover.library import default_library
from gearspec.discover.moments import moments
from gearspec.discover.search import Scaled, bootstrap_inclusion, path
from gearspec.fitdata import FitData
from gearspec.model import FrictionModel
from gearspec.simulate import model_recording

F2, F3 = 1 / (2 * np.pi * 14), 1 / (2 * np.pi)      # SILO4 worm-shaft and motor-shaft lines, cycles/rad


def _silo4_eq11() -> FrictionModel:
    """SILO4 eq. 11 with Table 2's direction-dependent values (the twin's truth, three shaft lines)."""
    from gearspec.simulate.silo4 import table2_model

    return table2_model()


@pytest.fixture(scope="module")
def twin():
    """8 motor speeds 1..600 rad/s per direction, 1.5 s each at 1 kHz, 0.1 mNm white noise: 24k
    samples in 16 segments, the library of both SILO4 lines (95 columns)."""
    speeds = [s * d for s in np.geomspace(1.0, 600, 8) for d in (1, -1)]
    rec, _ = model_recording(_silo4_eq11(), speeds, duration=1.5, fs=1000, noise=0.1e-3, gear="silo4-joint3",
                             seed=5, one_run_per_plateau=False)
    data = FitData.from_recording(rec)
    M = moments(data, [F2, F3], inertia=True)
    return M, default_library(M), data


def test_moments_reduced_a_chunk_of_segments_at_a_time_are_those_of_the_whole(twin, monkeypatch):
    """The sample bases are built for a chunk of whole segments at a time (memory bounded by the
    chunk, not rows x bases of the recording): the same per-segment arithmetic, so the same numbers
    exactly, whether the chunks hold one segment or all of them."""
    from gearspec.discover import moments as mod

    M, _, data = twin
    monkeypatch.setattr(mod, "_CHUNK_CELLS", 1)                 # one segment per chunk
    M1 = moments(data, [F2, F3], inertia=True)
    monkeypatch.setattr(mod, "_CHUNK_CELLS", 3 * 1500 * M.K)     # about 3 segments per chunk
    M3 = moments(data, [F2, F3], inertia=True)
    assert len(list(mod._chunks(M.n, M.K))) >= 5
    for k in ("G", "b", "yy", "n", "Gb", "bb", "yyb", "noise"):
        assert np.array_equal(getattr(M1, k), getattr(M, k)), k
        assert np.array_equal(getattr(M3, k), getattr(M, k)), k


def test_running_qr_gives_the_normal_equations_of_all_blocks():
    # an exact identity: R^T R = X^T X and R^T t = X^T y, to rounding (1e-12 of the entries' scale)
    rng = np.random.default_rng(1)
    X, y = rng.normal(size=(300, 20)) * np.geomspace(1, 1e4, 20), rng.normal(size=300)
    R, t = running_qr((X[a:a + 7], y[a:a + 7]) for a in range(0, 300, 7))   # blocks narrower than the columns
    G = X.T @ X
    scale = np.sqrt(np.outer(np.diag(G), np.diag(G)))
    assert R.shape == (20, 20)
    assert np.max(np.abs(R.T @ R - G) / scale) < 1e-12
    assert np.max(np.abs(R.T @ t - X.T @ y) / np.sqrt(np.diag(G) * (y @ y))) < 1e-12


def test_reduced_path_equals_the_dense_path(twin, monkeypatch):
    """The path on the folded normal equations (blocks of 3 segments) selects the same columns with
    the same coefficients as on the whole pseudo-row design.  Both are exact reductions of the same
    least-squares problems, so they agree to rounding: 1e-9 of the largest standardised coefficient
    leaves room for the conditioning of the near-collinear ripple shapes (condition ~1e5)."""
    M, lib, _ = twin
    design = SegmentDesign.of(lib, M)
    monkeypatch.setattr(blocks, "_BLOCK_CELLS", 3 * M.K * design.shape[1])
    ths = np.geomspace(1.0, 1e-5, 12)
    dense = path(Scaled(design.dense(), M.q.reshape(-1), M.N, float(np.sum(M.yy))), ths)
    reduced = path(Scaled(*design.reduce()), ths)
    assert design.shape[1] > 80 and len(dense) == len(reduced)
    n_selected = []
    for wd, wr in zip(dense, reduced):
        assert np.array_equal(wd != 0, wr != 0)
        assert np.max(np.abs(wd - wr)) <= 1e-9 * max(np.max(np.abs(wd)), 1e-300)
        n_selected.append(int(np.count_nonzero(wd)))
    assert n_selected[0] < n_selected[-1]          # the path goes from sparse to dense: not a trivial comparison


def test_reduced_bootstrap_equals_the_dense_bootstrap(twin):
    """A bootstrap replicate draws segments with replacement: the reduction weights a segment drawn c
    times by c, as the dense design repeats its rows c times; same seed, same inclusion fractions."""
    M, lib, _ = twin
    design = SegmentDesign.of(lib, M)
    X = design.dense()
    t = 1e-3
    a = bootstrap_inclusion(X, M, t, n_models=12, seed=3)
    b = bootstrap_inclusion(design, M, t, n_models=12, seed=3)
    assert np.array_equal(a, b)
    assert 0 < np.count_nonzero(a) < len(a)
    # the normal equations of one replicate: segments drawn twice or three times weigh as much
    pick = np.array([0, 0, 1, 2, 2, 2, 5, 7, 7, 11])
    R, t, N, yy = design.reduce(pick)
    Xp = X.reshape(M.S, M.K, -1)[pick].reshape(len(pick) * M.K, -1)
    G = Xp.T @ Xp
    scale = np.sqrt(np.outer(np.diag(G), np.diag(G)))
    assert np.max(np.abs(R.T @ R - G) / np.where(scale > 0, scale, 1.0)) < 1e-12
    assert N == float(np.sum(M.n[pick])) and yy == pytest.approx(float(np.sum(M.yy[pick])), rel=1e-15)


def test_held_columns_come_first_and_are_never_thresholded(twin):
    """A design with held-in columns: its reduction is that of ``[fixed | library]`` (checked against
    the dense stack to 1e-12), and the path keeps the held columns at every threshold."""
    M, lib, _ = twin
    fixed = SegmentDesign.of(lib, M).dense()[:, :3]
    design = SegmentDesign.of(lib, M, fixed)
    X = design.dense()
    assert np.array_equal(X[:, :3], fixed)
    R, t, N, yy = design.reduce()
    G = X.T @ X
    scale = np.sqrt(np.outer(np.diag(G), np.diag(G)))
    assert np.max(np.abs(R.T @ R - G) / scale) < 1e-12
    assert N == M.N and yy == pytest.approx(float(np.sum(M.yy)), rel=1e-15)
    free = np.arange(design.shape[1]) >= 3
    for w in path(Scaled(R, t, N, yy), [10.0, 1.0], free=free):     # thresholds above every coefficient
        assert np.all(w[:3] != 0) and not np.any(w[3:])


def test_screen_z_from_normal_equations_equals_z_statistic_on_the_rows():
    """The line screen's held-out Z, computed from each segment's normal equations of the columns it
    uses (cost segments x columns^2, whatever the number of lines), equals
    gearspec.core.crossval.z_statistic (one block per held-out group) on the rows themselves: an
    identity, to rounding (1e-10)."""
    from gearspec.core.crossval import z_statistic
    from gearspec.discover.screen import _held_out_z

    rng = np.random.default_rng(7)
    S, k = 30, 6
    n = rng.integers(20, 60, S)
    direction = np.where(np.arange(S) % 2 == 0, 1, -1)
    group = np.arange(S) // 3                        # runs of 3 segments held out together
    fold = group % 5
    X = [rng.normal(size=(m, k)) for m in n]
    y = [x @ np.array([0.3, -0.2, 0.1, 0.05, 0.0, 0.0]) + rng.normal(size=len(x)) for x in X]
    G = np.array([x.T @ x for x in X])
    g = np.array([x.T @ v for x, v in zip(X, y)])
    cols0, cols1 = [0, 1], [0, 1, 4, 5]
    z = _held_out_z(G, g, cols0, cols1, fold, direction, group)
    r0, dl = [], []
    for s in range(S):
        tr = (fold != fold[s]) & (direction == direction[s])
        b1 = np.linalg.lstsq(G[tr].sum(0)[np.ix_(cols1, cols1)], g[tr].sum(0)[cols1], rcond=None)[0]
        b0 = np.linalg.lstsq(G[tr].sum(0)[np.ix_(cols0, cols0)], g[tr].sum(0)[cols0], rcond=None)[0]
        f0, f1 = X[s][:, cols0] @ b0, X[s][:, cols1] @ b1
        r0.append(y[s] - f0)
        dl.append(f1 - f0)
    r0, dl = np.concatenate(r0), np.concatenate(dl)
    bounds = np.concatenate(([0], np.cumsum(n)))[::3]          # groups are consecutive segments
    z_rows = z_statistic(r0, dl, r0 - dl, bounds[:-1], bounds[1:], blocks=1)
    assert abs(z) > 1.0                               # a real change, not a comparison of zeros
    assert z == pytest.approx(z_rows, rel=1e-10)


def test_the_screen_rounds_stop_once_a_law_is_full(twin):
    """Both true lines of the twin pass the screen and enter its rounds, one per round; with
    ``max_lines=1`` (a law that holds one line) the rounds stop after the first: the line that
    entered first is in, the other keeps its verdict of round 1 and is not taken in."""
    from gearspec.discover.law import fold_ids
    from gearspec.discover.screen import screen_lines

    M, _, data = twin
    fold, groups = fold_ids(M, "segment", 5), M.groups("segment")
    full = screen_lines(data, [F3, F2], fold, groups, alpha=0.01)
    one = screen_lines(data, [F3, F2], fold, groups, alpha=0.01, max_lines=1)
    assert [r["inside"] for r in full] == [True, True] and all(r["passed"] for r in full)
    assert sorted(r["round"] for r in full) == [1, 2]
    first = [r["round"] for r in full].index(1)
    assert [r["inside"] for r in one] == [i == first for i in range(2)]
    assert [r["round"] for r in one] == [1, 1] and all(r["passed"] for r in one)
