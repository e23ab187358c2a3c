"""Quasi-static maps: rows stored only at rest after each step of a position loop, one sweep
forward and one back, irregular time stamps.  Recognised as segments of their own kind, analysed
as torque against position (no time derivative), fitted as level + lines per direction."""

import json

import numpy as np
import pytest

from gearspec.cli import main
from gearspec.errors import InputError
from gearspec.fitdata import FitData
from gearspec.recording import Recording
from gearspec.segment import FrictionTorque, derivatives, find_segments, friction_torque, quasi_static_sweeps
from gearspec.segment.quasistatic import _sweeps
from gearspec.simulate import Ripple, plateau_recording
from gearspec.simulate.synthetic import quasi_static_recording
from gearspec.spectrum import analyze

TP = 2 * np.pi
NOISE = 0.002  # Nm, white torque noise of the synthetic maps
GEAR = {"name": "bare motor", "stages": [{"name": "cogging", "kind": "other", "ratio": 1.0, "teeth": 6}]}
ORDERS = (6, 12, 24, 36)


def _ripples():
    """Cogging at 6, 12, 24 and 36 per turn: amplitudes differ slightly per direction, and the phase
    in the friction-magnitude frame is the drive-torque phase + pi (a conservative cogging torque)
    plus a small hysteresis."""
    return [Ripple(6 / TP, (0.010, 0.011), (0.3, 0.3 + np.pi + 0.1)),
            Ripple(12 / TP, (0.004, 0.0035), (1.0, 1.0 + np.pi - 0.1)),
            Ripple(24 / TP, (0.003, 0.003), (-1.0, -1.0 + np.pi)),
            Ripple(36 / TP, (0.002, 0.0025), (2.0, 2.0 + np.pi + 0.2))]


def _map(seed=1, **kw):
    # median step 13 ms, log-sd 0.5, 3 % pauses of up to 1 s, 5 % repeated positions
    opts = dict(ripples=_ripples(), levels=(0.05, 0.04), noise=NOISE, dt_spread=0.5, gap_probability=0.03,
                max_gap=1.0, repeat_probability=0.05, seed=seed, gear=GEAR)
    opts.update(kw)
    return quasi_static_recording(**opts)


def _wrap(x):
    return float(np.angle(np.exp(1j * x)))


def test_map_recognised_as_two_quasi_static_sweeps():
    rec, truth = _map()
    dt = np.diff(rec.t)
    assert np.median(dt) == pytest.approx(0.013, rel=0.05) and 0.5 < dt.max() <= 1.0   # the class of stamps
    assert np.sum(np.diff(rec.theta) == 0) > 100                                          # repeated positions
    seg = find_segments(rec)
    seg.check_ledger()
    qs = [s for s in seg if s.kind == "quasi_static"]
    assert [s.direction for s in qs] == [1, -1]
    assert sum(s.n for s in qs) >= 0.95 * len(rec)
    # the sweeps are split at the reversal: the turning row ends the forward sweep
    assert [(s.start, s.stop) for s in qs] == [tuple(x[:2]) for x in truth["sweeps"]]
    assert seg.segments[0].to_dict()["kind"] == "quasi_static"
    # the gap rule plays no part: the same recording cut into many pieces by a tight --max-gap
    # (the default rule keeps a broad step distribution whole) gives the same sweeps
    assert len(rec.pieces(max_gap=0.05)) > 50
    cut = Recording.from_arrays(t=rec.t, theta=rec.theta, torque=rec.tau, gear=GEAR, max_gap=0.05)
    assert len(cut.pieces()) > 50
    assert [(s.start, s.stop, s.kind) for s in find_segments(cut) if s.kind == "quasi_static"] == \
        [(s.start, s.stop, s.kind) for s in qs]
    # --quasi-static gives the same segments; --no-quasi-static none of them
    forced = find_segments(rec, quasi_static=True)
    assert forced.segments == seg.segments
    assert not any(s.kind == "quasi_static" for s in find_segments(rec, quasi_static=False))
    with pytest.raises(InputError, match="quasi_static"):
        find_segments(rec, quasi_static="yes")


def test_direction_offset_and_every_line_recovered_from_the_map():
    rec, truth = _map()
    res = analyze(rec, harmonics=6, min_cycles=0.9)
    d = res.to_dict()
    assert [s["kind"] for s in d["segments"]] == ["quasi_static", "quasi_static"]
    for s in res.segments:
        tr = truth["directions"][s.direction]
        # the level is a mean over n rows of white noise: 4 standard errors
        assert s.level == pytest.approx(tr["level"], abs=4 * NOISE / np.sqrt(s.segment.n))
        for r in tr["ripples"]:
            p = min(s.peaks, key=lambda p: abs(p.frequency - r["frequency"]))
            assert p.frequency == pytest.approx(r["frequency"]) and p.declared
            # standard errors checked honest over 10 seeds (z sd 1.09 amplitude, 0.94 phase)
            assert abs(p.amplitude - r["amplitude"]) < 4 * p.amplitude_se, (s.direction, r)
            assert abs(_wrap(p.phase - r["phase"])) < 4 * p.phase_se, (s.direction, r)
            # the white-noise error sqrt(2/n) sigma, rescaled by a local noise level that is itself an
            # estimate from a band of the periodogram (it scatters by some 20-30 %)
            assert p.amplitude_se == pytest.approx(NOISE * np.sqrt(2 / s.segment.n), rel=0.4)
        # lines the map does not have stay at the noise
        for p in s.peaks:
            if min(abs(p.frequency * TP - k) for k in ORDERS) > 0.5:
                assert p.amplitude < 5 * p.amplitude_se


def test_no_inertia_or_derivative_on_quasi_static_rows():
    # with an inertia in the gear spec a plateau loses J thetadd; a map must not (it was at rest)
    gear = dict(GEAR, inertia=0.05)
    rec, truth = _map(gear=gear)
    res = analyze(rec)
    for s in res.segments:
        assert s.level == pytest.approx(truth["directions"][s.direction]["level"], abs=4 * NOISE / np.sqrt(s.segment.n))
    data = FitData.from_recording(rec, find_segments(rec))
    assert np.all(data.acc == 0)
    assert np.array_equal(data.y, rec.tau[np.concatenate([np.arange(s.start, s.stop) for s in find_segments(rec)])])
    assert any("quasi-static" in n for n in data.notes)
    assert set(data.segments["kind"]) == {"quasi_static"}


def test_standard_errors_are_honest_over_seeds():
    za, zp = [], []
    for seed in range(10):
        rec, truth = _map(seed=seed)
        for s in analyze(rec, harmonics=6, min_cycles=0.9).segments:
            for r in truth["directions"][s.direction]["ripples"]:
                p = min(s.peaks, key=lambda p: abs(p.frequency - r["frequency"]))
                za.append((p.amplitude - r["amplitude"]) / p.amplitude_se)
                zp.append(_wrap(p.phase - r["phase"]) / p.phase_se)
    # 80 z-scores each: their sd is within 0.7..1.35 with probability > 0.999 if the errors are honest
    assert 0.7 < np.std(za) < 1.35 and 0.7 < np.std(zp) < 1.35
    assert abs(np.mean(za)) < 0.4 and abs(np.mean(zp)) < 0.4


def _write(tmp_path, rec, name="map"):
    """The recording as a CSV file and its gear spec as a TOML file."""
    csv, toml = tmp_path / f"{name}.csv", tmp_path / f"{name}.toml"
    rec.data.to_csv(csv, index=False)
    rec.gear.to_toml(toml)
    return csv, toml


def _fit_cli(tmp_path, files, *extra):
    out = tmp_path / f"fit{len(extra)}.json"
    lines = ",".join(repr(k / TP) for k in ORDERS)
    rc = main(["fit", str(files[0]), "--gear", str(files[1]), "--lines", lines, "--json", str(out), "--quiet", *extra])
    return rc, (json.loads(out.read_text()) if rc == 0 else None)


def _one_sentence(err):
    """stderr of a clean refusal: one error line, no traceback (warnings may precede it)."""
    return "Traceback" not in err and sum(x.startswith("gearspec: error:") for x in err.splitlines()) == 1


def test_fit_cli_gives_levels_and_lines_and_no_speed_law(tmp_path, capsys):
    rec, truth = _map(seed=3)
    csv = _write(tmp_path, rec)
    rc, d = _fit_cli(tmp_path, csv)
    assert rc == 0
    for d_, name in ((1, "positive"), (-1, "negative")):
        P, tr = d["directions"][name], truth["directions"][d_]
        assert P["tau_c"] == pytest.approx(tr["level"], abs=4 * P["tau_c_se"])
        assert P["tau_c_se"] == pytest.approx(NOISE / np.sqrt(P["n_samples"]), rel=0.25)
        for k in ("tau_s", "v_s", "viscous"):
            assert P[k] is None and f"{name}.{k}" in d["not_identified"]
        assert len(P["harmonics"]) == len(ORDERS)
        for h, r in zip(P["harmonics"], tr["ripples"]):
            assert h["frequency"] == pytest.approx(r["frequency"])
            assert abs(h["amplitude"] - r["amplitude"]) < 4 * h["amplitude_se"]
            assert abs(_wrap(h["phase"] - r["phase"])) < 4 * h["phase_se"]
            assert h["decay"] == 0 and h["law"] == "const"
            assert f"{name}.{h['label']}.decay" in d["not_identified"]
    # auto-detection and --quasi-static give the same
    rc2, d2 = _fit_cli(tmp_path, csv, "--quasi-static")
    assert rc2 == 0 and d2["directions"] == d["directions"]
    # and without quasi-static segments (and free motion: rows stored at rest are not a motion)
    # there is nothing to fit: one sentence, exit 2
    capsys.readouterr()
    rc3, _ = _fit_cli(tmp_path, csv, "--no-quasi-static", "--motion", "plateaus")
    assert rc3 == 2 and _one_sentence(capsys.readouterr().err)


def test_diagnose_cli_on_a_map_exits_cleanly(tmp_path, capsys):
    rec, _ = _map(seed=4)
    csv, toml = _write(tmp_path, rec)
    rc = main(["diagnose", str(csv), "--gear", str(toml), "--quiet"])
    err = capsys.readouterr().err
    assert rc == 0 or (rc == 2 and _one_sentence(err))


# ---------------------------------------------------------------------- no false positives
def _jittered_clock(speed, seed=0):
    """Continuous motion on a clock that drops 30 % of its rows and jitters by 1 %: time steps as
    irregular as a map's, but the position follows time."""
    rng = np.random.default_rng(seed)
    dt = rng.choice([0.001, 0.002], 20000, p=[0.7, 0.3]) * (1 + 0.01 * rng.standard_normal(20000))
    t = np.cumsum(dt)
    return Recording.from_arrays(t=t, theta=np.round(speed * t / 1e-4) * 1e-4, torque=0.1 + 1e-3 * np.sin(t))


def test_plateau_recordings_are_never_quasi_static():
    fs = 1000
    t = np.arange(0, 8, 1 / fs)
    v = 0.05 * (1 + 0.9 * np.sign(np.sin(2 * np.pi * 4 * t)))      # stick-slip plateau
    v[t < 1] = 0.05 * t[t < 1]
    stick = Recording.from_arrays(t=t, theta=np.cumsum(v) / fs, torque=0.1 + 1e-3 * np.sin(t))
    slow, _ = plateau_recording([0.02, -0.02], level=0.1, duration=4.0, fs=500, noise=0.001, quantum=2e-5, seed=2)
    ripple, _ = plateau_recording([2.0, -5.0], ripples=[Ripple(0.8, 0.05)], level=0.3, duration=2.0, fs=1000,
                                  speed_ripple=0.08, noise=0.01, seed=3)
    for rec in (stick, slow, ripple, _jittered_clock(0.3), _jittered_clock(3.0)):
        auto, plain = find_segments(rec), find_segments(rec, quasi_static=False)
        assert auto.segments == plain.segments and auto.excluded == plain.excluded
        assert not any(sw["at_rest"] for sw in quasi_static_sweeps(rec, force=True))


def test_sweeps_split_at_reversals_not_at_jitter():
    rng = np.random.default_rng(5)
    path = np.concatenate([np.arange(0, 1, 0.002), np.arange(1, 0.3, -0.002), np.arange(0.3, 0.8, 0.002)])
    theta = path + rng.normal(0, 0.0004, len(path))        # jitter: back-steps of up to ~one step
    sw = _sweeps(theta, 3 * 0.002)
    assert [d for *_, d in sw] == [1, -1, 1]
    turns = [b for _, b, _ in sw[:-1]]
    assert abs(turns[0] - 500) <= 3 and abs(turns[1] - 850) <= 3
    assert sw[0][0] == 0 and sw[-1][1] == len(theta) and all(a[1] == b[0] for a, b in zip(sw, sw[1:]))


def test_several_sweeps_and_runs():
    a, _ = _map(seed=6, revolutions=0.5)
    b, _ = _map(seed=7, revolutions=0.5)
    rec = Recording.from_arrays(t=np.concatenate([a.t, b.t]), theta=np.concatenate([a.theta, b.theta + 1.0]),
                                torque=np.concatenate([a.tau, b.tau]),
                                run=np.repeat([0, 1], [len(a), len(b)]))
    seg = find_segments(rec)
    seg.check_ledger()
    assert [(s.run, s.direction, s.kind) for s in seg] == [(0, 1, "quasi_static"), (0, -1, "quasi_static"),
                                                          (1, 1, "quasi_static"), (1, -1, "quasi_static")]


# ---------------------------------------------------------------------- derivative filter
def test_piece_too_short_for_the_derivative_filter_gets_no_derivative():
    # a regular piece of 40 rows, a pause, then 8 rows with a 13 ms median step but three rows
    # 1.3 ms apart: the uniform grid of the median step has 5 points, fewer than the 7-point filter
    # (savgol_filter raised here before: fit and diagnose exited 1)
    dt = np.concatenate([np.full(39, 0.013), [1.0], np.array([13, 13, 13, 13, 1.3, 1.3, 1.3]) * 1e-3])
    t = np.concatenate(([0.0], np.cumsum(dt)))
    tau = 0.2 + 0.01 * np.sin(t)  # varies: a constant torque channel is refused at load
    rec = Recording.from_arrays(t=t, theta=0.1 * t + 0.01 * t ** 2, torque=tau, gear={"name": "g", "inertia": 0.01})
    assert [(a, b) for _, a, b in rec.pieces()] == [(0, 40), (40, 48)]
    vel, acc = derivatives(rec)
    assert np.all(np.isnan(vel[40:])) and np.all(np.isnan(acc[40:]))
    assert np.allclose(acc[:40], 0.02) and np.allclose(vel[:40], 0.1 + 0.02 * t[:40])
    assert np.array_equal(friction_torque(rec)[40:], tau[40:])
    assert np.array_equal(FrictionTorque(rec)[40:48], tau[40:])


def test_fit_and_diagnose_on_a_map_cut_into_short_pieces(tmp_path, capsys):
    # pauses in 10 % of the steps: the gap rule cuts the map into hundreds of short jittered
    # pieces (fit and diagnose exited 1 here before, in the derivative filter)
    # (the default gap rule keeps such a map whole now: --max-gap 0.05 cuts it as the old rule did)
    rec, truth = _map(seed=2, dt_spread=0.7, gap_probability=0.1, gear=dict(GEAR, inertia=0.01))
    assert len(rec.pieces(max_gap=0.05)) > 300
    csv = _write(tmp_path, rec, "hard")
    rc, d = _fit_cli(tmp_path, csv, "--max-gap", "0.05")
    assert rc == 0
    assert d["directions"]["positive"]["tau_c"] == pytest.approx(0.05, abs=4 * d["directions"]["positive"]["tau_c_se"])
    capsys.readouterr()
    for extra in ([], ["--no-quasi-static"]):
        rc = main(["diagnose", str(csv[0]), "--gear", str(csv[1]), "--quiet", "--max-gap", "0.05", *extra])
        err = capsys.readouterr().err
        assert rc == 0 or (rc == 2 and _one_sentence(err))


def test_map_with_position_noise_at_rest():
    # the encoder reads each rest position with noise of a tenth of the step: repeated rows step
    # back by up to ~3 noise sd; those are jitter, not reversals (the sweeps stay two)
    rec, truth = _map(position_noise=2e-4)
    assert np.sum(np.diff(rec.theta)[: truth["sweeps"][0][1] - 1] < 0) > 50
    seg = find_segments(rec)
    assert [(s.start, s.stop, s.direction, s.kind) for s in seg] == \
        [(a, b, d, "quasi_static") for a, b, d in truth["sweeps"]]


def test_spectrum_cli_writes_the_kind_and_the_lines(tmp_path, capsys):
    rec, truth = _map(seed=8)
    csv, toml = _write(tmp_path, rec)
    out = tmp_path / "spectrum.json"
    assert main(["spectrum", str(csv), "--gear", str(toml), "--harmonics", "6", "--min-cycles", "0.9",
                 "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "2 segments" in printed and "cogging" in printed
    d = json.loads(out.read_text())
    assert d["settings"]["quasi_static"] == "auto" and d["settings"]["quasi_static_segments"] == 2
    for s in d["segments"]:
        assert s["kind"] == "quasi_static"
        tr = truth["directions"][s["direction"]]
        for r in tr["ripples"]:
            p = min(s["peaks"], key=lambda p: abs(p["frequency"] - r["frequency"]))
            assert abs(p["amplitude"] - r["amplitude"]) < 4 * p["amplitude_se"]
