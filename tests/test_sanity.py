"""Sanity checks that speak physics (issue "What a user sees", item 2): one sentence with the fix
when the data cannot be friction as recorded. Known answers: twins made wrong on purpose."""
import pytest

from gearspec import FitData, fit
from gearspec.model import FrictionModel
from gearspec.simulate.synthetic import model_recording

SPEEDS = [1.0, 2.0, 4.0, 8.0]


def _recording(tau_c, viscous=0.002, sign=1.0, seed=3):
    truth = FrictionModel("coulomb_viscous", {"tau_c": tau_c, "viscous": viscous})
    rec, _ = model_recording(truth, SPEEDS + [-s for s in SPEEDS], duration=1.0, fs=500, noise=1e-3, seed=seed)
    rec.data["torque"] = sign * rec.data["torque"]
    return FitData.from_recording(rec)


def test_a_torque_logged_with_the_opposite_sign_is_flagged_with_the_fix():
    with pytest.warns(UserWarning, match=r"opposes the velocity in 8 of 8 segments.*--scale torque=-1"):
        m = fit(_recording(0.3, sign=-1.0), "coulomb_viscous")
    assert "--scale torque=-1" in m.meta["flags"]["sign"]
    assert any(n.startswith("warning: ") and "inverted" in n for n in m.notes)
    # the fit itself is what the data say (friction -0.3 Nm): the check explains, it does not repair
    assert m.params("positive").values["tau_c"] == pytest.approx(-0.3, abs=0.01)


def test_right_sign_and_friction_lost_in_noise_are_not_flagged():
    # the right sign: no flag
    assert "sign" not in fit(_recording(0.3), "coulomb_viscous").meta.get("flags", {})
    # no friction at all under 1 mNm of noise (levels of 0 +- 0.05 mNm a segment): most segments
    # fall below 0 by chance here, but not by more than two of their standard errors
    fd = _recording(0.0, viscous=0.0, seed=6)
    assert int((fd.plateaus()["level"] < 0).sum()) == 7       # 7 of 8 below 0, by chance
    m = fit(fd, "coulomb_viscous")
    assert "sign" not in m.meta.get("flags", {})


def test_a_minority_of_inverted_segments_is_not_flagged():
    # torque inverted in the positive direction only: 4 of 8 segments oppose the velocity, not most
    fd = _recording(0.3)
    fd.y[fd.direction > 0] *= -1
    pl = fd.plateaus()
    assert int((pl["level"] < 0).sum()) == 4
    assert "sign" not in fit(fd, "coulomb_viscous").meta.get("flags", {})


def test_the_cli_says_a_finding_about_the_data_once(tmp_path, capsys):
    # fit compares several models on the same data; the inverted sign is said once, with the fix
    from gearspec.cli import main
    truth = FrictionModel("coulomb_viscous", {"tau_c": 0.3, "viscous": 0.002})
    rec, _ = model_recording(truth, SPEEDS + [-s for s in SPEEDS], duration=1.0, fs=500, noise=1e-3, seed=3)
    rec.data["torque"] = -rec.data["torque"]
    path = rec.save(tmp_path / "inverted.csv")
    for _ in range(2):                   # and again by a second command in the same process
        assert main(["fit", str(path), "--law", "stribeck", "--out", str(tmp_path / "out")]) == 0
        err = capsys.readouterr().err
        assert err.count("--scale torque=-1") == 1, err
