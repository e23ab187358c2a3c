"""What a round's candidates compute more cheaply (issue 13, helper "diagcand"), against the direct
computation each replaces: a grid candidate's cross products of all its values reduced in one pass
(equal to each value's own :meth:`Proposal.of` to round-off: the same products, BLAS adding them in
another order on a wider matrix), and the Gauss-Newton steps of :func:`~gearspec.diagnose.nonlinear.refine`
judged on the error their normal equations give (the pass over the rows only where that cannot
decide: the same state, bit for bit).
"""

from __future__ import annotations

import numpy as np
import pytest

import gearspec.diagnose as dg
from gearspec.diagnose import candidates, loop
from gearspec.diagnose.candidates import GridCandidate, Proposal, per_direction
from gearspec.diagnose.context import Round
from gearspec.diagnose.frommodel import state_from_model
from gearspec.model import FrictionModel
from gearspec.simulate import model_recording

FS = 500.0
SPEEDS = np.geomspace(0.5, 16, 6)
MODEL = FrictionModel("stribeck", {"tau_c": 0.05, "tau_s": 0.08, "v_s": 1.5, "viscous": 2e-3,
                                   "harmonics": [{"frequency": 0.75, "amplitude": 4e-3, "phase": 0.3, "decay": 0.0,
                                                  "law": "const"}]})
EXPONENTS = (0.25, 0.5, 0.75, 1.5, 2.0, 3.0)


@pytest.fixture(scope="module")
def rnd():
    speeds = [x for s in SPEEDS for x in (s, -s)]
    rec, _ = model_recording(MODEL, speeds, noise=1e-3, seed=2, duration=1.5, fs=FS)
    dd = dg.DiagnoseData.from_recording(rec).without_edges()
    return Round(dd, state_from_model(MODEL, dd), loop.folds_of(dd, 4))


def _grid(rnd):
    return GridCandidate("speed_law", "viscous power",
                         lambda x: (per_direction(rnd, "viscous_power", [("exponent", x)], "viscous_power",
                                                  "speed_law"), []), EXPONENTS)


def _spy(monkeypatch) -> list:
    widths = []
    real = candidates.cross_grams

    def spy(r, C):
        widths.append(sum(c.shape[1] for c in C) if isinstance(C, list) else C.shape[1])
        return real(r, C)

    monkeypatch.setattr(candidates, "cross_grams", spy)
    return widths


def test_grid_values_reduced_in_one_pass_equal_each_values_own(rnd, monkeypatch):
    widths = _spy(monkeypatch)
    cand = _grid(rnd)
    props = [cand._prop(rnd, i) for i in range(len(EXPONENTS))]
    # one pass for the six values (a column each: the model is symmetric), not six
    assert widths == [sum(p.ctc.shape[1] for p in props)] and widths[0] == len(EXPONENTS)
    for i, p in enumerate(props):
        add, drop = cand.make(EXPONENTS[i])
        ref = Proposal.of(rnd, add, drop)
        for a, b in ((p.xtc, ref.xtc), (p.ctc, ref.ctc), (p.cty, ref.cty)):
            assert a.shape == b.shape and a.flags.c_contiguous
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12 * np.abs(b).max())
    # every fold picks the value its own fit prefers, from the same training sums as before
    train = rnd.fold != 0
    best = cand.propose(rnd, train)
    rss = []
    for i in range(len(EXPONENTS)):
        add, drop = cand.make(EXPONENTS[i])
        ref = Proposal.of(rnd, add, drop)
        rss.append(candidates.train_fit(rnd, rnd.keep_mask(drop), ref, train)[1])
    assert best is props[int(np.argmin(rss))]


def test_grid_batch_bounded_by_bytes(rnd, monkeypatch):
    """Columns larger than the batch budget go one value at a time, as :meth:`Proposal.of` would
    (bit for bit)."""
    monkeypatch.setattr(candidates, "GRID_BATCH_BYTES", 12 * len(rnd.dd))    # 1.5 values' columns
    widths = _spy(monkeypatch)
    cand = _grid(rnd)
    props = [cand._prop(rnd, i) for i in range(len(EXPONENTS))]
    assert widths == [1] * len(EXPONENTS)
    for i, p in enumerate(props):
        add, drop = cand.make(EXPONENTS[i])
        ref = Proposal.of(rnd, add, drop)
        assert np.array_equal(p.xtc, ref.xtc) and np.array_equal(p.ctc, ref.ctc) and np.array_equal(p.cty, ref.cty)


def _two_blocks(rnd):
    cand = _grid(rnd)
    return [cand.make(0.5)[0][0].columns(rnd.dd), cand.make(2.0)[0][0].columns(rnd.dd) * 3.0]


def test_cross_grams_of_blocks_a_group_at_a_time_bit_for_bit(rnd, monkeypatch):
    """Blocks of new columns reduced a group's rows at a time: the numbers of their side-by-side
    columns, bit for bit, and no rows x columns copy of them."""
    blocks = _two_blocks(rnd)
    ref = candidates.cross_grams(rnd, np.column_stack(blocks))

    def no_stack(cols):
        raise AssertionError("the blocks were put side by side over all rows")

    monkeypatch.setattr(candidates, "side_by_side", no_stack)
    got = candidates.cross_grams(rnd, blocks)
    for a, b in zip(got, ref):
        assert a.shape == b.shape and np.array_equal(a, b)


def test_fold_predictions_from_blocks_bit_for_bit(rnd):
    from gearspec.diagnose.foldfits import predict_groups
    blocks = _two_blocks(rnd)
    dd = rnd.dd
    test = rnd.fold == 1
    beta, beta_c = rnd.beta(~test), np.array([0.7, -0.2])
    a, b = np.zeros(len(dd)), np.zeros(len(dd))
    predict_groups(a, test, dd, rnd.X, beta, blocks, beta_c)
    predict_groups(b, test, dd, rnd.X, beta, [np.column_stack(blocks)], beta_c)
    assert np.array_equal(a, b) and np.any(a != 0)
    rows = rnd.rows(test)
    np.testing.assert_allclose(a[rows], (np.asarray(rnd.X) @ beta + np.column_stack(blocks) @ beta_c)[rows],
                               rtol=1e-12, atol=1e-15)
    assert not a[~rows].any()
