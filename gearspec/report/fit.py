"""The report of ``gearspec fit``: the identified model in SI and the papers' units, how well it
and the models beside it predict held-out data, and the figures."""

from __future__ import annotations

from dataclasses import replace

from pathlib import Path

import numpy as np
import pandas as pd

from ..core.parallel import forked_map
from ..identify import FitResult
from ..model import RPM
from ..plots import fit as fplots
from . import bullets, header, markdown_table, model_table, report_dir, write_report

__all__ = ["write_fit_report"]


def _example_segments(data, per_direction: int = 3) -> list[int]:
    """A low, a middle and a high speed segment per direction (of free motion: among the longest
    tenth of its blocks, so that a line shows cycles)."""
    out = []
    seg = data.segments
    if data.free_motion and len(seg) > 10 * per_direction:
        seg = seg[seg["n"] >= seg["n"].quantile(0.9)]
    for d in (1, -1):
        s = seg[seg["direction"] == d].sort_values("speed")
        idx = np.unique(np.linspace(0, len(s) - 1, min(per_direction, len(s))).round().astype(int))
        out += [int(s.iloc[i]["segment"]) for i in idx]
    return out


#: what the rpm of the papers' units are of, by the gear spec's ``reference`` (None: no gear spec)
_SHAFT = {"motor": "rpm of the motor", "output": "rpm of the gear's output", None: "rpm of the shaft theta measures"}


def write_fit_report(result: FitResult, out: str | Path, command: str = "", recording_summary: str = "",
                     reference: str | None = None) -> Path:
    """Write ``report.md``, figures, ``model.json`` and per-segment CSVs into ``out``; ``reference``:
    the gear spec's shaft of theta ("motor" or "output", None unknown), which the speeds are of."""
    out = report_dir(out)
    m, data = result.model, result.data
    unit = data.unit
    tu = "Nm" if unit == "rad" else "N"
    plate = data.plateaus()
    points = "plateau averages"
    if data.free_motion:
        # blocks of free motion are short: their means hold the inertia torque and partial cycles of
        # the lines, so the points are the base law plus the residual (the fitted inertia and lines removed)
        base = m.copy()
        base.terms = []
        for p in base.directions.values():
            p.harmonics = []
        partial = replace(data, y=base.evaluate(data.theta, data.v) + m.residual(data), cache={})
        plate = partial.plateaus()
        points = "block means, fitted inertia and lines removed"
    # the figures are independent (a second each on 10^7 rows): drawn in forked workers, each as it
    # would be here (core.parallel.forked_map; the same files)
    draw = {"stribeck": lambda: fplots.plot_stribeck(plate, result.models, out / "stribeck.png", unit=unit,
                                                     points=points)}
    if result.amplitudes is not None and len(result.amplitudes):
        draw["amplitude"] = lambda: fplots.plot_amplitude_fit(result.amplitudes, result.models,
                                                              out / "amplitude_fit.png", unit=unit)
        result.amplitudes.to_csv(out / "line_amplitudes.csv", index=False)
    if any(h.get("amplitude") for d in (1, -1) for h in m.harmonics(d)):
        draw["position"] = lambda: fplots.plot_model_vs_data(data, m, _example_segments(data),
                                                             out / "model_vs_data.png")
    draw["residuals"] = lambda: fplots.plot_residuals(result.errors, out / "residuals.png", unit=unit)
    figs = dict(zip(draw, forked_map(lambda f: f(), list(draw.values()))))
    m.to_json(out / "model.json")
    for name, df in result.errors.items():
        df.to_csv(out / f"segment_errors_{_slug(name)}.csv", index=False)
    plate.to_csv(out / "plateaus.csv", index=False)

    md = header("gearspec fit report", command, recording_summary)
    n_qs = int((data.segments["kind"] == "quasi_static").sum()) if "kind" in data.segments else 0
    n_free = int((data.segments["kind"] == "free").sum()) if "kind" in data.segments else 0
    kinds = ", ".join(x for x in (f"{n_qs} quasi-static sweeps taken at rest" if n_qs else "",
                                  f"{n_free} blocks of free motion" if n_free else "") if x)
    md += [f"{len(data)} samples in {data.n_segments} " + (f"segments ({kinds}) " if kinds else "constant-speed segments ")
           + f"({int((data.segments['direction'] > 0).sum())} positive, {int((data.segments['direction'] < 0).sum())} "
           f"negative). " + " ".join(data.notes), ""]
    md += [f"## Model: {m.name}", "", f"Law: {m.law_spec.description}.", "",
           "Parameters per direction in SI units with standard errors, and in the SILO4 paper's units "
           f"(mNm, {_SHAFT.get(reference, _SHAFT[None])}) where the axis is rotary. `model.json` holds the same in the "
           "`gearspec fit --json` form.", "", markdown_table(model_table(m, paper=True)), ""]
    md += bullets([f"`{k}`: {why}" for k, why in m.not_identified.items()],
                  "**Not identified** (left out, not invented):")
    md += bullets(m.notes)
    md += ["## How well the models predict", "",
           f"rmse over all samples in segments, and held-out rmse from {m.meta.get('fit', {}).get('folds', 5)}-fold "
           f"cross-validation over whole segments (each fold predicted by a model fitted without it), in {tu}.", "",
           markdown_table(result.comparison.drop(columns=["rmse_holdout_reason"], errors="ignore")), ""]
    for _, r in result.comparison.iterrows():
        why = r.get("rmse_holdout_reason")
        if isinstance(why, str) and why:
            md += [f"- Held-out rmse of {r['model']}: "
                   f"{'not computed' if pd.isna(r['rmse_holdout']) else 'partial'} ({why})."]
    md += [""] + bullets(result.notes)
    md += ["## Stribeck curve", "", "Mean friction of every plateau (error bars: 2 standard errors from block "
           "means) and each model's friction averaged over position.", "", f"![stribeck]({figs['stribeck'].name})", ""]
    if figs.get("amplitude") is not None:
        md += ["## Ripple amplitude against speed", "",
               "Amplitude of every fitted line in every segment (joint least-squares fit of the lines on the "
               "segment's samples, as the spectra measure them; 95 % error bars) and each model's "
               "amplitude law (SILO4 eq. 8: A exp(-b|v|)). The published procedure fits log(amplitude) against "
               "speed (eq. 10); the joint fit fits the ripple itself.", "",
               f"![amplitude]({figs['amplitude'].name})", ""]
    if figs.get("position") is not None:
        md += ["## Model against data over position", "", f"![model vs data]({figs['position'].name})", ""]
    md += ["## Residuals", "", "Mean error e and its standard deviation s(e) of model - data per segment "
           "(SILO4 eqs. 12-13, Table 3), for each model.", "", f"![residuals]({figs['residuals'].name})", ""]
    errs = result.errors.get(m.name)
    if errs is not None and not errs.empty:
        show = errs.copy()
        if unit == "rad":
            show.insert(4, "speed (rpm)", show["speed"] / RPM)
        md += [markdown_table(show.drop(columns=["run"])), ""]
    md += ["## Method", "",
           "Joint fit: per direction, weighted nonlinear least squares of every parameter on the samples of all "
           "segments at once (exactly, through per-segment sufficient statistics), each segment weighted by its "
           "own residual variance; Stribeck velocity and decay constants by variable projection; standard errors "
           "from the covariance of the fit. Published procedure (SILO4 sections 3-4): Coulomb and viscous from "
           "plateaus above 100 rpm, static friction and Stribeck velocity from eq. 4 below, amplitudes and decays "
           "from the log-linear fit of eq. 10 to the spectra.", ""]
    return write_report(out, md)


def _slug(name: str) -> str:
    return "".join(c if c.isalnum() else "_" for c in name).strip("_").lower()

