"""The typed model (issue 11 item 4): a FrictionModel holds one :class:`Direction` per direction of
motion and :class:`Harmonic` objects, which the engines write through their attributes; the
JSON form (CONTRACTS.md section 4) is what it always was."""
import json
import math

import numpy as np
import pytest

from gearspec import FitData, fit
from gearspec.jsonsafe import dumps
from gearspec.model import Direction, FrictionModel, Harmonic
from gearspec.simulate.synthetic import model_recording

H = {"frequency": 0.5, "amplitude": 0.01, "amplitude_se": 1e-4, "decay": 0.002, "phase": 1.0,
     "label": "stage", "law": "rational", "speed_range": [1.0, 20.0], "segments": 7, "note": "kept"}


def test_a_harmonic_reads_typed_and_as_its_json():
    h = Harmonic.of(H)
    assert (h.frequency, h.amplitude, h.decay, h.phase, h.label, h.law, h.segments) == \
        (0.5, 0.01, 0.002, 1.0, "stage", "rational", 7)
    assert h.se == {"amplitude": 1e-4} and h.extra == {"note": "kept"}
    assert h["amplitude_se"] == 1e-4 and h.get("load_coefficient") is None and "decay_se" not in h
    assert h.to_dict() == H
    # the amplitude law of a harmonic that names none is exp (SILO4 eq. 8), and none is written
    bare = Harmonic.of({"frequency": 1.0, "amplitude": 0.1})
    assert bare.amplitude_law == "exp" and bare.to_dict() == {"frequency": 1.0, "amplitude": 0.1, "decay": 0.0,
                                                               "phase": 0.0}
    # a key written as null stays null, and an unknown key (with or without _se) is kept: a file
    # read and written back is unchanged
    assert Harmonic.of({**H, "label": None}).to_dict() == {**H, "label": None}
    assert Harmonic.of({**H, "width_se": 0.1}).to_dict() == {**H, "width_se": 0.1}


def test_records_are_changed_through_their_attributes_only():
    m = FrictionModel("coulomb_viscous", {"tau_c": 0.3, "viscous": 0.002, "harmonics": [H]})
    p = m.params("positive")
    assert isinstance(p, Direction) and isinstance(p.harmonics[0], Harmonic)
    with pytest.raises(TypeError):
        p["tau_c"] = 1.0
    with pytest.raises(TypeError):
        p.harmonics[0]["amplitude"] = 1.0
    p.set("tau_c", 0.5, 0.01)
    p.harmonics[0].amplitude = 0.02
    d = m.to_dict()["directions"]["positive"]
    assert d["tau_c"] == 0.5 and d["tau_c_se"] == 0.01 and d["harmonics"][0]["amplitude"] == 0.02
    # the negative direction was a copy, not the same object
    assert m.params("negative").values["tau_c"] == 0.3 and m.harmonics("negative")[0].amplitude == 0.01
    assert not m.symmetric


def test_a_typed_harmonic_evaluates_as_the_papers_law():
    # tau = sign(v) (tau_c + A / (1 + (decay |v|)^2) sin(2 pi f theta + phi)) with the rational law,
    # |v| held in the speed range the law was fitted on
    m = FrictionModel("coulomb_viscous", {"tau_c": 0.3, "viscous": 0.0, "harmonics": [H]})
    theta, v = np.array([0.1, 0.2, 0.3]), np.array([5.0, 50.0, -0.5])
    speed = np.clip(np.abs(v), 1.0, 20.0)
    ripple = 0.01 / (1 + (0.002 * speed) ** 2) * np.sin(2 * math.pi * 0.5 * theta + 1.0)
    np.testing.assert_allclose(m.evaluate(theta, v), np.sign(v) * (0.3 + ripple), rtol=1e-14)


def test_engines_write_typed_parameters_with_their_errors():
    truth = FrictionModel("coulomb_viscous", {"tau_c": 0.3, "viscous": 0.002},
                          {"tau_c": 0.25, "viscous": 0.003})
    speeds = [2.0, 4.0, 8.0, 12.0]
    rec, _ = model_recording(truth, speeds + [-s for s in speeds], duration=1.0, fs=500, noise=1e-3, seed=3)
    m = fit(FitData.from_recording(rec), "coulomb_viscous")
    for d in ("positive", "negative"):
        p, t = m.params(d), truth.params(d)
        assert set(p.values) == {"tau_c", "viscous"} and set(p.se) == {"tau_c", "viscous"}
        # the truth within 5 standard errors (white noise of 1 mNm over 2000 samples a direction)
        for k in ("tau_c", "viscous"):
            assert abs(p.values[k] - t.values[k]) < 5 * p.se[k], (d, k)
        assert p.n_segments == 4 and p.n_samples > 0
    # JSON through the one sanitiser: typed records become their JSON form
    back = FrictionModel.from_dict(json.loads(dumps(m.to_dict())))
    assert back.to_dict() == json.loads(dumps(m.to_dict()))
    assert json.loads(dumps({"p": m.params("positive")}))["p"]["tau_c"] == m.params("positive").values["tau_c"]
