"""The closed loop on real data (GEARSPEC_DATA): the EMPS reproduction (IDIM-LS reference numbers of
SOURCE.md, then the loop judged on the cross-test) and Kinova Gen3 joint 7."""

import json

import numpy as np
import pandas as pd
import pytest
from readme_numbers import check

import gearspec.datasets as ds
import gearspec.diagnose as dg

pytestmark = pytest.mark.realdata


@pytest.mark.slow
def test_emps_reproduction(data_dir, tmp_path):
    """One test (the reproduction runs once, ~25 s): IDIM-LS replicated, the loop judged on the
    cross-test, the ball-screw line reported in cycles/m."""
    import paper_repro

    report = paper_repro.run("emps", tmp_path)
    _idim_ls_reference_numbers_replicated((tmp_path, report))
    _loop_from_the_asymmetric_model_judged_on_the_cross_test((tmp_path, report))
    _emps_ball_screw_line_reported_in_cycles_per_metre((tmp_path, report))


def _idim_ls_reference_numbers_replicated(emps_out):
    """SOURCE.md: symmetric M 95.1089, Fv 203.5034, Fc 20.3935, offset -3.1648, 4.0834 % (estimation),
    5.9824 % (cross-test); asymmetric M 95.1540, Fv+ 166.7061, Fc+ 20.1440, Fv- 240.4236, Fc- 20.6277,
    3.1117 %.  The procedure is deterministic: agreement to the printed digits (5e-5 relative,
    the rounding of the published values)."""
    out, _ = emps_out
    t1 = pd.read_csv(out / "table1_idim_ls.csv")
    assert list(t1.columns[:4]) == ["quantity", "paper", "gearspec", "rel_diff"]
    assert len(t1) == 12
    assert np.all(np.abs(t1["rel_diff"]) < 5e-5), t1
    q = dict(zip(t1["quantity"], t1["gearspec"]))
    assert q["IDIM-LS symmetric: relative error, cross-test DATA_EMPS_PULSES (%)"] == pytest.approx(5.9824, abs=5e-4)
    assert q["IDIM-LS asymmetric: relative error, estimation set DATA_EMPS (%)"] == pytest.approx(3.1117, abs=5e-4)


def _loop_from_the_asymmetric_model_judged_on_the_cross_test(emps_out):
    out, report = emps_out
    t2 = pd.read_csv(out / "table2_closed_loop.csv")
    q = dict(zip(t2["quantity"], t2["gearspec"]))
    for name in ("IDIM-LS symmetric", "IDIM-LS asymmetric (the loop's baseline)", "gearspec final model"):
        assert any(k.startswith(name) and "estimation" in k for k in q) and any(
            k.startswith(name) and "cross-test" in k for k in q)
    est_base = q["IDIM-LS asymmetric (the loop's baseline): relative error, estimation set (%)"]
    cross_base = q["IDIM-LS asymmetric (the loop's baseline): relative error, cross-test (%)"]
    est_final = q["gearspec final model: relative error, estimation set (%)"]
    cross_final = q["gearspec final model: relative error, cross-test DATA_EMPS_PULSES (%)"]
    assert est_final < est_base                 # the loop's terms explain the estimation set better ...
    assert cross_final < cross_base             # ... and carry over to the cross-test
    q1 = dict(zip(*(pd.read_csv(out / "table1_idim_ls.csv")[c] for c in ("quantity", "gearspec"))))
    idim = [q1[f"IDIM-LS {k}"] for k in ("symmetric: relative error, estimation set DATA_EMPS (%)",
                                          "asymmetric: relative error, estimation set DATA_EMPS (%)",
                                          "symmetric: relative error, cross-test DATA_EMPS_PULSES (%)")]
    check("emps-repro", "symmetric {:.4f} %, asymmetric {:.4f} %, cross-test {:.4f} %".format(*idim),
          f"set {est_base:.3f} % -> {est_final:.3f} %, cross-test {cross_base:.3f} % -> {cross_final:.3f} %")
    d = json.loads((out / "loop" / "diagnose.json").read_text())
    kept = [e for e in d["effects"] if e["accepted"]]
    assert kept and all(e["validation"]["confirmed"] for e in kept)
    # every kept term lowers the cross-test error; those that helped on held-out moves only were removed
    removed = [e for e in d["effects"] if not e["accepted"] and e.get("validation")]
    assert removed, "the cross-test removed nothing: the issue expects it to judge"
    for e in removed:
        v = e["validation"]
        assert not v["confirmed"] and "rejected by the validation data" in e["decision"]
        assert e["rmse_holdout_after"] < e["rmse_holdout_before"]      # it did help on held-out moves
    text = report.read_text()
    assert "removed by the cross-test" in text and "| quantity | paper | gearspec | rel_diff |" in text


def _emps_ball_screw_line_reported_in_cycles_per_metre(emps_out):
    out, report = emps_out
    d = json.loads((out / "loop" / "diagnose.json").read_text())
    lines = [e for e in d["effects"] if e["kind"] == "periodic"]
    assert any(abs(e["frequency"] - 400) < 4 for e in lines)          # every 2.5 mm (spectrum test: ~400)
    assert "lead is 2.5 mm" in report.read_text()


@pytest.mark.slow
def test_kinova_loop_finds_the_seven_per_motor_turn_line_growing_with_speed(data_dir, tmp_path):
    from gearspec.report.diagnose import write_diagnose_report

    d = dg.diagnose(ds.load("kinova_gen3_joint7"), law="silo4")
    assert d.data.directions() == [1]                                      # positive direction only
    per = [e for e in d.accepted if e.kind == "periodic"]
    assert per, d.trace.to_string()
    e = per[0]
    motor = 100 / (2 * np.pi)                                              # ratio 100 assumed (preset)
    assert abs(e.frequency / (7 * motor) - 1) < 0.002
    assert e.label is None and e.hint.startswith("7x motor shaft")       # a motor order, not a gear line
    h = e.terms[0]["harmonic"]
    assert h["decay"] < 0 or h["law"] == "const"                           # grows with speed (not SILO4's decay)
    assert d.final_model.rmse_holdout < d.baseline_model.rmse_holdout
    check("kinova-sensor", f"{e.frequency:.2f} cycles/rad = 7x the motor shaft",
          f"held-out rmse {d.baseline_model.rmse_holdout:.4f} -> {d.final_model.rmse_holdout:.4f} Nm")
    # the declared gear lines (2x and 4x wave generator) are in the baseline: not found again as new lines
    labels = {hh.get("label") for hh in d.baseline_model.harmonics("positive")}
    assert {"strain-wave 2x wave generator", "strain-wave 4x wave generator"} <= labels
    assert not any(x.accepted and x.kind == "periodic" and x.label in labels for x in d.effects)
    text = write_diagnose_report(d, tmp_path).read_text()
    assert "7x motor shaft" in text and "unknown order" in text and "grows with speed" in text
