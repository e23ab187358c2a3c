"""The closed loop (gearspec.diagnose): undeclared effects are found, accepted and explain the data;
complete models get nothing added.

Test data: 20 constant-speed plateaus (10 speeds per direction, 0.5-16 rad/s, in shuffled order,
alternating directions, one run -- so that time, temperature and reversals are not tied to speed),
friction from a known FrictionModel (SILO4 eq. 3 per direction, a motor-shaft line and a tooth-mesh
line) plus white noise of sigma = 1 mNm, with one undeclared effect of gearspec.simulate.effects
injected at a time.  The noise floor is the held-out rmse of the *true* structure fitted the same
way (``diagnose(rec, model=truth, max_rounds=0)``), which for white noise is sigma within 1 %.

Tolerances: a found line within 1 % of the true frequency (the fitted frequency's standard error
is ~1e-4 relative here); the final held-out rmse within 15 % of the floor (a correct term leaves
sigma * sqrt(1 + p/n) ~ 1.002 sigma; 15 % is what an effect left out or mis-shaped costs).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import gearspec.diagnose as dg
from gearspec.cli import main
from gearspec.diagnose.data import moves, travel_since_reversal
from gearspec.gears import GearTrain, integer_hint, load_gear
from gearspec.model import FrictionModel
from gearspec.recording import Recording
from gearspec.simulate import effects as fx
from gearspec.simulate import model_recording, silo4_twin, table2_model, twin_gear
from gearspec.signals import decimate, decimation_index

SIGMA = 1e-3
GEAR = GearTrain.from_dict({"name": "test drive", "reference": "motor", "unit": "rad",
                            "stages": [{"name": "spur", "kind": "spur", "ratio": 10, "teeth": 17}]})
F_MOTOR = 1 / (2 * np.pi)
_mag = np.geomspace(0.5, 16, 10)
_rng = np.random.default_rng(7)
SPEEDS = [x for a, b in zip(_rng.permutation(_mag), _rng.permutation(_mag)) for x in (a, -b)]


def truth(symmetric: bool = False, amp: float = 5e-3) -> FrictionModel:
    def lines(a, ph):
        return [{"frequency": F_MOTOR, "amplitude": a, "decay": 0.05, "phase": ph, "label": "motor shaft"},
                {"frequency": 17 * F_MOTOR, "amplitude": 0.6 * a, "decay": 0.15, "phase": ph + 1,
                 "label": "spur tooth mesh"}]
    pos = {"tau_c": 0.05, "tau_s": 0.08, "v_s": 1.5, "viscous": 2e-3, "harmonics": lines(amp, 0.3)}
    neg = dict(pos) if symmetric else {"tau_c": 0.055, "tau_s": 0.085, "v_s": 1.5, "viscous": 2.2e-3,
                                       "harmonics": lines(0.8 * amp, 1.0)}
    return FrictionModel("silo4", pos, neg, name="truth")


def recording(effects=(), *, seed=0, symmetric=False, amp=5e-3, **kw):
    model = fx.apply_effects(truth(symmetric, amp), effects)
    rec, _ = model_recording(model, SPEEDS, noise=SIGMA, gear=GEAR, seed=seed, duration=1.5, fs=500.0,
                             one_run_per_plateau=False, **kw)
    return rec, model


def exact_recording(model, *, ripple=0.02, ripple_hz=3.0, seed=0, plateaus_per_run=1):
    """Plateaus with a speed oscillation in time and exact kinematics (theta, velocity and
    acceleration analytic): for the inertia effect, which needs accelerations the position agrees
    with to the last digit."""
    rng = np.random.default_rng(seed)
    cols = {"t": [], "theta": [], "v": [], "acc": [], "run": []}
    for k, v in enumerate(SPEEDS):
        t = np.arange(750) / 500.0
        w = 2 * np.pi * ripple_hz
        ph = rng.uniform(0, 2 * np.pi)
        cols["t"].append(t + 2.0 * (k % plateaus_per_run))
        cols["theta"].append(v * t + ripple * abs(v) / w * (np.sin(w * t + ph) - np.sin(ph)) + rng.uniform(0, 6))
        cols["v"].append(v + ripple * abs(v) * np.cos(w * t + ph))
        cols["acc"].append(-ripple * abs(v) * w * np.sin(w * t + ph))
        cols["run"].append(np.full(len(t), k // plateaus_per_run))
    t, th, v, a, run = (np.concatenate(cols[c]) for c in ("t", "theta", "v", "acc", "run"))
    tau = model.evaluate(th, v, t=t, acc=a, run=run) + rng.normal(0, SIGMA, len(t))
    return Recording.from_arrays(t=t, theta=th, torque=tau, run=run, gear=GEAR, source="synthetic")


def floor_model(rec, model, **kw) -> FrictionModel:
    """The true structure, fitted as the loop fits everything."""
    return dg.diagnose(rec, model=model, max_rounds=0, **kw).baseline_model


def floor(rec, model, **kw) -> float:
    """Held-out rmse of the true structure, fitted as the loop fits everything."""
    return floor_model(rec, model, **kw).rmse_holdout


def check(d, kind, model, rec, *, frequency=None, symmetric=None):
    found = [e for e in d.accepted if e.kind == kind]
    assert found, f"no accepted {kind} effect; trace:\n{d.trace.to_string()}"
    if frequency is not None:
        assert any(e.frequency and abs(e.frequency / frequency - 1) < 0.01 for e in found), \
            [e.frequency for e in found]
    fl = floor(rec, model, symmetric=symmetric)
    assert fl == pytest.approx(SIGMA, rel=0.05)
    assert d.final_model.rmse_holdout <= 1.15 * fl, (d.final_model.rmse_holdout, fl)
    assert d.baseline_model.rmse_holdout > d.final_model.rmse_holdout
    return found


# ---------------------------------------------------------------------- one effect kind at a time
@pytest.mark.slow
def test_periodic_cogging_unknown_order_with_integer_hint():
    rec, model = recording([fx.cogging(count=7, amplitude=1e-3)])
    d = dg.diagnose(rec, law="silo4", gear=GEAR)
    (e,) = check(d, "periodic", model, rec, frequency=7 * F_MOTOR)
    assert e.label is None and e.hint == "7x motor shaft"          # unknown order, integer relation suggested
    # a signed cogging torque shows in the friction magnitude with opposite phases in the two directions
    h = {t["direction"]: t["harmonic"] for t in e.terms}
    assert abs(abs(np.angle(np.exp(1j * (h["positive"]["phase"] - h["negative"]["phase"])))) - np.pi) < 0.1
    assert all(hh["law"] == "const" for hh in h.values())


@pytest.mark.slow
def test_periodic_decaying_line_gets_its_amplitude_law_from_the_data():
    rec, model = recording([fx.extra_order(frequency=0.7, amplitude=3e-3, decay=0.15, law="exp")])
    d = dg.diagnose(rec, law="silo4", gear=GEAR)
    (e,) = check(d, "periodic", model, rec, frequency=0.7)
    for t in e.terms:
        h = t["harmonic"]
        assert h["law"] in ("exp", "rational", "power") and h["decay"] > 0     # a decaying law, not a constant
        assert h["amplitude"] == pytest.approx(3e-3, rel=0.1)


@pytest.mark.slow
def test_speed_law_nonlinear_viscous():
    """8e-3 |v|^0.5 added to SILO4 eq. 3.  Over 0.5-16 rad/s a c|v|^p term and an extra Stribeck
    term (negative amplitude) fit these 20 plateaus to within 1e-6 of the held-out rmse of each
    other, so the loop may accept either family (on seed 0 it takes the rational Stribeck term);
    what it must get right is the speed law it ends with: the final model's friction at every
    plateau speed equals the truth's."""
    rec, model = recording([fx.nonlinear_viscous(coefficient=8e-3, exponent=0.5)])
    d = dg.diagnose(rec, law="silo4", gear=GEAR)
    check(d, "speed_law", model, rec)
    assert {e.kind for e in d.accepted} == {"speed_law"}
    speeds = np.sort(np.abs(SPEEDS[::2]))
    for direction in ("positive", "negative"):
        true = model.mean_level(speeds, direction)
        # 4 x the standard error of one plateau's mean (sigma / sqrt(750 samples) = 3.7e-5): a curve of
        # 6 parameters through 10 plateau means is no worse than one mean; the baseline alone is 4e-4 off
        assert d.final_model.mean_level(speeds, direction) == pytest.approx(true, abs=4 * SIGMA / np.sqrt(750))
        assert np.max(np.abs(d.baseline_model.mean_level(speeds, direction) - true)) > 2.5e-4
    # the true structure refitted (c|v|^p, p free) finds the exponent within 4 of its standard errors
    (term,) = floor_model(rec, model).terms
    assert term["kind"] == "viscous_power"
    assert abs(term["exponent"] - 0.5) < 4 * term["exponent_se"]


@pytest.mark.slow
def test_speed_law_amplitude_decay_of_a_declared_line():
    rec, model = recording([fx.decay_shape(target="spur tooth mesh", law="rational", decay=0.25, direction=1)],
                           amp=1.5e-2)
    d = dg.diagnose(rec, law="silo4", gear=GEAR)
    (e,) = check(d, "speed_law", model, rec)
    assert "spur tooth mesh" in e.name and "positive" in e.name
    h = next(t["harmonic"] for t in e.terms if t["direction"] == "positive" and t["harmonic"].get("label") ==
             "spur tooth mesh")
    assert h["law"] == "rational" and h["decay"] == pytest.approx(0.25, rel=0.1)


@pytest.mark.slow
def test_load_meshing_amplitude_eq14():
    loads = [0, 5, 10, 15, 20] * 4
    rec, model = recording([fx.load_meshing(target="motor shaft", coefficient=5e-5)], load=loads)
    d = dg.diagnose(rec, law="silo4", gear=GEAR)
    (e,) = check(d, "load", model, rec)
    k = [t["harmonic"]["load_coefficient"] for t in e.terms]
    assert k == pytest.approx([5e-5, 5e-5], rel=0.05)


@pytest.mark.slow
def test_temperature():
    eff = [fx.warming(coefficient=-4e-4, rise=15, time_constant=10.0)]
    rec, model = recording(eff, temperature=fx.channel_function(eff, "temperature"))
    d = dg.diagnose(rec, law="silo4", gear=GEAR)
    (e,) = check(d, "temperature", model, rec)
    assert e.terms[0]["term"]["coefficient"] == pytest.approx(-4e-4, rel=0.05)
    drift = [x for x in d.effects if x.kind == "drift"]
    assert not any(x.accepted for x in drift)         # the recorded temperature explains it, not time


@pytest.mark.slow
def test_drift():
    rec, model = recording([fx.drift(coefficient=2e-4)])
    d = dg.diagnose(rec, law="silo4", gear=GEAR)
    (e,) = check(d, "drift", model, rec)
    assert e.terms[0]["term"]["coefficient"] == pytest.approx(2e-4, rel=0.05)


def test_asymmetry_of_a_symmetric_model():
    rec, model = recording([fx.asymmetry(parameter="tau_c", factor=1.15, direction=-1)], symmetric=True)
    d = dg.diagnose(rec, law="silo4", gear=GEAR, symmetric=True)
    (e,) = check(d, "asymmetry", model, rec, symmetric=False)
    assert "tau_c" in e.name
    p, n = d.final_model.directions["positive"], d.final_model.directions["negative"]
    assert n["tau_c"] - p["tau_c"] == pytest.approx(0.15 * 0.05, rel=0.05)


def test_inertia():
    model = fx.apply_effects(truth(), [fx.extra_inertia(inertia=2e-3)])
    rec = exact_recording(model)
    d = dg.diagnose(rec, law="silo4", gear=GEAR)
    (e,) = check(d, "inertia", model, rec)
    assert e.terms[0]["term"]["inertia"] == pytest.approx(2e-3, rel=0.02)


@pytest.mark.parametrize("effect,param", [(fx.hysteresis(scale=8e-3, length=1.0), ("length", 1.0)),
                                          (fx.backlash(scale=4e-3, gap=0.4), ("gap", 0.4))],
                         ids=["presliding", "backlash"])
@pytest.mark.slow
def test_hysteresis_near_reversals(effect, param):
    rec, model = recording([effect])
    d = dg.diagnose(rec, law="silo4", gear=GEAR)
    found = check(d, "hysteresis", model, rec)
    terms = [t["term"] for e in found for t in e.terms]
    assert any(t["kind"] == effect.apply(truth()).terms[-1]["kind"] and
               t[param[0]] == pytest.approx(param[1], rel=0.1) for t in terms), terms


@pytest.mark.slow
def test_twin_cogging_found_in_the_closed_loop_silo4_twin():
    """The SILO4 joint-3 twin (closed-loop speed control, encoder, Bessel-filtered and sampled
    current, 1 % friction scatter between repetitions) with undeclared cogging: found within 1 %
    of 7 per motor turn, hinted as such, and the held-out error at (or below) that of the true
    structure."""
    speeds = [s * d for s in (200, 500, 1200, 3000, 6000) for d in (1, -1)]
    eff = [fx.cogging(count=7, amplitude=3e-4)]
    rec, _ = silo4_twin(speeds, repetitions=2, effects=eff, duration=2.0, seed=1)
    rec.gear = twin_gear()
    d = dg.diagnose(rec, law="silo4", gear=twin_gear())
    per = [e for e in d.accepted if e.kind == "periodic"]
    assert per and abs(per[0].frequency / (7 * F_MOTOR) - 1) < 0.01
    assert per[0].hint == "7x motor shaft"
    fl = floor(rec, fx.apply_effects(table2_model(), eff))
    assert d.final_model.rmse_holdout <= 1.15 * fl


# ---------------------------------------------------------------------- several at once
@pytest.mark.slow
def test_several_effects_in_one_recording_are_all_found():
    eff = [fx.cogging(count=7, amplitude=1e-3), fx.drift(coefficient=1e-4), fx.hysteresis(scale=5e-3, length=1.0)]
    rec, model = recording(eff)
    d = dg.diagnose(rec, law="silo4", gear=GEAR)
    kinds = sorted(e.kind for e in d.accepted)
    assert kinds == ["drift", "hysteresis", "periodic"], d.trace.to_string()
    per = next(e for e in d.accepted if e.kind == "periodic")
    assert abs(per.frequency / (7 * F_MOTOR) - 1) < 0.01
    assert d.final_model.rmse_holdout <= 1.15 * floor(rec, model)


# ---------------------------------------------------------------------- no false discoveries
FDR_SEEDS = 16


@pytest.mark.slow
def test_complete_models_get_nothing_added_over_many_seeds():
    """False-discovery rate: on recordings whose model is complete (the baseline law is the truth's
    law, every line declared), over FDR_SEEDS seeds; the rule is built for alpha = 1 % per round
    (family-wise over the round's candidates).  The longer run of the README's design notes gave
    1 false discovery in 100 recordings (four designs x 25 seeds); here at most one acceptance is
    allowed among the seeds (binomial: at a true rate of 1 %, P(>= 2 of 16) = 1.1 %)."""
    accepted = []
    for seed in range(1000, 1000 + FDR_SEEDS):
        rec, _ = recording([], seed=seed)
        d = dg.diagnose(rec, law="silo4", gear=GEAR, per_segment_spectra=False)
        accepted.append([e.name for e in d.accepted])
        assert d.final_model.rmse_holdout <= d.baseline_model.rmse_holdout * 1.0001
    n_false = sum(1 for a in accepted if a)
    print(f"false discoveries: {n_false} of {FDR_SEEDS} seeds ({accepted})")
    assert n_false <= 1, accepted


def test_nothing_added_when_the_effect_is_declared():
    """The same recording as the cogging test, with the cogging declared in the model: nothing."""
    rec, model = recording([fx.cogging(count=7, amplitude=1e-3)])
    d = dg.diagnose(rec, model=model)
    assert not d.accepted, d.trace.to_string()


# ---------------------------------------------------------------------- pieces
def test_residual_analysis_of_any_fitted_model():
    """A model without the drift, against a recording with it: the time analysis sees it, the
    acceleration and spectrum analyses see nothing of note; the true model leaves nothing."""
    rec, full = recording([fx.drift(coefficient=2e-4)])
    a = dg.residual_analysis(truth(), rec)
    assert a["t"][1]["p"] < 1e-6 and a["t"][1]["both"]["slope"] == pytest.approx(2e-4, rel=0.1)
    assert a["acc"][1]["p"] > 1e-3
    b = dg.residual_analysis(full, rec)
    assert b["t"][1]["p"] > 1e-3
    assert np.std(b["residual"]) == pytest.approx(SIGMA, rel=0.05)
    assert all(len(s.peaks) <= 1 for s in b["spectra"]["pooled"])


def test_travel_since_reversal_and_moves():
    theta = np.array([0, 1, 2, 3, 2.5, 2, 1, 1.5, 2.0])
    v = np.array([1, 1, 1, 1, -1, -1, -1, 1, 1])
    tr = travel_since_reversal(theta, v)
    assert np.all(np.isinf(tr[:4]))
    assert tr[4:7] == pytest.approx([0.5, 1.0, 2.0])      # from the turning point at 3
    assert tr[7:] == pytest.approx([0.5, 1.0])             # from the turning point at 1
    mv = moves(np.array([0, 1, 1, 0, 0, 1, 1, 0, -1, -1]), min_speed=0.5)
    assert list(mv) == [0, 0, 0, 0, 0, 1, 1, 1, 2, 2]


def test_decimate_matches_matlab_alignment():
    idx = decimation_index(24792, 10)
    assert idx[0] == 1 and idx[-1] == 24791                # MATLAB keeps the last sample
    x = np.sin(np.linspace(0, 20, 2000))   # far below the cut-off: passes within the Chebyshev ripple
    # (0.05 dB each way of filtfilt: 1.2 %); the exact numbers are checked against EMPS's reference
    assert decimate(x, 10) == pytest.approx(x[decimation_index(2000, 10)], abs=0.02)


def test_integer_hint_is_public_and_conservative():
    g = load_gear("kinova-gen3-joint7")
    assert integer_hint(g, 700 / (2 * np.pi), 0.05).startswith("7x motor shaft")
    assert integer_hint(g, 707 / (2 * np.pi), 0.05) is None


def test_json_contract_and_model_round_trip(tmp_path):
    rec, model = recording([fx.cogging(count=7, amplitude=1e-3)])
    d = dg.diagnose(rec, law="silo4", gear=GEAR, max_rounds=1)
    out = d.to_dict()
    json.dumps(out, default=float)
    assert set(out["baseline"]) >= {"model", "rmse", "rmse_holdout"}
    assert set(out["final"]) >= {"model", "rmse", "rmse_holdout"}
    for e in out["effects"]:
        assert set(e) >= {"kind", "accepted", "frequency", "label", "evidence", "rmse_holdout_before",
                          "rmse_holdout_after"}
        assert e["kind"] in dg.KINDS
    # the final model evaluates as the loop fitted it
    m = FrictionModel.from_json(d.final_model.to_json(tmp_path / "m.json"))
    pred = dg.predict_model(m, d.data)
    assert np.sqrt(np.mean((d.data.y - pred) ** 2)) == pytest.approx(d.final.rmse, rel=1e-6)


# ---------------------------------------------------------------------- command line
@pytest.mark.slow
def test_cli_diagnose_writes_report_and_json(tmp_path, capsys, monkeypatch):
    import matplotlib.image as mpimg
    import pandas as pd

    import gearspec.plots.diagnose as dplots

    figures, save = {}, dplots.save

    def keep(fig, path):                                   # the figures as drawn, then saved as ever
        figures[Path(path).name] = fig
        return save(fig, path)

    monkeypatch.setattr(dplots, "save", keep)
    rec, _ = recording([fx.cogging(count=7, amplitude=1e-3)])
    path = rec.save(tmp_path / "run.csv")
    spec = tmp_path / "drive.toml"
    spec.write_text('name = "test drive"\nreference = "motor"\nunit = "rad"\n[[stages]]\nname = "spur"\n'
                    'kind = "spur"\nratio = 10\nteeth = 17\n')
    rc = main(["diagnose", str(path), "--gear", str(spec), "--out", str(tmp_path / "rep"), "--json",
               str(tmp_path / "d.json"), "--max-rounds", "2"])
    assert rc == 0
    d = json.loads((tmp_path / "d.json").read_text())
    per = [e for e in d["effects"] if e["accepted"] and e["kind"] == "periodic"]
    assert per and abs(per[0]["frequency"] / (7 * F_MOTOR) - 1) < 0.01 and per[0]["label"] is None
    assert d["final"]["rmse_holdout"] < d["baseline"]["rmse_holdout"]
    report = (tmp_path / "rep" / "report.md").read_text()
    assert "7x motor shaft" in report and "## Candidates not accepted" in report
    for png in ("residual_spectra.png", "segment_errors.png"):
        img = mpimg.imread(tmp_path / "rep" / png)        # a picture, not a blank page
        assert img.ndim == 3 and min(img.shape[:2]) > 300 and img[..., :3].std() > 0.05
    assert "ACCEPTED periodic" in capsys.readouterr().out
    # the residual spectra: one panel per direction, log-log, units on the axes, every candidate line
    # marked (the accepted one green) inside the frequency range drawn
    fig = figures["residual_spectra.png"]
    assert len(fig.axes) == 2
    assert fig.axes[-1].get_xlabel() == "frequency (cycles/rad)"
    cands = [e["frequency"] for e in d["effects"] if e["frequency"]]
    for ax, direction in zip(fig.axes, ("positive", "negative")):
        assert ax.get_ylabel() == "amplitude (Nm)" and ax.get_xscale() == ax.get_yscale() == "log"
        assert direction in ax.get_title()
        lo, hi = ax.get_xlim()
        assert all(lo < f < hi for f in cands)
        marks = [ln for ln in ax.get_lines() if len(ln.get_xdata()) == 2 and ln.get_xdata()[0] == ln.get_xdata()[1]]
        assert sorted(float(ln.get_xdata()[0]) for ln in marks) == pytest.approx(sorted(cands), rel=1e-12)
        assert {ln.get_color() for ln in marks if abs(ln.get_xdata()[0] / (7 * F_MOTOR) - 1) < 0.01} == {"tab:green"}
        # the baseline's residual holds the whole cogging line: its peak within 1 % of 7 x the motor
        # shaft is the cogging amplitude, 1 mNm, within 12 %: 4 x the white-noise amplitude level
        # sqrt(4 / N) sigma = 2.3e-5 (N = 7500 samples a direction) plus 2 % for a peak read on the
        # oversampled grid
        x, y = (np.asarray(a) for a in (ax.get_lines()[0].get_xdata(), ax.get_lines()[0].get_ydata()))
        near = np.abs(x / (7 * F_MOTOR) - 1) < 0.01
        assert np.max(y[near]) == pytest.approx(1e-3, rel=0.12)
    # the held-out error per group: the table written beside it, drawn as it is; after the loop every
    # group's held-out rmse is the noise, 1 mNm (within 15 %, the tolerance of this file)
    fig = figures["segment_errors.png"]
    seg = pd.read_csv(tmp_path / "rep" / "segments.csv")
    assert len(fig.axes) == 2 and fig.axes[0].get_ylabel() == "rmse (Nm)"
    for ax, direction in zip(fig.axes, (1, -1)):
        assert ax.get_xlabel() == "speed (rad/s)"
        t = seg[seg["direction"] == direction].sort_values("speed")
        assert len(t) == 10
        for ln, col in zip(ax.get_lines(), ("rmse_holdout_before", "rmse_holdout_after", "rmse_after")):
            assert np.allclose(ln.get_xdata(), t["speed"]) and np.allclose(ln.get_ydata(), t[col])
        assert np.all(np.abs(t["rmse_holdout_after"] / SIGMA - 1) < 0.15)
        assert np.all(t["rmse_holdout_before"] > t["rmse_holdout_after"])


@pytest.mark.parametrize("args,needle", [
    (["--folds", "1"], "--folds"),
    (["--kinds", "periodic,magic"], "unknown kind"),
    (["--model", "nonexistent.json"], "not a friction model"),
])
def test_cli_bad_input_exits_2_with_one_message(tmp_path, capsys, args, needle):
    rec, _ = recording([])
    path = rec.save(tmp_path / "run.csv")
    rc = main(["diagnose", str(path), "--gear", "silo4-joint3", "--quiet"] + args)
    err = capsys.readouterr().err
    assert rc == 2 and needle in err and err.count("\n") == 1


def test_found_line_law_only_from_measurable_segments_and_held_outside():
    """A 72-per-turn line measurable (below 0.8 x the position Nyquist) at 6..26 rad/s only, gone
    at 40..56 (the logger's filter): the loop finds it, fits its amplitude law at 6..26 rad/s only,
    records that range, and the final model holds the amplitude at the edge outside it."""
    from test_identify import F_COG, aliased_line_recording

    rec = aliased_line_recording()
    diag = dg.diagnose(rec, law="coulomb_viscous", by="run", kinds=["periodic"])
    fm = diag.final_model
    for d, s in (("positive", 1), ("negative", -1)):
        h = next(h for h in fm.harmonics(d) if abs(h["frequency"] - F_COG) < 1e-3 * F_COG)
        assert h["speed_range"] == pytest.approx([6.0, 26.0], rel=1e-9)
        th = np.linspace(0, 1, 200)
        # the line alone: half the difference of the model half a line period apart
        line = lambda v: (fm.evaluate(th, np.full(200, s * v)) - fm.evaluate(th + 0.5 / F_COG, np.full(200, s * v))) / 2  # noqa
        amp = lambda v: np.sqrt(2 * np.mean(line(v) ** 2))  # noqa: E731
        # truth at the edges: 5e-3 exp(-0.03 * 6) = 4.18e-3 and 5e-3 exp(-0.03 * 26) = 2.29e-3 (10 % for noise)
        assert amp(6.0) == pytest.approx(5e-3 * np.exp(-0.03 * 6), rel=0.1)
        assert amp(26.0) == pytest.approx(5e-3 * np.exp(-0.03 * 26), rel=0.1)
        assert np.allclose(line(1e-9), line(6.0), rtol=1e-12, atol=0)
        assert np.allclose(line(56.0), line(26.0), rtol=1e-12, atol=0)


def test_line_with_denormal_amplitude_writes_finite_standard_errors():
    # fuzz finding: a denormal amplitude squared to 0 in the phase standard error (ZeroDivisionError)
    from gearspec.diagnose.design import HarmonicBlock
    m = FrictionModel("none", {"harmonics": []})
    blk = HarmonicBlock(frequency=2.0, dirs=(1,), law=((1, "const"),), decay=((1, 0.0),))
    blk.write(m, np.array([3e-310, 4e-310]), np.array([1e-311, 1e-311]))
    h = m.harmonics("positive")[0]
    assert h["amplitude"] == pytest.approx(5e-310, rel=1e-6)
    assert h["amplitude_se"] == pytest.approx(1e-311, rel=1e-6)    # |(a, c)/A| . (sa, sc) with sa = sc
    assert h["phase_se"] == pytest.approx(1e-311 / 5e-310, rel=1e-6)


def test_a_removed_term_is_not_accepted_again_on_the_same_evidence(monkeypatch):
    """Accept/eliminate cycling: a backward elimination that takes every earlier term out once a
    new one is in (forced here) makes the loop add and remove the same two terms round after round.
    The re-entry rule: a removed term comes back only with a larger held-out Z than it was accepted
    with, at most once; the loop then stops instead of cycling until max_rounds."""
    from gearspec.diagnose import loop
    from gearspec.simulate import model_recording

    def remove_all_earlier(rnd, effects, newest, *, z_crit, min_gain, round_no):
        out = None
        for e in [x for x in effects.values() if x.accepted and x is not newest]:
            out = rnd = loop.Round(rnd.dd, rnd.state.replaced(e.detail["blocks"], e.detail.get("dropped", [])),
                                   rnd.fold)
            e.accepted = False
            e.detail.setdefault("removed", []).append(round_no)
            e.decision = f"removed in round {round_no} (forced)"
        return out

    monkeypatch.setattr(loop, "_backward", remove_all_earlier)
    model = fx.apply_effects(truth(), [fx.cogging(count=7, amplitude=3e-3), fx.drift(coefficient=5e-4)])
    rec, _ = model_recording(model, SPEEDS[:12], noise=SIGMA, gear=GEAR, seed=0, duration=1.0, fs=500.0,
                             one_run_per_plateau=False)
    d = dg.diagnose(rec, law="silo4", kinds=["periodic", "drift"], max_rounds=6)
    accepted_rounds = [r for r in d.rounds if r.get("accepted")]
    assert len(accepted_rounds) < 6                  # it stopped; it did not cycle until max_rounds
    for e in d.effects:
        assert sum("accepted" in h for h in e.history) <= 1 + loop.MAX_REENTRIES, e.history
    barred = [e for e in d.effects if e.status == "removed"]
    assert barred and "not accepted again" in barred[0].decision
    # the final held-out rmse is the model's as it stood after the last step; the step's own figure
    # (the candidate's search re-run per fold) differs, and a note says why
    last = accepted_rounds[-1]
    assert d.final_model.rmse_holdout == pytest.approx(last["rmse_holdout_model"], rel=1e-12)
    if not np.isclose(last["rmse_holdout_step"], d.final_model.rmse_holdout, rtol=1e-9):
        assert any("last accepted step" in n for n in d.notes)


def test_z_gate_with_few_groups_says_the_test_has_little_power():
    from scipy import stats

    from gearspec.diagnose.loop import low_power_note

    # 6 candidates at alpha 1 %: t quantiles 17.3 (3 groups), 6.3 (5 groups), 3.1 (40 groups);
    # the normal quantile of the same level is 2.9
    def zc(groups):
        return float(stats.t.isf(0.01 / 6, groups - 1))

    assert "with 3 held-out groups the test cannot reach significance" in low_power_note(zc(3), 3)
    assert "with 5 held-out groups the test has little power" in low_power_note(zc(5), 5)
    assert low_power_note(zc(40), 40) == ""
    # in the loop: a small missing inertia (3e-5 kg m^2) held out by 4 runs of 5 plateaus; the rejection
    # names the failed gates and the power of the Z gate, and the printed summary shows it
    model = fx.apply_effects(truth(), [fx.extra_inertia(inertia=3e-5)])
    rec = exact_recording(model, plateaus_per_run=5)
    d = dg.diagnose(rec, law="silo4", by="run", kinds=["inertia"])
    (e,) = d.effects
    assert e.status == "rejected" and "held-out Z" in e.decision
    assert "with 4 held-out groups the test has little power" in e.decision


# ---------------------------------------------------------------------- one decision record
def test_one_reason_the_gate_that_decided_z_passes_but_the_gain_does_not():
    """The issue's inertia case: a term whose held-out Z passes but whose rmse gain is below the
    margin is rejected with that one reason (not the Z).  A strong cogging line (3 mNm over 1 mNm
    of noise: Z ~ 50 on 20 plateaus) against a margin raised to 99 % (the held-out rmse cannot fall
    by 99 %: it falls by ~ 1 - 1 / sqrt(1 + 4.5) ~ 57 %)."""
    rec, _ = recording([fx.cogging(count=7, amplitude=3e-3)])
    d = dg.diagnose(rec, law="silo4", gear=GEAR, kinds=["periodic"], min_gain=0.99, max_rounds=1)
    line = next(e for e in d.effects if e.frequency and abs(e.frequency / (7 * F_MOTOR) - 1) < 0.01)
    v = line.verdict
    assert line.status == v.status == "rejected" and v.test == "held-out"
    assert v.z >= v.z_crit and 0.3 < v.gain < 0.99                         # Z passed; the gain decided
    assert v.reason.startswith("held-out rmse changes by") and "needs a fall of 99 %" in v.reason
    assert "held-out Z" not in v.reason
    # the same record in the JSON, with the rendered line
    j = next(x for x in d.to_dict()["effects"] if x["name"] == line.name)["verdict"]
    assert j["reason"] == v.reason and j["z"] == pytest.approx(v.z) and j["line"].startswith("rejected")
    # two gates failing (consistency asked above 100 %, gain 99 %): the one reason is the first of them in
    # the order Z, consistency, gain; the full decision keeps both
    from gearspec.diagnose import loop
    from gearspec.diagnose.candidates import FixedCandidate
    from gearspec.diagnose.design import HarmonicBlock

    blk = HarmonicBlock(key="cogging", frequency=7 * F_MOTOR, dirs=(1, -1), law=((1, "const"), (-1, "const")),
                        decay=((1, 0.0), (-1, 0.0)))
    ev = loop.evaluate_candidate(loop.Round(d.data, d.baseline.state, d.folds), FixedCandidate("periodic", "c", [blk]),
                                 z_crit=3.0, min_gain=0.99, consistency=1.01, repolish=False)
    assert ev.z > 3.0 and not ev.passed
    assert ev.gate.startswith("improves in folds carrying only") and "rmse" not in ev.gate
    assert "needs a fall of 99 %" in ev.reason and ev.verdict("rejected", None, 1).reason == ev.gate


@pytest.mark.slow
def test_console_report_and_json_show_one_decision_and_the_final_numbers(tmp_path, capsys):
    """The issue's EMPS case on a known twin: a cogging line in the estimation recording and not in
    the independent one passes the held-out test, then the validation data remove it.  Every effect's
    decision line is printed, written in the report and in the JSON identically; a removed term is
    never shown as accepted with the same numbers; the terms every accepted effect lists are the
    final model's numbers (final_model.json)."""
    rec, _ = recording([fx.cogging(count=7, amplitude=1e-3), fx.drift(coefficient=2e-4)])
    val, _ = recording([fx.drift(coefficient=2e-4)], seed=5)
    spec = tmp_path / "drive.toml"
    spec.write_text('name = "test drive"\nreference = "motor"\nunit = "rad"\n[[stages]]\nname = "spur"\n'
                    'kind = "spur"\nratio = 10\nteeth = 17\n')
    rc = main(["diagnose", str(rec.save(tmp_path / "est.csv")), "--gear", str(spec), "--kinds", "periodic,drift",
               "--validate", str(val.save(tmp_path / "val.csv")), "--out", str(tmp_path / "rep"),
               "--json", str(tmp_path / "d.json"), "--max-rounds", "3"])
    assert rc == 0
    out = capsys.readouterr().out
    d = json.loads((tmp_path / "d.json").read_text())
    report = " ".join((tmp_path / "rep" / "report.md").read_text().split())
    for e in d["effects"]:
        v = e["verdict"]
        assert v["status"] == e["status"] and v["line"] in out and " ".join(v["line"].split()) in report
    cog = next(e for e in d["effects"] if e["frequency"] and abs(e["frequency"] / (7 * F_MOTOR) - 1) < 0.01)
    assert cog["status"] == "removed" and cog["verdict"]["test"] == "validation"
    assert cog["verdict"]["z"] == pytest.approx(cog["validation"]["z"])          # the deciding test's Z ...
    assert cog["verdict"]["z"] < cog["verdict"]["z_crit"]                        # ... which it failed
    assert cog["verdict"]["line"].startswith("removed") and "ACCEPTED periodic" not in out
    assert "validation: removed " + cog["name"] in out                 # the progress says so when it happens
    drift = next(e for e in d["effects"] if e["kind"] == "drift")
    assert drift["status"] == "accepted" and "confirmed on the independent recording" in drift["verdict"]["line"]
    final = json.loads((tmp_path / "rep" / "final_model.json").read_text())
    (t,) = drift["terms"]
    (ft,) = [x for x in final["terms"] if x["kind"] == t["term"]["kind"]]
    assert ft["coefficient"] == t["term"]["coefficient"]                 # the final model's number, exactly
    assert t["term"]["coefficient"] == pytest.approx(2e-4, rel=0.05)
