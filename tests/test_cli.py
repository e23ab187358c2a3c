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


@pytest.mark.slow
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


@pytest.mark.slow
def test_console_script_runs_demo(tmp_path):
    # the installed entry point, as `make demo` calls it: the SILO4 reproduction on its twin (11 speeds
    # per direction, 3 repetitions), analysed through the recording files it writes
    import pandas as pd

    from paper_repro.demo import DEMO_REPETITIONS, DEMO_SPEEDS_RPM

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


# ---------------------------------------------------------------------- fuzz findings (issue 10): one line, exit 2
@pytest.fixture(scope="module")
def small_frame():
    import pandas as pd

    rec, _ = plateau_recording([40, -40, 80], ripples=[Ripple(1 / (2 * np.pi), 1e-3, 0.5)], level=0.01,
                               duration=0.4, fs=1000, noise=1e-4, seed=4)
    return pd.DataFrame(rec.data[["t", "theta", "torque"]])


def _one_error_line(capsys) -> str:
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip() and not ln.startswith("gearspec: warning:")]
    assert len(lines) == 1 and lines[0].startswith("gearspec: error: "), err
    assert "Traceback" not in err and "Warning:" not in err.replace("gearspec: warning:", "")
    return lines[0]


def _recording_file(finding, d, folder):
    """The file of one recording-level finding and the words its message must hold."""
    import pyarrow as pa
    import pyarrow.parquet as pq
    import scipy.io

    if finding == "theta and 'theta '":
        p = folder / "blank.csv"
        d.rename(columns={"torque": "theta "}).assign(torque=d.torque).to_csv(p, index=False)
        return p, ["blank.csv", "column 'theta' appears twice", "differ only in blanks"]
    if finding == "duplicate csv names":
        p = folder / "dup.csv"
        p.write_text("t,theta,theta,torque\n" + "\n".join(f"{a},{b},{b},{c}" for a, b, c in d.to_numpy()))
        return p, ["dup.csv", "column 'theta' appears twice in the header"]
    if finding == "duplicate parquet names":
        p = folder / "dup.parquet"
        pq.write_table(pa.Table.from_arrays([pa.array(d[c]) for c in ("t", "theta", "theta", "torque")],
                                            names=["t", "theta", "theta", "torque"]), p)
        return p, ["dup.parquet", "column 'theta' appears twice"]
    if finding == "wide matrix, names capped":
        p = folder / "wide.mat"
        big = np.vstack([d.t, d.theta, d.torque] + [d.t] * 2000)[:, :1500]  # 1500 columns of 2003 rows
        scipy.io.savemat(p, {"data": big})
        return p, ["wide.mat", "no column 'theta'", "data_11, ... (1500 in all)"]
    p = folder / "r.csv"
    change, words = {
        "denormal theta": ({"theta": d.theta * 1e-310}, ["column 'theta' moves by only", "wrong unit"]),
        "denormal time": ({"t": d.t * 1e-310}, ["column 't' steps by", "wrong unit"]),
        "all-zero torque": ({"torque": 0.0}, ["column 'torque' never changes (always 0)"]),
        "denormal torque": ({"torque": d.torque * 1e-310}, ["column 'torque' changes only by"]),
    }[finding]
    d.assign(**change).to_csv(p, index=False)
    return p, [str(p)] + words


FINDINGS = ["theta and 'theta '", "duplicate csv names", "duplicate parquet names", "denormal theta", "denormal time",
            "all-zero torque", "denormal torque", "wide matrix, names capped"]


@pytest.mark.parametrize("command", ["spectrum", "fit", "diagnose"])
@pytest.mark.parametrize("finding", FINDINGS)
def test_fuzz_finding_in_the_recording_is_one_sentence(finding, command, small_frame, tmp_path, capsys):
    path, words = _recording_file(finding, small_frame, tmp_path)
    assert main([command, str(path), "--quiet"]) == 2
    line = _one_error_line(capsys)
    for w in words:
        assert w in line, line
    assert len(line) < 700


def test_a_row_major_matrix_is_transposed_with_a_note(small_frame, tmp_path, capsys):
    np.savez(tmp_path / "wide.npz", data=small_frame.to_numpy().T)  # 3 x N: one row per channel
    code = main(["spectrum", str(tmp_path / "wide.npz"), "--map", "t=data_0,theta=data_1,torque=data_2", "--quiet",
                 "--json", str(tmp_path / "s.json")])
    err = capsys.readouterr().err
    assert code == 0, err
    assert "variable 'data' is a 3 x 2000 matrix; read as 2000 rows of 3 columns" in err
    assert json.loads((tmp_path / "s.json").read_text())["n_rows"] == 2000


GEAR_FINDINGS = {
    'ratio = "abc"': "stage 1 ('planetary'): 'ratio' must be a number, got 'abc'",
    "ratio = [14]": "'ratio' must be a number, got [14] (a list)",
    'ratio = "14"': "'ratio' must be a number, got '14' (a text)",
    "ratio = true": "'ratio' must be a number, got True (true/false)",
    'ratio = 14\nteeth = "x"': "'teeth' must be a whole number, got 'x'",
    'ratio = 14\nlead = "x"': "'lead' must be a number, got 'x'",
    "stages = [1, 2]": "stage 1 must be a [[stages]] table, got 1",
    "non-UTF-8": "is not UTF-8 text",
    "50 stages": "50 stages; a gear train has at most 8",
    "ratio 1e4 x 3": "the stages' ratios multiply to 1e+12",
}


@pytest.mark.parametrize("finding", list(GEAR_FINDINGS))
def test_gear_spec_of_the_wrong_type_is_one_sentence_naming_the_file_and_field(finding, small_frame, tmp_path, capsys):
    spec = tmp_path / "gear.toml"
    if finding == "non-UTF-8":
        spec.write_bytes(b'name = "caf\xe9"\n')
    elif finding == "50 stages":
        spec.write_text('name = "g"\n' + '[[stages]]\nkind = "spur"\nratio = 1.5\n' * 50)
    elif finding == "ratio 1e4 x 3":
        spec.write_text('name = "g"\n' + '[[stages]]\nkind = "spur"\nratio = 1e4\n' * 3)
    elif finding.startswith("stages"):
        spec.write_text(f'name = "g"\n{finding}\n')
    else:
        kind = "ballscrew" if "lead" in finding else "planetary"
        unit = "m" if kind == "ballscrew" else "rad"
        spec.write_text(f'name = "g"\nunit = "{unit}"\n[[stages]]\nkind = "{kind}"\n{finding}\n')
    small_frame.to_csv(tmp_path / "r.csv", index=False)
    assert main(["fit", str(tmp_path / "r.csv"), "--gear", str(spec), "--quiet"]) == 2
    line = _one_error_line(capsys)
    assert f"gear spec {spec}" in line and GEAR_FINDINGS[finding] in line, line


OPTION_FINDINGS = [
    (["--window", "abc"], "argument --window: 'abc' is neither 'auto' nor a time in s"),
    (["--window", "-1"], "argument --window: must be above 0"),
    (["--sep", ""], "argument --sep: the separator is empty"),
    (["--max-frequency", "0"], "argument --max-frequency: must be above 0, got 0"),
    (["--max-frequency", "-1"], "argument --max-frequency: must be above 0, got -1"),
    (["--fap", "2"], "argument --fap: must be above 0 and below 1, got 2"),
    (["--fap", "0"], "argument --fap: must be above 0 and below 1, got 0"),
    (["--harmonics", "200"], "argument --harmonics: must be at least 1 and at most 16, got 200"),
    (["--harmonics", "1.5"], "argument --harmonics: '1.5' is not an integer"),
    (["--min-cycles", "0"], "argument --min-cycles: must be above 0"),
    (["--rel-tol", "0"], "argument --rel-tol: must be above 0 and at most 1"),
    (["--rel-tol", "nan"], "argument --rel-tol: 'nan' is not a finite number"),
    (["--max-peaks", "-1"], "argument --max-peaks: must be at least 0"),
    (["--min-speed", "-2"], "argument --min-speed: must be above 0"),
    (["--max-gap", "0"], "argument --max-gap: must be above 0"),
    (["--fs", "inf"], "argument --fs: 'inf' is not a finite number"),
    (["--json", "/proc/no/x.json"], "--json /proc/no/x.json: cannot be written"),
    (["--out", "/dev/null/report"], "--out /dev/null/report: cannot be written (/dev/null is not a folder)"),
]


@pytest.mark.parametrize("option,message", OPTION_FINDINGS)
def test_option_values_are_checked_before_any_work(option, message, small_frame, tmp_path, capsys):
    small_frame.to_csv(tmp_path / "r.csv", index=False)
    assert main(["spectrum", str(tmp_path / "r.csv"), *option]) == 2
    line = _one_error_line(capsys)
    assert message in line, line


@pytest.mark.parametrize("command,option,message", [
    ("fit", ["--folds", "1"], "argument --folds: must be at least 2"),
    ("diagnose", ["--alpha", "1.5"], "argument --alpha: must be above 0 and below 1"),
    ("diagnose", ["--cutoff", "0"], "argument --cutoff: must be above 0"),
    ("diagnose", ["--decimate", "0"], "argument --decimate: must be at least 1"),
    ("discover", ["--spectrum-fap", "1"], "argument --spectrum-fap: must be above 0 and below 1"),
    ("discover", ["--bootstrap", "-1"], "argument --bootstrap: must be at least 0"),
])
def test_option_values_of_other_commands(command, option, message, tmp_path, capsys):
    assert main([command, str(tmp_path / "never_read.csv"), *option]) == 2
    assert message in _one_error_line(capsys)


def test_multi_character_separator_is_read_without_parser_noise(small_frame, tmp_path, capsys):
    (tmp_path / "r.csv").write_text(small_frame.to_csv(index=False).replace(",", ";;"))
    assert main(["spectrum", str(tmp_path / "r.csv"), "--sep", ";;", "--quiet", "--json", str(tmp_path / "s.json")]) == 0
    assert capsys.readouterr().err == ""  # no ParserWarning, no RuntimeWarning, no progress (--quiet)
    (tmp_path / "r.csv").write_text(small_frame.to_csv(index=False).replace(",", ";"))
    assert main(["spectrum", str(tmp_path / "r.csv"), "--sep", ";;", "--quiet"]) == 2
    assert "only one column ('t;theta;torque') was found with --sep ';;'" in _one_error_line(capsys)


def test_max_gap_option_is_honoured(small_frame, tmp_path, capsys):
    d = small_frame.copy()
    d.loc[d.index >= 200, "t"] += 0.02  # a 21 ms hole in the first plateau of a 1 kHz log
    d.to_csv(tmp_path / "r.csv", index=False)
    for option, n_gaps in (([], 1), (["--max-gap", "0.05"], 0)):
        assert main(["spectrum", str(tmp_path / "r.csv"), "--quiet", "--json", str(tmp_path / "s.json"), *option]) == 0
        capsys.readouterr()
        from gearspec.recording import load_recording

        rec = load_recording(tmp_path / "r.csv", max_gap=float(option[1]) if option else None)
        assert len(rec.pieces()) == 1 + n_gaps
    # the segments follow the pieces: with the hole bridged, the first plateau is one segment again
    first = [s["n"] for s in json.loads((tmp_path / "s.json").read_text())["segments"] if s["direction"] == 1]
    assert max(first) > 250


def test_stage_lines_when_stderr_is_not_a_terminal(small_frame, tmp_path, capsys):
    small_frame.to_csv(tmp_path / "r.csv", index=False)
    assert main(["spectrum", str(tmp_path / "r.csv")]) == 0
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith("gearspec: loaded 2,000 rows from 1 file(s), 2,000 usable (") and err[0].endswith(" s)")
    assert err[1].startswith("gearspec: 3 segment(s) found, ") and "of 2,000 rows in them" in err[1]
    assert err[2].startswith("gearspec: spectra of 3 segment(s) (")
    assert main(["spectrum", str(tmp_path / "r.csv"), "--quiet"]) == 0
    assert capsys.readouterr().err == ""
