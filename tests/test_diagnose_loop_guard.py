"""The closed loop keeps only steps that leave a better model (issue 13, "one acceptance rule").

Measured case (Kinova Gen3 joint 7, GEARSPEC_DATA): the gear's friction = minus the data set's own
friction-estimate column.  The baseline (SILO4 with the gear's lines) has the motor-shaft line with
an exp amplitude law whose decay, settled on all data, is 66 per rad/s (the line only at the slowest
run); its held-out rmse over whole runs is 0.2122 Nm.  The amplitude-law candidate's own search
chooses exp with decay 5 / top speed = 3.3 per rad/s and predicts the held-out runs with 0.1517 Nm.
Before the fix the accepted model was settled again on all data, the decay went back to 69 per
rad/s (held-out 0.2297 Nm, worse than the baseline), and the same candidate was accepted in every
round.  Now the accepted model keeps the decay its search chose (``holds_parameters``), and any step
whose settled model is not better held-out is undone.
"""

import json

import numpy as np
import pytest
from readme_numbers import check

import gearspec.diagnose.guard as guard
import gearspec.diagnose.loop as loop
from gearspec.cli import main
from gearspec.diagnose.loop import Evaluation
from gearspec.diagnose.results import Effect, Verdict, verdict_line

NAMES = "torque_command,theta,velocity,sensor,current_command,current,friction_estimate"
MOTOR_LAW = "amplitude law of motor shaft (= strain-wave 1x wave generator) (positive)"


def _kinova(data_dir, tmp_path, capsys, *extra):
    files = sorted(str(p) for p in (data_dir / "kinova_gen3_joint7").glob("velocity_*readings.csv"))
    assert len(files) == 10
    out = tmp_path / "d.json"
    rc = main(["diagnose", *files, "--gear", "kinova-gen3-joint7", "--fs", "999", "--no-header", "--names", NAMES,
               "--map", "torque=friction_estimate", "--scale", "torque=-1", "--holdout", "run", "--max-rounds", "3",
               "--json", str(out), *extra])
    assert rc == 0
    return json.loads(out.read_text()), capsys.readouterr().out


def _accepted_per_round(d) -> list:
    return [r["accepted"] for r in d["rounds"] if r.get("accepted")]


@pytest.mark.realdata
def test_kinova_amplitude_law_accepted_once_and_kept_as_judged(data_dir, tmp_path, capsys):
    d, _ = _kinova(data_dir, tmp_path, capsys)
    base, final = d["baseline"]["rmse_holdout"], d["final"]["rmse_holdout"]
    # measured: the baseline of the issue was 0.2122; 0.2052 since diagnose leaves out the plateau
    # edges whose acceleration filter reaches into the ramps (gearspec.segment.trim)
    assert base == pytest.approx(0.2052, abs=5e-4)
    acc = _accepted_per_round(d)
    assert acc[0] == MOTOR_LAW
    assert len(acc) == len(set(acc))                         # no candidate accepted twice
    # the model kept is the model judged: its held-out rmse (settled, refitted in every fold) is the
    # candidate's own fold estimate to within 1 % (measured 0.1521 against 0.1517: the other blocks'
    # nonlinear parameters are settled on all data, the candidate's law and decay are not); before the
    # fix 0.2297, 51 % above
    step = d["rounds"][0]
    assert step["rmse_holdout_model"] == pytest.approx(step["rmse_holdout_step"], rel=0.01)
    # a real improvement: -28 % held-out (a run at an unseen speed is predicted by the law)
    assert final < 0.75 * base
    e = next(x for x in d["effects"] if x["name"] == MOTOR_LAW)
    assert e["status"] == "accepted" and e["verdict"]["test"] == "held-out"
    assert "exp" in e["fitted"]
    for r in d["rounds"]:
        if r.get("accepted"):
            assert r["rmse_holdout_model"] <= base and not r["undone"]
    z = e["verdict"]
    check("kinova-loop", f"held-out runs to {base:.4f} Nm", f"ends at {final:.4f} Nm ({100 * (final / base - 1):.0f} %)",
          f"held-out Z {z['z']:.2f} against {z['z_crit']:.2f}")


@pytest.mark.realdata
def test_step_whose_settled_model_is_worse_is_undone(data_dir, tmp_path, capsys, monkeypatch):
    """The rule for every kind: with the old settle (every nonlinear parameter refitted on all data)
    the same step leaves a model worse held-out (0.2297 against 0.2122 Nm): it is undone, recorded as
    rejected with that reason (one verdict: console, report and JSON), and not accepted again."""
    monkeypatch.setattr(guard, "settle_holding", lambda state, dd, held: loop._settle(state, dd))
    rep = tmp_path / "rep"
    d, console = _kinova(data_dir, tmp_path, capsys, "--out", str(rep))
    base, final = d["baseline"]["rmse_holdout"], d["final"]["rmse_holdout"]
    assert final <= base                                   # never worse than the baseline (was 0.2297)
    assert MOTOR_LAW not in _accepted_per_round(d)          # (was accepted in all 8 rounds)
    assert MOTOR_LAW in d["rounds"][0]["undone"]
    e = next(x for x in d["effects"] if x["name"] == MOTOR_LAW)
    v = e["verdict"]
    assert e["status"] == "rejected" and v["test"] == "settled model" and v["round"] == 1
    assert "not below" in v["reason"] and "step undone" in v["reason"]
    assert v["rmse_before"] == pytest.approx(base, rel=1e-9)
    # the settled model measured before the fix (0.2297 before the plateau edges were trimmed)
    assert v["rmse_after"] == pytest.approx(0.2215, abs=5e-4)
    assert v["rmse_after"] > v["rmse_before"] and v["gain"] < 0
    assert v["line"] in console                              # the console prints the JSON's line
    report = " ".join((rep / "report.md").read_text().split())
    assert " ".join(v["line"].split()) in report


def _passing_eval() -> Evaluation:
    return Evaluation(z=7.0, z_crit=3.0, drop=1.0, fold_drops=np.ones(5), consistency=1.0, rmse_holdout_before=1.0,
                      rmse_holdout_after=0.9, gain=0.1, n_params=2, passed=True, reason="accepted", gate="passes")


def test_no_candidate_accepted_twice():
    """A candidate passing again while its effect is in the model is not accepted again (the loop
    before the fix accepted the same amplitude law in all 8 rounds); one whose step was undone is not
    tried again; any other passes through."""
    e = Effect(kind="speed_law", name="amplitude law of line A", accepted=True, evidence="", rmse_holdout_before=1.0,
               rmse_holdout_after=0.9, round=1)
    e.verdict = Verdict("accepted", "held-out", "passes", 7.0, 3.0, 0.1, 0.005, 1.0, 0.9, 1)
    key = "speed_law: amplitude law of line A"
    ev = _passing_eval()
    guard.bar_repeat(e, key, {}, ev)
    assert not ev.passed and ev.test == "re-entry" and "in the model already (accepted in round 1)" in ev.gate
    ev = _passing_eval()
    guard.bar_repeat(None, key, {key: (2, "amplitude law of line A")}, ev)
    assert not ev.passed and ev.test == "settled model" and "undone in round 2" in ev.gate
    ev = _passing_eval()
    e.accepted = False
    guard.bar_repeat(e, key, {}, ev)
    assert ev.passed                                          # rejected before: may pass now
    assert verdict_line(e)                                    # the record still renders


def test_amplitude_law_settled_freely_when_that_predicts_better():
    """The held decay is kept only when it predicts the held-out groups better (Kinova); where the
    free settle finds the truth, it is used.  Twin: the tooth-mesh line (15 mNm, rational amplitude
    law, decay 0.25 s/rad) at 16 plateaus of 0.5-16 rad/s, white noise 1 mNm.  A proposal with decay
    0.05 s/rad held would leave the model 2.8x worse held-out (measured 2.8 against 1.0 mNm); settled
    freely the decay returns to 0.25 (measured 0.249996; 2 % is many standard errors wide at 15x the
    noise, far from 0.05)."""
    from dataclasses import replace

    import gearspec.diagnose as dg
    from gearspec.diagnose.candidates import Proposal
    from gearspec.diagnose.context import Round
    from gearspec.diagnose.design import state_from_model
    from gearspec.gears import GearTrain
    from gearspec.model import FrictionModel
    from gearspec.simulate import model_recording

    gear = GearTrain.from_dict({"name": "test drive", "reference": "motor", "unit": "rad",
                                "stages": [{"name": "spur", "kind": "spur", "ratio": 10, "teeth": 17}]})
    line = {"frequency": 17 / (2 * np.pi), "amplitude": 1.5e-2, "law": "rational", "decay": 0.25, "phase": 0.3,
            "label": "spur tooth mesh"}
    pos = {"tau_c": 0.05, "tau_s": 0.08, "v_s": 1.5, "viscous": 2e-3, "harmonics": [line]}
    truth = FrictionModel("silo4", pos, {**pos, "harmonics": [dict(line, phase=1.0)]}, name="truth")
    rng = np.random.default_rng(7)
    mag = np.geomspace(0.5, 16, 8)
    speeds = [x for a, b in zip(rng.permutation(mag), rng.permutation(mag)) for x in (a, -b)]
    rec, _ = model_recording(truth, speeds, noise=1e-3, gear=gear, seed=0, duration=1.5, fs=500.0,
                             one_run_per_plateau=False)
    dd = dg.DiagnoseData.from_recording(rec, by="segment")
    rnd = Round(dd, loop._settle(state_from_model(truth, dd, symmetric=False), dd), loop.folds_of(dd, 5))
    (blk,) = rnd.lines()
    off = replace(blk, decay=tuple((d, 0.05) for d, _ in blk.decay))
    prop = Proposal.of(rnd, [off], [blk])
    new, hold = guard.settle_step(rnd, prop, set(), True)
    assert hold == set()                                      # not held: the free settle predicts better
    for _, dec in new.lines()[0].decay:
        assert dec == pytest.approx(0.25, rel=0.02)
    assert new.baseline_holdout()["rmse"] == pytest.approx(1e-3, rel=0.05)   # the noise floor
    held = Round(dd, guard.settle_holding(rnd.state.replaced(prop.drop, prop.add), dd, {off.uid}), rnd.fold)
    assert [d for _, d in held.lines()[0].decay] == [0.05, 0.05]
    assert held.baseline_holdout()["rmse"] > 2 * new.baseline_holdout()["rmse"]


def test_a_candidate_whose_fold_fits_diverge_is_said_so():
    """Issue 16: on the Kinova sensor column two Stribeck candidates printed 'held-out rmse 0.0969
    -> 21.25 Nm' as if a measured size; the verdict line now says the fold fits diverged.  At 1.1x
    the model's rmse (a plain rejection) nothing is added."""
    from gearspec.diagnose.results import DIVERGED

    e = Effect(kind="speed_law", name="Stribeck term (exp)", accepted=False, evidence="", rmse_holdout_before=0.0969,
               rmse_holdout_after=21.25, round=1)
    e.verdict = Verdict("rejected", "held-out", "held-out Z -0.00 below 4.62", 0.0, 4.62, -218.3, 0.005, 0.0969,
                        21.25, 1)
    line = verdict_line(e, torque_unit="Nm")
    assert "its fold fits diverge (219x the model's held-out rmse)" in line
    e.verdict = Verdict("rejected", "held-out", "held-out Z 0.1 below 4.62", 0.1, 4.62, -0.1, 0.005, 0.0969,
                        0.0969 * 1.1, 1)
    assert "diverge" not in verdict_line(e, torque_unit="Nm")
    e.verdict = Verdict("rejected", "held-out", "x", 0.0, 4.62, -9.0, 0.005, 0.1, 0.1 * (DIVERGED - 0.5), 1)
    assert "diverge" not in verdict_line(e, torque_unit="Nm")
