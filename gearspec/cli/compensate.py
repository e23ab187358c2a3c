"""``gearspec compensate``: does the model help as a feed-forward?  A twin's speed loop run without,
with a Coulomb + viscous and with the model's exported C as friction compensation; the report, the
figures (ripple against speed; a time trace) and the JSON.

The figures and the report are written here (this module is a leaf, as ``gearspec.report`` and
``gearspec.plots`` are): the analysis is :func:`gearspec.export.compensate.compensate`.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from ..errors import InputError
from . import command_line, number, print_html

_EXAMPLES = """examples:
  gearspec fit twin/silo4_twin.csv --gear twin/silo4_twin_gear.toml --law silo4 --json model.json --quiet
  gearspec compensate model.json --twin silo4 --speeds-rpm 50,100,280,560,1000,3000 --out comp/
      velocity ripple and tracking error per speed and direction: none / Coulomb+viscous / the model (via its C)
"""

#: how each run is named in the report and the figures
NAMES = {"none": "no compensation", "coulomb_viscous": "Coulomb + viscous", "model": "full model (exported C)"}
_STYLE = {"none": ("0.55", "o", "-"), "coulomb_viscous": ("tab:blue", "s", "--"), "model": ("tab:red", "^", "-")}
#: "none" drawn wider and hollow, so that it shows where Coulomb + viscous lies on it
_WIDE = {"none": {"lw": 2.6, "ms": 11, "fillstyle": "none", "mew": 1.5}}


def _speeds(text: str) -> list[float]:
    try:
        out = [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a list of speeds in rpm such as 100,280,560") from None
    if not out or any(not (s > 0 and s < float("inf")) for s in out):
        raise argparse.ArgumentTypeError(f"'{text}': give positive motor speeds in rpm (each runs in both directions)")
    return out


def register(sub) -> None:
    p = sub.add_parser("compensate", help="a fitted model as friction feed-forward in a twin's speed loop: ripple "
                                          "and tracking error without / Coulomb+viscous / the model",
                       description="Run the speed plateaus of a twin (the SILO4 joint 3 or a direct drive with "
                                   "cogging) three times: no compensation, a Coulomb + viscous feed-forward from "
                                   "the model's own tau_c and viscous, and the model itself as feed-forward through "
                                   "its exported C (compiled with cc, called with ctypes). Reports velocity ripple "
                                   "and speed tracking error per speed and direction.",
                       epilog=_EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("model", metavar="MODEL.json", help="model file (gearspec fit --json or gearspec diagnose --json)")
    p.add_argument("--twin", choices=("silo4", "direct-drive"), default="silo4",
                   help="the speed loop to run (default silo4); theta, speeds and torques at its motor")
    p.add_argument("--speeds-rpm", type=_speeds, metavar="LIST",
                   help="motor speeds in rpm, comma-separated, each run in both directions (default silo4: "
                        "50,100,280,560,1000,3000; direct-drive: 10,20,30,60,120,240)")
    p.add_argument("--duration", type=number(0, low_open=True), default=3.0, metavar="S",
                   help="seconds held at each speed (default 3)")
    p.add_argument("--repetitions", type=number(1, integer=True), default=1, metavar="N",
                   help="runs per speed and direction, averaged (default 1)")
    p.add_argument("--seed", type=int, default=1, help="the twin's seed, the same for the three runs (default 1)")
    p.add_argument("--trace-rpm", type=number(0, low_open=True), metavar="RPM",
                   help="speed of the time-trace figure, one of --speeds-rpm (default nearest 280 / 30 rpm)")
    p.add_argument("--cc", metavar="COMPILER", help="C compiler (default $CC or cc)")
    p.add_argument("--out", metavar="DIR", help="write report.md, figures and compensation.csv here")
    p.add_argument("--json", metavar="FILE", help="write the machine-readable result here")
    p.add_argument("--quiet", action="store_true", help="no summary on stdout")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..export.compensate import compensate

    if not Path(args.model).is_file():
        raise InputError(f"{args.model}: no such model file")
    result = compensate(args.model, args.twin, args.speeds_rpm, duration=args.duration,
                        repetitions=int(args.repetitions), seed=args.seed, cc=args.cc, trace_rpm=args.trace_rpm)
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(result.to_dict(), indent=1))
    if args.out:
        write_compensate_report(result, args.out, command=command_line())
    if not args.quiet:
        print(summary_text(result))
        for n in result.notes:
            print(f"note: {n}")
        if args.out:
            print(f"report: {Path(args.out) / 'report.md'}")
            print_html(Path(args.out) / "report.md")
        if args.json:
            print(f"json: {args.json}")
    return 0


def ripple_table(result):
    """Velocity ripple std (rpm and %) per speed and direction, the three runs side by side."""
    t = result.table
    w = t.pivot_table(index=["direction", "speed_rpm"], columns="compensation",
                      values=["ripple_std_rpm", "ripple_std_pct"]).sort_index(ascending=[False, True])
    rows = []
    for (d, s), r in w.iterrows():
        row = {"direction": "positive" if d > 0 else "negative", "speed (rpm)": s}
        for c in ("none", "coulomb_viscous", "model"):
            row[f"{NAMES[c]}: std rpm (%)"] = f"{r[('ripple_std_rpm', c)]:.3g} ({r[('ripple_std_pct', c)]:.3g} %)"
        rows.append(row)
    import pandas as pd

    return pd.DataFrame(rows)


def summary_text(result) -> str:
    """The ripple table as printed."""
    return (f"velocity ripple (std of the true motor speed on each plateau), {result.twin} twin\n"
            + ripple_table(result).to_string(index=False))


def plot_ripple(result, path) -> Path:
    """Velocity ripple (std, % of the speed) against speed, the three runs, one panel per direction."""
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter

    t = result.table
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
    for ax, d in zip(axes, (1, -1)):
        for c in ("none", "coulomb_viscous", "model"):
            s = t[(t["direction"] == d) & (t["compensation"] == c)].sort_values("speed_rpm")
            color, marker, ls = _STYLE[c]
            ax.plot(s["speed_rpm"], s["ripple_std_pct"], marker=marker, ls=ls, color=color, label=NAMES[c],
                    **_WIDE.get(c, {}))
        rng = result.settings.get("fitted_speed_range")
        if rng:
            ax.axvspan(rng[0] * 60 / (2 * 3.141592653589793), min(rng[1] * 60 / (2 * 3.141592653589793),
                       t["speed_rpm"].max() * 1.5), color="0.9", zorder=0, label="speeds the lines were fitted on")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.yaxis.set_major_formatter(FuncFormatter(lambda y, _: f"{y:g}"))
        ax.yaxis.set_minor_formatter(FuncFormatter(lambda y, _: f"{y:g}" if f"{y:.0e}"[0] in "25" else ""))
        ax.set_xlabel("motor speed (rpm)")
        ax.set_title(f"{'positive' if d > 0 else 'negative'} direction")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("velocity ripple, std (% of the speed)")
    axes[0].legend(fontsize=8)
    fig.suptitle(f"{result.twin} twin: velocity ripple with and without friction feed-forward")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def plot_trace(result, path) -> Path:
    """The true motor speed over the held part of the positive plateau at ``trace_rpm``, three runs."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(10, 4.2))
    for c in ("none", "coulomb_viscous", "model"):
        tr = result.traces.get(c)
        if tr:
            color, _, ls = _STYLE[c]
            ax.plot(tr["t"], tr["velocity"], color=color, ls=ls, lw=2.2 if c == "none" else 0.9, label=NAMES[c])
    ax.axhline(result.trace_rpm, color="k", lw=0.6, ls=":", label="commanded")
    ax.set_xlabel("time on the plateau (s)")
    ax.set_ylabel("motor speed (rpm)")
    ax.set_title(f"{result.twin} twin at +{result.trace_rpm:g} rpm: true motor speed (grey under blue: Coulomb + "
                 f"viscous changes little)")
    ax.legend(fontsize=8, ncol=4, loc="upper center", bbox_to_anchor=(0.5, -0.18))
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def write_compensate_report(result, out, command: str = "") -> Path:
    """``out/report.md`` (+ HTML), ``ripple_vs_speed.png``, ``trace.png``, ``compensation.csv``."""
    from ..report import bullets, header, markdown_table, report_dir, write_report

    out = report_dir(out)
    plot_ripple(result, out / "ripple_vs_speed.png")
    plot_trace(result, out / "trace.png")
    result.table.to_csv(out / "compensation.csv", index=False)
    s = result.settings
    rng = s.get("fitted_speed_range")
    seen = ("the model does not record the speeds its lines were fitted on" if not rng else
            f"the model's lines were fitted on {rng[0] * 60 / 6.283185307179586:.4g}.."
            f"{rng[1] * 60 / 6.283185307179586:.4g} rpm (column in_fitted_range)")
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
