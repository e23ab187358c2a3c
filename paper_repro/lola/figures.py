"""The Lola/CROPS testbed paper's Figs. 7-11 (and the catalog fit of Table V) redrawn from the twin's
analysis.  Presentation only: every number comes from the public API."""

from __future__ import annotations

import numpy as np
import pandas as pd

from gearspec import identify
from gearspec.model import RPM
from gearspec.plots import plt, save


def _colors(n):
    return plt.cm.viridis(np.linspace(0.05, 0.9, max(n, 1)))


def efficiency_vs_load(points: pd.DataFrame, model, ratio: float, title: str, path, catalog: pd.DataFrame | None = None,
                       catalog_label: str = ""):
    """Efficiency against load torque per motor speed (positive direction): the twin's points, the
    truth's law, and optionally a catalog table (dashed)."""
    fig, ax = plt.subplots(figsize=(8.5, 5))
    pos = points[points["velocity"] > 0]
    speeds = sorted(pos["speed_cmd"].unique())
    for c, sp in zip(_colors(len(speeds)), speeds):
        sub = pos[pos["speed_cmd"] == sp].sort_values("load")
        ax.plot(sub["load"], sub["efficiency"], "o-", color=c, ms=4, lw=1.0,
                label=f"twin, {sp:.0f} rad/s ({sp / RPM:.0f} rpm)")
        grid = np.linspace(max(sub["load"].min() * 0.8, 1e-3), sub["load"].max() * 1.05, 100)
        ax.plot(grid, identify.efficiency_model(model, np.full(len(grid), sp), grid, ratio), ":", color=c, lw=0.8)
    if catalog is not None and len(catalog):
        for sp_rpm, sub in catalog[catalog["load"] > 0].groupby("input_speed_rpm"):
            if sp_rpm <= 0:
                continue
            ax.plot(sub["load"], sub["efficiency"], "--", color="0.45", lw=0.9)
            ax.text(sub["load"].iloc[-1], sub["efficiency"].iloc[-1], f" {sp_rpm:.0f} rpm", fontsize=6, color="0.35",
                    va="center")
        ax.plot([], [], "--", color="0.45", label=catalog_label)
    ax.plot([], [], ":", color="k", lw=0.8, label="law (11) with Table IV (the twin's truth)")
    ax.set_xlabel("load torque at the output (Nm)")
    ax.set_ylabel("efficiency (eq. 13)")
    ax.set_ylim(0, 1)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=6.5, loc="lower right")
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    return save(fig, path)


def friction_vs_speed(points: pd.DataFrame, model, title: str, path):
    """Friction at the motor against motor speed for each load level: the twin's points and a
    fitted law (sign of the velocity: the torque the drive supplies against friction)."""
    fig, ax = plt.subplots(figsize=(9, 5))
    levels = sorted(points["load_level"].unique())
    vmax = float(np.abs(points["velocity"]).max()) * 1.05
    for c, lv in zip(_colors(len(levels)), levels):
        sub = points[points["load_level"] == lv].sort_values("velocity")
        ax.plot(sub["velocity"], sub["friction"], "o", color=c, ms=4, mfc="none", label=f"twin, load {lv:.1f} Nm")
        for d in (1, -1):
            grid = d * np.linspace(0.5, vmax, 200)
            ax.plot(grid, model.friction(None, grid, load=np.full(len(grid), lv)), "-", color=c, lw=0.9)
    ax.plot([], [], "-", color="k", lw=0.9, label=model.name)
    ax.axhline(0, color="0.7", lw=0.5)
    ax.axvline(0, color="0.7", lw=0.5)
    ax.set_xlabel("motor speed (rad/s)")
    ax.set_ylabel("friction at the motor (Nm, sign of the velocity)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=6.5, ncol=2)
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    return save(fig, path)


def catalog_fit(table: pd.DataFrame, path, title: str):
    """Catalog efficiency against load per input speed with the law (8) fit (the paper's Fig. 12 form)."""
    fig, ax = plt.subplots(figsize=(8, 4.8))
    sp = sorted(table.loc[table["used"], "input_speed_rpm"].unique())  # rows the fit used (not 0 rpm, not 0 Nm)
    for c, s in zip(_colors(len(sp)), sp):
        sub = table[(table["input_speed_rpm"] == s) & (table["load"] > 0)].sort_values("load")
        used = sub[sub["used"]]
        ax.plot(used["load"], used["efficiency"], "o", color=c, ms=4, mfc="none", label=f"catalog, {s:.0f} rpm")
        ax.plot(sub["load"], sub["model"], "-", color=c, lw=0.9)
    ax.plot([], [], "-", color="k", lw=0.9, label="law (8) fit (eq. 9, constraints of eq. 10)")
    ax.set_xlabel("load torque at the output (Nm)")
    ax.set_ylabel("efficiency")
    ax.set_ylim(0, 1.05)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=6.5, ncol=2)
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    return save(fig, path)
