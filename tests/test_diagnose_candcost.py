"""What a round's candidates compute without a rows x columns copy of their new columns (issue 13,
helper "diagcand"): a proposal's blocks of columns put side by side a group's rows at a time for its
cross products against the round's design and for a fold's predictions.  Known answer: the same
computation on the blocks stacked over all rows, bit for bit (the same group arrays, the same BLAS
products).
"""

from __future__ import annotations

import numpy as np
import pytest

import gearspec.diagnose as dg
from gearspec.diagnose import candidates, loop
from gearspec.diagnose.candidates import GridCandidate, per_direction
from gearspec.diagnose.context import Round
from gearspec.diagnose.frommodel import state_from_model
from gearspec.model import FrictionModel
from gearspec.simulate import model_recording

FS = 500.0
SPEEDS = np.geomspace(0.5, 16, 6)
MODEL = FrictionModel("stribeck", {"tau_c": 0.05, "tau_s": 0.08, "v_s": 1.5, "viscous": 2e-3,
                                   "harmonics": [{"frequency": 0.75, "amplitude": 4e-3, "phase": 0.3, "decay": 0.0,
                                                  "law": "const"}]})
EXPONENTS = (0.5, 2.0)


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
