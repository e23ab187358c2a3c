"""The report of ``gearspec diagnose``: the baseline model, each effect with its figure and terms,
every candidate not accepted and why, and the error before and after."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from ..diagnose import Diagnosis
from ..diagnose.results import verdict_line
from ..plots import diagnose as dplots
from . import bullets, header, markdown_table, model_table, report_dir, write_report

__all__ = ["write_diagnose_report", "effect_table", "interpretation", "analysis_table"]


def _f(x, fmt=".4g"):
    return "" if x is None or (isinstance(x, float) and not math.isfinite(x)) else format(x, fmt)


def effect_table(diag: Diagnosis) -> pd.DataFrame:
    """One row per candidate: kind, name, frequency, label (or integer hint), accepted, Z and the
    threshold, held-out rmse before and after, and the decision."""
    return pd.DataFrame([{"kind": e.kind, "effect": e.name, "accepted": "yes" if e.accepted else "no",
                          "status": e.status, "frequency": e.frequency,
                          "label": e.label or (f"({e.hint})" if e.hint else ""), "Z": e.z, "Z needed": e.z_crit,
                          "held-out before": e.rmse_holdout_before, "held-out after": e.rmse_holdout_after,
                          "round": e.round} for e in diag.effects])


#: what an effect of these kinds means, before its fitted parameters
_MEANING = {"speed_law": "The speed dependence of the friction (or of a line's amplitude) has another shape than the "
                         "model's law: ",
            "load": "Friction depends on the output load: ",
            "hysteresis": "Friction near reversals differs from the steady law (presliding / backlash): "}


def interpretation(diag: Diagnosis, e) -> list[str]:
    """Plain sentences on what an effect is physically (labels, integer relations, amplitude law,
    lead of a screw)."""
    unit = diag.data.unit
    out = []
    if e.kind == "periodic" and e.frequency:
        period = 1.0 / e.frequency
        if e.label:
            out.append(f"The line is explained by the declared gear train: **{e.label}**"
                       + (f" (order {e.order:.4g} per output revolution)." if e.order else "."))
        elif e.hint:
            out.append(f"No declared line explains it: an **unknown order**; it sits at **{e.hint}** "
                       f"(order {e.order:.4g} per output revolution) -- a motor pole-pair, slot or commutation "
                       f"order, or cogging, shows up this way." if e.order else
                       f"No declared line explains it: an **unknown order**, at {e.hint}.")
        else:
            out.append("No declared line explains it and it is no integer multiple of a declared shaft: an "
                       "**unknown order**.")
        if unit == "m":
            out.append(f"One cycle every {1e3 * period:.4g} mm of travel. On a ball-screw axis of unknown lead, a "
                       f"once-per-turn ripple would mean a lead of {1e3 * period:.4g} mm (a k-th harmonic: k x "
                       f"{1e3 * period:.4g} mm).")
        else:
            out.append(f"One cycle every {period:.4g} rad ({360 * period / (2 * math.pi):.4g} deg) of theta.")
        laws = []
        for t in e.terms:
            h = t.get("harmonic")
            if h:
                law = h.get("law", "exp")
                if law == "const":
                    laws.append(f"{t['direction']}: constant amplitude {h['amplitude']:.3g}")
                else:
                    laws.append(f"{t['direction']}: amplitude {h['amplitude']:.3g} x {law} law, decay "
                                f"{h.get('decay', 0):.3g} ({'grows' if h.get('decay', 0) < 0 else 'falls'} with speed)")
        if laws:
            out.append("Amplitude against speed (chosen by the data): " + "; ".join(laws) + ".")
    if e.kind in _MEANING:
        out.append(_MEANING[e.kind] + (e.parameters or e.name) + ".")
    if e.kind == "lag" and e.value is not None:
        out.append(f"The torque channel is logged {1e3 * e.value:.4g} ms behind the position channel (the lines' "
                   "phases drift with speed); every line is fitted at theta - v lag. Re-run with `--lag "
                   f"{e.value:.4g}` to shift the torque back before any analysis.")
    return out


def _figure_for(diag: Diagnosis, e, out: Path, i: int):
    res = e.detail.get("residual")
    con = e.detail.get("contribution")
    if res is None:
        res = diag.baseline.residual
    if con is None:
        con = np.zeros(len(res))
    spec = e.detail.get("spectrum")
    if spec is None and (e.frequency or e.detail.get("frequency")):
        f = e.frequency or e.detail.get("frequency")
        cands = [s for s in diag.analyses.get("spectra", {}).get("pooled", [])
                 if s.frequency[0] <= f <= s.frequency[-1]]
        spec = max(cands, key=lambda s: s.power_z(f)) if cands else None
    try:
        return dplots.plot_effect(diag.data, e, res, con, out / f"effect_{i:02d}.png", spectrum=spec)
    except Exception as exc:  # a figure must not cost the report; say what happened
        e.history.append(f"(figure not drawn: {exc})")
        return None


def write_diagnose_report(diag: Diagnosis, out: str | Path, command: str = "", recording_summary: str = "",
                          title: str = "gearspec diagnose report") -> Path:
    """Write ``report.md``, the figures, ``baseline_model.json``, ``final_model.json`` and
    ``effects.csv`` / ``segments.csv`` into ``out``; returns the path of the report."""
    out = report_dir(out)
    tu, unit = diag.data.torque_unit, diag.data.unit
    diag.baseline_model.to_json(out / "baseline_model.json")
    diag.final_model.to_json(out / "final_model.json")
    effect_table(diag).to_csv(out / "effects.csv", index=False)
    seg = diag.segment_table()
    seg.to_csv(out / "segments.csv", index=False)
    spectra = diag.analyses.get("spectra", {}).get("pooled", [])
    fig_spec = dplots.plot_spectra(spectra, diag.effects, out / "residual_spectra.png", unit=unit, torque_unit=tu)
    final_spec = diag.final_analyses.get("spectra", {}).get("pooled", []) if diag.final_analyses else []
    fig_final = dplots.plot_spectra(final_spec, [e for e in diag.effects if e.accepted], out / "final_spectra.png",
                                    unit=unit, torque_unit=tu, title="Residual spectra over position (final model)") \
        if final_spec else None
    fig_seg = dplots.plot_segment_errors(seg, out / "segment_errors.png", torque_unit=tu, unit=unit)
    md = (_header_section(diag, title, command, recording_summary) + _summary_section(diag)
          + _baseline_section(diag, fig_spec) + _accepted_section(diag, out) + _rejected_section(diag, out)
          + _final_section(diag, seg, fig_final, fig_seg) + _method_section(diag))
    return write_report(out, md)


def _header_section(diag: Diagnosis, title: str, command: str, recording_summary: str) -> list[str]:
    """Title, command, recording and the held-out groups (Markdown lines)."""
    dd = diag.data
    held = "moves" if dd.kind == "trajectory" else f"{dd.by}s"
    k = diag.settings.get("folds")
    return header(title, command, recording_summary) + [
        f"{len(dd)} observations in {dd.n_groups} held-out groups (whole {held}); {k}-fold cross-validation "
        "over whole groups, never interleaved samples. " + " ".join(dd.notes), ""]


def _summary_section(diag: Diagnosis) -> list[str]:
    """The accepted effects, before and after, the notes and the validation data (Markdown lines)."""
    tu = diag.data.torque_unit
    acc = [e for e in diag.effects if e.accepted]
    md = ["## Summary", ""]
    if acc:
        n_rem = sum(e.status == "removed" for e in diag.effects)
        md += [f"{len(acc)} effect(s) accepted, " + (f"{n_rem} accepted and removed again, " if n_rem else "")
               + f"{len(diag.effects) - len(acc) - n_rem} candidate(s) rejected:", ""]
        md += [f"- {_line(e, diag)}" for e in acc]
        md.append("")
    else:
        md += [f"Nothing was accepted: no candidate lowered the held-out error by more than noise would "
               f"({len(diag.effects)} candidate(s) tested).", ""]
    md += ["Before and after (rmse in-sample, and on held-out groups: each fold predicted by a model fitted "
           f"without it), in {tu}:", "", markdown_table(diag.summary_table()), ""]
    md += bullets(diag.notes)
    if diag.validation:
        v = diag.validation
        md += [f"On the independent recording `{v['name']}` ({v['groups']} groups; models fitted on the estimation "
               f"data only): rmse {v['baseline_rmse']:.4g} -> {v['final_rmse']:.4g} {tu}, relative error "
               f"{v['baseline_relative_error']:.3f} % -> {v['final_relative_error']:.3f} %.", ""]
        if v.get("removed"):
            md += ["Removed because they did not help there: " + ", ".join(v["removed"]) + ".", ""]
    return md


def _baseline_section(diag: Diagnosis, fig_spec: Path) -> list[str]:
    """The baseline model, its residual spectra and analyses (Markdown lines)."""
    bm = diag.baseline_model
    md = ["## Baseline model", "", f"`{bm.name}` -- law {bm.law} ({bm.law_spec.description}); nonlinear "
          "parameters (Stribeck velocity, decays) refined by least squares, linear ones refitted jointly by "
          "ordinary least squares, as every model of the loop is.", "", markdown_table(model_table(bm)), ""]
    if bm.terms:
        md += ["Terms: " + "; ".join(_term_text(t) for t in bm.terms), ""]
    md += ["## Residual spectra", "", "Residual of the baseline model over position, pooled over the segments of each "
           "direction (each segment's mean removed), with the local noise level; the lines the loop tested are "
           "marked (green: accepted, grey: rejected).", "", f"![spectra]({fig_spec.name})", ""]
    md += ["## Residual analyses of the baseline", "",
           "What each detector saw in the baseline's residual (groups are the units of every test but the "
           "spectra):", "", markdown_table(analysis_table(diag.analyses)), ""]
    segs = diag.analyses.get("spectra", {}).get("segments", [])
    if segs:
        rows = []
        for sp in segs:
            top = sp.peaks.iloc[0] if len(sp.peaks) else {}
            rows.append({"segment": sp.segments[0], "direction": sp.direction, "speed": sp.speed_min, "n": sp.n,
                         "strongest peak": top.get("frequency"), "amplitude": top.get("amplitude"),
                         "FAP": top.get("fap"), "noise level (median)": float(np.median(sp.noise))})
        md += ["Per segment: the strongest residual peak with false-alarm probability below 1 % (every "
               "independent frequency of the segment searched; empty: none).", "",
               markdown_table(pd.DataFrame(rows)), ""]
    return md


def _accepted_section(diag: Diagnosis, out: Path) -> list[str]:
    """Every accepted effect: evidence, test, fitted terms and its figure (Markdown lines)."""
    tu = diag.data.torque_unit
    md = ["## Effects accepted", ""]
    if not any(e.accepted for e in diag.effects):
        md += ["_(none)_", ""]
    for i, e in enumerate(diag.effects):
        if not e.accepted:
            continue
        fig = _figure_for(diag, e, out, i)
        md += [f"### {e.kind}: {e.name}", "", f"- decision: {_line(e, diag)}", f"- evidence: {e.evidence}",
               f"- held-out rmse {e.rmse_holdout_before:.4g} -> {e.rmse_holdout_after:.4g} {tu} "
               f"({-100 * e.gain:+.2f} %), {e.n_params} parameter(s) added", f"- fitted: {e.parameters}"]
        if e.validation:
            v = e.validation
            md.append(f"- independent recording: rmse {v['rmse_without']:.4g} -> {v['rmse_with']:.4g} {tu}, "
                      f"relative error {v['relative_error_without']:.3f} % -> {v['relative_error_with']:.3f} % "
                      f"(Z {v['z']:.2f}, needs {v['z_crit']:.2f}): confirmed")
        md.append("")
        md += interpretation(diag, e) + [""] if interpretation(diag, e) else []
        md += bullets([_term_text(t.get("term") or t.get("harmonic"), t.get("direction")) for t in e.terms],
                      "Terms added (SI, with standard errors):")
        if fig is not None:
            md += [f"![{e.name}]({fig.name})", ""]
    return md


def _line(e, diag: Diagnosis) -> str:
    """The effect's decision record as the console prints it (:func:`verdict_line`), one line."""
    return " ".join(verdict_line(e, diag.data.unit, diag.data.torque_unit).split())


def _rejected_section(diag: Diagnosis, out: Path) -> list[str]:
    """Every candidate not accepted, why, and the figures of the strongest (Markdown lines)."""
    unit = diag.data.unit
    md = ["## Candidates not accepted", "", "Every candidate the detectors proposed, with its evidence and why it was "
          "not accepted (Z: the held-out correlation of the residual with what the candidate predicts, in units of "
          "its noise; needed: the one-sided t quantile at the round's Bonferroni level).", ""]
    if all(e.accepted for e in diag.effects):
        md += ["_(none)_", ""]
    for e in diag.effects:
        if e.accepted:
            continue
        f = f" at {e.frequency:.6g} cycles/{unit}" if e.frequency else ""
        md += [f"- {_line(e, diag)}", f"  - evidence{f}: {e.evidence}", f"  - in full: {e.decision}"]
        if len(e.history) > 1:
            md.append("  - history: " + "; ".join(e.history))
    md.append("")
    shown = [(i, e) for i, e in enumerate(diag.effects) if not e.accepted and (e.validation or e.z >= 2)]
    for i, e in shown[:6]:
        fig = _figure_for(diag, e, out, i)
        if fig is not None:
            md += [f"Figure for the rejected candidate *{e.name}*:", "", f"![{e.name}]({fig.name})", ""]
    return md


def _final_section(diag: Diagnosis, seg: pd.DataFrame, fig_final, fig_seg: Path) -> list[str]:
    """The final model and the error per held-out group (Markdown lines)."""
    fm = diag.final_model
    md = ["## Final model", "", f"`{fm.name}`", "", markdown_table(model_table(fm)), ""]
    if fm.terms:
        md += ["Terms: " + "; ".join(_term_text(t) for t in fm.terms), ""]
    md += ["`final_model.json` holds it in the `gearspec fit --json` form (terms included); "
           "`baseline_model.json` the baseline.", ""]
    if fig_final is not None:
        md += [f"![final spectra]({fig_final.name})", ""]
    md += ["## Error per held-out group", "", f"![segments]({fig_seg.name})", "",
           markdown_table(seg[["group", "direction", "speed", "n", "rmse_before", "rmse_after", "rmse_holdout_before",
                               "rmse_holdout_after"]]), ""]
    return md


def _method_section(diag: Diagnosis) -> list[str]:
    """How the residual was analysed and a term accepted (Markdown lines)."""
    return ["## Method", "",
            "Residual analyses (gearspec.diagnose.residual): Lomb-Scargle periodograms of the residual over position "
            "per segment and pooled over segments of one direction and similar speed, with local noise and "
            "false-alarm probabilities; residual means against speed per direction (lack of fit), against load, "
            "temperature and time per group; against acceleration; against the travel since the last reversal. "
            "Each detector turns what it sees into candidate terms (a line at the found frequency with its "
            "amplitude law chosen by the data, other speed laws, load terms and SILO4 eq. 14, temperature, drift, "
            "direction asymmetry, inertia, presliding and backlash).", "",
            "Acceptance (gearspec.diagnose.loop): in every fold the candidate searches its own frequency or shape on "
            "the training groups only and is fitted jointly with the model; on the held-out groups the statistic "
            "Z = sum <r0, Delta> / sqrt(sum V) (r0: held-out residual without the candidate, Delta: the change the "
            "candidate predicts, V: cluster-robust variance per group) must exceed the one-sided t quantile at "
            f"alpha = {diag.settings.get('alpha')} / (candidates of the round), the improving folds must carry 90 % "
            f"of the change, and the held-out rmse must fall by {100 * diag.settings.get('min_gain', 0):.2g} % at "
            "least. The best passing candidate is added, nonlinear parameters are refined, terms accepted earlier "
            "are checked again (backward elimination), and the loop repeats until nothing passes.", ""]


def analysis_table(analyses: dict) -> pd.DataFrame:
    """One row per residual analysis: what it tests and its statistic."""
    rows = []
    sp = analyses.get("speed")
    if sp is not None:
        for k, v in sp[1].items():
            if k in (1, -1):
                rows.append({"analysis": f"against speed, {'positive' if k > 0 else 'negative'} direction",
                             "statistic": f"chi2 {v['chi2']:.3g} on {v['dof']} dof", "p": v["p"]})
        if "asymmetry" in sp[1]:
            a = sp[1]["asymmetry"]
            rows.append({"analysis": "direction asymmetry (mean residual by direction)",
                         "statistic": f"difference {a['difference']:.3g}, Welch t {a['t']:.2f}", "p": a["p"]})
    for ch, name in (("load", "against |load|"), ("temperature", "against temperature"), ("t", "against time")):
        res = analyses.get(ch)
        if res is not None:
            b = res[1].get("both", {})
            rows.append({"analysis": name, "statistic": f"slope {b.get('slope', float('nan')):.3g}",
                         "p": res[1]["p"]})
    ac = analyses.get("acc")
    if ac is not None:
        rows.append({"analysis": "against acceleration (inertia)",
                     "statistic": ("accelerations are round-off (exact plateaus): no test" if ac[1].get("roundoff")
                                   else f"slope {ac[1]['slope']:.3g} (t {ac[1]['t']:.2f})"), "p": ac[1]["p"]})
    rv = analyses.get("reversal")
    if rv is not None:
        rows.append({"analysis": "near reversals (presliding profile)",
                     "statistic": f"length {rv[1].get('length', float('nan')):.3g}, t {rv[1]['t']:.2f}",
                     "p": rv[1]["p"]})
    pooled = analyses.get("spectra", {}).get("pooled", [])
    rows.append({"analysis": "over position (pooled periodograms)",
                 "statistic": f"{sum(len(s.peaks) for s in pooled)} peak(s) with FAP < 1 % in {len(pooled)} pools",
                 "p": None})
    return pd.DataFrame(rows)


def _term_text(t, direction=None) -> str:
    if t is None:
        return ""
    if "kind" not in t:  # a harmonic
        s = (f"line {t.get('label') or ''} at {t['frequency']:.6g}: amplitude {t['amplitude']:.4g} "
             f"(+- {_f(t.get('amplitude_se'), '.2g')}), phase {t.get('phase', 0):.3f} (+- {_f(t.get('phase_se'), '.2g')}), "
             f"{t.get('law', 'exp')} law, decay {t.get('decay', 0):.4g}")
        if t.get("load_coefficient"):
            s += f", load coefficient {t['load_coefficient']:.4g} (+- {_f(t.get('load_coefficient_se'), '.2g')})"
        if t.get("speed_range"):
            lo, hi = t["speed_range"]
            s += f", law fitted on |v| {lo:.4g}..{hi:.4g} (held at the edge outside)"
        return (f"{direction}: " if direction else "") + s
    parts = []
    for k, v in t.items():
        if k in ("kind", "effect_kind") or k.endswith("_se"):
            continue
        if isinstance(v, float):
            se = t.get(k + "_se")
            parts.append(f"{k} {v:.4g}" + (f" (+- {se:.2g})" if isinstance(se, float) and math.isfinite(se) else ""))
        else:
            parts.append(f"{k} {v}")
    return f"{t['kind']}: " + ", ".join(parts)
