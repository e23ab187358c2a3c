"""A declared line that carries no ripple does not stop the joint fit (issue 15): its decay is not
identified, so it keeps a constant amplitude and the fit says so; a fit that still does not
converge says where it stopped.

Tolerances: the twins have white torque noise (1 mNm per sample) and one run, so the fit's standard
errors (covariance of independent samples) are the right scale of the error; a fitted parameter
within 4 of them of the truth fails by chance with probability 6e-5 (normal, two-sided).
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from gearspec.fitdata import FitData
from gearspec.identify import fit
from gearspec.identify.stats import SIGNIFICANT, ConvergenceError
from gearspec.model import FrictionModel
from gearspec.segment import find_segments
from gearspec.simulate import fleet as fleet_mod
from gearspec.simulate.synthetic import model_recording

pytest.importorskip("rosbags")

Z = 4.0            # truth within Z standard errors (see the module's docstring)
NOT_SEEN = "not distinguishable from zero"


def _fleet_joint(tmp_path, robot: int, date: int, joint: int):
    """The truth model and noise seed of one recording-joint of the fleet twin (default settings), drawn
    by :func:`gearspec.simulate.fleet.fleet_twin` itself with its recordings and bags left out."""
    calls = []

    def record_only(model, *args, **kwargs):
        calls.append((model, kwargs["seed"]))
        return None, None

    mp = pytest.MonkeyPatch()
    mp.setattr(fleet_mod, "model_recording", record_only)
    mp.setattr(fleet_mod, "_write_bag", lambda *a, **k: None)
    try:
        fleet_mod.fleet_twin(tmp_path / "draws", robots=robot)
    finally:
        mp.undo()
    dates, joints = 10, 6
    return calls[((robot - 1) * dates + date - 1) * joints + joint - 1]


def _bag_of(tmp_path, model, seed, date: int, robot: int, name: str):
    """The fleet twin's bag of one joint (the same samples, stamps and velocities as in the fleet's bag)."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    rec, _ = model_recording(model, fleet_mod.SPEEDS, duration=1.0, fs=fleet_mod.FS, noise=fleet_mod.NOISE, seed=seed,
                             one_run_per_plateau=False)
    start = fleet_mod.T0 + (date - 1) * 7.0 * 86400.0 + (robot - 1) * 3600.0
    path = tmp_path / "bag"
    fleet_mod._write_bag(path, start, [name], [rec], get_typestore(Stores.ROS2_HUMBLE), Writer, StoragePlugin.MCAP)
    return path


def _within(fitted: float, se: float, truth: float, what: str) -> None:
    assert np.isfinite(se) and se > 0, what
    assert abs(fitted - truth) < Z * se, f"{what}: {fitted:.6g} +- {se:.2g}, truth {truth:.6g}"


def test_the_fleet_joint_that_was_refused_now_fits_in_both_directions(tmp_path):
    """robot3/date02 joint6 of the fleet twin: its motor-shaft line (declared by the gear, no ripple in
    the truth) had a decay that ran to -0.97 s/rad until the least squares used its 400 evaluations."""
    from gearspec.fleet.runner import analyse_one

    model, seed = _fleet_joint(tmp_path, robot=3, date=2, joint=6)
    bag = _bag_of(tmp_path, model, seed, date=2, robot=3, name="joint6")
    out = analyse_one(str(bag), "joint6", fleet_mod.FLEET_GEAR)
    assert [(r["direction"], r["status"], r["error"]) for r in out["rows"]] == [
        ("positive", "ok", None), ("negative", "ok", None)]
    fitted = out["fit"]
    for d in ("positive", "negative"):
        P, T = fitted["directions"][d], model.params(d)
        for k in ("tau_c", "tau_s", "v_s", "viscous"):
            _within(P[k], P[f"{k}_se"], float(T.values[k]), f"{d} {k}")
        lines = {h["label"]: h for h in P["harmonics"]}
        mesh, truth = lines["spur tooth mesh"], T.harmonics[0]
        _within(mesh["amplitude"], mesh["amplitude_se"], truth.amplitude, f"{d} mesh amplitude")
        _within(mesh["phase"], mesh["phase_se"], truth.phase, f"{d} mesh phase")
        _within(mesh["decay"], mesh["decay_se"], 0.0, f"{d} mesh decay")
        assert mesh.get("law", "exp") == "exp"     # a line with ripple keeps its decay
        # the motor shaft has no ripple: held constant, said so, its amplitude consistent with 0
        shaft = lines["motor shaft"]
        assert shaft["law"] == "const" and shaft["decay"] == 0.0 and shaft["decay_se"] == 0.0
        assert shaft["amplitude"] < Z * shaft["amplitude_se"]
        assert NOT_SEEN in fitted["not_identified"][f"{d}.motor shaft.decay"]
        assert fitted["not_identified"][f"{d}.motor shaft.decay"].endswith("its amplitude is held constant")


MESH = 5 / (2 * np.pi)      # cycles/rad: the fleet gear's tooth mesh
SHAFT = 1 / (2 * np.pi)     # cycles/rad: its motor shaft


def _twin(seed: int = 3):
    """SILO4 with one mesh line whose amplitude decays (0.01 Nm, 0.02 s/rad), eight plateaus per
    direction at 0.5..20 rad/s, 2 s each, 1 mNm noise."""
    mesh = {"frequency": MESH, "amplitude": 0.01, "decay": 0.02, "phase": 1.0, "label": "mesh"}
    truth = {"tau_c": 0.1, "tau_s": 0.15, "v_s": 2.0, "viscous": 1e-3, "harmonics": [mesh]}
    model = FrictionModel("silo4", truth, dict(truth, tau_c=0.12))
    speeds = [0.5, 1.0, 2.0, 3.0, 5.0, 8.0, 12.0, 20.0]
    rec, _ = model_recording(model, speeds + [-v for v in speeds], duration=2.0, fs=250.0, noise=1e-3, seed=seed)
    return model, FitData.from_recording(rec, find_segments(rec))


@pytest.mark.parametrize("shape", ["exp", "rational", "power"])
def test_a_declared_line_without_amplitude_is_fitted_constant_and_said(shape):
    """Every amplitude law with a shape parameter: the empty line is held constant, the real line keeps
    its decay (0.02 s/rad recovered), the friction is recovered."""
    model, data = _twin()
    lines = [{"frequency": MESH, "label": "mesh"}, {"frequency": SHAFT, "label": "empty", "law": shape}]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = fit(data, "silo4", harmonics=lines, holdout=None)
    for d in ("positive", "negative"):
        P, T = m.params(d), model.params(d)
        for k in ("tau_c", "tau_s", "v_s", "viscous"):
            _within(P.values[k], P.se[k], float(T.values[k]), f"{d} {k}")
        mesh, empty = P.harmonics
        assert mesh.law == "exp"
        _within(mesh.decay, mesh.se["decay"], 0.02, f"{d} mesh decay")
        _within(mesh.amplitude, mesh.se["amplitude"], 0.01, f"{d} mesh amplitude")
        assert empty.law == "const" and empty.decay == 0.0
        assert empty.amplitude < Z * empty.se["amplitude"]
        why = m.not_identified[f"{d}.empty.decay"]
        assert NOT_SEEN in why and f"below {SIGNIFICANT:g} standard errors" in why
        assert f"{d}.mesh.decay" not in m.not_identified


def test_the_rule_holds_a_line_only_below_its_threshold():
    """The rule's edge: the same twin, its mesh line fitted with the threshold just below and just above
    the line's own amplitude / standard error (at fixed shape) -- held only above."""
    from gearspec.identify import jointlines

    _, data = _twin()
    lines = [{"frequency": MESH, "label": "mesh"}]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = fit(data, "silo4", harmonics=lines, holdout=None, se="independent")
    h = m.params("positive").harmonics[0]
    ratio = h.amplitude / h.se["amplitude"]          # ~150: the mesh line is far above the noise
    assert ratio > 50
    mp = pytest.MonkeyPatch()
    try:
        for z, held in ((0.5 * ratio, False), (2.0 * ratio, True)):
            mp.setattr(jointlines, "SIGNIFICANT", z)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                m = fit(data, "silo4", harmonics=lines, holdout=None, se="independent")
            assert (m.params("positive").harmonics[0].law == "const") is held
            assert ("positive.mesh.decay" in m.not_identified) is held
    finally:
        mp.undo()


def test_a_fit_that_does_not_converge_says_where_it_stopped(monkeypatch):
    """The least squares cut to one evaluation: the refusal names the evaluations used and the
    parameters where it stopped, in one sentence."""
    from scipy import optimize

    import gearspec.identify.joint as joint

    real = optimize.least_squares
    monkeypatch.setattr(joint.optimize, "least_squares", lambda *a, **k: real(*a, **{**k, "max_nfev": 1}))
    _, data = _twin()
    with pytest.raises(ConvergenceError) as err:
        fit(data, "silo4", harmonics=[{"frequency": MESH, "label": "mesh"}], holdout=None)
    text = str(err.value)
    assert text.startswith("the silo4 fit did not converge in the positive direction (it used its 1 evaluations")
    assert "rad/s" in text and "decay of mesh = " in text and " s/rad" in text and "\n" not in text
