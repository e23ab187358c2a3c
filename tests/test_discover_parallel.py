"""discover's law fits in worker processes (gearspec.core.parallel.forked_map): the pool's
bookkeeping is what one law after another gave, and a search on two processes ends with the pool,
the errors and the selection of the search on one, bit for bit (both run BLAS on one thread).
The twin: tests/test_discover_false.py's (SILO4 eq. 11, 8 speeds per direction, 2 s at 1 kHz)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gearspec.core import parallel
from gearspec.discover import accept
from gearspec.discover.law import Part, canonical, cross_validate, cross_validate_linear, fit_law, fold_ids
from gearspec.discover.moments import moments
from gearspec.discover.pool import _neighbours, _Pool, _signature
from gearspec.discover.search import Scaled, _fit, bootstrap_inclusion

from test_discover_false import DECOYS, F2, F3, twin

fork_only = pytest.mark.skipif(parallel.can_fork() is False, reason="no fork on this system")


@pytest.fixture(scope="module")
def small():
    fd = twin(0)
    M = moments(fd, [F2, F3])
    return fd, M, fold_ids(M, "segment", 5)


@pytest.fixture
def two(monkeypatch):
    """Two worker processes, and a count of the maps that used them."""
    monkeypatch.setenv("GEARSPEC_THREADS", "2")
    calls = []
    real = parallel.forked_map

    def counted(fn, items, **kw):
        items = list(items)
        if len(items) >= max(kw.get("min_items", 2), 2) and parallel.worker_count() >= 2:
            calls.append(len(items))
        return real(fn, items, **kw)

    monkeypatch.setattr(parallel, "forked_map", counted)
    return calls


def _law():
    return canonical([Part("coulomb", split=True), Part("viscous", split=True), Part("stribeck_exp", param0=1.0),
                      Part("ripple_exp", 0, True, 1e-3), Part("ripple_const", 1, True, None)])


def _one(pool: _Pool, parts, origin, thr, refine=True):
    """One law considered, as the pool did before its fits ran at once (0.10's _Pool.consider)."""
    parts = canonical(parts)
    if not parts or parts in pool.tried or len(parts) > pool.max_parts:
        return None
    pool.tried.add(parts)
    sig = _signature(parts)
    if sig in pool.full:
        return sig
    fit = fit_law(pool.M, parts, max_nfev=pool.screen_nfev, refine=refine)
    old = pool.fits.get(sig)
    if old is None or np.sum(fit.sse) < np.sum(old[0].sse) * (1 - 1e-9):
        pool.fits[sig] = (fit, origin if old is None else old[1], thr if old is None else old[2])
        pool.cands.pop(sig, None)
        pool.full.discard(sig)
    return sig


def _state(pool: _Pool) -> tuple:
    """Everything the pool holds, in its order: fits (signature, sse, z, w, origin, threshold),
    screened laws (held-out sse, rmse, predictions), the refitted and the tried laws."""
    fits = [(s, f.sse.tobytes(), f.z.tobytes(), f.w.tobytes(), o, t) for s, (f, o, t) in pool.fits.items()]
    cands = [(s, c.cv_sse.tobytes(), c.rmse_holdout, c.cv_pred.tobytes(), c.fit.z.tobytes())
             for s, c in pool.cands.items()]
    return fits, cands, sorted(pool.full), sorted(pool.tried, key=repr)


def _moves(M):
    """A batch with every case of consider: new laws, a repeat (tried), a law of the same signature
    from another start, a law held already with a held-out error, an empty and an over-long law."""
    base = _law()
    lib_parts = [Part("coulomb"), Part("viscous"), Part("stribeck_exp", param0=3.0), Part("ripple_exp", 0, False, 1e-3),
                 Part("ripple_const", 1, False, None)]
    moves = _neighbours(base, M, lib_parts)
    other = canonical([Part(p.family, p.freq, p.split, None if p.param0 is None else 2 * p.param0) for p in moves[3]])
    return [base] + moves[:12] + [moves[3], other, (), base + base] + moves[12:]


@fork_only
def test_consider_all_keeps_the_books_of_one_law_after_another(small, two):
    _, M, fold = small
    ref, par = _Pool(M, fold, "segment", 6, 4.0), _Pool(M, fold, "segment", 6, 4.0)
    poor = _law()[:3]                                             # screened from its start values
    better = canonical(poor[:2] + (Part(poor[2].family, poor[2].freq, poor[2].split, 3.0),))
    assert _signature(better) == _signature(poor) and better != poor
    for p in (ref, par):
        sig = _one(p, _law(), "start", 0.5)       # a law with a held-out error already: it keeps it
        _one(p, poor, "poor", 0.2, refine=False)
        p.screen()
        p.full.add(sig)
    screened = ref.cands[_signature(poor)]
    items = [(m, f"move {k}", float(k)) for k, m in enumerate(_moves(M) + [better])]
    want = [_one(ref, parts, o, t) for parts, o, t in items]
    got = par.consider_all(items)
    assert two, "the fits ran in one process"
    assert got == want and sum(g is None for g in got) >= 3
    # the refined start replaced the poor fit (keeping its origin) and dropped its screen
    assert ref.fits[_signature(poor)][1] == "poor" and _signature(poor) not in ref.cands
    assert np.sum(ref.fits[_signature(poor)][0].sse) < np.sum(screened.fit.sse)
    assert _state(par) == _state(ref)
    # a fit put in the pool otherwise is screened afresh, not with the screen of the fit it replaced
    s0 = next(s for s in got if s is not None and s not in par.full and any(p.free for p in par.fits[s][0].parts))
    for p in (ref, par):
        p.fits[s0] = (fit_law(M, p.fits[s0][0].parts, refine=False), *p.fits[s0][1:])
    ref.screen()
    par.screen()
    assert _state(par) == _state(ref)
    for s, c in par.cands.items():      # the screen: the linear held-out refits of each fit
        cv, pred = cross_validate_linear(M, par.fits[s][0], fold)
        assert np.array_equal(c.cv_sse, cv) and np.array_equal(c.cv_pred, pred)


@fork_only
def test_held_out_refits_at_once_are_each_laws_own_and_join_the_refitted_set(small, two):
    _, M, fold = small
    pool = _Pool(M, fold, "segment", 6, 4.0)
    sigs = [s for s in pool.consider_all([(m, "move", None) for m in _moves(M)]) if s is not None]
    pool.screen()
    # a few more refinement steps for laws screened at their start values: the refined fit, screened
    some = [s for s in sigs if any(p.free for p in pool.fits[s][0].parts)][:9]
    old = {s: pool.fits[s][0] for s in some}
    assert len(some) == 9
    pool.refine(some)
    for s in some:
        fit = fit_law(M, old[s].parts, z0=old[s].z, max_nfev=pool.screen_nfev)
        c = pool.cands[s]
        assert pool.fits[s][0] is c.fit and np.array_equal(c.fit.z, fit.z) and np.array_equal(c.fit.sse, fit.sse)
        assert np.array_equal(c.cv_sse, cross_validate_linear(M, fit, fold)[0])
    start = {s: pool.cands[s].fit.z.copy() for s in sigs}
    todo = sigs[:6]
    pool.refit_holdout(todo)
    assert two and set(todo) <= pool.full and not (set(sigs) - set(todo)) & pool.full
    n_free = 0
    for s in dict.fromkeys(todo):
        c = pool.cands[s]
        if any(p.free for p in c.parts):
            fit = fit_law(M, c.parts, z0=start[s])
            cv, pred = cross_validate(M, c.parts, fold, z0=fit.z)
            assert np.array_equal(c.fit.z, fit.z) and np.array_equal(c.cv_sse, cv) and np.array_equal(c.cv_pred, pred)
            assert c.rmse_holdout == math.sqrt(float(np.sum(cv)) / M.N)
            n_free += 1
    assert n_free >= 3
    # the acceptance test's laws: new ones fitted from their grid values, in the order asked, once
    laws = [_law()[:3], _law()[1:], _law()[:3], _law()[:2] + _law()[3:], _law()[2:4]]
    n_before, had = len(pool.fits), set(pool.full)
    pool.holdout_all(laws)
    new = list(pool.fits)[n_before:]
    assert new == list(dict.fromkeys(_signature(p) for p in laws if _signature(p) not in set(sigs)))
    n_new = 0
    for parts in laws:
        s = _signature(parts)
        assert s in pool.full
        if s not in had:
            assert canonical(parts) in pool.tried
            fit = fit_law(M, canonical(parts))
            cv, pred = cross_validate(M, canonical(parts), fold, z0=fit.z)
            assert np.array_equal(pool.holdout(parts)[0], cv) and np.array_equal(pool.holdout(parts)[1], pred)
            n_new += 1
    assert n_new >= 3


@fork_only
def test_the_acceptance_test_asks_the_pool_in_the_same_order_with_its_laws_computed_first(small, two):
    _, M, fold = small
    groups = M.groups("segment")
    out = []
    for prefetch in (False, True):
        pool = _Pool(M, fold, "segment", 12, 4.0)
        final, verdicts = accept.backward(M, fold, groups, _law(), alpha=0.01, min_gain=0.005, n_candidates=8,
                                          holdout=pool.holdout, prefetch=pool.holdout_all if prefetch else None)
        out.append((final, [v.to_dict() for v in verdicts], _state(pool)))
    assert two and len(out[1][2][0]) >= 5
    assert out[0] == out[1]


@fork_only
def test_the_bootstrap_at_once_draws_and_counts_the_replicates_in_turn(small, two):
    from gearspec.discover.blocks import SegmentDesign
    from gearspec.discover.library import default_library

    _, M, _ = small
    lib = default_library(M)
    X = SegmentDesign.of(lib, M)
    got = bootstrap_inclusion(X, M, 0.01, n_models=12, seed=3)
    assert two == [12]
    # the loop it replaces
    rng = np.random.default_rng(3)
    g = M.groups("segment")
    members = [np.flatnonzero(g == u) for u in np.unique(g)]
    hits = np.zeros(X.shape[1])
    for _ in range(12):
        pick = np.concatenate([members[i] for i in rng.integers(0, len(members), len(members))])
        hits += _fit("stlsq", 0.01, 1e-4, Scaled(*X.reduce(pick))) != 0
    assert np.array_equal(got, hits / 12) and 0 < np.sum(got) < X.shape[1]


@fork_only
def test_a_search_on_two_processes_is_the_search_on_one(small, monkeypatch):
    from gearspec.discover.explorer import _prepare, _search

    fd = small[0]
    res = []
    for threads in ("1", "2"):
        monkeypatch.setenv("GEARSPEC_THREADS", threads)
        lines = []
        run = _prepare(fd, 0.0, frequencies=DECOYS, gear="silo4-joint3", spectrum=None, library=None,
                       library_options=None, optimizer="stlsq", alpha=1e-4, thresholds=24, folds=5, by="segment",
                       n_models=0, max_parts=12, se_rule=4.0, local_search=True, inertia="auto", seed=0,
                       test_alpha=0.01, say=lines.append)
        pool, pool1, sel, _ = _search(run, lines.append)
        res.append((sel, _state(pool), _state(pool1), lines, run.settings["selection_rounds"]))
    assert res[0][1][2], "no law was refitted on the folds"
    assert res[0] == res[1]
