"""The joint fit as an estimator (scikit-learn manner): settings in ``__init__``, learned values with
a trailing underscore, ``get_params`` / ``set_params`` / ``clone``, and ``refit`` rebuilding the
estimator from the settings a model records in ``meta["fit"]`` (CONTRACTS.md)."""

import pytest

from gearspec import identify
from gearspec.errors import InputError
from gearspec.fitdata import FitData
from gearspec.identify import JointFit, clone, refit
from gearspec.model import FrictionModel
from gearspec.simulate import model_recording

LINE = {"frequency": 0.8, "label": "stage A"}     # cycles/rad
TRUTH = {"tau_c": 0.1, "tau_s": 0.15, "v_s": 2.0, "viscous": 5e-4,
         "harmonics": [{**LINE, "amplitude": 0.01, "decay": 0.01, "phase": 0.3}]}
SETTINGS = dict(harmonics=[LINE], weights="uniform", min_cycles=2.0, holdout=None, name="twin fit")


@pytest.fixture(scope="module")
def data():
    """A twin with known friction: 6 plateau speeds per direction (rad/s), 0.1 % torque noise."""
    speeds = [0.5, 1.0, 2.0, 5.0, 15.0, 60.0]
    sp = speeds + [-s for s in speeds]
    dur = [max(1.5, 3 / (0.8 * abs(v))) for v in sp]        # s: three cycles of the line at least
    rec, _ = model_recording(FrictionModel("silo4", TRUTH, TRUTH), sp, duration=dur, fs=500, ramp=0.1,
                             noise=1e-4, seed=3)
    return FitData.from_recording(rec)


def test_get_params_round_trip_and_set_params():
    est = JointFit("stribeck", **SETTINGS)
    p = est.get_params()
    assert list(p) == ["law", "harmonics", "gear", "weights", "se", "bootstrap", "min_cycles", "holdout", "folds",
                       "init", "seed", "name", "check", "inertia"]
    assert p["law"] == "stribeck" and p["weights"] == "uniform" and p["min_cycles"] == 2.0 and p["se"] == "covariance"
    assert JointFit(**p).get_params() == p
    assert est.set_params(folds=3, seed=7) is est
    assert est.get_params() == {**p, "folds": 3, "seed": 7}


def test_clone_is_unfitted_with_equal_params(data):
    est = JointFit("silo4", **SETTINGS).fit(data)
    assert isinstance(est.model_, FrictionModel) and est.harmonics_ == [LINE]
    c = clone(est)
    assert c is not est and not hasattr(c, "model_") and not hasattr(c, "harmonics_")
    assert c.get_params() == est.get_params()
    c.harmonics[0]["frequency"] = 9.0                # the clone's settings are copies
    assert est.harmonics[0]["frequency"] == 0.8


def test_fit_recovers_the_truth_and_records_its_settings(data):
    m = identify.fit(data, "silo4", **SETTINGS)
    for d in ("positive", "negative"):
        p = m.params(d)
        for k in ("tau_c", "tau_s", "viscous"):
            assert p[k] == pytest.approx(TRUTH[k], rel=0.02), (d, k)
        assert p["v_s"] == pytest.approx(TRUTH["v_s"], rel=0.05)
        assert p["harmonics"][0]["amplitude"] == pytest.approx(0.01, rel=0.03)
    assert m.meta["fit"] == {"law": "silo4", "harmonics": [LINE], "weights": "uniform", "se": "covariance",
                             "min_cycles": 2.0, "bootstrap": 200, "inertia": "auto"}
    rebuilt = JointFit.from_model(m).get_params()
    assert rebuilt == {**JointFit().get_params(), "law": "silo4", "harmonics": [LINE], "weights": "uniform",
                       "min_cycles": 2.0, "name": "twin fit"}


def _same(a: FrictionModel, b: FrictionModel):
    for d in ("positive", "negative"):
        pa, pb = a.params(d), b.params(d)
        for k in ("tau_c", "tau_s", "v_s", "viscous", "tau_c_se", "v_s_se"):
            assert pa[k] == pytest.approx(pb[k], rel=1e-12, abs=0), (d, k)
        for ha, hb in zip(pa["harmonics"], pb["harmonics"]):
            for k in ("amplitude", "decay", "phase", "amplitude_se"):
                assert ha[k] == pytest.approx(hb[k], rel=1e-12, abs=0), (d, k)
    assert a.rmse == pytest.approx(b.rmse, rel=1e-12) and a.name == b.name


def test_refit_equals_a_fresh_fit_with_the_same_settings(data):
    m = identify.fit(data, "silo4", **SETTINGS, se="bootstrap", bootstrap=20)
    part = data.subset(data.segment != data.segment[0])
    fresh = identify.fit(part, "silo4", **SETTINGS, check=False)
    _same(refit(m, part), fresh)
    # an override is a setting changed on the rebuilt estimator
    _same(refit(m, part, weights="segment"), identify.fit(part, "silo4", **{**SETTINGS, "weights": "segment"}))


def test_unknown_setting_and_missing_settings_are_one_sentence_errors(data):
    with pytest.raises(InputError, match=r"^JointFit has no setting 'lines' \(settings: law, harmonics, .*check, inertia\)$"):
        JointFit().set_params(lines=[1.0])
    m = identify.fit(data, "stribeck", holdout=None)
    with pytest.raises(InputError, match="no setting 'lines'"):
        refit(m, data, lines=[1.0])
    with pytest.raises(InputError, match="carries no fit settings"):
        refit(FrictionModel("stribeck", {"tau_c": 0.1, "tau_s": 0.2, "v_s": 1.0, "viscous": 0.0}), data)
