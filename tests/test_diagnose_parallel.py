"""A round's candidates in forked workers (:mod:`gearspec.diagnose.parallel_round`): the same
results, bit for bit, as the loop in one process, with what a candidate's run leaves behind carried
back (its cache for the round, the round's shared held-out residual, block ids no other block has).

Test data: the 20-plateau recording of ``tests/test_diagnose.py`` with a drift and an undeclared
cogging line (7 per motor revolution): round 1 holds periodic and grid candidates (Stribeck shapes,
speed laws, drift, ...), each drawing new blocks in every fold.
"""

from __future__ import annotations

import json
import pickle
from dataclasses import replace

import numpy as np
import pytest

import gearspec.diagnose as dg
from gearspec.core.parallel import worker_count
from gearspec.diagnose import design, loop, parallel_round
from gearspec.diagnose.candidates import PeriodicCandidate
from gearspec.diagnose.context import Round
from gearspec.diagnose.detectors import analyse, propose
from gearspec.diagnose.frommodel import state_from_model
from gearspec.simulate import effects as fx

from test_diagnose import GEAR, recording

pytestmark = pytest.mark.skipif(worker_count(2) < 2, reason="needs fork (Linux)")


def _recording():
    rec, _ = recording([fx.drift(coefficient=2e-4), fx.cogging(count=7, amplitude=3e-3)])
    return rec


def _round():
    """Round 1 of the loop on the test recording, and its candidates."""
    dd = dg.DiagnoseData.from_recording(_recording()).without_edges()
    fold = loop.folds_of(dd, 5)
    model = dg.baseline_model(dd, "silo4", gear=GEAR)
    rnd = Round(dd, loop._settle(state_from_model(model, dd), dd), fold)
    return rnd, propose(rnd, analyse(rnd), gate=0.01)


def _spy(monkeypatch) -> list:
    """Record the worker count of every map :func:`run_candidates` asks for."""
    asked = []
    real = parallel_round.forked_map

    def spy(fn, items, *, workers=None, **kw):
        asked.append(worker_count(workers))
        return real(fn, items, workers=workers, **kw)

    monkeypatch.setattr(parallel_round, "forked_map", spy)
    return asked


def _run(workers: int, monkeypatch):
    asked = _spy(monkeypatch)
    rnd, cands = _round()
    base = next(design._UID)       # ids below were drawn before the round (blocks the detectors made)
    runs = parallel_round.run_candidates(rnd, cands, loop._run_folds, workers=workers)
    assert asked == [workers]
    return rnd, cands, runs, base


def test_forked_candidates_give_the_loops_numbers_bit_for_bit(monkeypatch):
    rnd1, cands1, runs1, _ = _run(1, monkeypatch)
    rnd2, cands2, runs2, _ = _run(2, monkeypatch)
    kinds = {type(c).__name__ for c in cands2}
    assert len(cands2) >= 4 and "PeriodicCandidate" in kinds and "GridCandidate" in kinds
    for c1, c2, a, b in zip(cands1, cands2, runs1, runs2):
        assert c1.name == c2.name
        assert np.array_equal(a.p1, b.p1) and np.array_equal(a.r0, b.r0) and a.n_par == b.n_par
        assert (a.contribution is None) == (b.contribution is None)
        if a.contribution is not None:
            assert np.array_equal(a.contribution, b.contribution)
        for x, y in zip(a.proposals, b.proposals):
            assert (x is None) == (y is None)
            if x is not None:
                assert np.array_equal(x[0], y[0]) and x[1].describe == y[1].describe
                assert np.array_equal(x[1].columns(rnd1.dd), y[1].columns(rnd2.dd))
        e1 = loop._decide(rnd1, a, None, z_crit=3.0, min_gain=0.005)
        e2 = loop._decide(rnd2, b, None, z_crit=3.0, min_gain=0.005)
        assert (e1.z, e1.drop, e1.gain, e1.passed) == (e2.z, e2.drop, e2.gain, e2.passed)


def test_what_a_candidates_run_leaves_behind_comes_back_from_its_worker(monkeypatch):
    rnd, cands, runs, base = _run(2, monkeypatch)
    r0 = rnd.held_out_residual()
    # the round's one held-out residual, read-only, as the loop in one process gives it
    assert all(fr.r0 is r0 for fr in runs) and not r0.flags.writeable
    # block ids drawn in the round: every candidate's its own, none the round's, all below the counter
    ids = [{b.uid for item in fr.proposals if item is not None for b in item[1].add if b.uid > base}
           for fr in runs]
    assert sum(len(s) for s in ids) == len(set().union(*ids)) > len(cands)
    assert not set().union(*ids) & {b.uid for b in rnd.state.blocks}
    after = next(design._UID)
    assert max(set().union(*ids)) < after
    # a periodic candidate keeps its all-data proposal for the round: asked again when the loop
    # accepts it, it is the one its test measured (no new search, no new block id)
    periodic = [c for c in cands if isinstance(c, PeriodicCandidate)]
    assert periodic
    for c in periodic:
        assert c._cache.get("round") is rnd and c._cache.get("all") is not None
        assert c.propose(rnd, rnd.all_groups()) is c._cache["all"]
    assert next(design._UID) == after + 1
    # what comes back from a worker: the rows of its prediction and contribution, no cached columns
    rows = 8 * len(rnd.dd)
    for c, fr in zip(cands, runs):
        back = (replace(fr, r0=None), {k: v for k, v in c._cache.items() if k != "round"})
        assert len(pickle.dumps(back)) < (2 + (fr.contribution is not None)) * rows


def test_a_round_whose_design_exceeds_the_bound_runs_in_one_process(monkeypatch):
    rnd, cands = _round()
    X = rnd.X
    assert 8 * X.shape[0] * X.shape[1] == X.nbytes
    monkeypatch.setattr(parallel_round, "FORK_DESIGN_BYTES", X.nbytes)
    assert parallel_round.fork_allowed(rnd)
    monkeypatch.setattr(parallel_round, "FORK_DESIGN_BYTES", X.nbytes - 1)
    assert not parallel_round.fork_allowed(rnd)
    asked = _spy(monkeypatch)
    parallel_round.run_candidates(rnd, cands[:2], loop._run_folds, workers=2)
    assert asked == [1]
    # in one process the folds' training residuals (rows) are not computed ahead of the candidates
    rnd, cands = _round()
    assert any(isinstance(c, PeriodicCandidate) for c in cands)
    parallel_round.prefetch(rnd, cands, residuals=False)
    assert not [k for k in rnd._memo if k[0] == "r0"]
    parallel_round.prefetch(rnd, cands)
    assert len([k for k in rnd._memo if k[0] == "r0"]) == rnd.K


def test_diagnose_on_one_and_two_workers_writes_the_same_results(monkeypatch):
    rec = _recording()
    out = []
    for threads in ("1", "2"):
        monkeypatch.setenv("GEARSPEC_THREADS", threads)
        lines = []
        d = dg.diagnose(rec, law="silo4", gear=GEAR, progress=lines.append)
        out.append((json.dumps(d.to_dict(), sort_keys=True), d.final.coef, lines, d.trace.to_csv()))
    (j1, c1, l1, t1), (j2, c2, l2, t2) = out
    assert j1 == j2 and np.array_equal(c1, c2) and l1 == l2 and t1 == t2
    assert sum(e["accepted"] for e in json.loads(j1)["effects"]) == 2      # the drift and the line

