"""What keeps the closed loop's memory bounded in rows and candidates (issue 13, "Scale"; helper
"diagfast"): normal equations of a design given as column blocks, summed a bounded number of rows at
a time (never stacked: rows x terms), design columns cached by the block's parameters (a copy with
refitted coefficients reuses them), and no candidate keeping the design of its extended round.
Known answers: the stacked computation (equal to round-off: the sums only change order, 1e-12
relative on well-conditioned random columns), identity of cached arrays, and what the candidate
holds after its held-out test.  Timings of the default twin are a benchmark, not a test.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

import gearspec.diagnose as dg
from gearspec.diagnose import design, gram, loop
from gearspec.diagnose.candidates import FixedCandidate, per_direction
from gearspec.diagnose.context import Round
from gearspec.diagnose.frommodel import state_from_model
from gearspec.model import FrictionModel
from gearspec.simulate import model_recording

MODEL = FrictionModel("stribeck", {"tau_c": 0.05, "tau_s": 0.08, "v_s": 1.5, "viscous": 2e-3})


def _plateau_data(n_speeds=4, fs=500.0, duration=1.0):
    speeds = [x for s in np.geomspace(0.5, 16, n_speeds) for x in (s, -s)]
    rec, _ = model_recording(MODEL, speeds, noise=1e-3, seed=0, duration=duration, fs=fs)
    return dg.DiagnoseData.from_recording(rec)


def test_spans_cover_the_selected_groups_in_bounded_chunks():
    sizes = np.array([30, 70, 20, 150, 10, 40])
    stops = np.cumsum(sizes)
    starts = stops - sizes
    mask = np.array([True, True, False, True, True, False])
    got = gram.spans(starts, stops, mask, chunk=64)
    rows = np.concatenate([np.arange(a, z) for a, z in got])
    want = np.concatenate([np.arange(a, z) for a, z, m in zip(starts, stops, mask) if m])
    assert np.array_equal(rows, want)                       # every selected row once, in order
    assert max(z - a for a, z in got) <= 64                  # no chunk longer than asked (150 split)
    # groups 0 and 1 (100 rows) cannot share a 64-row chunk; group 3 (150) split; group 4 joins
    # the tail of group 3 (22 + 10 rows)
    assert got == [(0, 30), (30, 94), (94, 100), (120, 184), (184, 248), (248, 280)]


def test_normals_and_prediction_equal_the_stacked_design():
    rng = np.random.default_rng(3)
    sizes = [300, 50, 700, 120, 400]
    stops = np.cumsum(sizes)
    starts = stops - np.asarray(sizes)
    n = stops[-1]
    A, B, C = rng.normal(size=(n, 5)), rng.normal(size=(n, 2)), rng.normal(size=(n, 3))
    keep = np.array([True, False, True, True, False])
    y = rng.normal(size=n)
    cols = [(A, keep), B, C]
    X = np.column_stack([A[:, keep], B, C])
    train = np.array([True, False, True, True, False])
    rows = np.concatenate([np.arange(a, z) for a, z, m in zip(starts, stops, train) if m])
    G, b = gram.normals(cols, y, gram.spans(starts, stops, train, chunk=256))
    assert gram.width(cols) == X.shape[1] == 8
    # 1e-12: the same products summed in another order (random unit-scale columns, condition ~ 1)
    assert np.allclose(G, X[rows].T @ X[rows], rtol=1e-12, atol=1e-12)
    assert np.allclose(b, X[rows].T @ y[rows], rtol=1e-12, atol=1e-12)
    beta = rng.normal(size=8)
    out = np.full(n, np.nan)
    gram.predict(cols, beta, gram.spans(starts, stops, ~train, chunk=256), out=out)
    test_rows = np.isnan(out)
    assert np.array_equal(test_rows[rows], np.ones(len(rows), bool))     # training rows untouched
    assert np.allclose(out[~test_rows], (X @ beta)[~test_rows], rtol=1e-12, atol=1e-12)
    whole = gram.predict(cols, beta, gram.spans(starts, stops, chunk=256), n=n)   # every row, fresh array
    assert np.allclose(whole, X @ beta, rtol=1e-12, atol=1e-12)


def test_a_refitted_copy_of_a_block_reuses_its_columns_a_changed_parameter_does_not():
    dd = _plateau_data()
    law = ((1, "exp"), (-1, "exp"))
    blk = design.HarmonicBlock(key="l", frequency=0.4, dirs=(1, -1), law=law, decay=((1, 0.01), (-1, 0.01)))
    cols = blk.columns(dd)
    refit = replace(blk, coef=(1e-3, 2e-3, -1e-3, 5e-4))      # what State.refreshed makes after every fit
    assert refit.columns(dd) is cols                            # the plain columns do not depend on coef
    moved = design.with_parameter(blk, ("decay", 1), 0.05)
    other = moved.columns(dd)
    assert other is not cols and not np.allclose(other, cols)   # a nonlinear parameter changes them
    assert np.array_equal(other[:, 2:], cols[:, 2:])            # ... in its own direction only
    # the Taylor columns do depend on the coefficients
    t1 = refit.columns(dd, taylor=True)
    t2 = replace(blk, coef=(2e-3, 2e-3, -1e-3, 5e-4)).columns(dd, taylor=True)
    assert t1 is not t2 and not np.allclose(t1[:, 4:], t2[:, 4:])


def test_a_candidate_does_not_keep_the_design_of_its_extended_round():
    """A candidate whose test refines the model's nonlinear parameters (every kind but lines) runs
    on an extended round with its own rows x terms design; kept in the candidate's memo for each of
    a round's candidates, that was 12 designs of the default twin (3.8 GB)."""
    dd = _plateau_data()
    rnd = Round(dd, state_from_model(MODEL, dd), loop.folds_of(dd, 4))
    cand = FixedCandidate("other", "offset", per_direction(rnd, "offset", key="offset"))
    fr = loop._run_folds(rnd, cand)
    assert any(p is not None for p in fr.proposals)
    assert cand._cache.get("round") in (None, rnd)
    # and the test's numbers do not depend on the memo: run again, same held-out predictions
    again = loop._run_folds(rnd, cand)
    assert np.array_equal(again.p1, fr.p1) and np.array_equal(again.r0, fr.r0)
