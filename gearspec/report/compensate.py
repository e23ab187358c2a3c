"""Report of ``gearspec compensate``: the ripple table, the summary printed by the command, and
``report.md`` (+ HTML) with the figures of :mod:`gearspec.plots.compensate` and
``compensation.csv``.  Speeds in rpm, ripple in rpm and % of the speed (SI inside the JSON model)."""

from __future__ import annotations

import math
from pathlib import Path

import pandas as pd

from ..export.compensate import COMPENSATIONS, LABELS, CompensationResult
from ..plots.compensate import plot_ripple, plot_trace
from . import bullets, header, markdown_table, report_dir, write_report

__all__ = ["ripple_table", "summary_text", "write_compensate_report"]

_RPM_PER_RAD_S = 60 / (2 * math.pi)


def ripple_table(result: CompensationResult) -> pd.DataFrame:
    """Velocity ripple std (rpm and %) per speed and direction, the three runs side by side."""
    t = result.table
    w = t.pivot_table(index=["direction", "speed_rpm"], columns="compensation",
                      values=["ripple_std_rpm", "ripple_std_pct"]).sort_index(ascending=[False, True])
    rows = []
    for (d, s), r in w.iterrows():
        row = {"direction": "positive" if d > 0 else "negative", "speed (rpm)": s}
        for c in COMPENSATIONS:
            row[f"{LABELS[c]}: std rpm (%)"] = f"{r[('ripple_std_rpm', c)]:.3g} ({r[('ripple_std_pct', c)]:.3g} %)"
        rows.append(row)
    return pd.DataFrame(rows)


def summary_text(result: CompensationResult) -> str:
    """The ripple table as printed."""
    return (f"velocity ripple (std of the true motor speed on each plateau), {result.twin} twin\n"
            + ripple_table(result).to_string(index=False))


def write_compensate_report(result: CompensationResult, out, command: str = "") -> Path:
    """``out/report.md`` (+ HTML), ``ripple_vs_speed.png``, ``trace.png``, ``compensation.csv``."""
    out = report_dir(out)
    plot_ripple(result, out / "ripple_vs_speed.png")
    plot_trace(result, out / "trace.png")
    result.table.to_csv(out / "compensation.csv", index=False)
    s = result.settings
    rng = s.get("fitted_speed_range")
    seen = ("the model does not record the speeds its lines were fitted on" if not rng else
            f"the model's lines were fitted on {rng[0] * _RPM_PER_RAD_S:.4g}.."
            f"{rng[1] * _RPM_PER_RAD_S:.4g} rpm (column in_fitted_range)")
    md = header(f"Friction compensation on the {result.twin} twin", command)
    md += ["Each speed is run three times with the same seed: no compensation; a Coulomb + viscous feed-forward: "
           f"{s['coulomb_viscous']}; and the model as feed-forward: {s['model']}. The feed-forward gets the "
           f"{s['feedforward_inputs']}; its torque is added to the PID's command. Measured on the held part of "
           "each plateau, from the twin's true motor velocity: ripple (std and peak-to-peak), its position-locked "
           "part (rms of the sinusoids at the model's line frequencies with at least two cycles on the plateau) "
           f"and the speed error (commanded - true). {s['duration']:g} s per plateau, {s['repetitions']} "
           f"repetition(s), seed {s['seed']}; {seen}.", "",
           f"Model: {result.model.name} (law {result.model.law}). Compiled with: `{s['compiler']}`.", "",
           "## Velocity ripple", "", markdown_table(ripple_table(result)),
           "![ripple against speed](ripple_vs_speed.png)", "",
           f"![time trace at {result.trace_rpm:g} rpm](trace.png)", ""]
    md += bullets(result.notes or ["at every speed and direction the full model lowers the ripple below "
                                   "Coulomb + viscous"], "## Where the full model does not help")
    cols = ["direction", "speed_rpm", "compensation", "ripple_std_rpm", "ripple_pp_rpm", "ripple_pp_pct",
            "locked_rpm", "error_mean_rpm", "error_rms_rpm", "in_fitted_range"]
    md += ["## All measures (rpm; % of the speed)", "", markdown_table(result.table[cols]), "",
           "Files: `compensation.csv` (this table), `ripple_vs_speed.png`, `trace.png`.", ""]
    return write_report(out, md)
