"""discover gives a law one held-out error (issue 13): its fold refits converge from the all-data
optimum, whatever start a caller had, and the acceptance test judges by the search's numbers; the
selection stops at a fixed point, not at a round limit.  The twin: SILO4 eq. 11 (Table 2) on 8
speeds per direction, 2 s each at 1 kHz, 0.1 mNm white noise, as in tests/test_discover_false.py.

Before this, ``scipy.optimize.least_squares``' gradient tolerance (absolute, 1e-8) stopped every
refinement after 2-4 evaluations on torques of mNm (a sum of squares ~1e-7): fold refits of the
same law from starts 0.3 apart in log parameters gave held-out rmse 6e-6 and 3e-5 relative apart,
and the search's and a fresh computation's held-out rmse of one law up to 0.9 % apart on this twin.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from gearspec.discover import accept, discover
from gearspec.discover.law import Part, canonical, cross_validate, fit_law, fold_ids
from gearspec.discover.moments import moments
from gearspec.discover.pool import _neighbours, _select, _signature, _inherit

from test_discover_false import DECOYS, F2, F3, TRUE_STRUCTURE, structure, twin

#: one law's held-out rmse from two starts, or from the search and from a fresh computation: the
#: refinements stop at least_squares' relative tolerances (1e-8 on the cost and the steps); measured
#: spreads are 3e-10 (starts) and 7e-10 (search vs fresh) -- 1e-8 leaves room, 6e-6 (the old
#: spread) does not pass
REL = 1e-8


def _truth_law():
    return canonical([Part("coulomb", split=True), Part("viscous", split=True), Part("stribeck_exp", param0=1.0),
                      Part("ripple_exp", 0, True, 1e-3), Part("ripple_exp", 1, True, 1e-3)])


@pytest.fixture(scope="module")
def small():
    fd = twin(0)
    M = moments(fd, [F2, F3])
    return M, fold_ids(M, "segment", 5)


def _rmse(M, sse):
    return math.sqrt(float(np.sum(sse)) / M.N)


def test_a_laws_held_out_error_does_not_depend_on_where_its_fold_refits_start(small):
    # the truth's structure (5 nonlinear parameters: a Stribeck velocity, four decays): the fold
    # refits started at the all-data optimum, 0.3 above and below it (log parameters) and at the
    # grid values (the all-data fit then found by a scan) end at the same held-out rmse
    M, fold = small
    parts = _truth_law()
    z = fit_law(M, parts).z
    got = [_rmse(M, cross_validate(M, parts, fold, z0=z0)[0]) for z0 in (z, z + 0.3, z - 0.3, None)]
    assert got[0] == pytest.approx(1.0e-4, rel=0.01)              # the twin's noise, 0.1 mNm
    for g in got[1:]:
        assert g == pytest.approx(got[0], rel=REL)


@pytest.fixture(scope="module")
def searched():
    """discover on the twin with its decoys (no references, no bootstrap), the acceptance test
    refused any held-out refit of its own: it must take every law's error from the search."""
    calls = []

    def refuse(*a, **k):
        calls.append(a[1])
        raise AssertionError("the acceptance test refitted a law on the folds itself")

    mp = pytest.MonkeyPatch()
    mp.setattr(accept, "cross_validate", refuse)
    try:
        res = discover(twin(0), gear="silo4-joint3", frequencies=DECOYS, references=(), n_models=0)
    finally:
        mp.undo()
    return res, calls


def test_the_acceptance_test_judges_by_the_searchs_held_out_errors(searched):
    res, calls = searched
    assert calls == []
    assert structure(res) == TRUE_STRUCTURE
    # it judged every term of the selected law in its last round (all pass: the truth's structure)
    last = res.acceptance[-len(res.best.parts):]
    assert len(last) == len(res.best.parts) and all(v["passed"] for v in last)
    # the report says how the search's selection ended
    from gearspec.report.discover import _rounds

    n = res.settings["selection_rounds"]
    assert res.settings["selection_settled"] and f"settled after {n} round(s)" in _rounds(res)


def test_every_candidates_held_out_error_is_what_a_fresh_computation_gives(searched):
    # what the acceptance test computes for a law the search does not hold (cross_validate from the
    # law's grid values: a scan, the all-data fit, the folds from its optimum) equals the error the
    # search reports for the laws it holds -- one law, one error
    res, _ = searched
    M = res.moments
    n = 0
    for c in res.candidates:
        if any(p.free for p in c.parts):
            sse, _ = cross_validate(M, c.parts, res.fold)
            assert _rmse(M, sse) == pytest.approx(c.rmse_holdout, rel=REL), c.terms(M.frequencies)
            n += 1
    assert n >= 30


def test_the_selection_stops_at_a_fixed_point():
    # the search's selection on the twin: the law it selects is what the rule selects over the laws
    # refitted, and each of that law's simplifications is among them (nothing left that could change
    # the choice); the rounds it took are reported
    fd = twin(0)
    from gearspec.discover.explorer import _prepare, _search

    run = _prepare(fd, 0.0, frequencies=DECOYS, gear="silo4-joint3", spectrum=None, library=None,
                   library_options=None, optimizer="stlsq", alpha=1e-4, thresholds=24, folds=5, by="segment",
                   n_models=0, max_parts=12, se_rule=4.0, local_search=True, inertia="auto", seed=0,
                   test_alpha=0.01, say=lambda t: None)
    pool, _, sel, _ = _search(run, lambda t: None)
    assert run.settings["selection_settled"] is True
    assert run.settings["selection_rounds"] == pool.rounds >= 2
    assert _select({s: pool.cands[s] for s in pool.full}, pool.M, pool.groups, pool.se_rule) == sel
    simple = {_signature(p) for p in _neighbours(_inherit(pool.cands[sel].fit), pool.M, pool.addable, adds=False)}
    assert simple and simple <= pool.full


def test_a_law_keeps_its_held_out_error_once_computed(small):
    # the pool holds one fit per law; a law refitted on the folds keeps that fit and its error even
    # when a later start of the same law fits the data better (here: its fit made to look worse) --
    # an error that changed between rounds of the selection could make it cycle
    from gearspec.discover.pool import _Pool

    M, fold = small
    pool = _Pool(M, fold, "segment", 12, 4.0)
    parts = _truth_law()
    sig = pool.consider(parts, "test", None)
    pool.screen()
    pool.refit_holdout([sig])
    before = pool.cands[sig].rmse_holdout
    pool.fits[sig][0].sse = pool.fits[sig][0].sse * 10          # any new fit now looks better in-sample
    again = canonical([Part(p.family, p.freq, p.split, None if p.param0 is None else 2 * p.param0) for p in parts])
    assert pool.consider(again, "test", None) == sig
    assert sig in pool.full and pool.cands[sig].rmse_holdout == before
