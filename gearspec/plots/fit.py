"""Figures of ``gearspec fit``: Stribeck curve, amplitude against speed with the decay law, model
against data over position (SILO4 Fig. 9), residuals."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from ..fitdata import FitData
from ..model import RPM, FrictionModel
from ..terms import amplitude_law, clamp_speed
from . import DIRS, NEG, POS, one_direction_note, plain_log_axis, plt, present_dirs, save
from .ordermap import _scale

__all__ = ["plot_stribeck", "plot_amplitude_fit", "plot_model_vs_data", "plot_residuals"]

_STYLES = ("-", "--", ":", "-.")


def _units(unit):
    """Speed axis label, its scale from unit/s, and the torque unit."""
    return ("speed (rpm)", 1 / RPM, "Nm") if unit == "rad" else (f"speed ({unit}/s)", 1.0, "N")


def plot_stribeck(plateaus: pd.DataFrame, models: dict[str, FrictionModel], path, unit: str = "rad",
                  points: str = "plateau averages") -> Path:
    """Plateau friction against speed per direction (error bars: 2 se) with each model's
    position-averaged friction (SILO4 Fig. 4)."""
    xl, xs, tu = _units(unit)
    present = present_dirs(plateaus["direction"])
    fig, axes = plt.subplots(1, len(present), figsize=(6 * len(present), 4.2), sharey=True, squeeze=False)
    axes = axes[0]
    has_load = "load" in plateaus and plateaus["load"].nunique() > 1
    for ax, (d, name, color, mk) in zip(axes, present):
        pl = plateaus[plateaus["direction"] == d]
        if pl.empty:
            ax.text(0.5, 0.5, f"no {name} segment", transform=ax.transAxes, ha="center")
            ax.set_title(f"{name} direction")
            continue
        ax.errorbar(pl["speed"] * xs, pl["level"], yerr=2 * pl["level_se"].fillna(0), fmt=mk, color=color, ms=4,
                    mfc="none", label=points)
        grid = np.geomspace(max(pl["speed"].min() / 2, 1e-9), pl["speed"].max() * 1.2, 300)
        for (label, m), ls in zip(models.items(), _STYLES):
            try:
                load = float(pl["load"].median()) if "load" in pl else None
                y = m.mean_level(grid, d, load=None if load is None else np.full(len(grid), load))
            except Exception:  # a model that cannot predict this direction
                continue
            ax.plot(grid * xs, y, ls, color="k", lw=1.0, label=label + (" (median load)" if has_load else ""))
        ax.set_xscale("log")
        plain_log_axis(ax.xaxis)
        ax.set_xlabel(xl)
        ax.set_title(f"{name} direction")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    axes[0].set_ylabel(f"mean friction ({tu})")
    fig.suptitle("Friction against speed (Stribeck curve): data and fitted laws" + one_direction_note(present),
                 fontsize=11)
    fig.tight_layout()
    return save(fig, path)


def plot_amplitude_fit(amplitudes: pd.DataFrame, models: dict[str, FrictionModel], path, unit: str = "rad"
                       ) -> Path | None:
    """Amplitude of each fitted line against speed per direction (per-segment fits, 95 % bars;
    :func:`gearspec.identify.line_amplitudes`) with each model's amplitude law ``A g(|v|)``
    (SILO4 Fig. 7 with eq. 8)."""
    labels = list(dict.fromkeys(h["label"] for m in models.values() for d in (1, -1) for h in m.harmonics(d)
                                if h.get("label")))
    if not labels:
        return None
    xl, xs, tu = _units(unit)
    fig, axes = plt.subplots(1, len(labels), figsize=(5.2 * len(labels), 4.0), squeeze=False)
    for ax, lab in zip(axes[0], labels):
        df = amplitudes[amplitudes["label"] == lab]
        smax = 0.0
        for d, name, color, mk in DIRS:
            sub = df[df["direction"] == d].sort_values("speed")
            if len(sub):
                smax = max(smax, sub["speed"].max())
                ax.errorbar(sub["speed"] * xs, sub["amplitude"], yerr=1.96 * sub["amplitude_se"], fmt=mk,
                            color=color, ms=4, mfc="none", label=f"{name}: per segment")
        grid = np.linspace(0, (smax or 1.0) * 1.1, 200)
        for (mlabel, m), ls in zip(models.items(), _STYLES):
            for d, name, color, _ in DIRS:
                h = next((h for h in m.harmonics(name) if h.get("label") == lab), None)
                if h is None:
                    continue
                # as the model evaluates it: held at the edges of the speeds the law was fitted on
                amp = h["amplitude"] * amplitude_law(h.get("law", "exp"), clamp_speed(grid, h.get("speed_range")),
                                                     h.get("decay") or 0.0)
                ax.plot(grid * xs, amp, ls, color=color, lw=1.0, label=f"{name}: {mlabel}")
        ax.set_title(lab, fontsize=10)
        ax.set_xlabel(xl)
        ax.set_ylabel(f"amplitude ({tu})")
        ax.set_ylim(bottom=0)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=6)
    fig.suptitle("Ripple amplitude against speed: spectra and fitted amplitude laws", fontsize=11)
    fig.tight_layout()
    return save(fig, path)


def plot_model_vs_data(data: FitData, model: FrictionModel, segments: list[int], path, cycles: float = 3.0) -> Path:
    """Friction over position for a few segments: data and model (SILO4 Fig. 9).  Each panel shows
    ``cycles`` periods of the slowest fitted line from the segment start."""
    n = len(segments)
    unit = data.unit
    tu = "Nm" if unit == "rad" else "N"
    fig, axes = plt.subplots(n, 1, figsize=(11, 2.3 * n + 0.6), squeeze=False)
    for ax, sid in zip(axes[:, 0], segments):
        sub = data.subset(data.segment == sid)
        d = int(sub.direction[0])
        th = sub.theta
        f = min((h["frequency"] for h in model.harmonics(d) if h.get("amplitude")), default=None)
        order = np.argsort(th * d)
        th, y = th[order], sub.y[order]
        x = d * (th - th[0])
        keep = x <= (cycles / f if f else np.inf)
        pred = model.evaluate(**sub.subset(order[keep]).inputs())
        ax.plot(x[keep], d * y[keep], ".", ms=1.5, color="0.6", label="data")
        ax.plot(x[keep], d * pred, "-", color=POS if d > 0 else NEG, lw=1.2, label=model.name)
        sp = float(np.mean(np.abs(sub.v)))
        ax.set_title(f"segment {sid}: {'+' if d > 0 else '-'}{sp:.4g} {unit}/s"
                     + (f" ({sp / RPM:.0f} rpm)" if unit == "rad" and sp / RPM >= 10 else
                        f" ({sp / RPM:.2g} rpm)" if unit == "rad" else ""), fontsize=9, loc="left")
        ax.set_ylabel(f"friction ({tu})")
        ax.legend(fontsize=7, loc="upper right")
    axes[-1, 0].set_xlabel(f"travel from the segment start ({unit})")
    fig.suptitle("Model against data over position", fontsize=11)
    fig.tight_layout()
    return save(fig, path)


def plot_residuals(errors: dict[str, pd.DataFrame], path, unit: str = "rad") -> Path:
    """Per segment: mean error e and rmse of model - data against speed, per model and direction;
    each segment a marker, the median of the repetitions of a speed joined by a line (never the
    repetitions themselves: a tangle)."""
    from ..spectrum.results import speed_groups

    xl, xs, tu = _units(unit)
    frames = [df for df in errors.values() if not df.empty]
    factor, tu = _scale(np.concatenate([np.abs(df[c].to_numpy(float)) for df in frames for c in ("e", "rmse")])
                        if frames else np.ones(1), tu)
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.0))
    for (label, df), ls in zip(errors.items(), _STYLES):
        if df.empty:
            continue
        df = df.assign(group=speed_groups(df["speed"], df["direction"]))
        for d, name, color, mk in DIRS:
            sub = df[df["direction"] == d].sort_values("speed")
            if sub.empty:
                continue
            med = sub.groupby("group")[["speed", "e", "rmse"]].median().sort_values("speed")
            for ax, col in zip(axes, ("e", "rmse")):
                ax.plot(sub["speed"] * xs, factor * sub[col], mk, color=color, ms=3.5, mfc="none", alpha=0.7,
                        rasterized=len(sub) > 2000)
                ax.plot(med["speed"] * xs, factor * med[col], ls, color=color, lw=1.0,
                        label=f"{label}, {name}" + (" (median per speed)" if len(med) < len(sub) else ""))
    axes[0].axhline(0, color="0.6", lw=0.6)
    axes[0].set_ylabel(f"mean error e = model - data ({tu})")
    axes[1].set_ylabel(f"rmse per segment ({tu})")
    for ax in axes:
        ax.set_xscale("log")
        plain_log_axis(ax.xaxis)
        ax.set_xlabel(xl)
        ax.grid(alpha=0.3, which="both")
        ax.ticklabel_format(axis="y", style="plain", useOffset=False)
    handles, labels = axes[0].get_legend_handles_labels()
    if handles:  # one legend for both panels, below them: never over the points
        fig.legend(handles, labels, loc="lower center", ncol=min(len(handles), 4), fontsize=7, frameon=False)
    fig.suptitle("Residuals per segment (markers: segments)", fontsize=11)
    fig.tight_layout(rect=(0, 0.02 + 0.055 * ((len(handles) + 3) // 4), 1, 1))
    return save(fig, path)
