"""Figures of ``gearspec compensate``: velocity ripple against speed for the three runs (none,
Coulomb + viscous, the full model), and the true motor speed over time on one plateau.  Speeds in
rpm and ripple in % of the speed, as the report shows them."""

from __future__ import annotations

import math
from pathlib import Path

from ..export.compensate import COMPENSATIONS, LABELS, CompensationResult
from . import plt

__all__ = ["plot_ripple", "plot_trace"]

#: colour, marker and line style of each run
_STYLE = {"none": ("0.55", "o", "-"), "coulomb_viscous": ("tab:blue", "s", "--"), "model": ("tab:red", "^", "-")}
#: "none" drawn wider and hollow, so that it shows where Coulomb + viscous lies on it
_WIDE = {"none": {"lw": 2.6, "ms": 11, "fillstyle": "none", "mew": 1.5}}
_RPM_PER_RAD_S = 60 / (2 * math.pi)


def plot_ripple(result: CompensationResult, path) -> Path:
    """Velocity ripple (std, % of the speed) against speed (rpm), the three runs, one panel per
    direction; the speeds the model's lines were fitted on shaded."""
    from matplotlib.ticker import FuncFormatter

    t = result.table
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
    for ax, d in zip(axes, (1, -1)):
        for c in COMPENSATIONS:
            s = t[(t["direction"] == d) & (t["compensation"] == c)].sort_values("speed_rpm")
            color, marker, ls = _STYLE[c]
            ax.plot(s["speed_rpm"], s["ripple_std_pct"], marker=marker, ls=ls, color=color, label=LABELS[c],
                    **_WIDE.get(c, {}))
        rng = result.settings.get("fitted_speed_range")
        if rng:
            ax.axvspan(rng[0] * _RPM_PER_RAD_S, min(rng[1] * _RPM_PER_RAD_S, t["speed_rpm"].max() * 1.5),
                       color="0.9", zorder=0, label="speeds the lines were fitted on")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("motor speed (rpm)")
        ax.set_title(f"{'positive' if d > 0 else 'negative'} direction")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("velocity ripple, std (% of the speed)")
    pct = t["ripple_std_pct"].to_numpy(dtype=float)
    pct = pct[pct > 0]
    if len(pct):                     # a margin above and below the points (no marker cut by the frame)
        axes[0].set_ylim(pct.min() / 1.25, pct.max() * 1.25)
    # within about a decade every minor tick is labelled (else only 2 and 5 x a power of ten)
    lo, hi = axes[0].get_ylim()
    every = math.log10(hi / lo) < 1.2
    for ax in axes:
        ax.yaxis.set_major_formatter(FuncFormatter(lambda y, _: f"{y:g}"))
        ax.yaxis.set_minor_formatter(FuncFormatter(lambda y, _: f"{y:g}" if every or f"{y:.0e}"[0] in "25" else ""))
        ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x:g}"))      # rpm as plain numbers
        ax.xaxis.set_minor_formatter(FuncFormatter(lambda x, _: f"{x:g}" if f"{x:.0e}"[0] in "25" else ""))
    # the legend below the panels, where it hides no point
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, fontsize=8, ncol=len(labels), loc="lower center")
    fig.suptitle(f"{result.twin} twin: velocity ripple with and without friction feed-forward")
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def plot_trace(result: CompensationResult, path) -> Path:
    """The true motor speed (rpm) over the held part (s) of the positive plateau at ``trace_rpm``,
    the three runs."""
    fig, ax = plt.subplots(figsize=(10, 4.2))
    for c in COMPENSATIONS:
        tr = result.traces.get(c)
        if tr:
            color, _, ls = _STYLE[c]
            ax.plot(tr["t"], tr["velocity"], color=color, ls=ls, lw=2.2 if c == "none" else 0.9, label=LABELS[c])
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
