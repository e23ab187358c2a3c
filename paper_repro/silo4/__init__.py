"""SILO4 (Garcia, Gonzalez de Santos, Canudas de Wit, IJRR 21(9) 2002) reproduced on its digital twin.

The paper's raw data are not public.  The reproduction therefore

1. runs the twin of the SILO4 joint-3 bench (:func:`gearspec.simulate.silo4_twin`), whose friction
   is Table 2's full model (eq. 11): ten repetitions per speed, both directions, closed-loop speed
   control on a 500-line encoder, current through a 1 kHz Bessel filter sampled every 4 ms;
   and one creeping run at 1e-4 rad/s of the joint (Fig. 3);
2. saves the recordings in the recording format (parquet) with the gear spec (TOML) and the truth
   (JSON), and reads them back with :func:`gearspec.recording.load_recording`;
3. analyses the re-read recording exactly as ``gearspec spectrum`` and ``gearspec fit --law silo4``
   do (segments, per-segment spectra, the joint fit beside the published procedure and simpler
   laws, per-segment errors as eqs. 12-13), writing their JSON and the fit report;
4. redraws the figures that rest on data (3, 4, 5, 6, 7, 9), compares Tables 2 and 3 with the
   paper (CSV: ``quantity, paper, gearspec, rel_diff``), runs a control experiment on the
   measurement chain (the same bench with non-decaying lines), and audits the paper's numbers
   against each other (:mod:`.audit`).

``run(out, seed=0)`` writes ``out/report.md``; ``python -m paper_repro.silo4 --out DIR`` and
``gearspec repro silo4 --out DIR`` call it.  Options make smaller configurations (tests, demo).
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np
import pandas as pd

from gearspec import identify
from gearspec.fitdata import FitData
from gearspec.model import RPM
from gearspec.recording import load_recording
from gearspec.report import markdown_table, write_report
from gearspec.report.fit import write_fit_report
from gearspec.segment import find_segments
from gearspec.simulate.silo4 import (DEFAULT_SPEEDS_RPM, PAPER_TABLE2, PLANT, RATIO, silo4_twin, stick_slip_run,
                                     table2_model)
from gearspec.spectrum import analyze

from ..tables import comparison_table, write_table
from . import audit
from . import figures as figs

__all__ = ["run", "table2_comparison", "TOLERANCES"]

#: the issue's tolerances for Table 2 (relative)
TOLERANCES = {"tau_E": 0.05, "tau_C": 0.05, "B": 0.05, "A1": 0.10, "A2": 0.10, "A3": 0.10, "b2": 0.25, "b3": 0.25}
_BASE = {"tau_E": ("tau_s", 1e3, "mNm"), "tau_C": ("tau_c", 1e3, "mNm"), "theta_s": ("v_s", 1 / RPM, "rpm"),
         "B": ("viscous", 1e3 * RPM, "mNm/rpm")}
_ORDER = ("tau_E", "tau_C", "theta_s", "B", "A1", "omega1", "phi1", "A2", "b2", "omega2", "phi2", "A3", "b3",
          "omega3", "phi3")
FIG5_RPM = (2000, 4500, 6500)
TABLE3_RPM = (280, 560, 3000)


def _harmonic(model, direction, k):
    lab = figs.LABELS[k]
    for h in model.harmonics(direction):
        if h.get("label") == lab or lab in (h.get("label") or "").split(" = "):
            return h
    return None


def _value(model, direction: str, q: str) -> tuple[float | None, float | None]:
    """Parameter ``q`` of Table 2 (paper units) and its standard error from a FrictionModel."""
    paper = PAPER_TABLE2[q][direction]
    if q in _BASE:
        key, f, _ = _BASE[q]
        p = model.params(direction)
        v, se = p.get(key), p.get(key + "_se")
        return (None if v is None else v * f), (None if se is None else se * f)
    kind, k = q[:-1], int(q[-1])
    h = _harmonic(model, direction, k)
    if h is None or h.get("amplitude") is None:
        return None, None
    if kind == "A":
        return h["amplitude"] * 1e3, _f(h.get("amplitude_se"), 1e3)
    if kind == "b":
        return (h.get("decay") or 0.0) * RPM, _f(h.get("decay_se"), RPM)
    if kind == "phi":  # the equivalent angle nearest the paper's
        return paper + (h["phase"] - paper + math.pi) % (2 * math.pi) - math.pi, h.get("phase_se")
    if kind == "omega":
        return 2 * math.pi * h["frequency"], None
    raise KeyError(q)


def _f(x, factor):
    return None if x is None or not np.isfinite(x) else x * factor


def table2_comparison(joint, published, notes: dict | None = None) -> pd.DataFrame:
    """Table 2 against the joint fit (``gearspec``) and the published procedure, per direction."""
    rows = []
    for q in _ORDER:
        for d in ("positive", "negative"):
            paper = PAPER_TABLE2[q][d]
            g, g_se = _value(joint, d, q)
            pb, _ = _value(published, d, q)
            tol = TOLERANCES.get(q)
            rel = None if g is None else (g - paper) / abs(paper)
            rows.append({"quantity": f"{q} {d} ({PAPER_TABLE2[q]['unit']})", "paper": paper, "gearspec": g,
                         "gearspec_se": g_se, "published_procedure": pb,
                         "rel_diff_published": None if pb is None else (pb - paper) / abs(paper),
                         "tolerance": tol,
                         "within": None if tol is None or rel is None else bool(abs(rel) <= tol),
                         "note": (notes or {}).get((q, d), "declared by the gear spec (1/287, 1/14, 1), not fitted"
                                                   if q.startswith("omega") else "")})
    return comparison_table(rows)


def _zero_decay(model):
    m = model.copy()
    for p in m.directions.values():
        for h in p.harmonics:
            h.decay = 0.0
    m.name = "Table 2 with every decay set to 0 (control)"
    return m


def _chain_transfer(seed: int, repetitions: int, speeds=(100, 280, 560, 800, 1000, 1500, 2000, 3000, 4500)):
    """Control run: the same bench, Table 2 with b2 = b3 = 0; measured / true amplitude per segment."""
    truth = _zero_decay(table2_model())
    rec, _ = silo4_twin([s * d for s in speeds for d in (1, -1)], repetitions=repetitions, truth=truth,
                        seed=seed + 1000)
    data = FitData.from_recording(rec)
    amp = identify.line_amplitudes(data, identify.harmonic_specs(None, rec.gear))
    rows = []
    for _, a in amp.iterrows():
        k = next((k for k, lab in figs.LABELS.items() if lab == a["label"]), None)
        if k not in (2, 3):
            continue
        h = _harmonic(truth, "positive" if a["direction"] > 0 else "negative", k)
        rows.append({"k": k, "direction": int(a["direction"]), "rpm": float(np.round(a["speed"] / RPM, -1)),
                     "ratio": a["amplitude"] / h["amplitude"], "se": a["amplitude_se"] / h["amplitude"]})
    return pd.DataFrame(rows)


def _passband(transfer: pd.DataFrame, k: int = 3, tol: float = 0.05) -> float:
    """Highest control speed up to which line k is not attenuated: the mean measured/true ratio
    stays above ``1 - tol`` in both directions at that speed and every slower one (the chain only
    attenuates; ratios above 1 are scatter)."""
    g2 = transfer[transfer["k"] == k].groupby(["rpm", "direction"])["ratio"].mean().unstack()
    ok = (g2 >= 1 - tol).all(axis=1).sort_index()
    top = 0.0
    for rpm, good in ok.items():
        if not good:
            break
        top = float(rpm)
    return top if top > 0 else float(ok.index.min())


def _table3(errors: dict[str, pd.DataFrame]) -> pd.DataFrame:
    rows = []
    for r in TABLE3_RPM:
        for qty in ("s_e", "e"):
            for d, dn in ((1, "positive"), (-1, "negative")):
                row = {"quantity": f"{'s(e)' if qty == 's_e' else 'e'} at {r} rpm, {dn} (mNm)",
                       "paper": audit.TABLE3[r][qty]}
                for name, df in errors.items():
                    sub = df[(df["direction"] == d) & (np.abs(df["speed"] / RPM / r - 1) < 0.03)]
                    row[name] = 1e3 * float(sub[qty].mean()) if len(sub) else None
                    if name == "gearspec":
                        row["segments"] = len(sub)
                        if qty == "e":
                            row["e_percent_of_level"] = float(sub["e_percent"].mean()) if len(sub) else None
                rows.append(row)
    return comparison_table(rows)


def run(out, seed: int = 0, *, speeds_rpm=None, repetitions: int = 10, stick_slip_duration: float = 30.0,
        control_repetitions: int = 2, fmt: str = "parquet") -> Path:
    """Reproduce SILO4's data figures and Tables 2-3 on the twin; returns ``out/report.md``.

    Parameters
    ----------
    out : path
        Output folder (created).
    seed : int
        Seed of the twins' noise.
    speeds_rpm : sequence of float, optional
        Motor speeds (rpm, positive; each run in both directions).  Default: the twin's 20 speeds
        from 2 to 6500 rpm (they include Table 3's and Fig. 5's).
    repetitions : int
        Runs per speed and direction (the paper: ten).
    stick_slip_duration : float
        Seconds of the creeping run of Fig. 3.
    control_repetitions : int
        Repetitions of the measurement-chain control run (0: skip it).
    fmt : {"parquet", "csv"}
        File format of the saved twin recordings.
    """
    t_start = time.perf_counter()
    timings: dict[str, float] = {}

    def tick(name, t0):
        timings[name] = time.perf_counter() - t0
        return time.perf_counter()

    out = Path(out)
    (out / "data").mkdir(parents=True, exist_ok=True)
    speeds = sorted(float(s) for s in (speeds_rpm if speeds_rpm is not None else DEFAULT_SPEEDS_RPM))
    t0 = time.perf_counter()

    # ---- 1. the twin and its recordings, saved and read back as a user's files
    rec0, truth = silo4_twin([s * d for s in speeds for d in (1, -1)], repetitions=repetitions, seed=seed)
    path = rec0.save(out / "data" / f"silo4_twin.{fmt}")
    gear_path = out / "data" / "silo4_twin_gear.toml"
    truth.gear.to_toml(gear_path)
    truth.to_json(out / "data" / "silo4_twin_truth.json")
    ss0, ss_truth = stick_slip_run(duration=stick_slip_duration, seed=seed)
    ss_path = ss0.save(out / "data" / f"silo4_stick_slip.{fmt}")
    t0 = tick("twin (simulate, save)", t0)
    rec = load_recording(path, gear_path)
    ss = load_recording(ss_path, gear_path)
    reread = {c: float(np.max(np.abs(rec.data[c].to_numpy(float) - rec0.data[c].to_numpy(float))))
              for c in ("t", "theta", "current")}
    t0 = tick("re-read", t0)

    # ---- 2. gearspec spectrum
    seg = find_segments(rec)
    spectrum = analyze(rec, segmentation=seg, keep_spectra=True)
    spectrum.to_json(out / "spectrum.json")
    t0 = tick("gearspec spectrum (segments, spectra)", t0)

    # ---- 3. gearspec fit --law silo4 (joint fit, published procedure, simpler laws), with eq. 11's
    # structure: the joint-turn line F1 of constant amplitude (eq. 6), F2 and F3 decaying (eq. 8)
    specs = [dict(h, decay=False) if h["label"] == figs.LABELS[1] else h
             for h in identify.harmonic_specs(None, rec.gear)]
    fitted = identify.identify_recording(rec, "silo4", segmentation=seg, harmonics=specs)
    joint = fitted.model
    published = next(m for name, m in fitted.models.items() if "published" in name)
    (out / "fit").mkdir(exist_ok=True)
    (out / "fit" / "fit.json").write_text(json.dumps(fitted.to_dict(), indent=1))
    write_fit_report(fitted, out / "fit", command=f"gearspec fit {path.name} --gear {gear_path.name} --law silo4",
                     recording_summary=rec.summary())
    data = fitted.data
    t0 = tick("gearspec fit (joint fit, published procedure, simpler laws)", t0)

    # ---- 4. the published procedure with eq. 4 on the very slowest plateaus only
    low_cut = 20.0
    keep = (np.abs(data.v) <= low_cut * RPM * 1.02) | (np.abs(data.v) > 100 * RPM)
    published_low = None
    if (np.abs(data.v[keep]) <= low_cut * RPM * 1.02).any():
        published_low = identify.silo4_published(data.subset(keep), amplitudes=fitted.amplitudes, harmonics=specs,
                                                 holdout=None)
        published_low.name = f"published, eq. 4 on plateaus <= {low_cut:g} rpm"

    # ---- 5. the measurement chain: control run with non-decaying lines, b3 in its pass band
    transfer = _chain_transfer(seed, control_repetitions) if control_repetitions else pd.DataFrame()
    passband = _passband(transfer) if len(transfer) else 560.0
    band = data.subset(np.abs(data.v) <= passband * RPM * 1.02)
    joint_band = identify.fit(band, "silo4", harmonics=specs, holdout=None, name=f"joint fit <= {passband:g} rpm")
    t0 = tick("control run and band-limited fit", t0)

    # ---- 6. what the realised repetitions imply for the Stribeck curve (twin truth)
    realised = {}
    for d, dn in ((1, "positive"), (-1, "negative")):
        r = truth.runs[truth.runs["direction"] == d]
        fd = FitData.from_points(r["velocity"].to_numpy(), d * r["level"].to_numpy())
        realised[dn] = identify.fit(fd, "stribeck", holdout=None, weights="uniform").params(dn)

    # ---- Table 2
    truth_model = table2_model()
    notes = {}
    for dn in ("positive", "negative"):
        g, se = _value(joint, dn, "theta_s")
        rv = realised[dn]["v_s"] / RPM
        notes[("theta_s", dn)] = (f"the twin's repetitions scatter by {100 * PLANT['repeatability']:g} % in level "
                                  f"(each run one factor); the realised run levels themselves give "
                                  f"{rv:.2f} rpm: the fit follows the data, its se ({se:.2g}) counts samples, "
                                  "not repetitions")
        for k in (2, 3):
            tr = transfer[(transfer["k"] == k) & (transfer["direction"] == (1 if dn == "positive" else -1))] \
                if len(transfer) else transfer
            hi = tr[tr["rpm"] == tr["rpm"].max()] if len(tr) else tr
            if k == 3:
                b_band = _harmonic(joint_band, dn, 3)
                nb = ("" if b_band is None else
                      f"; fitted on the chain's pass band (<= {passband:g} rpm) b3 = {b_band['decay'] * RPM:.3g} "
                      f"+- {(b_band.get('decay_se') or float('nan')) * RPM:.2g} /rpm")
                notes[("b3", dn)] = (
                    f"not identifiable from such data: the control run (b = 0) measures "
                    f"{hi['ratio'].mean():.2f} x the true F3 amplitude at {hi['rpm'].max():.0f} rpm "
                    f"(speed loop and inertia correction, see the chain section) -- a larger drop than Table 2's "
                    f"own decay there, e^(-b3 v) = {math.exp(-PAPER_TABLE2['b3'][dn] * hi['rpm'].max()):.3f}{nb}"
                    if len(hi) else "")
            if k == 3:
                notes[("A3", dn)] = "extrapolated to 0 rpm by the fitted (too fast) decay"
    table2 = table2_comparison(joint, published, notes)
    band_rows = []
    for dn in ("positive", "negative"):
        for q in ("A3", "b3"):
            g, se = _value(joint_band, dn, q)
            band_rows.append({"quantity": f"{q} {dn} ({PAPER_TABLE2[q]['unit']}), joint fit on plateaus <= "
                                          f"{passband:g} rpm (the chain's pass band)",
                              "paper": PAPER_TABLE2[q][dn], "gearspec": g, "gearspec_se": se,
                              "tolerance": TOLERANCES[q]})
    band_tab = comparison_table(band_rows)
    band_tab["within"] = [None if r is None or not np.isfinite(r) else bool(abs(r) <= t)
                          for r, t in zip(band_tab["rel_diff"], band_tab["tolerance"])]
    table2 = pd.concat([table2, band_tab], ignore_index=True)
    if published_low is not None:
        for dn in ("positive", "negative"):
            for q in ("tau_E", "theta_s"):
                g, _ = _value(published_low, dn, q)
                table2.loc[len(table2)] = {"quantity": f"{q} {dn} ({PAPER_TABLE2[q]['unit']}), published procedure "
                                                       f"with eq. 4 on plateaus <= {low_cut:g} rpm",
                                           "paper": PAPER_TABLE2[q][dn], "published_procedure": g,
                                           "rel_diff_published": (g - PAPER_TABLE2[q][dn]) / PAPER_TABLE2[q][dn]}
    write_table(table2, out / "table2.csv")
    # the published procedure alone, in the plain four-column form
    pub_tab = comparison_table([{"quantity": r["quantity"], "paper": r["paper"], "gearspec": r["published_procedure"]}
                                for _, r in table2.iloc[:2 * len(_ORDER)].iterrows()])
    write_table(pub_tab, out / "table2_published_procedure.csv")

    # ---- Table 3
    errors = {"gearspec": fitted.errors[joint.name], "table2_truth": identify.segment_errors(truth_model, data),
              "published_procedure": fitted.errors[published.name]}
    table3 = _table3(errors)
    write_table(table3, out / "table3.csv")

    # ---- audit
    audit_rows, audit_md = audit.rows_and_text(speeds)
    twin_pct = {}
    for k in (2, 3):
        df = spectrum.amplitude_vs_speed(figs.LABELS[k])
        for d, dn in ((1, "positive"), (-1, "negative")):
            sub = df[df["direction"] == d]
            twin_pct[(k, dn)] = float((100 * sub["amplitude"] / sub["level"]).max()) if len(sub) else float("nan")
            audit_rows.append({"quantity": f"F{k} amplitude, max % of mean friction, {dn}, measured on the twin",
                               "paper": audit.TEXT[f"F{k}_percent"], "gearspec": twin_pct[(k, dn)],
                               "note": "largest per-segment amplitude / segment mean (gearspec spectrum)"})
    audit_tab = comparison_table(audit_rows)
    write_table(audit_tab, out / "audit.csv")
    t0 = tick("tables", t0)

    # ---- figures
    f = {}
    f["fig3"] = figs.fig3_stick_slip(ss, truth_model, out / "fig3_stick_slip.png")
    models4 = {"Table 2 (twin truth)": truth_model, "joint fit": joint, "published procedure": published}
    if published_low is not None:
        models4[published_low.name] = published_low
    f["fig4"] = figs.fig4_stribeck(data.plateaus(), models4, out / "fig4_stribeck.png")
    f["fig5"] = figs.fig5_position_spectra(spectrum, data, FIG5_RPM, out / "fig5_position_spectra.png")
    f["fig6"] = figs.fig6_f3(spectrum, truth_model, FIG5_RPM, out / "fig6_f3_component.png")
    f["fig7"] = figs.fig7_percent(spectrum, truth_model, out / "fig7_percent.png")
    f["fig9"] = figs.fig9_model_vs_data(data, {"joint fit": joint, "Table 2 (truth)": truth_model}, TABLE3_RPM,
                                        out / "fig9_model_vs_data.png")
    if len(transfer):
        f["chain"] = figs.fig_chain(transfer, passband, out / "chain_transfer.png")
        transfer.to_csv(out / "chain_transfer.csv", index=False)
    t0 = tick("figures", t0)
    timings["total"] = time.perf_counter() - t_start

    report = _report(out, locals())
    return report


# ---------------------------------------------------------------------- report
def _fmt(x, spec=".4g"):
    if x is None or (isinstance(x, float) and not np.isfinite(x)):
        return "n/a"
    return format(x, spec)


def _report(out: Path, v: dict) -> Path:
    rec, truth, spectrum, fitted = v["rec"], v["truth"], v["spectrum"], v["fitted"]
    joint, published, table2, table3 = v["joint"], v["published"], v["table2"], v["table3"]
    transfer, passband, speeds = v["transfer"], v["passband"], v["speeds"]
    data = fitted.data
    n_runs = int(truth.runs["run"].nunique())
    main = table2.iloc[:2 * len(_ORDER)]
    tol = main[main["tolerance"].notna()]
    ok = tol[tol["within"] == True]  # noqa: E712
    bad = tol[tol["within"] != True]  # noqa: E712
    md = ["# SILO4 (Garcia et al., IJRR 2002) reproduced on a digital twin", "",
          "The paper's raw data are not public. This reproduction runs the **twin of the SILO4 joint-3 bench** "
          "(`gearspec.simulate.silo4_twin`), whose friction is the paper's own Table 2 (eq. 11), records it the way "
          "the paper recorded (closed-loop speed control on a 500-line encoder, current through a 1 kHz Bessel "
          "filter sampled every 4 ms, ten repetitions per speed and direction), saves it in the recording format, "
          "reads it back, and analyses it with exactly the public pipeline a user runs. It shows whether the "
          "pipeline recovers what the paper reports, and where the paper's own numbers disagree with each other. "
          "The twin's unknowns (motor, inertia, loop gains, noise) are chosen in `gearspec/simulate/silo4.py` and "
          "were not tuned to make any table match.", "",
          "## Twin recording and pipeline", "",
          f"- {n_runs} runs: {len(speeds)} motor speeds from {min(speeds):g} to {max(speeds):g} rpm, both directions, "
          f"{v['repetitions']} repetitions each (seed {v['seed']}); {len(rec)} samples, {rec.t[-1]:.0f} s of "
          "experiment. Plus one creeping run at 1e-4 rad/s of the joint for Fig. 3 "
          f"({v['stick_slip_duration']:g} s).",
          f"- Saved as `data/{v['path'].name}` and `data/{v['ss_path'].name}` (recording format), "
          f"`data/{v['gear_path'].name}` (gear spec: the silo4-joint3 train with the twin's torque constant "
          f"{truth.gear.torque_constant} Nm/A and inertia {truth.gear.inertia:g} kg m^2), "
          "`data/silo4_twin_truth.json` (the truth). Everything below is computed from the files as re-read by "
          "`gearspec.recording.load_recording` (largest difference to the simulated arrays: "
          + ", ".join(f"{k} {val:.2g}" for k, val in v["reread"].items()) + ").",
          f"- `gearspec spectrum data/{v['path'].name} --gear data/{v['gear_path'].name} --json spectrum.json`: "
          f"{len(spectrum.segments)} constant-speed segments ({sum(s.direction > 0 for s in spectrum.segments)} "
          f"positive), per-segment spectra -> `spectrum.json`.",
          f"- `gearspec fit data/{v['path'].name} --gear data/{v['gear_path'].name} --law silo4 --out fit/`: the "
          "joint fit of eq. 11 per direction, the published procedure (sections 3-4: Coulomb and viscous above "
          "100 rpm, eq. 4 below, eq. 10 on the spectra's amplitudes) and simpler laws, with held-out errors -> "
          "[fit/report.md](fit/report.md). As in eq. 11, the joint-turn line F1 has a constant amplitude (eq. 6) "
          "and F2, F3 decay (eq. 8): `identify_recording(..., harmonics=[..., {\"label\": \"output shaft\", "
          "\"decay\": False}, ...])` (the command line fits a decay for every line; it has no option for this).", "",
          markdown_table(fitted.comparison.assign(rmse=lambda d: 1e3 * d["rmse"],
                                                  rmse_holdout=lambda d: 1e3 * d["rmse_holdout"])
                         .rename(columns={"rmse": "rmse (mNm)", "rmse_holdout": "held-out rmse (mNm)"})), ""]

    # Table 2
    md += ["## Table 2: parameters recovered from the twin", "",
           "`table2.csv`: the paper's value, the joint fit (`gearspec`, with its standard error), the published "
           "procedure, their relative differences, and the issue's tolerance (static, Coulomb, viscous 5 %, "
           "amplitudes 10 %, decay constants 25 %). Paper units: mNm, motor rpm. `table2_published_procedure.csv` "
           "has the published procedure alone in the four-column form.", ""]
    show = table2[["quantity", "paper", "gearspec", "gearspec_se", "rel_diff", "published_procedure",
                   "rel_diff_published", "tolerance", "within"]]
    md += [markdown_table(show), ""]
    md += [f"**Within tolerance (joint fit):** {len(ok)} of {len(tol)} toleranced parameters: "
           + ", ".join(ok["quantity"].str.split(" \\(").str[0]) + ".", ""]
    if len(bad):
        md += ["**Outside tolerance, and why:**", ""]
        for _, r in bad.iterrows():
            note = str(r["note"]) if isinstance(r["note"], str) else ""
            md.append(f"- `{r['quantity']}`: {_fmt(r['gearspec'])} against {_fmt(r['paper'])} "
                      f"(rel. diff. {_fmt(r['rel_diff'], '+.2f')}). {note[:1].upper() + note[1:]}.")
        md.append("")
    notes_other = main[(main["tolerance"].isna()) & (main["note"].astype(str).str.len() > 0)
                       & ~main["quantity"].str.startswith("omega")]
    for _, r in notes_other.iterrows():
        md.append(f"- `{r['quantity']}`: {_fmt(r['gearspec'])} against {_fmt(r['paper'])} "
                  f"(rel. diff. {_fmt(r['rel_diff'], '+.3f')}): {r['note']}.")
    md += ["", _b3_text(v), "",
           "**The published procedure** recovers Coulomb and viscous friction (straight line through the plateaus "
           "above 100 rpm) and the amplitudes, but not the Stribeck part: " + _published_text(v), ""]

    # Table 3
    md += ["## Table 3: model errors at 280 / 560 / 3000 rpm", "",
           "`table3.csv`: e and s(e) of eqs. 12-13 per segment (e = mean of model - data, gearspec's "
           "`segment_errors`; see the audit for the paper's sign), averaged over the repetitions at each speed, for "
           "the joint fit (`gearspec`), for Table 2 itself (the twin's truth) and for the published procedure. The "
           "paper does not say which direction its Table 3 is; both are given.", "",
           markdown_table(table3), "",
           _table3_text(v), ""]

    # figures
    md += ["## Figures", ""]
    md += _figure_texts(v)

    # chain
    if len(transfer):
        g = transfer.groupby(["k", "rpm"])["ratio"].mean().unstack(0)
        md += ["## The measurement chain (control run)", "",
               "The same bench run with Table 2's model but every decay constant set to 0, at "
               f"{', '.join(f'{r:g}' for r in sorted(transfer['rpm'].unique()))} rpm: what the chain (speed loop at "
               f"{PLANT['bandwidth_hz']:g} Hz, current filter and 4 ms sampling, inertia correction F = tau - J "
               "thetadd with a Savitzky-Golay derivative of the encoder) does to a line that does not decay. "
               "`chain_transfer.csv`.", "", "![chain](chain_transfer.png)", "",
               markdown_table(g.rename(columns=lambda k: f"F{k} measured/true").reset_index()), "",
               f"F2 (the worm shaft, at most {6500 / 60 / 14:.1f} Hz at 6500 rpm) passes unchanged. F3 (the motor "
               f"shaft, {1000 / 60:.1f} Hz at 1000 rpm, {4500 / 60:.0f} Hz at 4500 rpm) is attenuated from about "
               f"{passband:g} rpm up: above the loop's bandwidth the ripple torque is taken by the rotor's inertia, "
               "and the 28 ms Savitzky-Golay acceleration that should give it back to F = tau - J thetadd cannot follow "
               "a ripple of tens of Hz sampled at 250 Hz. What the loop's derivative action passes to the current is "
               "what is measured. The paper's loop bandwidth is not published, so the same could have happened to "
               "its F3 spectra; the twin cannot say how much.", ""]

    md += ["## Audit: where the paper's numbers do not agree with each other", "",
           "`audit.csv`: each claim (`paper`) against what the paper's other numbers imply (`gearspec`).", ""]
    md += v["audit_md"]
    md += [markdown_table(v["audit_tab"][["quantity", "paper", "gearspec", "rel_diff", "note"]]), ""]

    md += ["## Noticed and left alone", "",
           "- The 6500 rpm plateaus put F3 at 108 Hz, 0.87 of the 125 Hz Nyquist frequency of 4 ms sampling. The "
           "spectra fit lines up to 0.9 of the position Nyquist frequency, the joint fit (`identify`) only up to 0.8: "
           "the spectrum measures F3 at 6500 rpm (Fig. 6c), the joint fit leaves those segments out of F3.",
           "- Standard errors of the joint fit count samples as independent within a segment, weighted by each "
           "segment's residual variance; the repetition-to-repetition scatter of the level (1 % per run in the twin) "
           "is not in them. `gearspec fit --se bootstrap` resamples whole segments and includes it.",
           "- Phases: Table 2's pi/2, pi/2, pi are recovered by both procedures (rows phi1-3); the joint-turn line F1 "
           "is fitted from partial cycles (one joint turn is 1803 motor rad), so its phase is the least precise.",
           "- Fig. 5/6/9 use one segment per speed; the twin repeats each speed ten times from the same start "
           "position (the bench returns home), so the repetitions look alike.", ""]
    md += ["## Run", "", f"`gearspec repro silo4 --out {out} --seed {v['seed']}`; times (s): "
           + ", ".join(f"{k} {t:.1f}" for k, t in v["timings"].items()) + ".", ""]
    return write_report(out, md)   # report.md and the same content as report.html


def _b3_text(v) -> str:
    jb = v["joint_band"]
    parts = []
    for dn in ("positive", "negative"):
        h = _harmonic(jb, dn, 3)
        if h is None:
            continue
        b, se = h["decay"] * RPM, (h.get("decay_se") or float("nan")) * RPM
        ref = PAPER_TABLE2["b3"][dn]
        parts.append(f"{dn} {b:.3g} +- {se:.2g} /rpm against Table 2's {ref:.3g} (standard error "
                     f"{100 * se / ref:.0f} % of it)")
    pb = v["passband"]
    return ("**b3, evidence.** Fitted over all speeds, the motor-shaft decay b3 absorbs the attenuation of the "
            "measurement chain (see its section: the control run with b = 0 measures F3 smaller and smaller above "
            f"{pb:g} rpm) and comes out several times Table 2's, in both procedures. Restricted to the plateaus where "
            f"the chain passes F3 unattenuated (<= {pb:g} rpm), the joint fit gives b3 = " + "; ".join(parts)
            + f". Over 0-{pb:g} rpm Table 2's decay changes the F3 amplitude by only "
            f"{100 * (1 - math.exp(-PAPER_TABLE2['b3']['positive'] * pb)):.1f} % (positive) and "
            f"{100 * (1 - math.exp(-PAPER_TABLE2['b3']['negative'] * pb)):.2f} % (negative), against a scatter of "
            "per-segment amplitudes of a few %: the decay is not resolved to 25 % there either. b3 is therefore not "
            "identifiable from data recorded this way -- above the pass band the chain's attenuation dominates it, "
            "below it the decay is too small -- and the negative one (4.8 % over the whole speed range) would not "
            "be even without the chain. b2 (the worm shaft, inside the loop's bandwidth at every speed) is "
            "recovered.")


def _published_text(v) -> str:
    pub, low = v["published"], v["published_low"]
    s = []
    for dn in ("positive", "negative"):
        p = pub.params(dn)
        if p.get("v_s"):
            s.append(f"{dn} theta_s = {p['v_s'] / RPM:.4g} rpm, tau_E = {p['tau_s'] * 1e3:.4g} mNm")
        else:
            s.append(f"{dn}: no Stribeck part ({pub.not_identified.get(dn + '.v_s', 'not identified')})")
    txt = ("with eq. 4 applied to every plateau below 100 rpm (as implemented by `silo4_published`) it gives "
           + "; ".join(s) + " against 28.18 / 26.58 rpm and 8.58 / 9.41 mNm. Eq. 4 neglects the viscous term, which "
           "below 100 rpm is as large as the Stribeck excess it is meant to measure (audit). ")
    s2 = [] if low is None else [f"{dn} {low.params(dn)['v_s'] / RPM:.3g} rpm, tau_E {low.params(dn)['tau_s'] * 1e3:.3f} mNm"
                                 for dn in ("positive", "negative") if low.params(dn).get("v_s")]
    if low is not None and not s2:
        txt += ("Restricted to the slowest plateaus (<= 20 rpm) it identifies no Stribeck part here: "
                + "; ".join(f"{k}: {why}" for k, why in low.not_identified.items() if k.endswith("v_s")) + ".")
    elif low is not None:
        txt += ("Restricted to the slowest plateaus (<= 20 rpm, the paper's \"very low velocities\" read narrowly) it "
                "gives " + "; ".join(s2) + ": static friction close, the Stribeck velocity still about twice "
                "Table 2's. The joint fit, which fits eq. 3 whole, has no such bias. The decays of the published "
                "procedure (eq. 10, logs of per-segment amplitudes) follow the same chain effect as the joint fit's "
                "for F3.")
    return txt


def _table3_text(v) -> str:
    t3 = v["table3"]

    def get(qty, r, col="gearspec"):
        g = t3[t3["quantity"].str.startswith(f"{qty} at {r} rpm")]
        return ", ".join(_fmt(x, ".3f") for x in g[col])

    noise = 1e3 * PLANT["current_noise"] * PLANT["torque_constant"]
    return ("**s(e).** Twin, joint fit (positive, negative): "
            + "; ".join(f"{r} rpm {get('s(e)', r)} mNm (paper {audit.TABLE3[r]['s_e']})" for r in TABLE3_RPM)
            + ". Table 2 itself gives the same (column `table2_truth`): with the right model, s(e) is what the "
            f"model cannot know -- the current noise ({noise:.3f} mNm per 4 ms sample: "
            f"{1e3 * PLANT['current_noise']:g} mA x {PLANT['torque_constant']} Nm/A), the controller's encoder-rate "
            "ripple, and at 3000 rpm the F3 ripple the chain attenuates. The twin's s(e) is about half the paper's at "
            "280 and 560 rpm and a little above it at 3000 rpm; the paper's decreases with speed, which its text "
            "attributes to the meshing model (the ripple shrinks with speed). A twin with this noise cannot say how "
            "much of the paper's 0.21 mNm is noise and how much model error.\n\n"
            "**e.** Twin, joint fit: "
            + "; ".join(f"{r} rpm {get('e', r)} mNm (paper {audit.TABLE3[r]['e']})" for r in TABLE3_RPM)
            + ". Both the joint fit and Table 2 itself have |e| of a few hundredths to 0.2 mNm here: the twin's "
            "repetitions scatter by 1 % of the level (0.1 mNm at 280 rpm, 0.5 mNm at 3000 rpm per run), which ten "
            "repetitions average to about a third. The paper's e of -0.17, -0.12, +0.16 mNm changes sign with "
            "speed: a viscous-slope error of its model on its own data (audit), which a twin built from that model "
            "cannot show. The published procedure's e of about +1 mNm at 280 and 560 rpm is its Stribeck term "
            "(theta_s in the thousands of rpm, see Table 2) still adding friction there.")


def _f6(v, rpm) -> str:
    s = figs._segment_at(v["spectrum"], rpm, 1)
    p = None if s is None else s.peak(figs.LABELS[3])
    return "n/a" if p is None else f"{1e3 * p.amplitude:.3f}"


def _slips(ss) -> dict:
    """Slips of the creeping run: how many, how often, how many encoder counts each."""
    if "velocity" not in ss.data:
        return {}
    v, t, th = ss.channel("velocity"), ss.t, ss.theta
    m = t > 1.0
    starts = np.flatnonzero((v[1:] > 0) & (v[:-1] == 0) & m[1:])
    if len(starts) < 2:
        return {"n": len(starts)}
    return {"n": len(starts), "interval": float(np.mean(np.diff(t[starts]))),
            "counts": float(np.mean(np.diff(th[starts]))) / (2 * np.pi / 2000),
            "stuck": float(np.mean(v[m] == 0))}


def _figure_texts(v) -> list[str]:
    truth_model = table2_model()
    ss = v["ss"]
    stuck = float(np.mean(ss.channel("velocity")[ss.t > 0.5] == 0)) if "velocity" in ss.data else float("nan")
    p = truth_model.params("positive")
    md = []
    sl = _slips(ss)
    q_period = 2 * np.pi / 2000 / (1e-4 * RATIO)
    md += ["### Fig. 3: stick-slip at low joint velocity", "", "![fig3](fig3_stick_slip.png)", "",
           "Paper: at a commanded 1e-4 rad/s the joint speed \"undergoes impulsive decrements due to small increments "
           "in the friction torque\" (at joint positions 0.0182 and 0.022 rad) and increases again when friction "
           "decreases, until the controller acts. Twin: the motor is at rest "
           f"{100 * sl.get('stuck', float('nan')):.0f} % of the time and moves in {sl.get('n', 0)} slips of "
           f"{sl.get('counts', float('nan')):.2g} encoder count each, one every {sl.get('interval', float('nan')):.3f} s "
           f"(the commanded speed crosses a count every {q_period:.3f} s): a limit cycle of the PID on the quantised "
           "position against the static friction (Table 2 at 0+: tau_E plus the ripple of the lines). Stick-slip at "
           "this speed is reproduced; the paper's pattern -- a few large decrements at particular positions -- is "
           "not: over the 0.003 rad of joint travel shown, Table 2's static friction changes smoothly (panel c), "
           "and the twin's slips are set by the encoder, not by the friction's position dependence. The encoder "
           "(3.1 mrad per count at the motor, 11 microrad at the joint) shows the slips only as steps (panel b); "
           "the true speed is the twin's.", ""]
    pl = v["data"].plateaus()
    md += ["### Fig. 4: average friction against motor speed (Stribeck curve)", "", "![fig4](fig4_stribeck.png)", "",
           f"Plateau averages of the {int((pl['speed'] / RPM <= 1000 * 1.02).sum())} segments up to 1000 rpm "
           f"(of {len(pl)}; the faster ones are in Figs. 5-7 and 9: above 1000 rpm the viscous term hides the "
           "Stribeck curve) with Table 2's eq. 3, the joint fit and the published "
           "procedure (with eq. 4 on every plateau below 100 rpm, and on those <= 20 rpm only). The curve has the "
           "shape of the paper's Fig. 4: a minimum near 40 rpm, static friction above Coulomb, viscous slope above "
           "100 rpm. The published procedure's Stribeck part is visibly too slow (audit: the published Stribeck step).", ""]
    s5 = [figs._segment_at(v["spectrum"], r, 1) for r in FIG5_RPM]
    md += ["### Fig. 5: friction against joint position and its spectrum at 2000 / 4500 / 6500 rpm", "",
           "![fig5](fig5_position_spectra.png)", "",
           "Paper: three spectral components, F1 = 0.159, F2 = 3.26, F3 = 45.6 cycles/rad (joint), F1 of constant "
           "amplitude, F2 and F3 smaller at higher speed. Twin: the same three lines -- F1 as the slow bow of the "
           "friction over one joint turn (at 2000 and 4500 rpm a plateau covers about one turn and the spectrum's "
           "detrending takes it; at 6500 rpm it is a peak) -- and F2 of "
           + ", ".join(f"{1e3 * s.peak(figs.LABELS[2]).amplitude:.3f}" if s is not None and s.peak(figs.LABELS[2])
                       else "n/a" for s in s5)
           + " mNm at 2000/4500/6500 rpm (Table 2: "
           + ", ".join(f"{0.576 * math.exp(-1.27e-4 * r):.3f}" for r in FIG5_RPM) + ").", ""]
    md += ["### Fig. 6: the component at F3", "", "![fig6](fig6_f3_component.png)", "",
           "Paper: the F3 component decreases from 2000 to 6500 rpm. Twin (fitted line, 95 % bar): "
           + ", ".join(_f6(v, r) for r in FIG5_RPM) + " mNm at " + " / ".join(str(r) for r in FIG5_RPM)
           + " rpm against Table 2's " + ", ".join(f"{0.133 * math.exp(-5.28e-5 * r):.3f}" for r in FIG5_RPM)
           + ": it does decrease, but much faster than Table 2's b3 says, because of the measurement chain (see its "
           "section).", ""]
    md += ["### Fig. 7: ripple at F2 and F3 in % of the mean friction, forwards and backwards", "",
           "![fig7](fig7_percent.png)", "",
           "Paper: \"more than 25 percent\" at F2 and 4 % at F3 at low speed, decreasing exponentially with speed, "
           f"different forwards and backwards. Twin: at most {v['twin_pct'][(2, 'positive')]:.1f} % (forwards) and "
           f"{v['twin_pct'][(2, 'negative')]:.1f} % (backwards) at F2, {v['twin_pct'][(3, 'positive')]:.1f} % / "
           f"{v['twin_pct'][(3, 'negative')]:.1f} % at F3 -- which is what Table 2 implies (audit: the 25 % at F2). The "
           "decrease with speed and the asymmetry are reproduced; the 25 % is not, because Table 2 cannot produce it. "
           "(F2 is fitted only where a plateau covers a full worm-shaft turn, 88 motor rad: from 100 rpm up.)", ""]
    md += ["### Fig. 9: model against data at 280 / 560 / 3000 rpm", "", "![fig9](fig9_model_vs_data.png)", "",
           "Twin data (grey) with the joint fit and Table 2 over two worm-shaft turns of the repetition of median "
           "level. The twin's friction varies by 1 % between repetitions (the paper's bench: < 3 %), so the "
           "repetition shown sits off the fit's level by its share of that scatter, said in each panel's title "
           "(1 % of 48 mNm at 3000 rpm is 0.5 mNm). As in the paper, the model "
           "follows the F2 and F3 ripple; what is left is noise and the loop's encoder-rate ripple (not locked to "
           "position).", ""]
    return md
