"""The term registry (gearspec.terms): every law declared once, and everything built from it.

Known answers are the printed equations evaluated by hand (literals); columns @ linear parameters
must equal the law's magnitude, the plain function of gearspec.laws and the FrictionModel to
1e-12 relative (float64 rounding of the same closed form).
"""

import math

import numpy as np
import pytest

from gearspec import identify, laws, model
from gearspec.diagnose import design
from gearspec.discover import library
from gearspec.model import FrictionModel
from gearspec.terms import (BASE_LAWS, LAW_LINEAR, TERM_LINEAR, TERMS, BaseLaw, amplitude_law, basis, register_law,
                            stribeck_shape)

TIGHT = dict(rel=1e-12, abs=1e-15)

# (law, params in the model's order, speed, load, hand-computed magnitude)
KNOWN = [
    # 1 + 0.1 * 3
    ("coulomb_viscous", {"tau_c": 1.0, "viscous": 0.1}, 3.0, 0.0, 1.3),
    # SILO4 eq. 3 at v = 0.5: 1 + 0.5 e^-1 + 0.05
    ("stribeck", {"tau_c": 1.0, "tau_s": 1.5, "v_s": 0.5, "viscous": 0.1}, 0.5, 0.0, 1.2339397205857212),
    ("silo4", {"tau_c": 1.0, "tau_s": 1.5, "v_s": 0.5, "viscous": 0.1}, 0.5, 0.0, 1.2339397205857212),
    # Lola (8) at v = 2, T_l = -10: 0.2 + 0.01*10 + (0.001 + 1e-4*10) * 2
    ("lola8", {"t_f0": 0.2, "mu": 0.01, "b": 0.001, "gamma": 1e-4}, 2.0, -10.0, 0.304),
    # Lola (11) at v = 2 = v_S, T_l = 10: 0.2 + 0.1 + (0.3 - 0.2) / 2 + 0.002
    ("lola11", {"t_f0": 0.2, "mu": 0.01, "b": 0.001, "t_fs": 0.3, "v_s": 2.0}, 2.0, 10.0, 0.352),
]
PLAIN = {"stribeck": lambda v, ld, p: laws.stribeck(v, p["tau_c"], p["tau_s"], p["v_s"], p["viscous"]),
         "lola8": lambda v, ld, p: laws.lola8(v, ld, p["t_f0"], p["mu"], p["b"], p["gamma"]),
         "lola11": lambda v, ld, p: laws.lola11(v, ld, p["t_f0"], p["mu"], p["b"], p["t_fs"], p["v_s"])}


@pytest.mark.parametrize("name, p, speed, load, want", KNOWN, ids=[k[0] for k in KNOWN])
def test_columns_times_linear_equal_magnitude_laws_and_model(name, p, speed, load, want):
    law = BASE_LAWS[name]
    s, ld = np.array([speed]), np.array([load])
    X = law.columns(s, ld, *[p[k] for k in law.nonlinear_names])
    assert X.shape == (1, len(law.linear))
    assert (X @ [p[k] for k in law.linear])[0] == pytest.approx(want, **TIGHT)
    assert np.asarray(law.magnitude(s, ld, *[p[k] for k in law.params]))[0] == pytest.approx(want, **TIGHT)
    # friction has the sign of the velocity: both directions of a symmetric model
    m = FrictionModel(name, p)
    got = m.evaluate(None, np.array([speed, -speed]), load=np.array([load, load]))
    assert got == pytest.approx([want, -want], **TIGHT)
    if name in PLAIN:
        assert PLAIN[name](np.array([speed, -speed]), np.array([load, load]), p) == pytest.approx([want, -want], **TIGHT)


def test_every_law_declared_once_and_shared_by_model_identify_and_design():
    assert model.LAWS is BASE_LAWS and model.Law is BaseLaw and identify.joint._basis is basis
    for name, law in BASE_LAWS.items():
        assert design.LINEAR[name] == (law.linear, law.nonlinear_names) == LAW_LINEAR[name]
        b = identify.joint._basis(name)
        assert b.columns is law.columns and b.lin == law.linear and b.nonlin == law.nonlinear_names
        assert set(law.linear) | set(law.nonlinear_names) <= set(law.params)
        for d in law.degraded:
            assert identify.joint._basis(d.name).columns(np.array([1.0]), np.array([1.0])).shape == (1, len(d.linear))
    # term kinds: the closed loop's linear parameters are the kinds' declarations
    assert dict(design.TERM_LINEAR) == {k: tk.linear for k, tk in TERMS.items() if tk.linear is not None}
    assert design.TERM_LINEAR is TERM_LINEAR


def test_degraded_forms_when_the_stribeck_velocity_is_not_identified():
    st = BASE_LAWS["stribeck"]
    d = st.degraded_for("v_s")
    assert d.linear == ("tau_c", "viscous") and d.dropped == ("tau_s", "v_s")
    assert st.optional == ("tau_s", "v_s", "viscous")
    s = np.array([0.5, 3.0])
    # 2 + 0.1 |v|, by the degraded columns, by the design of those parameters and by a model with None
    assert d.columns(s, None) @ [2.0, 0.1] == pytest.approx([2.05, 2.3], **TIGHT)
    assert st.design(("tau_c", "viscous"), {"v_s": None}, s, None) @ [2.0, 0.1] == pytest.approx([2.05, 2.3], **TIGHT)
    m = FrictionModel("stribeck", {"tau_c": 2.0, "tau_s": None, "v_s": None, "viscous": 0.1})
    assert m.evaluate(None, -s) == pytest.approx([-2.05, -2.3], **TIGHT)
    # Lola (11) without its Stribeck part: law (8) without gamma; at v=2, T_l=10: 0.2 + 0.1 + 0.002
    l11 = BASE_LAWS["lola11"]
    d11 = l11.degraded_for("v_s")
    assert d11.name == "lola8_nogamma" and d11.dropped == ("t_fs", "v_s")
    assert (d11.columns(np.array([2.0]), np.array([10.0])) @ [0.2, 0.01, 0.001])[0] == pytest.approx(0.302, **TIGHT)
    assert l11.magnitude(np.array([2.0]), np.array([10.0]), 0.2, 0.01, 0.001, None, None)[0] \
        == pytest.approx(0.302, **TIGHT)
    # quasi-static data: the level alone
    assert BASE_LAWS["silo4"].degraded_for("speed").linear == ("tau_c",)
    assert BASE_LAWS["lola8"].degraded_for("speed") is None


def test_shapes_known_answers_and_library_families_use_them():
    # exp(-1), exp(-4), 1/(1+4); amplitude laws at |v| = 1, b = 1: e^-1, 1, 1/2, 2^-1
    assert stribeck_shape("exp", np.array([2.0]), 2.0) == pytest.approx([math.exp(-1)], **TIGHT)
    assert stribeck_shape("gauss", np.array([4.0]), 2.0) == pytest.approx([math.exp(-4)], **TIGHT)
    assert stribeck_shape("rational", np.array([4.0]), 2.0) == pytest.approx([0.2], **TIGHT)
    one = np.array([1.0])
    assert [float(amplitude_law(lw, one, 1.0)[0]) for lw in ("exp", "const", "rational", "power")] \
        == pytest.approx([math.exp(-1), 1.0, 0.5, 0.5], **TIGHT)
    u = np.array([0.3, 1.7])
    for shape in ("exp", "gauss", "rational"):
        assert np.array_equal(library.FAMILIES[f"stribeck_{shape}"].magnitude(u, 0.9), stribeck_shape(shape, u, 0.9))
    for lw in ("const", "exp", "rational"):
        assert np.array_equal(library.FAMILIES[f"ripple_{lw}"].magnitude(u, 0.9), amplitude_law(lw, u, 0.9))
    # the stribeck_extra term kind and the meshing ripple of eq. 8 use the same shapes
    t = {"kind": "stribeck_extra", "amplitude": 2.0, "v_s": 2.0, "shape": "rational"}
    assert TERMS["stribeck_extra"].func(t, v=np.array([-4.0])) == pytest.approx([0.4], **TIGHT)
    # 2 e^{-0.25*4} sin(2 pi 2 0.125 + 0.3) = 2 e^-1 cos 0.3
    assert laws.meshing_ripple(0.125, -4.0, 2.0, 0.25, 2.0, 0.3) == pytest.approx(0.7028973075004312, **TIGHT)


def test_a_law_registered_once_is_known_to_model_identify_and_design():
    # a newcomer's law: a level plus a quadratic drag c v^2 (both linear)
    law = BaseLaw("test_quadratic", ("tau_c", "c"), ("Nm", "Nm s^2/rad^2"),
                  lambda speed, load, tau_c, c: tau_c + c * speed * speed, description="test law",
                  linear=("tau_c", "c"), columns=lambda s, load: np.column_stack([np.ones_like(s), s * s]))
    register_law(law)
    try:
        assert FrictionModel("test_quadratic", {"tau_c": 1.0, "c": 0.5}).evaluate(None, np.array([-2.0])) \
            == pytest.approx([-3.0], **TIGHT)
        assert design.LINEAR["test_quadratic"] == (("tau_c", "c"), ())
        assert identify.joint._basis("test_quadratic").lin == ("tau_c", "c")
    finally:
        BASE_LAWS.pop("test_quadratic")
    assert "test_quadratic" not in design.LINEAR
