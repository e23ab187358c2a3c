"""The command line as a user meets it: exit codes, messages, files written."""

import json
import subprocess
import sys

import numpy as np
import pytest

from gearspec.cli import main
from gearspec.simulate import Ripple, plateau_recording


@pytest.fixture
def recording_csv(tmp_path):
    rec, _ = plateau_recording([40, -40, 80, -80], ripples=[Ripple(1 / (2 * np.pi), 1e-3, 0.5)], level=0.01,
                               duration=2.5, fs=1000, noise=1e-4, seed=4)
    return rec.save(tmp_path / "rec.csv")


def test_spectrum_writes_report_and_json(recording_csv, tmp_path, capsys):
    out = tmp_path / "out"
    code = main(["spectrum", str(recording_csv), "--gear", "silo4-joint3", "--out", str(out),
                 "--json", str(out / "s.json")])
    assert code == 0
    d = json.loads((out / "s.json").read_text())
    assert len(d["segments"]) == 4
    assert sum(s["n"] for s in d["segments"]) + sum(d["excluded"].values()) == d["n_rows"]
    for s in d["segments"]:
        p = next(p for p in s["peaks"] if p["label"] == "motor shaft")
        assert p["amplitude"] == pytest.approx(1e-3, rel=0.02)
    for name in ("report.md", "segments.png", "spectra_01.png", "amplitude_vs_speed.png", "peaks.csv"):
        assert (out / name).stat().st_size > 0
    text = (out / "report.md").read_text()
    assert "motor shaft" in text and "![segments](segments.png)" in text
    assert "4 segments" in capsys.readouterr().out


def test_bad_input_exits_2_with_one_message(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("t,position,torque\n0,0,1\n0.001,0.1,1\n")
    assert main(["spectrum", str(bad), "--gear", "silo4-joint3"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("gearspec: error:") and "no column 'theta'" in err and "--map theta=" in err
    assert main(["spectrum", str(bad), "--gear", "no-such-gear"]) == 2
    assert "no such preset" in capsys.readouterr().err


def test_no_segment_is_a_clear_error(tmp_path, capsys):
    t = np.arange(0, 2, 0.001)
    theta = 0.5 * np.sin(2 * np.pi * 3 * t)        # never holds a speed
    import pandas as pd

    pd.DataFrame({"t": t, "theta": theta, "torque": np.cos(t) + 0.01 * np.sin(77 * t)}).to_csv(tmp_path / "o.csv",
                                                                                              index=False)
    assert main(["spectrum", str(tmp_path / "o.csv")]) == 2
    assert "no constant-speed segment" in capsys.readouterr().err


def test_gears_command_lists_presets(capsys):
    assert main(["gears"]) == 0
    assert "silo4-joint3" in capsys.readouterr().out
    assert main(["gears", "silo4-joint3"]) == 0
    assert "287" in capsys.readouterr().out


def test_console_script_runs_demo(tmp_path):
    # the installed entry point, as `make demo` calls it: the SILO4 reproduction on its twin (11 speeds
    # per direction, 3 repetitions), analysed through the recording files it writes
    import pandas as pd

    from gearspec.demo import DEMO_REPETITIONS, DEMO_SPEEDS_RPM

    r = subprocess.run([sys.executable, "-m", "gearspec.cli", "demo", "--out", str(tmp_path / "demo")],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    out = tmp_path / "demo"
    assert (out / "data" / "silo4_twin.parquet").is_file() and (out / "data" / "silo4_twin_gear.toml").is_file()
    d = json.loads((out / "spectrum.json").read_text())
    # every speed and direction: one segment per repetition, each holding most of its plateau
    for rpm in DEMO_SPEEDS_RPM:
        for dirn in (1, -1):
            n = [s["n"] for s in d["segments"] if s["direction"] == dirn and abs(s["speed"] / (rpm * np.pi / 30) - 1) < 0.03]
            assert len(n) >= DEMO_REPETITIONS and sorted(n)[-DEMO_REPETITIONS] >= 0.8 * max(n), (rpm, dirn, n)
    # the worm-shaft line is found and labelled in every segment that holds a cycle of it (from 100 rpm)
    for s in d["segments"]:
        if s["speed"] > 110 * np.pi / 30:
            assert any(p["label"] == "planetary output shaft" and p["fap"] < 1e-6 for p in s["peaks"]), s["speed"]
    f = json.loads((out / "fit" / "fit.json").read_text())
    # the twin's truth is SILO4 Table 2 (positive: tau_c 7.106 mNm, tau_E 8.58 mNm, B 0.0134 mNm/rpm)
    p = f["directions"]["positive"]
    assert p["tau_c"] == pytest.approx(7.106e-3, rel=0.05) and p["tau_s"] == pytest.approx(8.58e-3, rel=0.05)
    t2 = pd.read_csv(out / "table2.csv")
    for q in ("tau_E", "tau_C", "B", "A2", "b2"):
        for dn in ("positive", "negative"):
            row = t2[t2["quantity"].str.startswith(f"{q} {dn} (")].iloc[0]
            assert abs(row["rel_diff"]) <= row["tolerance"], (q, dn, row["gearspec"], row["paper"])
    report = (out / "report.md").read_text()
    assert "## Audit" in report and "25 %" in report and (out / "fig7_percent.png").is_file()
