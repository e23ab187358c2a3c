"""The paper reproductions (paper_repro.silo4, paper_repro.lola) on reduced configurations.

The full SILO4 reproduction (``gearspec repro silo4``) takes over a minute; here it runs every speed
of the twin with 3 instead of 10 repetitions (the issue's tolerances hold there, b3 excepted, with
its reason stated).  The Lola reproduction runs in full (about 20 s): on a smaller grid with shorter
points (4 x 4, 3 s) the small viscous coefficient of module A is 6 % off, outside 5 %.  The numbers asserted are the
issue's tolerances against the papers' tables, and the audit's arithmetic against hand-computed
values.
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from gearspec.fitdata import FitData
from gearspec.recording import load_recording

COLUMNS = ["quantity", "paper", "gearspec", "rel_diff"]


def _csv(path):
    df = pd.read_csv(path)
    assert list(df.columns[:4]) == COLUMNS, (path.name, list(df.columns))
    return df


def _png_ok(path):
    from PIL import Image

    assert path.is_file(), path
    with Image.open(path) as im:
        assert im.size[0] > 400 and im.size[1] > 250, (path.name, im.size)


# ---------------------------------------------------------------------- SILO4
@pytest.mark.slow
def test_silo4_reproduction(tmp_path):
    """One run (about 40 s), every check on it: one test, so that parallel workers do not each run it."""
    import paper_repro.silo4 as s4

    s4.run(tmp_path, seed=0, repetitions=3, stick_slip_duration=5.0, control_repetitions=2)
    _silo4_outputs_exist(tmp_path)
    _silo4_twin_recording_is_reread_by_the_loaders(tmp_path)
    _silo4_table2_recovered_within_the_issue_tolerances(tmp_path)
    _silo4_chain_attenuates_only_the_motor_shaft_line(tmp_path)
    _silo4_table3_recomputed_at_the_papers_speeds(tmp_path)


def _silo4_outputs_exist(silo4_out):
    for name in ("fig3_stick_slip", "fig4_stribeck", "fig5_position_spectra", "fig6_f3_component", "fig7_percent",
                 "fig9_model_vs_data", "chain_transfer"):
        _png_ok(silo4_out / f"{name}.png")
    for name in ("table2", "table3", "audit", "table2_published_procedure"):
        _csv(silo4_out / f"{name}.csv")
    report = (silo4_out / "report.md").read_text()
    for section in ("## Table 2", "## Table 3", "## Audit", "## The measurement chain", "Fig. 3", "Fig. 9"):
        assert section in report
    assert (silo4_out / "fit" / "report.md").is_file()


def _silo4_twin_recording_is_reread_by_the_loaders(silo4_out):
    rec = load_recording(silo4_out / "data" / "silo4_twin.parquet", silo4_out / "data" / "silo4_twin_gear.toml")
    assert rec.gear.torque_constant == pytest.approx(0.0231) and rec.gear.inertia == pytest.approx(2e-6)
    assert rec.data["run"].nunique() == 20 * 2 * 3
    truth = json.loads((silo4_out / "data" / "silo4_twin_truth.json").read_text())
    assert len(truth["runs"]) == 120 and truth["model"]["law"] == "silo4"
    # the spectrum was computed from the re-read file: one segment per run
    spec = json.loads((silo4_out / "spectrum.json").read_text())
    assert len(spec["segments"]) >= 120


def _silo4_table2_recovered_within_the_issue_tolerances(silo4_out):
    t = _csv(silo4_out / "table2.csv")
    main = t[t["tolerance"].notna() & ~t["quantity"].str.contains("pass band")]
    assert len(main) == 16
    for _, r in main.iterrows():
        if r["quantity"].startswith("b3"):
            # not identifiable from such data: the reason is stated, with the control run's evidence
            assert "not identifiable" in r["note"] and "control run" in r["note"], r["quantity"]
            continue
        assert abs(r["rel_diff"]) <= r["tolerance"], (r["quantity"], r["gearspec"], r["paper"])
    # the published procedure: Coulomb and viscous recovered too
    for q in ("tau_C positive", "tau_C negative", "B positive", "B negative"):
        r = t[t["quantity"].str.startswith(q)].iloc[0]
        assert abs(r["rel_diff_published"]) <= 0.05, q


def _silo4_chain_attenuates_only_the_motor_shaft_line(silo4_out):
    tr = pd.read_csv(silo4_out / "chain_transfer.csv")
    g = tr.groupby(["k", "rpm"])["ratio"].mean()
    assert all(abs(g[2][r] - 1) < 0.08 for r in g[2].index)         # F2: passes at every speed
    assert g[3][3000] < 0.8 and g[3][4500] < 0.8                       # F3: attenuated at high speed
    assert abs(g[3][280] - 1) < 0.08


def _silo4_table3_recomputed_at_the_papers_speeds(silo4_out):
    t = _csv(silo4_out / "table3.csv")
    for r in (280, 560, 3000):
        for d in ("positive", "negative"):
            se = t[t["quantity"] == f"s(e) at {r} rpm, {d} (mNm)"].iloc[0]
            e = t[t["quantity"] == f"e at {r} rpm, {d} (mNm)"].iloc[0]
            # noise of 4 mA x 0.0231 Nm/A = 0.092 mNm per sample is the floor of s(e)
            assert 0.09 < se["gearspec"] < 0.3 and se["segments"] >= 3
            # |e| within twice the repetition scatter (1 % of the level per run)
            assert abs(e["gearspec"]) < 0.02 * (7.1 + 0.0134 * r)


def test_silo4_audit_arithmetic():
    from paper_repro.silo4 import audit

    # Table 2's mean friction is lowest near 36-38 rpm: 7.106 + 1.474 e^(-v/28.18) + 0.0134 v = 7.998 mNm
    r = audit.ripple_percent(2, "positive")
    assert r["level"] == pytest.approx(7.998, abs=2e-3) and r["percent"] == pytest.approx(7.17, abs=0.02)
    assert audit.ripple_percent(3, "positive")["percent"] == pytest.approx(1.66, abs=0.01)
    # eq. 4 on the noiseless law over 2..20 rpm: the viscous term biases the Stribeck velocity up
    assert audit.eq4_on_table2([2, 5, 10, 20], "positive", 20.0)["v_s"] > 40
    rows, _ = audit.rows_and_text([2, 5, 10, 20, 30, 50, 75, 100])
    pct = {r["quantity"]: r["gearspec"] for r in rows}
    # Table 3's e at 280 rpm against the negative direction's level: 0.17 / 11.77 = 1.44 % (text: 1.4 %)
    key = "|e| at 280 rpm, % of mean friction, negative (text vs Table 3 / Table 2 level)"
    assert pct[key] == pytest.approx(100 * 0.17 / (7.909 + 0.0138 * 280), rel=1e-3)


# ---------------------------------------------------------------------- Lola/CROPS
@pytest.mark.slow
def test_lola_reproduction(tmp_path):
    """The full reproduction (about 20 s), every check on it in one test."""
    import os

    import paper_repro.lola as lo
    from conftest import data_root

    have_catalog = data_root().is_dir()
    if have_catalog:  # Table V needs the catalog data set (as the data_dir fixture does)
        os.environ.setdefault("GEARSPEC_DATA", str(data_root()))
    lo.run(tmp_path, seed=0)
    _lola_outputs_exist(tmp_path)
    _lola_table4_recovered_from_the_twin(tmp_path)
    _lola_rms_ratio_reported_per_module(tmp_path)
    if have_catalog:
        _lola_table5_on_the_available_catalog(tmp_path)
    else:
        assert "Table V skipped" in (tmp_path / "report.md").read_text()


def _lola_outputs_exist(lola_out):
    for name in ("fig7_efficiency_A", "fig8_efficiency_C", "fig9_friction_A_law8", "fig10_friction_A_law11",
                 "fig11_friction_C_law11"):
        _png_ok(lola_out / f"{name}.png")
    for name in ("table3", "table4", "rms_ratio"):
        _csv(lola_out / f"{name}.csv")
    report = (lola_out / "report.md").read_text()
    assert "## Table IV" in report and "## Audit" in report
    assert "not the paper's catalog" in report or "Table V skipped" in report
    for m in "ABC":
        rec = load_recording(lola_out / "data" / f"lola_{m}_twin.parquet", lola_out / "data" / f"lola_{m}_twin_gear.toml")
        assert "load" in rec.data and rec.data["run"].nunique() == 8 * 2 * 8


def _lola_table4_recovered_from_the_twin(lola_out):
    t = _csv(lola_out / "table4.csv")
    par = t[t["tolerance"].notna()]
    assert len(par) == 15
    assert (np.abs(par["rel_diff"]) <= 0.05).all(), par[["quantity", "paper", "gearspec"]]


def _lola_rms_ratio_reported_per_module(lola_out):
    t = _csv(lola_out / "rms_ratio.csv")
    for m, ratio in (("A", 0.0111 / 0.0046), ("B", 0.0499 / 0.012), ("C", 0.0064 / 0.003)):
        row = t[t["quantity"] == f"RMS ratio, {m}: Table III RMS / Table IV RMS"].iloc[0]
        assert row["gearspec"] == pytest.approx(ratio, rel=1e-9)
        twin = t[t["quantity"] == f"RMS ratio law (8) / law (11), {m}: twin"].iloc[0]
        assert twin["gearspec"] > 1  # law (11) is the truth: it always fits better


def _lola_table5_on_the_available_catalog(lola_out):
    t = _csv(lola_out / "table5.csv")
    assert set(t["gear"]) == {"HFUC-25-100", "CSG-32-50", "CSD-20-100"}
    # the efficiency grid does not carry the ratio: N = 50 parameters are twice the N = 100 ones
    a = t[t["quantity"] == "T_f0 HFUC-25-100 (Nm)"]["gearspec"].iloc[0]
    b = t[t["quantity"] == "T_f0 CSG-32-50 (Nm)"]["gearspec"].iloc[0]
    assert b == pytest.approx(2 * a, rel=1e-3)
    assert "NOT this gear" in t["note"].iloc[0]


# ---------------------------------------------------------------------- the API the reproductions needed
def test_efficiency_fit_finds_the_sharp_minimum_of_law_11():
    """Law (11) on precise points has a narrow minimum at v_S that a coarse start grid can straddle;
    the fit polishes from every local minimum of the grid (Lola A and C landed at v_S ~ 600 rad/s)."""
    from gearspec import identify
    from gearspec.simulate.lola import PAPER_TABLE4, table4_model

    v = np.repeat(np.linspace(25, 400, 8), 8)
    load = np.tile(np.linspace(4.55, 72.8, 8), 8)
    for m in ("A", "C"):
        eta = identify.efficiency_model(table4_model(m), v, load, 100.0)
        fit = identify.fit_efficiency(FitData.from_points(v, eta, load=load), "lola11", ratio=100.0)
        p = fit.params("positive")
        for k in ("t_f0", "mu", "b", "t_fs", "v_s"):
            assert p[k] == pytest.approx(PAPER_TABLE4[m][k], rel=0.01), (m, k, p[k])


def test_gear_spec_toml_round_trip(tmp_path):
    from gearspec.gears import GearTrain
    from gearspec.simulate.silo4 import twin_gear

    g = twin_gear()
    text = g.to_toml(tmp_path / "g.toml")
    assert "torque_constant = 0.0231" in text
    assert GearTrain.from_toml(tmp_path / "g.toml") == g
