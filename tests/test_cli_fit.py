"""``gearspec fit`` as a user meets it: JSON per CONTRACTS.md, report with figures, bad input."""

import json
import math

import pytest

from gearspec.cli import main
from gearspec.model import FrictionModel
from gearspec.simulate import model_recording

TRUTH = {"tau_c": 0.1, "tau_s": 0.15, "v_s": 2.0, "viscous": 1e-3,
         "harmonics": [{"frequency": 0.8, "amplitude": 0.01, "decay": 0.01, "phase": 1.0, "label": "stage A"}]}
NEG = dict(TRUTH, tau_c=0.12, viscous=1.2e-3)


@pytest.fixture(scope="module")
def recording_csv(tmp_path_factory):
    truth = FrictionModel("silo4", TRUTH, NEG)
    sp = [0.5, 1, 2, 4, 8, 20, 50, 100]
    sp = sp + [-s for s in sp]
    dur = [max(1.5, 3.0 / (0.8 * abs(v))) for v in sp]
    rec, _ = model_recording(truth, sp, duration=dur, fs=500, noise=1e-3, seed=3)
    return rec.save(tmp_path_factory.mktemp("fit") / "rec.csv")


@pytest.mark.slow
def test_fit_writes_contract_json_and_report(recording_csv, tmp_path, capsys):
    out = tmp_path / "out"
    code = main(["fit", str(recording_csv), "--law", "silo4", "--lines", "0.8", "--out", str(out),
                 "--json", str(out / "fit.json"), "--folds", "4"])
    assert code == 0
    d = json.loads((out / "fit.json").read_text())
    assert d["law"] == "silo4" and d["rmse"] > 0 and d["rmse_holdout"] > 0
    for name, truth in (("positive", TRUTH), ("negative", NEG)):
        P = d["directions"][name]
        for k in ("tau_c", "tau_s", "v_s", "viscous"):
            assert P[k] == pytest.approx(truth[k], rel=0.05) and P[k + "_se"] > 0
        h = P["harmonics"][0]
        assert h["frequency"] == 0.8 and h["amplitude"] == pytest.approx(0.01, rel=0.05)
        assert h["decay"] == pytest.approx(0.01, rel=0.2)     # s/rad
    names = [r["model"] for r in d["comparison"]]
    assert "SILO4 published procedure" in names and "stribeck" in names
    for f in ("report.md", "stribeck.png", "amplitude_fit.png", "model_vs_data.png", "residuals.png", "model.json"):
        assert (out / f).stat().st_size > 0, f
    text = (out / "report.md").read_text()
    assert "held-out" in text and "mNm" in text
    # the model written can be read back and evaluated
    m = FrictionModel.from_json(out / "model.json")
    assert math.isfinite(float(m.evaluate(0.0, 1.0)[0]))
    assert "rmse_holdout" in capsys.readouterr().out


def test_lola_law_without_load_is_exit_2(recording_csv, capsys):
    assert main(["fit", str(recording_csv), "--law", "lola8", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("gearspec: error:") and "load" in err


def test_bad_lines_option_is_exit_2(recording_csv, capsys):
    assert main(["fit", str(recording_csv), "--lines", "0.8,abc", "--quiet"]) == 2
    assert "--lines" in capsys.readouterr().err


def test_heldout_rmse_is_null_with_its_reason_when_cross_validation_cannot_run(tmp_path, capsys):
    # 4 plateau speeds per direction: eq. 3 has 4 parameters, so no fold leaving a speed out can be
    # fitted; the held-out rmse is null with the reason (never the in-sample rmse), while
    # coulomb_viscous (2 parameters) is cross-validated as usual
    truth = FrictionModel("stribeck", {k: v for k, v in TRUTH.items() if k != "harmonics"})
    sp = [0.5, 2, 8, 30]
    rec, _ = model_recording(truth, sp + [-s for s in sp], duration=1.0, fs=500, noise=1e-3, seed=4)
    path = rec.save(tmp_path / "four.csv")
    js = tmp_path / "fit.json"
    assert main(["fit", str(path), "--law", "stribeck", "--no-published", "--json", str(js)]) == 0
    d = json.loads(js.read_text())
    assert d["rmse"] > 0 and d["rmse_holdout"] is None
    assert "could not run" in d["rmse_holdout_reason"] and "3 speed(s)" in d["rmse_holdout_reason"]
    comp = {r["model"]: r for r in d["comparison"]}
    cv = comp["coulomb_viscous"]
    assert cv["rmse_holdout"] > cv["rmse"] and cv["rmse_holdout_reason"] is None
    out = capsys.readouterr().out
    assert "held-out rmse n/a" in out and "3 speed(s)" in out
    m = FrictionModel.from_json(js)
    assert m.rmse_holdout is None and "could not run" in m.rmse_holdout_reason


def test_negative_viscous_coefficient_is_warned_and_flagged(tmp_path, capsys):
    # friction falling with speed over 1..20 rad/s (what a missing inertia or a lag can produce):
    # the fitted viscous coefficient is negative (-2e-3 +- ~1e-5 at this noise), and fit says so
    truth = FrictionModel("coulomb_viscous", {"tau_c": 0.1, "viscous": -2e-3})
    sp = [1, 2, 4, 8, 12, 20]
    rec, _ = model_recording(truth, sp + [-s for s in sp], duration=1.0, fs=500, noise=1e-3, seed=5)
    path = rec.save(tmp_path / "neg.csv")
    js = tmp_path / "fit.json"
    assert main(["fit", str(path), "--law", "coulomb_viscous", "--json", str(js)]) == 0
    d = json.loads(js.read_text())
    assert d["directions"]["positive"]["viscous"] == pytest.approx(-2e-3, rel=0.05)
    flags = d["meta"]["flags"]
    assert set(flags) == {"positive.viscous", "negative.viscous"}
    assert "inertia" in flags["positive.viscous"] and "too narrow" in flags["positive.viscous"]
    cap = capsys.readouterr()
    warned = [ln for ln in cap.err.splitlines() if ln.startswith("gearspec: warning:") and "negative" in ln]
    assert len(warned) == 2                     # one sentence per direction, not one per fold
    assert "warning: coulomb_viscous" in cap.out  # and in print(model)


def test_comparison_text_prints_a_missing_held_out_rmse_as_n_a_with_its_reason():
    import pandas as pd

    from gearspec.cli.fit import comparison_text

    # no model could be cross-validated (one sweep per direction): the column holds only None
    comp = pd.DataFrame({"model": ["a", "b"], "rmse": [0.5, 0.25], "rmse_holdout": [None, None],
                         "rmse_holdout_reason": ["2 segments only", "2 segments only"]})
    text = comparison_text(comp)
    assert "None" not in text
    assert [ln.split()[-1] for ln in text.splitlines()[1:3]] == ["n/a", "n/a"]
    assert "held-out rmse n/a for a: 2 segments only" in text


def test_segment_errors_cut_once_equal_the_whole_data_loop(recording_csv):
    """The fit's per-segment errors (report, residual figure) computed from the data cut into one
    piece per segment once are the rows segment_errors gives on the whole data (same samples, same
    order: equal to the last bit), and the truth's own errors are the noise: e ~ 0 within 4 se of a
    mean of n samples, rmse ~ 1e-3 (the twin's white noise)."""
    import numpy as np
    import pandas as pd

    from gearspec.identify import pipeline
    from gearspec.identify.validate import segment_errors
    from gearspec.recording import load_recording

    rec = load_recording(recording_csv)
    res = pipeline.identify_recording(rec, "coulomb_viscous", published=False, compare_with=[], folds=3)
    truth = FrictionModel("silo4", TRUTH, NEG)
    models = {**res.models, "truth": truth}
    cut = pipeline._segment_errors(models, res.data)
    assert len(cut["truth"]) == 16
    for name, m in models.items():
        pd.testing.assert_frame_equal(cut[name], segment_errors(m, res.data))
    t = cut["truth"]
    assert (np.abs(t["e"]) < 4 * 1e-3 / np.sqrt(t["n"])).all()
    assert t["rmse"].to_numpy() == pytest.approx(1e-3, rel=0.15)


def test_no_inertia_reaches_the_fit(recording_csv, monkeypatch):
    """``--no-inertia`` is a common option of every command; ``fit`` accepted it and dropped it
    (J thetadd subtracted anyway). The option must reach the data the fit reads."""
    import gearspec.identify.pipeline as pipeline

    seen = []
    real = pipeline.FitData.from_recording

    def spy(*a, **k):
        seen.append(k.get("inertia", True))
        return real(*a, **k)

    monkeypatch.setattr(pipeline.FitData, "from_recording", spy)
    assert main(["fit", str(recording_csv), "--law", "coulomb_viscous", "--no-inertia", "--quiet"]) == 0
    assert main(["fit", str(recording_csv), "--law", "coulomb_viscous", "--quiet"]) == 0
    assert seen == [False, True]


@pytest.mark.realdata
def test_silo4_on_a_gear_without_lines_says_so_not_that_the_gear_is_missing(data_dir, capsys):
    """Issue 16: `fit --law silo4 --gear emps` warned 'without a gear spec'; the spec is there and
    declares no line (a ball screw as modelled), which is what the warning now says."""
    path = data_dir / "emps" / "DATA_EMPS.mat"
    assert main(["fit", str(path), "--gear", "emps", "--map", "theta=qm,torque=vir", "--scale", "torque=gtau",
                 "--law", "silo4", "--no-published", "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "without a gear spec" not in err
    assert "declares no line and no harmonics (--lines) were given: fitting eq. 3 only" in err
