"""FrictionModel and friction terms against hand-computed values of the papers' laws."""

import json
import math

import numpy as np
import pytest

from gearspec import laws
from gearspec.errors import InputError
from gearspec.model import RPM, FrictionModel
from gearspec.terms import evaluate_term

POS = {"tau_c": 7.106e-3, "tau_s": 8.58e-3, "v_s": 28.18 * RPM, "viscous": 0.0134e-3 / RPM,
       "harmonics": [{"frequency": 1 / (2 * math.pi * 14), "amplitude": 0.576e-3, "decay": 1.27e-4 * 60 / (2 * math.pi),
                      "phase": math.pi / 2, "label": "worm"}]}
NEG = {"tau_c": 7.909e-3, "tau_s": 9.41e-3, "v_s": 26.58 * RPM, "viscous": 0.0138e-3 / RPM,
       "harmonics": [{"frequency": 1 / (2 * math.pi * 14), "amplitude": 0.526e-3, "decay": 1.12e-4 * 60 / (2 * math.pi),
                      "phase": math.pi / 2, "label": "worm"}]}


def test_silo4_model_is_eq11_per_direction():
    m = FrictionModel("silo4", POS, NEG)
    theta = np.array([0.3, 10.0, 100.0])
    v = np.array([50.0, -50.0, 3.0])
    got = m.evaluate(theta, v)
    for i in range(3):
        p = POS if v[i] > 0 else NEG
        h = p["harmonics"][0]
        mag = (p["tau_c"] + (p["tau_s"] - p["tau_c"]) * math.exp(-abs(v[i]) / p["v_s"]) + p["viscous"] * abs(v[i])
               + h["amplitude"] * math.exp(-h["decay"] * abs(v[i]))
               * math.sin(2 * math.pi * h["frequency"] * theta[i] + h["phase"]))
        assert got[i] == pytest.approx(math.copysign(mag, v[i]), rel=1e-12)
    # the same through laws.silo4_full (one source of truth)
    assert np.allclose(got, laws.silo4_full(theta, v, POS, NEG), rtol=1e-12)


def test_table_in_paper_units():
    t = FrictionModel("silo4", POS, NEG).table().set_index("parameter")
    assert t.loc["tau_s", "positive_paper"] == pytest.approx(8.58)
    assert t.loc["v_s", "negative_paper"] == pytest.approx(26.58)
    assert t.loc["viscous", "positive_paper"] == pytest.approx(0.0134)
    assert t.loc["worm decay", "negative_paper"] == pytest.approx(1.12e-4)
    assert t.loc["worm amplitude", "positive_paper"] == pytest.approx(0.576)
    # the units printed beside the numbers: SI and the paper's
    assert t.loc["tau_c", ["unit", "paper_unit"]].tolist() == ["Nm", "mNm"]
    assert t.loc["v_s", ["unit", "paper_unit"]].tolist() == ["rad/s", "rpm"]
    assert t.loc["viscous", ["unit", "paper_unit"]].tolist() == ["Nm s/rad", "mNm/rpm"]
    assert t.loc["worm decay", ["unit", "paper_unit"]].tolist() == ["s/rad", "1/rpm"]
    assert t.loc["worm phase", ["unit", "paper_unit", "positive", "negative"]].tolist() == \
        ["rad", "rad", math.pi / 2, math.pi / 2]
    # an extra term is one row named by its description
    t2 = FrictionModel("silo4", POS, NEG).with_terms({"kind": "offset", "offset": 0.5}).table()
    assert t2["parameter"].iloc[-1] == "offset 0.5" and t2["unit"].iloc[-1] == ""
    # the columns a user reads, in this order, and no other (a term row adds none)
    assert list(t2.columns) == ["parameter", "unit", "paper_unit", "positive", "positive_se", "positive_paper",
                                "negative", "negative_se", "negative_paper", "frequency"]


def test_direction_names_accepted_everywhere():
    m = FrictionModel("coulomb_viscous", {"tau_c": 1.0, "viscous": 0.1}, {"tau_c": 2.0, "viscous": 0.2})
    for name in ("positive", 1, 1.0, "+", "+1"):
        assert m.params(name)["tau_c"] == 1.0, name
    for name in ("negative", -1, -1.0, "-", "-1"):
        assert m.params(name)["tau_c"] == 2.0, name
    with pytest.raises(InputError, match="direction must be"):
        m.params("up")


def test_describe_says_whether_the_held_out_rmse_is_missing_or_partial():
    p = {"tau_c": 1.0, "viscous": 0.1}
    part = FrictionModel("coulomb_viscous", p, rmse=0.01, rmse_holdout=0.02,
                         rmse_holdout_reason="from 900 of 1000 samples: 1 of 5 folds could not be fitted")
    assert "held-out rmse partial: from 900 of 1000 samples" in part.describe()
    none = FrictionModel("coulomb_viscous", p, rmse=0.01, rmse_holdout_reason="one segment per direction")
    assert "held-out rmse not computed: one segment per direction" in none.describe()


def test_linear_axis_says_N_and_m():
    # on a linear axis (theta in m) torques are forces: the table and the printed summary say N, m
    p = {"tau_c": 2.0, "tau_s": 3.0, "v_s": 0.5, "viscous": 0.25,
         "harmonics": [{"frequency": 0.5, "amplitude": 0.1, "decay": 0.2}]}
    m = FrictionModel("stribeck", p, unit="m", rmse=0.0123)
    t = m.table().set_index("parameter")
    rows = ["tau_c", "tau_s", "v_s", "viscous", "harmonic 1 amplitude", "harmonic 1 decay", "harmonic 1 phase"]
    # the phase of sin(2 pi f x + phi) is an angle on a linear axis too
    assert t.loc[rows, "unit"].tolist() == ["N", "N", "m/s", "N s/m", "N", "s/m", "rad"]
    assert "paper_unit" not in t                      # the paper's mNm/rpm are for a rotary axis
    assert "rmse 0.0123, held-out rmse n/a (N)" in m.describe().splitlines()


def test_lola_laws_in_drive_convention():
    p = {"t_f0": 0.174, "mu": 3.1e-3, "b": 4.41e-5, "t_fs": 0.079, "v_s": 99.98}
    m = FrictionModel("lola11", p)
    v, load = np.array([-100.0, 0.0, 100.0]), np.array([20.0, 20.0, 20.0])
    got = m.evaluate(None, v, load=load)
    # the paper's law (11) gives the torque on the motor: -(sgn v)(...) - b v - ...; friction the
    # drive supplies is its negative, with the Stribeck term made odd
    expect = np.sign(v) * (0.174 + 3.1e-3 * 20 + (0.079 - 0.174) / (1 + (v / 99.98) ** 2)) + 4.41e-5 * v
    assert np.allclose(got, expect, rtol=1e-12)
    with pytest.raises(InputError, match="needs the output load"):
        m.evaluate(None, v)


def test_terms_add_what_they_say():
    m = FrictionModel("coulomb_viscous", {"tau_c": 1.0, "viscous": 0.1})
    v = np.array([2.0, -2.0, 2.0])
    m2 = m.with_terms({"kind": "temperature", "coefficient": -0.01, "reference": 20.0},
                      {"kind": "offset", "offset": 0.5},
                      {"kind": "periodic", "frequency": 0.25, "amplitude": 0.2, "decay": 0.0, "phase": 0.0,
                       "direction": 1})
    got = m2.evaluate(np.array([1.0, 1.0, 0.0]), v, temperature=np.array([30.0, 30.0, 20.0]))
    assert got[0] == pytest.approx(1.2 - 0.1 + 0.5 + 0.2)           # +0.2 sin(pi/2) in + only
    assert got[1] == pytest.approx(-(1.2 - 0.1) + 0.5)
    assert got[2] == pytest.approx(1.2 + 0.5)
    with pytest.raises(InputError, match="needs the 'temperature' channel"):
        m2.evaluate(np.zeros(3), v)


def test_hysteresis_term_acts_after_reversals_only():
    theta = np.concatenate([np.linspace(0, 1, 11), np.linspace(0.9, 0, 10)])
    v = np.concatenate([np.ones(11), -np.ones(10)])
    out, signed = evaluate_term({"kind": "hysteresis", "scale": 1.0, "length": 0.1}, theta=theta, v=v)
    assert not signed
    assert np.all(out[:11] == 0)                                  # no reversal yet
    assert out[11] == pytest.approx(-math.exp(-0.1 / 0.1))       # 0.1 after the reversal at 1.0
    assert out[-1] == pytest.approx(-math.exp(-1.0 / 0.1))


def test_unknown_law_and_term_are_refused():
    with pytest.raises(InputError, match="unknown friction law"):
        FrictionModel("coulomb", {})
    with pytest.raises(InputError, match="unknown friction term"):
        FrictionModel("none", {}, terms=[{"kind": "magic"}])


def test_amplitude_law_is_held_at_the_edge_of_its_speed_range(tmp_path):
    # an exp law fitted on 6..26 rad/s: below 6 (standstill) and above 26 the amplitude is the law's
    # value at the edge, exactly; inside, the law as written
    h = {"frequency": 2.0, "amplitude": 5e-3, "decay": 0.03, "phase": 0.0, "speed_range": [6.0, 26.0]}
    m = FrictionModel("coulomb_viscous", {"tau_c": 0.0, "viscous": 0.0, "harmonics": [h]})
    theta = np.full(5, 0.125)                        # sin(2 pi 2 0.125) = 1: the amplitude itself
    v = np.array([1e-9, 3.0, 10.0, 26.0, 60.0])
    got = m.evaluate(theta, v)
    amp = lambda s: 5e-3 * math.exp(-0.03 * s)       # noqa: E731
    assert got == pytest.approx([amp(6), amp(6), amp(10), amp(26), amp(26)], rel=1e-12)
    # JSON round trip exact, and the range is said in print(model)
    back = FrictionModel.from_json(m.to_json(tmp_path / "m.json"))
    assert back.harmonics(1)[0]["speed_range"] == [6.0, 26.0]
    assert np.array_equal(back.evaluate(theta, v), got)
    assert "fitted on |v| 6..26 rad/s; held at the edge outside" in str(m)
    t = m.table().set_index("parameter")                # and in the table, per direction, in rad/s and rpm
    assert t.loc["harmonic 1 law fitted |v| min", "positive"] == 6.0
    assert t.loc["harmonic 1 law fitted |v| max", "negative"] == 26.0
    assert t.loc["harmonic 1 law fitted |v| max", "unit"] == "rad/s"
    # a model written before speed_range (no range): no clamp, and it says so
    old = m.to_dict()
    for p in old["directions"].values():
        for hh in p["harmonics"]:
            del hh["speed_range"]
    m_old = FrictionModel.from_dict(json.loads(json.dumps(old)))
    assert m_old.evaluate(theta, v)[0] == pytest.approx(amp(0), rel=1e-9)
    assert "no speed range recorded" in str(m_old)
    with pytest.raises(InputError, match="speed_range"):
        FrictionModel("none", {"harmonics": [dict(h, speed_range=[5.0])]})


def test_lola11_without_its_stribeck_part_is_law8_without_coupling():
    # T_fS and v_S not identified: law (11) keeps T_f0 + mu |T_l| + b |v| (hand-computed)
    m = FrictionModel("lola11", {"t_f0": 0.174, "mu": 3.1e-3, "b": 4.41e-5, "t_fs": None, "v_s": None})
    got = m.evaluate(None, np.array([-100.0, 50.0]), load=np.array([20.0, -10.0]))
    assert got == pytest.approx([-(0.174 + 0.062 + 4.41e-3), 0.174 + 0.031 + 2.205e-3], rel=1e-12)


def test_friction_mean_level_leave_out_what_is_not_friction():
    # asymmetric Coulomb + viscous, an offset, inertia and a position ripple
    pos = {"tau_c": 1.0, "viscous": 0.1, "harmonics": [{"frequency": 0.25, "amplitude": 0.2}]}
    neg = {"tau_c": 1.5, "viscous": 0.2}
    # (+ a nonlinear viscous 0.05 |v|^2, a magnitude term that does not depend on position)
    m = FrictionModel("coulomb_viscous", pos, neg).with_terms({"kind": "offset", "offset": 0.5},
                                                               {"kind": "inertia", "inertia": 0.01},
                                                               {"kind": "viscous_power", "coefficient": 0.05,
                                                                "exponent": 2.0})
    theta, v, acc = np.array([1.0, 1.0]), np.array([2.0, -2.0]), np.array([10.0, 10.0])
    # evaluate: friction (ripple 0.2 sin(pi/2) forwards) + offset + J acc; friction(): without the last two
    assert m.evaluate(theta, v, acc=acc) == pytest.approx([1.4 + 0.2 + 0.5 + 0.1, -2.1 + 0.5 + 0.1], rel=1e-12)
    assert m.friction(theta, v, acc=acc) == pytest.approx([1.4 + 0.2, -2.1], rel=1e-12)
    # mean level over position: base law + 0.05 v^2 of each direction, a magnitude, without the ripple
    assert m.mean_level([1.0, 3.0], "negative") == pytest.approx([1.75, 2.55], rel=1e-12)
    assert m.mean_level([1.0, 3.0], -1) == pytest.approx([1.75, 2.55], rel=1e-12)
    assert m.mean_level(2.0, "positive") == pytest.approx([1.4], rel=1e-12)


def test_constant_amplitude_law_needs_no_speed_range():
    # a const-law harmonic is the same at every speed: print(model) warns of no missing speed range
    h = {"frequency": 0.25, "amplitude": 0.2, "law": "const"}
    m = FrictionModel("coulomb_viscous", {"tau_c": 1.0, "viscous": 0.0, "harmonics": [h]})
    assert m.evaluate(np.ones(2), np.array([0.1, 100.0])) == pytest.approx([1.2, 1.2], rel=1e-12)
    assert "no speed range recorded" not in str(m)
    # the same harmonic with the default exp law: said once per direction
    m_exp = FrictionModel("coulomb_viscous", {"tau_c": 1.0, "viscous": 0.0, "harmonics": [dict(h, law="exp")]})
    assert str(m_exp).count("no speed range recorded") == 2


def test_what_is_missing_is_named():
    # a direction the data could not identify: motion that way is refused with the reason recorded
    m = FrictionModel("coulomb_viscous", {"tau_c": 1.0, "viscous": 0.1}, {"tau_c": None, "viscous": None},
                      not_identified={"negative.tau_c": "no backward motion in the recording"})
    assert m.evaluate(None, 2.0).tolist() == [1.2]
    with pytest.raises(InputError, match=r"no negative-direction value for tau_c "
                                         r"\(not identified: no backward motion in the recording\)"):
        m.evaluate(None, -2.0)
    with pytest.raises(InputError, match="a harmonic of the model lacks frequency, amplitude"):
        FrictionModel("none", {"harmonics": [{"decay": 0.1}]})
    rippled = FrictionModel("none", {"harmonics": [{"frequency": 0.25, "amplitude": 0.2}]})
    with pytest.raises(InputError, match="position-locked harmonics and needs theta"):
        rippled.evaluate(None, 1.0)


def test_a_harmonic_not_identified_is_left_out_and_the_next_still_counts():
    # the first line's amplitude was not identified (None): it adds nothing; the second adds
    # 0.2 sin(2 pi 0.25 1) = 0.2 (exact up to rounding)
    hs = [{"frequency": 0.1, "amplitude": None}, {"frequency": 0.25, "amplitude": 0.2}]
    m = FrictionModel("coulomb_viscous", {"tau_c": 1.0, "viscous": 0.0, "harmonics": hs})
    assert m.evaluate(1.0, np.array([3.0, -3.0])) == pytest.approx([1.2, -1.2], rel=1e-12)
