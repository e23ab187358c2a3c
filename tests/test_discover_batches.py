"""discover's maps in bigger batches: the selected law's simplifications fitted and refitted on the
held-out folds in one map (one task per signature) give the pool of a map of fits then a map of
refits, bit for bit; and a map hands its costliest tasks out first, its results in the items' order.
The twin: tests/test_discover_false.py's (SILO4 eq. 11, 8 speeds per direction, 2 s at 1 kHz)."""

from __future__ import annotations

import numpy as np

from gearspec.core import parallel
from gearspec.discover import forked
from gearspec.discover import pool as pool_mod
from gearspec.discover.law import Part, canonical, fit_law
from gearspec.discover.pool import _Pool, _signature

from test_discover_parallel import _law, _moves, _one, _state, fork_only, small, two  # noqa: F401


def test_a_map_hands_out_the_costliest_tasks_first_and_returns_in_order(monkeypatch):
    monkeypatch.setenv("GEARSPEC_THREADS", "1")      # a loop: the order the tasks run in is seen here
    ran = []

    def fn(x):
        ran.append(x)
        return 10 * x

    items = [3, 7, 1, 7, 5, 2]
    cost = {3: 1.0, 7: 4.0, 1: 0.5, 5: 4.0, 2: 3.0}
    assert forked.fits_map(fn, items, cost=cost.get) == [30, 70, 10, 70, 50, 20]
    assert ran == [7, 7, 5, 2, 3, 1]                # by cost, ties in the items' order
    ran.clear()
    assert forked.fits_map(fn, items) == [30, 70, 10, 70, 50, 20] and ran == items


def _pools(M, fold):
    """Two pools holding the same laws: one screened at its start values whose refined start comes
    later in the batch (the fit the pool keeps is not the batch's first), and one with a held-out error."""
    out = []
    for _ in range(2):
        p = _Pool(M, fold, "segment", 6, 4.0)
        sig = _one(p, _law(), "start", 0.5)
        _one(p, _law()[:3], "poor", 0.2, refine=False)
        p.screen()
        p.refit_holdout([sig])
        out.append(p)
    return out


@fork_only
def test_simplifications_fitted_and_refitted_in_one_map_are_two_maps_bit_for_bit(small, two, monkeypatch):  # noqa: F811 (pytest fixtures imported above)
    _, M, fold = small
    ref, par = _pools(M, fold)
    poor = _law()[:3]
    better = canonical(poor[:2] + (Part(poor[2].family, poor[2].freq, poor[2].split, 3.0),))
    # a law tried before, screened, without a held-out error: refitted though the batch does not fit it
    tried = canonical(_law()[1:])
    for p in (ref, par):
        _one(p, tried, "tried", 0.3)
        p.screen()
    moves = _moves(M) + [better, tried]
    items = [(m, f"move {k}", float(k)) for k, m in enumerate(moves)]

    def held(pool):
        return {_signature(m) for m in moves if _signature(m) in pool.fits}

    two.clear()
    want = ref.consider_all(items)
    ref.screen()
    ref.refit_holdout(held(ref))
    n_ref = list(two)
    two.clear()
    got = par.consider_all(items, holdout=True)
    assert par.prefit and all(s in par.fits for s in par.prefit)
    par.screen()
    here = []              # refits computed by refit_holdout itself (in this process or its map)
    real = pool_mod._full_holdout
    monkeypatch.setattr(pool_mod, "_full_holdout", lambda *a: here.append(1) or real(*a))
    n_maps = len(two)
    par.refit_holdout(held(par))
    assert not here and len(two) == n_maps, "refit_holdout refitted laws the batch had refitted"
    assert got == want and _state(par) == _state(ref)
    assert not par.prefit
    # one map where there were two; every law the batch holds now has its full held-out error
    assert len(n_ref) == 2 and len(two) == 1 and held(par) <= par.full
    # the poor start lost to its refined start, and the refit began at the refined optimum
    s = _signature(poor)
    assert par.fits[s][1] == "poor" and s in par.full
    assert np.sum(par.cands[s].fit.sse) <= np.sum(fit_law(M, poor, refine=False).sse)
    assert _signature(tried) in par.full


def test_segment_chunks_cut_the_samples_in_equal_shares(monkeypatch):
    from gearspec.discover.forked import segment_chunks

    monkeypatch.setenv("GEARSPEC_THREADS", "2")
    monkeypatch.setattr(forked, "MIN_CELLS", 0)
    if parallel.worker_count() < 2:
        return
    # 16 segments of 10 samples: 8 chunks (4 per worker) of 2 segments
    assert segment_chunks([10] * 16) == [(2 * i, 2 * i + 2) for i in range(8)]
    # one long segment: alone in its chunk, the others share the rest
    got = segment_chunks([100] + [10] * 10)
    assert got[0] == (0, 1) and got[-1][1] == 11 and all(a < z for a, z in got)
    assert [z for _, z in got[:-1]] == [a for a, _ in got[1:]]
    assert segment_chunks([5, 5]) == [(0, 1), (1, 2)]
    # a pass too small to pay for a map: one chunk
    monkeypatch.setattr(forked, "MIN_CELLS", 4_000_000)
    assert segment_chunks([10_000] * 40, 9) == [(0, 40)]          # 3.6 M cells: one chunk
    assert len(segment_chunks([10_000] * 40, 11)) == 8         # 4.4 M cells: split
    monkeypatch.setenv("GEARSPEC_THREADS", "1")
    assert segment_chunks([10] * 16) == [(0, 16)]


@fork_only
def test_passes_over_the_samples_in_chunks_of_segments_are_the_loop_bit_for_bit(small, two, monkeypatch):  # noqa: F811 (pytest fixtures imported above)
    from gearspec.discover.moments import moments
    from gearspec.discover.screen import joint_statistics, line_statistics

    from test_discover_false import F2, F3

    fd = small[0]
    monkeypatch.setattr(forked, "MIN_CELLS", 0)       # the small twin's passes cut in chunks too
    freqs = [F2, F3, 0.37]
    out = []
    for threads in ("1", "2"):
        monkeypatch.setenv("GEARSPEC_THREADS", threads)
        two.clear()
        M = moments(fd, freqs)
        ls = line_statistics(fd, freqs)
        js = joint_statistics(fd, freqs)
        out.append(([M.G, M.b, M.yy, M.noise, M.Gb, M.bb, M.yyb, M.P], ls, js))
        if threads == "2":
            assert len(two) == 3 and min(two) >= 4, two      # each pass in chunks of segments, in workers
    for a, b in zip(out[0], out[1]):
        for x, y in zip(a, b):
            assert np.array_equal(x, y)
    assert out[0][0][0].shape[0] == len(np.unique(fd.segment)) > 8


@fork_only
def test_the_papers_laws_are_fitted_in_this_process_sharing_the_samples_statistics(small, monkeypatch):  # noqa: F811 (pytest fixtures imported above)
    from gearspec.discover.explorer import discover

    monkeypatch.setenv("GEARSPEC_THREADS", "2")
    import copy

    fd = copy.copy(small[0])
    fd.cache = {}                   # its own cache, empty
    assert not any(k[0] == "segment_stats" for k in fd.cache if isinstance(k, tuple))
    res = discover(fd, gear="silo4-joint3", local_search=False, n_models=0, references=("stribeck", "silo4"))
    keys = [k for k in fd.cache if isinstance(k, tuple) and k[0] == "segment_stats"]
    # both laws' statistics were computed here (a worker's would be lost with it), eq. 11's with its lines
    assert len(keys) >= 2 and any(len(k[1]) >= 2 for k in keys)
    assert [r.name for r in res.references if r.model is not None] and len(res.references) == 2
