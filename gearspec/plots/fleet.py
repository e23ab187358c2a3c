"""Figures of the fleet report (``gearspec batch``): every well-determined parameter over the dates,
flagged series in colour, and one figure per flagged joint with its trend lines."""

from __future__ import annotations

from pathlib import Path

import matplotlib.dates as mdates
import numpy as np
import pandas as pd

from ..fleet.trend import DAY
from ..terms import BASE_LAWS
from . import DIRS, plt, save

__all__ = ["plot_fleet_overview", "plot_flagged_joint"]


def _unit(parameter: str, laws) -> str:
    if parameter.endswith(" amplitude"):
        return "Nm"
    for law in laws:
        spec = BASE_LAWS.get(law)
        if spec is not None and parameter in spec.params:
            return spec.units[spec.params.index(parameter)]
    return ""


def _dates(t):
    return pd.to_datetime(pd.Series(t, dtype=float), unit="s")


def _date_axis(ax) -> None:
    """Dates on the x axis: a few ticks, written concisely (no overlapping labels)."""
    ax.xaxis.set_major_locator(mdates.AutoDateLocator(minticks=2, maxticks=4))
    ax.xaxis.set_major_formatter(mdates.DateFormatter("%Y-%m-%d"))
    ax.tick_params(axis="x", labelrotation=20, labelsize=8)


def _p_text(p: float) -> str:
    """An adjusted p-value as the figure states it: below 1e-16 only as a bound (a normal or t tail so
    far out says more about the model than the data; an underflow would print 0)."""
    return "p_adj < 1e-16" if p < 1e-16 else f"p_adj {p:.1e}"


def _well_determined(df, p: str) -> bool:
    """A parameter worth an overview panel: its typical value at least 3 standard errors."""
    v, se = pd.to_numeric(df[p], errors="coerce"), pd.to_numeric(df[p + "_se"], errors="coerce")
    ratio = (v.abs() / se).replace([np.inf], np.nan).dropna()
    return len(ratio) > 0 and float(ratio.median()) >= 3


def plot_fleet_overview(df, trends, path) -> Path | None:
    """Every well-determined tested parameter over the dates, as a change from each series' mean
    (%), one grey line per (robot, joint, direction); the flagged series in colour (``df``: the
    batch table, ``trends``: :func:`~gearspec.fleet.trend.trend_tests`)."""
    params = [p for p in dict.fromkeys(trends["parameter"]) if _well_determined(df, p)]
    if not params:
        return None
    ok = df[df["status"] == "ok"]
    flagged = set(map(tuple, trends.loc[trends["flagged"], ["robot", "joint", "direction", "parameter"]].to_numpy()))
    ncol = min(3, len(params))
    nrow = -(-len(params) // ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.6 * ncol, 3.2 * nrow), squeeze=False)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, p in zip(axes.flat, params):
        k = 0
        joint_colour: dict = {}
        for (robot, joint, d), g in ok.groupby(["robot", "joint", "direction"], sort=True):
            g = g.sort_values("start_time")
            y = pd.to_numeric(g[p], errors="coerce")
            rel = 100 * (y / y.mean() - 1)
            if (robot, joint, d, p) in flagged:
                colour = joint_colour.setdefault((robot, joint), colours[len(joint_colour) % len(colours)])
                ax.plot(_dates(g["start_time"]), rel, "o-" if d == "positive" else "s--", color=colour, lw=1.6,
                        ms=3, label=f"{robot} {joint} {d}", zorder=3)
                k += 1
            else:
                ax.plot(_dates(g["start_time"]), rel, "-", color="0.7", lw=0.7, zorder=1)
        ax.set_title(p, fontsize=10)
        ax.set_ylabel("change from the series' mean, %")
        ax.set_xlabel("recording date (UTC)")
        _date_axis(ax)
        ax.grid(alpha=0.3)
        if k:
            ax.legend(fontsize=7, loc="upper left")
    for ax in list(axes.flat)[len(params):]:
        ax.set_visible(False)
    fig.suptitle("Fleet: parameters over time (grey: not flagged; colour: flagged, one per joint; "
                 "solid: positive, dashed: negative direction)", fontsize=11)
    fig.tight_layout()
    return save(fig, path)


def plot_flagged_joint(df, trends, robot, joint, path) -> Path:
    """One flagged joint: each flagged parameter against the date with its standard error, both
    directions, and the fitted trend line."""
    t = trends[(trends["robot"] == robot) & (trends["joint"] == joint) & trends["flagged"]]
    params = list(dict.fromkeys(t["parameter"]))
    laws = df["law"].dropna().unique()
    fig, axes = plt.subplots(1, len(params), figsize=(4.8 * len(params), 3.4), squeeze=False)
    g = df[(df["robot"] == robot) & (df["joint"] == joint) & (df["status"] == "ok")].sort_values("start_time")
    for ax, p in zip(axes[0], params):
        for _, dname, colour, marker in DIRS:
            s = g[g["direction"] == dname]
            if s.empty:
                continue
            x = s["start_time"].to_numpy(float)
            ax.errorbar(_dates(x), s[p].astype(float), yerr=s[p + "_se"].astype(float), fmt=marker, color=colour,
                        ms=4, capsize=2, label=dname)
            tr = t[(t["direction"] == dname) & (t["parameter"] == p)]
            if len(tr):
                r = tr.iloc[0]
                line = r["mean"] + r["slope_per_day"] * ((x - r["t_ref"]) / DAY)
                ax.plot(_dates(x), line, "-", color=colour, lw=1,
                        label=f"{dname} trend {100 * r['relative_change']:+.1f} % ({_p_text(r['p_adjusted'])})")
        unit = _unit(p, laws)
        ax.set_ylabel(f"{p} ({unit})" if unit else p)
        ax.set_xlabel("recording date (UTC)")
        _date_axis(ax)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle(f"{robot} {joint}: flagged parameters (error bars: one standard error)", fontsize=11)
    fig.tight_layout()
    return save(fig, path)
