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
    assert base == pytest.approx(0.2122, abs=5e-4)          # measured: the baseline of the issue
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
    assert v["rmse_after"] == pytest.approx(0.2297, abs=5e-4)   # the settled model measured before the fix
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
