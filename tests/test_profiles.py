"""Velocity profiles (gearspec.simulate.profiles), the twins driven by them, motion_recording and
the ``simulate --profile`` command line, against known answers: the shapes' closed forms (travel of
a minimum-jerk move, zero crossings of a chirp, held speeds), the exact trapezoid identity between
position and velocity, the model's own torque, the closed loop's tracking error, and the plateau
twins' output as it was before profiles existed."""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest
from scipy import signal

from gearspec.cli import main
from gearspec.errors import InputError
from gearspec.model import RPM, FrictionModel
from gearspec.simulate import PROFILES, lola_twin, motion_recording, silo4_twin, table2_model, velocity_profile
from gearspec.simulate.lola import MODULES, TESTBED, table4_model
from gearspec.simulate.silo4 import PAPER_TABLE2, PLANT
from gearspec.simulate.profiles import position

TOP, DUR = 100.0, 40.0


# ---------------------------------------------------------------------- the profiles
@pytest.mark.parametrize("fs", [1000.0, 250.0])
@pytest.mark.parametrize("kind", PROFILES)
def test_every_profile_rests_at_both_ends_and_reaches_the_top_both_ways(kind, fs):
    t, v = velocity_profile(kind, top_speed=TOP, duration=DUR, fs=fs)
    assert len(t) == round(DUR * fs) + 1 and t[-1] == pytest.approx(DUR) and np.allclose(np.diff(t), 1 / fs)
    assert v[0] == 0 and abs(v[-1]) < 1e-12 * TOP                       # starts and ends at rest
    # the sampled top within 1 % each way (the brief's tolerance; a move spans >= 20 samples)
    assert v.max() == pytest.approx(TOP, rel=0.01) and v.min() == pytest.approx(-TOP, rel=0.01)
    assert np.abs(v).max() <= TOP * (1 + 1e-12)
    # every tenth of the speed range is visited in both directions (a friction law over speed)
    for sign in (1, -1):
        bins = np.floor(10 * np.clip(sign * v[sign * v > 0] / TOP, 0, 0.999)).astype(int)
        assert set(bins) == set(range(10)), (kind, sign)


@pytest.mark.parametrize("kind", PROFILES)
def test_position_is_the_trapezoid_integral_of_the_velocity(kind):
    fs = 500.0
    _, v = velocity_profile(kind, top_speed=TOP, duration=DUR, fs=fs)
    theta = position(v, fs, theta0=1.5)
    assert theta[0] == 1.5
    # exact identity of the trapezoid rule: (theta[i+1] - theta[i-1]) / 2dt = v[i] + (v[i-1] - 2 v[i] + v[i+1]) / 4
    central = (theta[2:] - theta[:-2]) * fs / 2
    assert np.allclose(central - v[1:-1], (v[:-2] - 2 * v[1:-1] + v[2:]) / 4, atol=1e-9 * TOP)
    if kind != "chirp":  # every other profile goes there and back: the shaft returns to its start
        assert theta[-1] == pytest.approx(1.5, abs=1e-9 * TOP * DUR)


def test_ramp_travel_and_constant_acceleration():
    t, v = velocity_profile("ramp", top_speed=TOP, duration=DUR, fs=100.0, rest=2.0)
    th = position(v, 100.0)
    leg = (DUR - 4.0) / 4
    assert np.all(v[t <= 2.0] == 0) and np.all(v[t >= DUR - 2.0] == 0)
    # triangle of height TOP over two legs: travel TOP * leg, exact for piecewise-linear v with knots on samples
    assert th.max() == pytest.approx(TOP * leg, rel=1e-12)
    acc = np.diff(v) * 100.0
    assert np.allclose(np.abs(acc[(acc != 0)]), TOP / leg, rtol=1e-9)


def test_chirp_crosses_zero_as_often_as_its_sweep_says():
    # linear sweep from 1/T to 10/T: T (f0 + f1) / 2 = 5.5 cycles = 11 half cycles, 10 crossings inside
    _, v = velocity_profile("chirp", top_speed=TOP, duration=DUR, fs=1000.0)
    assert np.count_nonzero(np.diff(np.sign(v[1:-1])) != 0) == 10
    # log sweep from 0.05 to 0.5 Hz: 2 pi f0 T / ln 10 (10 - 1) rad = 7.82 cycles -> 15.6 -> 16 half cycles
    _, v = velocity_profile("chirp", top_speed=TOP, duration=DUR, fs=1000.0, f0=0.05, f1=0.5, method="log")
    assert np.count_nonzero(np.diff(np.sign(v[1:-1])) != 0) == 15 and abs(v[-1]) < 1e-12
    # ... reached smoothly: the last step is at most the steepest slope, top x 2 pi f1 / fs (x 1.05:
    # f1 scaled by up to 16 / 15.6)
    assert abs(v[-2]) < 1.05 * TOP * 2 * np.pi * 0.5 / 1000.0


def test_bell_moves_peak_where_declared_and_travel_their_amplitude():
    fs, peaks, shares, rest = 1000.0, (1.0, 0.5, 0.1), (1.0, 0.5, 1.0), 0.5
    t, v = velocity_profile("bell", top_speed=TOP, duration=DUR, fs=fs, peaks=peaks, shares=shares, rest=rest)
    T = np.array(shares) * (DUR - 7 * rest) / (2 * sum(shares))          # seconds of each move
    start = rest
    th = position(v, fs)
    for p, Tk in zip(peaks, T):
        for d in (1, -1):
            sel = (t >= start) & (t <= start + Tk)
            peak = v[sel].max() if d > 0 else -v[sel].min()
            assert peak == pytest.approx(p * TOP, rel=1e-3)
            # travel A = peak T / 1.875 (the integral of 30 s^2 (1-s)^2 is 1 and its peak 1.875);
            # the trapezoid rule's error is O(dt^2): 1e-6 here
            i0, i1 = np.flatnonzero(sel)[[0, -1]]
            assert th[i1] - th[i0] == pytest.approx(d * p * TOP * Tk / 1.875, rel=1e-6)
            start += Tk + rest
    assert np.all(v[t < rest] == 0)


def test_plateaus_hold_their_geometric_speeds():
    t, v = velocity_profile("plateaus", top_speed=TOP, duration=DUR, fs=100.0, levels=4)
    held = [float(np.median(v[(t > s * 5 + 2) & (t < s * 5 + 3)])) for s in range(8)]
    expect = [d * x for x in TOP * np.geomspace(1 / 30, 1, 4) for d in (1, -1)]
    assert np.allclose(held, expect, rtol=1e-12)


def test_sine_phases_from_the_seed():
    a = velocity_profile("sine", top_speed=TOP, duration=DUR, fs=100.0)[1]
    b = velocity_profile("sine", top_speed=TOP, duration=DUR, fs=100.0, seed=4)[1]
    c = velocity_profile("sine", top_speed=TOP, duration=DUR, fs=100.0, seed=4)[1]
    assert np.array_equal(b, c) and not np.allclose(a, b)
    with pytest.raises(InputError, match="must be an integer >= 0"):
        velocity_profile("sine", top_speed=TOP, duration=DUR, fs=100.0, seed="four")
    # the second half is the first reversed in time and sign
    n = len(a)
    assert np.allclose(a[n // 2 + 1:], -a[:n // 2][::-1], atol=1e-12 * TOP)
    # its spectrum: the 5 harmonics of 4 / T = 0.1 Hz (Tukey window: leakage below 10 % elsewhere)
    spec = np.abs(np.fft.rfft(a[: n // 2]))
    f = np.fft.rfftfreq(n // 2, 0.01)
    strong = f[spec > 0.3 * spec.max()]
    assert strong.min() >= 0.09 and strong.max() <= 0.51


@pytest.mark.parametrize("kind, kw, says", [
    ("wobble", {}, "unknown velocity profile"),
    ("ramp", {"f0": 1.0}, "no option f0"),
    ("ramp", {"duration": 0.05}, "give at least"),                  # 13 samples: fewer than 4 x 20
    ("bell", {"duration": 1.0}, "fewer than 20 samples"),            # the 0.7-share move: 15 samples at 250 Hz
    ("ramp", {"top_speed": -1.0}, "top_speed must be a positive"),
    ("chirp", {"f0": 0.01, "f1": 0.01}, "at least one whole cycle"),  # 0.4 cycles in 40 s
    ("chirp", {"f1": 20.0}, "below fs / 20"),
    ("chirp", {"method": "cubic"}, "'linear' or 'log'"),
    ("bell", {"peaks": (0.5, 0.25), "shares": (1, 1)}, "largest peak must be 1"),
    ("sine", {"harmonics": 0}, "harmonics >= 1"),
    ("chirp", {"f1": "fast"}, "option f1 must be a finite number"),
    ("bell", {"peaks": (1.0, float("nan")), "shares": (1, 1)}, "option peaks must be a finite number"),
])
def test_bad_profile_arguments_are_refused_in_one_sentence(kind, kw, says):
    args = {"top_speed": TOP, "duration": DUR, "fs": 250.0, **kw}
    with pytest.raises(InputError, match=says):
        velocity_profile(kind, **args)


# ---------------------------------------------------------------------- motion_recording
@pytest.mark.parametrize("kind", PROFILES)
def test_motion_recording_torque_is_the_model_plus_inertia_times_acceleration(kind):
    model, J = table2_model(), 2e-6
    rec, truth = motion_recording(model, kind, top_speed=300.0, duration=10.0, inertia=J, seed=1)
    d = rec.data
    v, acc = truth["velocity"], truth["acceleration"]
    assert np.array_equal(truth["theta"], position(v, 1000.0)) and np.array_equal(d["theta"], truth["theta"])
    assert np.array_equal(acc, np.gradient(v, 1e-3))
    expect = model.evaluate(truth["theta"], v) + J * acc
    assert np.abs(d["torque"].to_numpy() - expect).max() < 1e-12
    assert truth["profile"]["kind"] == kind and truth["profile"]["top_speed"] == 300.0
    assert set(d["run"]) == {0}


def test_motion_recording_noise_load_and_refusals():
    model = table4_model("A")  # law (11): needs the load
    rec, truth = motion_recording(model, "chirp", top_speed=300.0, duration=10.0, load=20.0, noise=0.01,
                                  position_noise=1e-4, seed=3)
    d = rec.data
    assert np.all(d["load"] == 20.0)
    resid = d["torque"].to_numpy() - model.evaluate(truth["theta"], truth["velocity"], load=np.full(len(d), 20.0))
    # sample sd of 10001 normal draws: relative standard error 1 / sqrt(2 n) = 0.7 %; 3 % is 4 of them
    assert np.std(resid) == pytest.approx(0.01, rel=0.03)
    assert np.std(d["theta"].to_numpy() - truth["theta"]) == pytest.approx(1e-4, rel=0.03)
    with pytest.raises(InputError, match="load must be a number"):
        motion_recording(model, "chirp", top_speed=300.0, duration=10.0, load=np.ones(7))
    with pytest.raises(InputError, match="no option"):
        motion_recording(model, "bell", top_speed=300.0, duration=10.0, f1=3.0)


# ---------------------------------------------------------------------- the SILO4 twin
# Small runs: 3 s profiles up to 2000 rpm, two repetitions (about 3 s of simulation each).
S4 = {"top_speed_rpm": 2000.0, "duration": 3.0, "repetitions": 2, "seed": 7, "record_velocity": True}


@pytest.fixture(scope="module")
def silo4_profiles():
    return {k: silo4_twin(profile=k, **S4) for k in PROFILES if k != "plateaus"}


@pytest.mark.parametrize("kind", ["ramp", "chirp", "bell", "sine"])
def test_silo4_twin_follows_each_profile(silo4_profiles, kind):
    rec, truth = silo4_profiles[kind]
    top = 2000.0 * RPM
    d = rec.data
    assert sorted(d["run"].unique()) == [0, 1]
    prof = truth.settings["profile"]
    assert prof["kind"] == kind and prof["top_speed"] == pytest.approx(top) and prof["duration"] == 3.0
    assert json.loads(json.dumps(truth.to_dict()))["settings"]["profile"]["kind"] == kind
    runs = truth.runs
    assert list(runs["profile"]) == [kind, kind] and np.allclose(runs["t1"] - runs["t0"], 3.0)
    # Tracking, against the loop's own prediction.  The PID is tuned for a triple pole at
    # wc = 2 pi 15 Hz, so that (linear part) the velocity error to the reference is
    # E(s) v_ref, E = (J s^3 + b s^2) / (J (s + wc)^3) (b = k_M^2 / R, back-EMF damping), and (friction)
    # each reversal is a torque step dF = tau_s+ + tau_s- = 18 mNm whose velocity transient
    # dF / J * L^-1[s / (s + wc)^3] has energy (dF / J)^2 * 0.0625 / wc^3.  The two add in quadrature
    # when uncorrelated, up to sqrt(2) x that when fully correlated; the Stribeck slope and the
    # encoder's counts add a little: measured / predicted within [0.5, 1.6] (measured: 0.8-1.4).
    # A loop that ignored the profile would track with an error of order the top speed: 10-20 x.
    J, b, wc = PLANT["inertia"], PLANT["torque_constant"] ** 2 / PLANT["resistance"], 2 * np.pi * PLANT["bandwidth_hz"]
    t, v_ref = velocity_profile(kind, top_speed=top, duration=3.0, fs=PLANT["control_rate"])
    _, e_lin, _ = signal.lsim(signal.lti([J, b, 0, 0], J * np.poly([-wc] * 3)), v_ref, t)
    n_rev = np.count_nonzero(np.diff(np.sign(v_ref[np.abs(v_ref) > 1e-9])) != 0)
    dF = (PAPER_TABLE2["tau_E"]["positive"] + PAPER_TABLE2["tau_E"]["negative"]) * 1e-3
    predicted = math.sqrt(np.mean(e_lin[::16] ** 2) + n_rev * (dF / J) ** 2 * 0.0625 / wc ** 3 / 3.0)
    assert runs["tracking_rms"].between(0.5 * predicted, 1.6 * predicted).all(), (runs["tracking_rms"], predicted)
    assert runs["velocity_max"].between(0.98 * top, 1.15 * top).all()
    v = d["velocity"].to_numpy()
    assert v.max() > 0.95 * top and v.min() < -0.95 * top          # both directions
    # every run starts from rest at the same place (theta0 auto: 0) and ends at rest
    first = d.groupby("run").head(1)
    assert np.all(first["theta"] == 0) and np.all(d.groupby("run")["velocity"].last() == 0)


def test_silo4_profile_refusals():
    with pytest.raises(InputError, match="no-load speed"):
        silo4_twin(profile="ramp", top_speed_rpm=12000, duration=1.0, repetitions=1)   # 24 V / kM = 9921 rpm
    with pytest.raises(InputError, match="speeds_rpm is for plateaus"):
        silo4_twin([280], profile="ramp")
    with pytest.raises(InputError, match="speeds_rpm is for plateaus"):
        silo4_twin([280], top_speed_rpm=3000)
    with pytest.raises(InputError, match="one number of seconds"):
        silo4_twin(profile="bell", duration=[1.0, 2.0])


def test_plateaus_are_the_twins_output_before_profiles():
    """profile="plateaus" is the default path, and its numbers are those the twin gave before
    profiles existed (pinned from commit 05aae56; same platform arithmetic: rtol 1e-12)."""
    a, ta = silo4_twin([280, -3000], repetitions=2, duration=1.0, seed=3)
    b, tb = silo4_twin([280, -3000], repetitions=2, duration=1.0, seed=3, profile="plateaus")
    for col in a.data.columns:
        assert np.array_equal(a.data[col].to_numpy(), b.data[col].to_numpy())
    pd.testing.assert_frame_equal(ta.runs, tb.runs)
    assert tb.settings["profile"] == {"kind": "plateaus"}
    d = b.data
    assert len(d) == 1474
    assert d["current"].sum() == pytest.approx(-1016.8115650011501, rel=1e-12)
    assert np.abs(d["theta"]).sum() == pytest.approx(358597.02432896855, rel=1e-12)
    assert d["current"].iloc[700] == pytest.approx(-2.0554326793752016, rel=1e-12)
    rec, pts = lola_twin("C", speeds=[100.0, -100.0], loads=[2.0, 10.0], hold=1.0, seed=4, profile="plateaus")
    d = rec.data
    assert len(d) == 6000
    assert d["current"].sum() == pytest.approx(1532.476021598648, rel=1e-12)
    assert d["load"].sum() == pytest.approx(2966.214676123931, rel=1e-12)
    assert np.abs(d["theta"]).sum() == pytest.approx(883306.040339797, rel=1e-12)


# ---------------------------------------------------------------------- the Lola twin
@pytest.mark.parametrize("kind", ["ramp", "chirp", "bell", "sine"])
def test_lola_twin_follows_each_profile_once_per_load(kind):
    loads = [5.0, 30.0]  # one per campaign (30 Nm needs the testbed gear)
    rec, pts = lola_twin("A", loads=loads, profile=kind, duration=3.0, seed=2)
    d = rec.data
    mod = MODULES["A"]
    top, fs = mod["speed_range"][1], TESTBED["fs"]
    _, v_ref = velocity_profile(kind, top_speed=top, duration=3.0, fs=fs)
    n = len(v_ref)
    assert len(d) == 2 * n and list(pts["load_cmd"]) == loads and list(pts["campaign"]) == [1, 2]
    truth = pts.attrs["truth"]
    assert truth.settings["profile"]["kind"] == kind and len(truth.runs) == 2
    # ideal speed control: the encoder reads the profile's position within one count (8192 / rev)
    theta = np.concatenate([position(v_ref, fs), position(v_ref, fs, position(v_ref, fs)[-1])])
    q = 2 * math.pi / TESTBED["counts_per_rev"]
    assert np.all((theta - d["theta"].to_numpy() >= -1e-9) & (theta - d["theta"].to_numpy() < q + 1e-9))
    # the brake holds each load from the start (settled): while moving, |load| = load_cmd within
    # the sensor's noise (5e-4 x range: 0.01 / 0.1 Nm sd; mean of >2000 samples: < 0.003 Nm)
    v = np.concatenate([v_ref, v_ref])
    for r, lv in enumerate(loads):
        sel = (d["run"].to_numpy() == r) & (v != 0)
        assert np.abs(d["load"].to_numpy()[sel]).mean() == pytest.approx(lv, abs=0.01)
        assert np.all(np.sign(d["load"].to_numpy()[sel & (np.abs(v) > 1)]) == np.sign(v[sel & (np.abs(v) > 1)]))
    # the current is law (11) + load / N + J acc over k_m, plus its noise (5e-3 x 7 A = 0.035 A sd)
    model = table4_model("A")
    load_true = np.sign(v) * np.repeat(loads, n)
    torque = model.evaluate(theta, v, load=load_true) + load_true / mod["ratio"] + mod["inertia"] * np.gradient(v, 1e-3)
    resid = d["current"].to_numpy() - torque / mod["torque_constant"]
    # sd of 6000 draws within 3 % (4 standard errors); the brake's PI noise adds < 1e-3 A
    assert np.std(resid) == pytest.approx(TESTBED["current_noise"] * mod["nominal_current"], rel=0.03)


def test_lola_profile_refusals():
    with pytest.raises(InputError, match="speeds and hold are for the plateau grid"):
        lola_twin("A", speeds=[50.0], profile="bell")
    with pytest.raises(InputError, match="not the grid"):
        lola_twin("A", top_speed=100.0)


# ---------------------------------------------------------------------- command line
def test_cli_simulate_profile_writes_files_and_refuses_nonsense(tmp_path, capsys):
    out = tmp_path / "twin"
    assert main(["simulate", "silo4", "--out", str(out), "--profile", "chirp", "--duration", "3",
                 "--repetitions", "1", "--top-speed-rpm", "1500", "--quiet"]) == 0
    truth = json.loads((out / "silo4_twin_truth.json").read_text())
    assert truth["settings"]["profile"]["kind"] == "chirp"
    assert truth["settings"]["profile"]["top_speed"] == pytest.approx(1500 * RPM)
    assert truth["runs"][0]["profile"] == "chirp"
    rec = pd.read_csv(out / "silo4_twin.csv")
    assert {"t", "theta", "current", "run"} <= set(rec.columns) and len(rec) == 825   # 0 to 3.296 s at 4 ms
    FrictionModel.from_dict(truth["model"])
    assert main(["simulate", "lola", "--module", "B", "--out", str(out), "--profile", "bell", "--duration", "3",
                 "--top-speed", "100", "--loads", "5", "--quiet", "--profile-options", "peaks=1;0.3,shares=1;2"]) == 0
    pts = pd.read_csv(out / "lola_B_twin_points.csv")
    assert list(pts["load_cmd"]) == [5.0] and pts["speed_max"].iloc[0] == pytest.approx(100.0, rel=0.01)
    truth = json.loads((out / "lola_B_twin_truth.json").read_text())
    assert truth["settings"]["profile"]["options"] == {"peaks": [1, 0.3], "shares": [1, 2]}
    # the options reach the profile: the second move peaks at 0.3 x 100 rad/s over twice the time
    rec = pd.read_csv(out / "lola_B_twin.csv")
    v = np.gradient(rec["theta"].to_numpy(), rec["t"].to_numpy())
    assert np.sort(np.abs(v))[-30:].min() > 90                   # the first move reaches ~100 rad/s
    assert np.abs(v[rec["t"].to_numpy() > 1.6]).max() == pytest.approx(30.0, rel=0.05)  # the second: 30
    capsys.readouterr()
    for argv, says in [
        (["silo4", "--profile", "wobble"], "invalid choice: 'wobble'"),
        (["silo4", "--top-speed-rpm", "2000"], "--top-speed-rpm applies to a motion --profile"),
        (["silo4", "--profile", "ramp", "--speeds-rpm", "280"], "sets its own speeds"),
        (["silo4", "--profile", "ramp", "--top-speed-rpm", "20000"], "no-load speed"),
        (["silo4", "--profile", "ramp", "--duration", "0.01"], "give at least 80"),
        (["lola", "--profile", "ramp", "--hold", "3"], "sets its own speeds"),
        (["lola", "--duration", "3"], "apply to a motion --profile"),
        (["lola", "--profile", "sine", "--top-speed", "-3"], "must be above 0"),
        (["lola", "--profile-options", "f1=2"], "--profile-options applies to a motion --profile"),
        (["lola", "--profile", "chirp", "--profile-options", "f1"], "'f1' is not KEY=VALUE"),
        (["lola", "--profile", "chirp", "--profile-options", "f1=fast"], "option f1 must be a finite number"),
        (["silo4", "--profile", "chirp", "--profile-options", "wobble=1"], "no option wobble"),
    ]:
        assert main(["simulate", *argv, "--out", str(out), "--quiet"]) == 2, argv
        err = capsys.readouterr().err
        assert says in err and "Traceback" not in err and len(err.strip().splitlines()) == 1, err
