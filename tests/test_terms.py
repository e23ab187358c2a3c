"""Friction term kinds (gearspec.terms) against hand-computed values: a newcomer's registered kind,
the reversal rule of the backlash term across runs, the amplitude laws of periodic terms."""

import json

import numpy as np
import pytest

from gearspec.errors import InputError
from gearspec.model import FrictionModel
from gearspec.terms import TERMS, amplitude_law, register_term


@pytest.fixture
def quadratic_drag_kind():
    """A kind registered the way a newcomer would (no describe: the default one-line description);
    removed again afterwards so that the registry stays as shipped."""
    kind = "test_quadratic_drag"
    assert kind not in TERMS

    @register_term(kind, params=("c", "v0"))
    def _drag(term, *, v, **_):
        return term["c"] * (np.abs(np.asarray(v, dtype=float)) - term.get("v0", 0.0)) ** 2

    yield kind
    TERMS.pop(kind, None)


def test_registered_kind_describes_evaluates_and_round_trips(quadratic_drag_kind, tmp_path):
    kind = quadratic_drag_kind
    tk = TERMS[kind]
    assert tk.params == ("c", "v0") and not tk.signed and tk.needs == ()
    # the default description: every declared parameter at 4 significant digits, absent ones as 0
    assert tk.describe({"kind": kind, "c": 0.0123456, "v0": 2.5}) == f"{kind}: c=0.01235, v0=2.5"
    assert tk.describe({"kind": kind, "c": 1.5}) == f"{kind}: c=1.5, v0=0"
    term = {"kind": kind, "c": 0.5, "v0": 1.0}
    m = FrictionModel("coulomb_viscous", {"tau_c": 1.0, "viscous": 0.0}).with_terms(term)
    # friction magnitude 1 + 0.5 (|v| - 1)^2, with the sign of v: exact in floating point
    v = np.array([3.0, -2.0, 0.0])
    got = m.evaluate(None, v)
    assert got.tolist() == [1.0 + 0.5 * 4.0, -(1.0 + 0.5 * 1.0), 0.0]
    # the printed table names it with its values, and a model read back from JSON evaluates identically
    assert f"{kind}: c=0.5, v0=1" in m.table()["parameter"].tolist()
    back = FrictionModel.from_json(m.to_json(tmp_path / "m.json"))
    assert json.loads((tmp_path / "m.json").read_text())["terms"] == [term]
    assert np.array_equal(back.evaluate(None, v), got)


def test_backlash_gap_restarts_at_each_reversal_and_not_across_runs():
    # run 0 goes 0 -> 2 and back to 0; run 1 starts again at 0.5 going forwards: a new run has no
    # reversal yet, so no gap, although its positions are within the gap of run 0's turning point
    theta = np.array([0.0, 1.0, 2.0, 1.0, 0.0, 0.5, 1.0, 2.5])
    v = np.array([1.0, 1.0, 1.0, -1.0, -1.0, 1.0, 1.0, 1.0])
    run = np.array([0, 0, 0, 0, 0, 1, 1, 1])
    m = FrictionModel("coulomb_viscous", {"tau_c": 5.0, "viscous": 0.0},
                      terms=[{"kind": "backlash", "scale": 2.0, "gap": 1.5}])
    # travel since the turning point at 2: 1 (< gap: 5 - 2, backwards), then 2 (>= gap: full 5)
    assert m.evaluate(theta, v, run=run).tolist() == [5.0, 5.0, 5.0, -3.0, -5.0, 5.0, 5.0, 5.0]
    # without runs it is one motion reversing at theta = 0: travel 0.5, 1.0 (gap), 2.5 (no gap)
    assert m.evaluate(theta, v).tolist() == [5.0, 5.0, 5.0, -3.0, -5.0, 3.0, 3.0, 5.0]


def test_backlash_model_at_one_standstill_sample():
    # a feedforward evaluates the model one sample at a time; at rest it gives only the signed terms
    m = FrictionModel("coulomb_viscous", {"tau_c": 5.0, "viscous": 0.1},
                      terms=[{"kind": "backlash", "scale": 2.0, "gap": 0.01}, {"kind": "offset", "offset": 0.25}])
    assert m.evaluate(0.3, 0.0, run=0).tolist() == [0.25]
    assert m.evaluate(0.3, 2.0, run=0).tolist() == [5.0 + 0.2 + 0.25]   # no reversal yet: no gap


def test_amplitude_laws_at_hand_computed_speeds():
    # g(|v|) of a periodic term, one value per speed (what plots and fits lay against speed);
    # decay 0.5 s/rad at |v| = 0 and 2 rad/s, closed forms to rounding (rel 1e-12)
    speed = np.array([0.0, 2.0])
    expect = {"exp": [1.0, np.exp(-1.0)], "const": [1.0, 1.0], "rational": [1.0, 0.5], "power": [1.0, 3 ** -0.5]}
    for law, values in expect.items():
        g = amplitude_law(law, speed, 0.5)
        assert g.shape == (2,) and g.dtype == float, law
        assert g.tolist() == pytest.approx(values, rel=1e-12), law
    with pytest.raises(InputError, match="unknown amplitude law 'cubic'"):
        amplitude_law("cubic", speed, 0.5)


def test_presliding_and_backlash_profiles_on_a_given_travel():
    # the closed loop passes the travel since reversal of the whole recording (travel=); the kind
    # then uses it as given: here the samples themselves never reverse (their own travel is inf)
    from gearspec.terms import evaluate_term
    travel = np.array([np.inf, 0.0, 0.25, 1.0, 3.0, np.inf])
    theta, v = np.zeros(6), np.ones(6)
    hys = {"kind": "hysteresis", "scale": 2.0, "length": 0.5}
    bkl = {"kind": "backlash", "scale": 2.0, "gap": 1.0}
    # -scale exp(-travel / length), nothing before the first reversal (rel 1e-15: numpy's exp vs math's)
    got, _ = evaluate_term(hys, theta=theta, v=v, travel=travel)
    assert got.tolist() == pytest.approx([0.0, -2.0, -2 * np.e ** -0.5, -2 * np.e ** -2, -2 * np.e ** -6, 0.0],
                                         rel=1e-15, abs=0.0)
    # -scale while travel < gap (a travel of exactly gap is past it), nothing before the first reversal
    got, _ = evaluate_term(bkl, theta=theta, v=v, travel=travel)
    assert got.tolist() == [0.0, -2.0, -2.0, 0.0, 0.0, 0.0]
    # the travel the kind computes itself (one motion reversing at theta = 2, then at 0) given
    # explicitly: the same profile to the bit
    theta = np.array([0.0, 1.0, 2.0, 1.0, 0.0, 0.5, 1.0, 2.5])
    v = np.array([1.0, 1.0, 1.0, -1.0, -1.0, 1.0, 1.0, 1.0])
    own = np.array([np.inf, np.inf, np.inf, 1.0, 2.0, 0.5, 1.0, 2.5])
    for term in (hys, {**bkl, "gap": 1.5}):
        recomputed, _ = evaluate_term(term, theta=theta, v=v)
        given, _ = evaluate_term(term, theta=theta, v=v, travel=own)
        assert np.array_equal(given, recomputed) and np.count_nonzero(given) >= 3, term
