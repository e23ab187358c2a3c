"""Every friction law at hand-computed values (the numbers are the printed equations evaluated by hand,
written as literals): the laws are the single source the fits, the twins and the models evaluate."""

import numpy as np
import pytest

from gearspec import laws

# float64 evaluation of closed forms: agreement to 1e-12 relative, far tighter than any physics
TIGHT = dict(rel=1e-12, abs=1e-15)


def test_stribeck_eq3():
    # tau_c 1, tau_s 1.5, v_s 0.5, B 0.1:  v=0.5 -> 1 + 0.5 e^-1 + 0.05;  v=3 -> 1 + 0.5 e^-6 + 0.3
    got = laws.stribeck(np.array([-2.0, 0.0, 0.5, 3.0]), 1.0, 1.5, 0.5, 0.1)
    assert got == pytest.approx([-1.209157819444367, 0.0, 1.2339397205857212, 1.3012393760883332], **TIGHT)


def test_position_and_meshing_ripple_eq6_eq8():
    # 2 sin(2 pi 2 0.125 + 0.3) = 2 cos 0.3;  with decay 0.25 s/rad at |v| = 4: times e^-1
    assert laws.position_ripple(0.125, 2.0, 2.0, 0.3) == pytest.approx(1.910672978251212, **TIGHT)
    assert laws.meshing_ripple(0.125, -4.0, 2.0, 0.25, 2.0, 0.3) == pytest.approx(0.7028973075004312, **TIGHT)


POS = {"tau_c": 1.0, "tau_s": 1.5, "v_s": 0.5, "viscous": 0.1,
       "harmonics": [{"frequency": 2.0, "amplitude": 0.2}]}            # decay and phase default to 0
NEG = {"tau_c": 0.8, "tau_s": 1.0, "v_s": 1.0, "viscous": 0.2,
       "harmonics": [(2.0, 0.1, 0.5, 0.3)]}                          # the tuple form


def test_silo4_full_eq11_per_direction_with_both_harmonic_forms():
    # +0.5 rad/s: 1 + 0.5 e^-1 + 0.05 + 0.2 sin(pi/2)
    # -2 rad/s:  -(0.8 + 0.2 e^-2 + 0.4 + 0.1 e^-1 cos 0.3)
    got = laws.silo4_full(np.array([0.125, 0.125, 0.3]), np.array([0.5, -2.0, 0.0]), POS, NEG)
    assert got == pytest.approx([1.4339397205857212, -1.2622119220223442, 0.0], **TIGHT)


def test_silo4_full_broadcasts_and_handles_one_direction_or_no_harmonics():
    theta = np.array([0.125, 0.375])                                  # sin(pi/2), sin(3 pi/2)
    both = laws.silo4_full(theta, 0.5, POS, NEG)                      # scalar speed, array position
    assert both == pytest.approx([1.2339397205857212 + 0.2, 1.2339397205857212 - 0.2], **TIGHT)
    only_neg = laws.silo4_full(0.125, np.array([-2.0, -2.0]), POS, NEG)  # no positive sample at all
    assert only_neg == pytest.approx([-1.2622119220223442] * 2, **TIGHT)
    plain = laws.silo4_full(0.125, np.array([0.5]), {k: v for k, v in POS.items() if k != "harmonics"}, NEG)
    assert plain == pytest.approx([1.2339397205857212], **TIGHT)


def test_load_dependent_amplitude_eq14():
    assert laws.load_dependent_amplitude(np.array([-4.0, 0.0]), 1.0, 0.3) == pytest.approx([5.8, 1.0], **TIGHT)


def test_lola8_and_lola11_in_the_drive_convention():
    # (8): sgn(v)(T_f0 + mu |T_l|) + (b + gamma |T_l|) v at T_l = -20 Nm, v = +-100 rad/s
    got = laws.lola8(np.array([100.0, -100.0]), -20.0, 0.174, 3.1e-3, 4.41e-5, 2e-6)
    assert got == pytest.approx([0.24441, -0.24441], **TIGHT)
    # (11) made odd: sgn(v)(T_f0 + mu|T_l| + (T_fS - T_f0)/(1 + (v/v_S)^2)) + b v at v = 50
    got = laws.lola11(np.array([50.0, -50.0]), 20.0, 0.174, 3.1e-3, 4.41e-5, 0.079, 99.98)
    assert got == pytest.approx([0.16221108133783352, -0.16221108133783352], **TIGHT)


def test_lola_efficiency_laws_eq12_eq13():
    # k_m I - T_l/N = 0.05 * 5 - 20/100;  eta = T_l/(N k_m I) = 20/(100 * 0.05 * 5)
    assert laws.friction_from_load_current(20.0, 5.0, 100.0, 0.05) == pytest.approx(0.05, **TIGHT)
    assert laws.efficiency(20.0, 5.0, 100.0, 0.05) == pytest.approx(0.8, **TIGHT)
    # (T_l/N)/(T_l/N + |tau_f|) = 0.2/(0.2 + 0.1), and the motor torque of eta 0.8 at 20 Nm, N 100
    assert laws.efficiency_from_friction(-0.1, -20.0, 100.0) == pytest.approx(2 / 3, **TIGHT)
    assert laws.motor_torque_from_efficiency(0.8, 20.0, 100.0) == pytest.approx(0.25, **TIGHT)
