"""Model files written by an earlier gearspec load and evaluate as they did (CONTRACTS.md section 4).

``tests/data/models_0.4.1.json`` was written by gearspec 0.4.1 (before the term registry and the
estimation core): four models as ``gearspec fit --json`` writes them (a SILO4 joint fit whose lines
carry ``speed_range``, a Stribeck law, a Lola (11) law, and a Coulomb + viscous model with one term
of every kind, per direction and in both), a grid of inputs (a reversing motion over two runs with
load, temperature, time and acceleration), and what 0.4.1 evaluated there. The known answer is
0.4.1's own output: a refactor may change how a model is held, never what a file means.
"""
import json
from pathlib import Path

import numpy as np
import pytest

from gearspec.model import FrictionModel

GOLDEN = json.loads((Path(__file__).parent / "data" / "models_0.4.1.json").read_text())
INPUTS = {k: np.asarray(v) for k, v in GOLDEN["inputs"].items()}


@pytest.mark.parametrize("name", sorted(GOLDEN["models"]))
def test_a_041_model_file_evaluates_as_041_did(name):
    entry = GOLDEN["models"][name]
    model = FrictionModel.from_dict(entry["model"])
    kw = {k: INPUTS[k] for k in ("load", "temperature", "t", "acc", "run")}
    got = model.evaluate(INPUTS["theta"], INPUTS["v"], **kw)
    want = np.asarray(entry["evaluate"])
    # the same arithmetic up to the order of a few operations: agreement to rounding (1e-12 of the
    # largest torque), far below any noise a measured torque carries
    assert np.all(np.isfinite(got))
    assert np.max(np.abs(got - want)) <= 1e-12 * np.max(np.abs(want))


@pytest.mark.parametrize("name", sorted(GOLDEN["models"]))
def test_a_041_model_file_is_written_back_unchanged(name):
    d = GOLDEN["models"][name]["model"]
    assert json.loads(json.dumps(FrictionModel.from_dict(d).to_dict())) == d
