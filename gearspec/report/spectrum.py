"""The report of ``gearspec spectrum``: segments, declared lines, unexplained peaks, spectra."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from .. import plots
from ..recording import Recording
from ..segment import Segmentation
from ..spectrum.analysis import SpectrumResult
from . import _rpm, markdown_table

__all__ = ["write_spectrum_report"]


def write_spectrum_report(result: SpectrumResult, rec: Recording, seg: Segmentation, out: str | Path,
                          command: str = "") -> Path:
    """Write ``report.md``, the figures and ``peaks.csv`` of a spectrum analysis into ``out``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    unit = result.unit
    tu = "Nm" if unit == "rad" else "N"
    figs = {}
    figs["segments"] = plots.plot_segments(rec, seg, out / "segments.png")
    figs["spectra"] = plots.plot_order_spectra(result, str(out / "spectra_{:02d}.png"))
    figs["amplitude"] = plots.plot_amplitude_vs_speed(result, out / "amplitude_vs_speed.png")
    figs["relative"] = plots.plot_amplitude_vs_speed(result, out / "amplitude_vs_speed_relative.png", relative=True)
    figs["unexplained"] = plots.plot_unexplained(result, out / "unexplained_peaks.png")
    table = result.peaks_table()
    table.to_csv(out / "peaks.csv", index=False)

    md = ["# gearspec spectrum report", ""]
    if command:
        md += [f"Command: `{command}`", ""]
    md += ["## Recording", "", "```", rec.summary(), "```", ""]
    n_seg = sum(s.segment.n for s in result.segments)
    md += [f"Rows read: {result.n_rows}; in segments: {n_seg}; excluded: "
           + (", ".join(f"{k} {v}" for k, v in sorted(result.excluded.items())) or "none")
           + ". (Every row is in one segment or counted once.)", ""]
    if result.gear is not None:
        md += ["## Gear train", "", "```", result.gear.describe(), "```", ""]
    else:
        md += ["## Gear train", "", "No gear spec: no line is declared; every peak found is reported unlabelled.", ""]
    md += ["## Segments", "",
           f"Found from position alone ("
           + "".join(f"speed window(s) {', '.join(f'{w:g} s' for w in ws)}, " for ws in [seg.settings.get('windows_chosen')] if ws)
           + f"relative tolerance {seg.settings.get('rel_tol')})"
           + (f"; {seg.settings['quasi_static_segments']} quasi-static sweep(s) (rows taken at rest: torque against "
              "position, no time derivative, nominal speed = travel / duration)"
              if seg.settings.get("quasi_static_segments") else "") + ".", "",
           f"![segments]({figs['segments'].name})", ""]
    rows = []
    for i, s in enumerate(result.segments):
        g = s.segment
        rows.append({"segment": i, "kind": g.kind.replace("_", "-"), "run": g.run, "dir": g.direction,
                     f"speed ({unit}/s)": g.speed,
                     **({"speed (rpm)": _rpm(g.speed, unit)} if unit == "rad" else {}),
                     "samples": g.n, f"travel ({unit})": s.span, f"mean friction ({tu})": s.level,
                     f"residual sd ({tu})": s.sigma, "speed ripple (rel. sd)": g.speed_ripple})
    md += [markdown_table(pd.DataFrame(rows)), ""]
    # declared lines
    md += ["## Declared lines", ""]
    if result.gear is None or table.empty or not table["declared"].any():
        md += ["_No declared line fits in any segment._", ""]
    else:
        md += ["Amplitude (with 95 % error bars) of every declared line in every segment where it completes at "
               "least one cycle and lies below the position Nyquist frequency.", "",
               f"![amplitude vs speed]({figs['amplitude'].name})", "",
               f"![relative amplitude vs speed]({figs['relative'].name})", ""]
        dec = table[table["declared"]]
        summary = (dec.groupby(["label", "direction"])
                   .agg(frequency=("frequency", "first"), segments=("segment", "count"),
                        amplitude_min=("amplitude", "min"), amplitude_max=("amplitude", "max"),
                        median_snr=("snr", "median"))
                   .reset_index())
        md += [markdown_table(summary), ""]
        skipped = {}
        for s in result.segments:
            for k in s.skipped:
                skipped.setdefault(k["label"], k["reason"].split(";")[0].split(" (")[0])
        if skipped:
            md += ["Lines not fitted in some segments (too slow to complete a cycle, or above the position "
                   "Nyquist frequency): " + "; ".join(f"{k}" for k in skipped) + ".", ""]
    # found peaks
    md += ["## Peaks no declared line explains", ""]
    found = table[~table["declared"]] if not table.empty else table
    if found.empty:
        md += ["_None significant (false-alarm probability < 0.01)._", ""]
    else:
        if figs["unexplained"] is not None:
            md += [f"![unexplained peaks]({figs['unexplained'].name})", ""]
        cols = ["segment", "direction", "speed", "frequency", "order", "amplitude", "amplitude_se", "fap", "label", "hint"]
        md += [markdown_table(found.sort_values(["frequency"])[cols].rename(
            columns={"speed": f"speed ({unit}/s)", "frequency": f"frequency (cycles/{unit})",
                     "amplitude": f"amplitude ({tu})", "amplitude_se": "s.e."})), ""]
        md += ["`label`: the harmonic or sideband of declared lines that explains the peak; empty when nothing "
               "declared does. `hint`: an integer multiple of a shaft the peak sits on (a motor pole-pair or "
               "cogging order looks like this), a clue, not an explanation.", ""]
    md += ["## Order spectra", "",
           "FFT of torque resampled over position (Hann window, amplitude-calibrated) in grey, Lomb-Scargle of the "
           "raw samples in green, the local noise level dotted; dots are the jointly fitted amplitudes "
           "(purple: declared, orange: harmonic/sideband, red: unexplained).", ""]
    md += [f"![spectra]({p.name})" for p in figs["spectra"]]
    md += ["", "## Method", "",
           "Friction magnitude y = direction x (torque - J thetadd) over position; joint least-squares fit of all "
           "declared lines and significant peaks with a Legendre nuisance polynomial; standard errors scaled by "
           "the local noise level of the Lomb-Scargle periodogram; false-alarm probabilities against the local "
           "noise level (one frequency for declared lines, all searched frequencies for found peaks). "
           f"Frequencies in cycles/{unit}; amplitudes in {tu}; phases in rad of A sin(2 pi f theta + phi).", ""]
    if result.notes:
        md += ["Notes:", ""] + [f"- {n}" for n in result.notes] + [""]
    path = out / "report.md"
    path.write_text("\n".join(md))
    return path
