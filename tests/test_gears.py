"""Gear trains: frequencies of shafts, meshes, wave generators; labels; specs and their errors."""

import math

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


def test_every_preset_loads_and_describes():
    ps = presets()
    for name in ("silo4-joint3", "lola-a", "lola-b", "lola-c", "direct-drive", "kinova-gen3-joint7", "emps"):
        assert name in ps
        assert ps[name].describe()
    assert ps["lola-b"].total_ratio == 50 and ps["lola-a"].torque_constant == 0.13
