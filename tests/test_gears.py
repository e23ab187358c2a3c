"""Gear trains: frequencies of shafts, meshes, wave generators; labels; specs and their errors."""

import math
import re

import pytest

from gearspec.errors import InputError
from gearspec.gears import GearTrain, load_gear, presets

TWO_PI = 2 * math.pi


def test_silo4_joint_referenced_lines_match_the_paper():
    # SILO4 section 3.2: F1 = 0.159, F2 = 3.26, F3 = 45.6 cycles/rad of JOINT position
    g = GearTrain.from_dict({"name": "silo4 joint side", "reference": "output",
                             "stages": [{"name": "planetary", "kind": "planetary", "ratio": 14},
                                        {"name": "worm", "kind": "worm", "ratio": 20.5}]})
    f = {ln.label: ln.frequency for ln in g.declared_lines()}
    assert f["output shaft"] == pytest.approx(0.159, abs=0.0005)
    assert f["planetary output shaft"] == pytest.approx(3.26, abs=0.005)
    assert f["motor shaft"] == pytest.approx(45.6, abs=0.1)
    assert g.order(f["motor shaft"]) == pytest.approx(287)


def test_silo4_preset_is_motor_referenced_like_table_2():
    # Table 2's omega: 1/287, 1/14 (printed 3.5e-3, 0.071) and 1 per rad of MOTOR position
    g = presets()["silo4-joint3"]
    f = {ln.label: ln.frequency * TWO_PI for ln in g.declared_lines()}
    assert f["output shaft"] == pytest.approx(1 / 287)
    assert f["planetary output shaft"] == pytest.approx(1 / 14)
    assert f["motor shaft"] == pytest.approx(1.0)
    assert g.total_ratio == pytest.approx(287)


def test_strain_wave_family_and_labels():
    g = load_gear("kinova-gen3-joint7")  # theta at the output, ratio 100
    f = {ln.label: ln.frequency for ln in g.declared_lines()}
    assert f["strain-wave 2x wave generator"] == pytest.approx(200 / TWO_PI)
    assert f["strain-wave 4x wave generator"] == pytest.approx(400 / TWO_PI)
    assert "1x wave generator" in g.label(100 / TWO_PI, 0.01).label
    assert g.label(200 / TWO_PI + 0.004, 0.01).label == "strain-wave 2x wave generator"
    assert g.label(200 / TWO_PI + 0.1, 0.01) is None
    # 3x of the 2x line = 6x wave generator: a harmonic
    lab = g.label(600 / TWO_PI, 0.01)
    assert lab.kind == "harmonic"


def test_tooth_mesh_and_sidebands():
    g = GearTrain.from_dict({"name": "spur", "reference": "motor",
                             "stages": [{"name": "pair", "kind": "spur", "ratio": 3, "teeth": 12},
                                        {"name": "sun", "kind": "planetary", "ratio": 4, "teeth": 10}]})
    f_motor = 1 / TWO_PI
    lines = {ln.label: ln.frequency for ln in g.declared_lines()}
    assert lines["pair tooth mesh"] == pytest.approx(12 * f_motor)
    # planetary: sun teeth x (input - carrier) speed
    f_in, f_out = f_motor / 3, f_motor / 12
    assert lines["sun tooth mesh"] == pytest.approx(10 * (f_in - f_out))
    sb = g.label(12 * f_motor + f_motor, 1e-6)
    assert sb.kind == "sideband" and "+" in sb.label
    sb = g.label(12 * f_motor - f_in, 1e-6)
    assert sb.kind == "sideband" and " - " in sb.label


def test_linear_ballscrew_axis():
    g = GearTrain.from_dict({"name": "axis", "unit": "m", "reference": "output",
                             "stages": [{"name": "belt", "kind": "belt", "ratio": 2},
                                        {"name": "screw", "kind": "ballscrew", "lead": 0.005}]})
    f = {ln.label: ln.frequency for ln in g.declared_lines()}
    assert f["screw shaft"] == pytest.approx(200.0)       # 1/lead cycles per metre
    assert f["motor shaft"] == pytest.approx(400.0)
    assert g.order(400.0) == pytest.approx(2.0)            # per screw turn


@pytest.mark.parametrize("spec, match", [
    ({"name": "x", "stages": [{"kind": "warp", "ratio": 2}]}, "unknown kind 'warp'"),
    ({"name": "x", "stages": [{"kind": "spur", "ratio": -2}]}, "ratio must be a positive"),
    ({"name": "x", "stages": [{"kind": "spur"}]}, "has no 'ratio'"),
    ({"name": "x", "reference": "joint"}, "reference must be 'motor' or 'output'"),
    ({"name": "x", "unit": "deg"}, "unit must be 'rad'"),
    ({"name": "x", "unit": "m", "stages": [{"kind": "spur", "ratio": 2}]}, "must end in one ballscrew"),
    ({"name": "x", "stages": [{"kind": "spur", "ratio": 2, "lead": 0.01}]}, "only meaningful for a ballscrew"),
    ({"name": "x", "torque_constant": 0}, "torque_constant must be a positive"),
])
def test_bad_specs_are_refused_with_a_reason(spec, match):
    with pytest.raises(InputError, match=match):
        GearTrain.from_dict(spec)


def test_toml_file_and_unknown_preset(tmp_path):
    p = tmp_path / "g.toml"
    p.write_text('name = "t"\nreference = "motor"\ntorque_constant = 0.02\n[[stages]]\nkind = "worm"\nratio = 30\n')
    g = load_gear(str(p))
    assert g.torque_constant == 0.02 and g.total_ratio == 30
    with pytest.raises(InputError, match="no such file and no such preset"):
        load_gear("no-such-gear")
    bad = tmp_path / "bad.toml"
    bad.write_text("name = \n")
    with pytest.raises(InputError, match="not valid TOML"):
        load_gear(str(bad))


# what each preset's description must say (whitespace collapsed): stages and ratios, the total, and
# every declared line at its frequency by hand, 6 digits: shaft of order k at k / (2 pi N) cycles/rad
# of motor position (N the total ratio) or k / (2 pi) of output position
DESCRIBED = {
    "silo4-joint3": ["reference: motor, theta in rad", "stage planetary planetary ratio 14",
                     "stage worm worm ratio 20.5", "total ratio 287",
                     "0.000554547 cycles/rad order 1 output shaft",                 # 1 / (2 pi 287)
                     "0.0113682 cycles/rad order 20.5 planetary output shaft",      # 20.5 / (2 pi 287) = 1 / (2 pi 14)
                     "0.159155 cycles/rad order 287 motor shaft"],                  # 1 / (2 pi)
    "lola-a": ["k_m 0.13 Nm/A", "nominal 7 A", "stage HFUC-25-100 harmonic ratio 100", "total ratio 100",
               "0.00159155 cycles/rad order 1 output shaft",
               "0.159155 cycles/rad order 100 motor shaft (= HFUC-25-100 1x wave generator)",
               "0.31831 cycles/rad order 200 HFUC-25-100 2x wave generator",
               "0.63662 cycles/rad order 400 HFUC-25-100 4x wave generator"],
    "lola-b": ["k_m 0.097 Nm/A", "nominal 15 A", "stage CSG-32-50 harmonic ratio 50", "total ratio 50",
               "0.0031831 cycles/rad order 1 output shaft", "0.31831 cycles/rad order 100 CSG-32-50 2x wave generator"],
    "lola-c": ["k_m 0.075 Nm/A", "nominal 3.5 A", "stage CSD-20-100 harmonic ratio 100", "total ratio 100",
               "0.63662 cycles/rad order 400 CSD-20-100 4x wave generator"],
    "direct-drive": ["reference: motor", "0.159155 cycles/rad order 1 shaft"],
    "kinova-gen3-joint7": ["reference: output, theta in rad", "stage strain-wave harmonic ratio 100",
                           "0.159155 cycles/rad order 1 output shaft",
                           "15.9155 cycles/rad order 100 motor shaft",              # 100 / (2 pi)
                           "31.831 cycles/rad order 200 strain-wave 2x wave generator",
                           "63.662 cycles/rad order 400 strain-wave 4x wave generator"],
    "emps": ["reference: output, theta in m", "lead is not published"],
}


@pytest.mark.parametrize("name", sorted(DESCRIBED))
def test_every_preset_loads_and_describes(name):
    ps = presets()
    assert name in ps
    raw = ps[name].describe()
    text = " ".join(raw.split())
    for fact in DESCRIBED[name]:
        assert fact in text, (fact, text)
    # one row per stage and one per declared line
    rows = raw.splitlines()
    assert sum(bool(re.match(r"\s+[0-9.e+-]+ cycles/(rad|m)\b", r)) for r in rows) == len(ps[name].declared_lines())
    assert sum(r.lstrip().startswith("stage ") for r in rows) == len(ps[name].stages)
    assert ("total ratio" in text) == bool(ps[name].stages)


def test_presets_ratios_and_constants():
    ps = presets()
    assert ps["lola-b"].total_ratio == 50 and ps["lola-a"].torque_constant == 0.13
