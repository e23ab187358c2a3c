"""Figures of ``gearspec diagnose``: the residual spectra with the candidate lines, one figure per
effect (the residual it explains against the variable of its kind, and what the term predicts), and
the held-out error per segment before and after."""

from __future__ import annotations

import math
import textwrap
from pathlib import Path

import numpy as np
import pandas as pd

from . import DIRS, NEG, POS, one_direction_note, plain_log_axis, plt, present_dirs, save

#: logarithmic frequency bins a residual spectrum is drawn with (its minimum and maximum in each:
#: every peak and trough stays; 11 inches at 110 dpi are 1210 pixels): a pooled spectrum of a long
#: recording has millions of frequencies, which took matplotlib 10 s per figure to draw
SPECTRUM_POINTS = 3000

__all__ = ["plot_spectra", "plot_effect", "plot_segment_errors", "plot_time_series", "effect_curve"]


def plot_spectra(spectra: list, effects: list, path, *, unit: str = "rad", torque_unit: str = "Nm",
                 title: str = "Residual spectra over position (baseline model)") -> Path:
    """The pooled residual periodograms of each direction with their local noise level, every
    candidate line marked (accepted: green, rejected: grey; dashed: beyond every spectrum drawn).
    Beside the all-speed pool, thinner, up to two pools of slower speeds that reach higher
    frequencies, where a line found at slow speed may lie."""
    pooled = [s for s in spectra if s.pooled and len(s.frequency)]
    # the all-speed pool of each direction (the one with most segments), and the pools that reach
    # further up, highest reach first
    per_dir = {d: max((s for s in pooled if s.direction == d), key=lambda s: len(s.segments))
               for d in dict.fromkeys(s.direction for s in pooled)}
    extra = {d: sorted((s for s in pooled if s.direction == d and s is not m
                        and s.frequency[-1] > 1.05 * m.frequency[-1]), key=lambda x: -x.frequency[-1])[:2]
             for d, m in per_dir.items()}
    rows = [d for d in (1, -1) if d in per_dir]
    marks = sorted((e for e in effects if getattr(e, "frequency", None) is not None and np.isfinite(e.frequency)
                    and e.frequency > 0), key=lambda e: e.frequency)
    # each candidate line is a numbered tag in the axes; the key below the axes names it (long
    # names drawn beside the lines overlapped each other and ran below the axes)
    key_rows = math.ceil(len(marks) / 2)
    height = 3.6 * max(len(rows), 1) + 0.13 * key_rows + 0.1
    fig, axes = plt.subplots(max(len(rows), 1), 1, figsize=(11, height), squeeze=False)
    for ax, d in zip(axes[:, 0], rows):
        s = per_dir[d]
        color = POS if s.direction > 0 else NEG
        drawn = [s] + extra.get(d, [])
        ax.semilogy(*_drawn(s.frequency, s.amplitude), color=color, lw=0.6, label=f"residual: {s.label}")
        ax.semilogy(*_drawn(s.frequency, s.noise), color="k", lw=0.8, ls="--", label="local noise level")
        for k, x in enumerate(extra.get(d, [])):
            ax.semilogy(*_drawn(x.frequency, x.amplitude), color=color, lw=0.5, alpha=0.35 - 0.1 * k,
                        label=f"residual: {x.label}")
            ax.semilogy(*_drawn(x.frequency, x.noise), color="k", lw=0.6, ls=":", alpha=0.6)
        ax.set_xlim(min([x.frequency[0] for x in drawn] + [e.frequency / 1.5 for e in marks]),
                    max([x.frequency[-1] for x in drawn] + [e.frequency * 1.5 for e in marks]))
        ax.set_xscale("log")
        # numbered tags, staggered in height (axes fraction) so that neighbours do not overlap
        for k, e in enumerate(marks):
            c = "tab:green" if e.accepted else "0.45"
            beyond = not any(x.frequency[0] <= e.frequency <= x.frequency[-1] for x in drawn)
            ax.axvline(e.frequency, color=c, lw=1.2 if e.accepted else 0.9, ls="--" if beyond else "-",
                       alpha=0.9, zorder=0)
            ax.annotate(f"{k + 1}" + (" (beyond the spectra)" if beyond else ""), (e.frequency, 0.97 - 0.06 * (k % 3)),
                        xycoords=("data", "axes fraction"),
                        fontsize=7, color=c, va="top", ha="center", fontweight="bold" if e.accepted else "normal",
                        bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.8})
        ax.set_ylabel(f"amplitude ({torque_unit})")
        ax.set_title(s.label, fontsize=9)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7, loc="lower left")
    if not rows:
        axes[0, 0].text(0.5, 0.5, "no residual spectrum (no positions, or segments too short)", ha="center",
                        transform=axes[0, 0].transAxes)
    axes[-1, 0].set_xlabel(f"frequency (cycles/{unit})")
    bottom = 0.0
    if marks and rows:
        entries = [f"{k + 1}: {e.frequency:.5g} cycles/{unit}, {e.label or getattr(e, 'hint', None) or 'unknown order'}"
                   f" ({'accepted' if e.accepted else 'rejected'})" for k, e in enumerate(marks)]
        entries = [textwrap.shorten(x, 95) for x in entries]
        half = key_rows
        for col, chunk in enumerate((entries[:half], entries[half:])):
            fig.text(0.02 + 0.5 * col, 0.01, "\n".join(chunk), fontsize=7, va="bottom", ha="left", family="monospace")
        bottom = (0.1 + 0.13 * key_rows) / height
    fig.suptitle(title + " -- candidate lines: green accepted, grey rejected", fontsize=10)
    fig.tight_layout(rect=(0, bottom, 1, 1))
    return save(fig, path)


def _drawn(frequency, amplitude, points: int = SPECTRUM_POINTS) -> tuple[np.ndarray, np.ndarray]:
    """A spectrum as drawn: at positive frequencies (ascending), in at most ``points`` logarithmic
    bins, the minimum and the maximum of each bin in the order they occur (a vertical stroke per
    bin, as a pixel column shows it); unchanged when short already.  Amplitudes floored at 1e-300
    for the log axis."""
    f, a = np.asarray(frequency, float), np.asarray(amplitude, float)
    ok = f > 0
    f, a = f[ok], a[ok]
    if len(f) > 4 * points:
        edges = np.geomspace(f[0], f[-1] * (1 + 1e-9), points + 1)
        start = np.unique(np.searchsorted(f, edges[:-1]))
        start = start[start < len(f)]
        i_min = start + np.array([np.argmin(x) for x in np.split(a, start[1:])])
        i_max = start + np.array([np.argmax(x) for x in np.split(a, start[1:])])
        idx = np.sort(np.concatenate([i_min, i_max]))
        f, a = f[idx], a[idx]
    return f, np.maximum(a, 1e-300)


def effect_curve(dd, residual, contribution, kind: str) -> dict:
    """What the figure of an effect shows: the x variable of its kind and, per direction, the
    binned (or per-segment) means of the residual before the term was added and of the term's
    contribution (both in the friction magnitude, except inertia: drive torque)."""
    d = dd.at("direction")
    signed = kind == "inertia"
    m_res = residual if signed else d * residual
    m_con = contribution if signed else d * contribution
    # per kind: the column, whether its absolute value, the axis label, one point per group
    speed = ("v", True, f"speed ({dd.unit}/s)", dd.kind == "plateaus")
    axes = {"speed_law": speed, "asymmetry": speed,
            "load": ("load", True, f"|load| (N{'m' if dd.unit == 'rad' else ''})", True),
            "temperature": ("temperature", False, "temperature (degC)", True), "drift": ("t", False, "time (s)", True),
            "inertia": ("acc", False, f"acceleration ({dd.unit}/s^2)", False),
            "hysteresis": ("travel", False, f"travel since the last reversal ({dd.unit})", False)}
    if kind not in axes:
        return {}
    column, absolute, xl, per_group = axes[kind]
    x = np.abs(dd.at(column)) if absolute else dd.at(column)
    out = {"xlabel": xl, "series": []}
    groups = ([(0, "both directions", "k", np.ones(len(d), bool))] if kind == "inertia"
              else [(k, name, color, d == k) for k, name, color, _ in DIRS])
    for direction, name, color, sel in groups:
        if not sel.any():
            continue
        if per_group:  # the groups at least half in this direction
            rows = sorted((np.mean(x[a:z]), np.mean(m_res[a:z]), np.mean(m_con[a:z]),
                           np.std(m_res[a:z]) / math.sqrt(max(z - a, 1)))
                          for a, z in zip(dd.starts, dd.stops) if not sel[a:z].mean() < 0.5)
            if not rows:
                continue
        else:
            xx = x[sel]
            fin = np.isfinite(xx)
            if fin.sum() < 8:
                continue
            if kind == "hysteresis":
                edges = np.geomspace(max(np.min(xx[fin & (xx > 0)]), 1e-12), np.max(xx[fin]), 16)
            else:
                edges = np.quantile(xx[fin], np.linspace(0, 1, 16))
            which = np.clip(np.searchsorted(edges, xx, side="right") - 1, 0, len(edges) - 2)
            rr, cc = m_res[sel], m_con[sel]
            bins = [b for b in (fin & (which == k) for k in range(len(edges) - 1)) if b.sum() >= 3]
            rows = [(np.mean(xx[b]), np.mean(rr[b]), np.mean(cc[b]), np.std(rr[b]) / math.sqrt(b.sum())) for b in bins]
        xs, rs, cs, se = np.array(rows, float).reshape(-1, 4).T
        out["series"].append({"direction": direction, "name": name, "color": color,
                              "x": xs, "residual": rs, "contribution": cs, "se": se})
    return out


def _line_amplitudes(dd, residual, contribution, frequency):
    """Amplitude of a line in each segment: in the residual before it was added, and in what the
    term predicts (least squares of sin/cos at the frequency, each segment's mean removed)."""
    theta = dd.at("theta")
    d = dd.at("direction")
    s = np.abs(dd.at("v"))
    rows = []
    for a, z in zip(dd.starts, dd.stops):
        th = theta[a:z]
        if np.ptp(th) * frequency < 1.0:
            continue
        X = np.column_stack([np.ones(z - a), np.sin(2 * np.pi * frequency * th), np.cos(2 * np.pi * frequency * th)])
        y = d[a:z] * residual[a:z]
        br = np.linalg.lstsq(X, y, rcond=None)[0]
        bc = np.linalg.lstsq(X, d[a:z] * contribution[a:z], rcond=None)[0]
        rows.append({"direction": int(d[a]), "speed": float(np.mean(s[a:z])), "amplitude": math.hypot(br[1], br[2]),
                     "model": math.hypot(bc[1], bc[2]), "se": float(np.std(y - X @ br) * math.sqrt(2.0 / (z - a)))})
    return pd.DataFrame(rows)


def plot_effect(dd, effect, residual, contribution, path, *, spectrum=None) -> Path | None:
    """The figure of one effect: the residual it is fitted to (for an accepted term: the partial
    residual, data minus the rest of the final model; otherwise the residual of the model it was
    tested against) and what the term predicts."""
    tu = dd.torque_unit
    what = "data - rest of final model" if effect.detail.get("partial") else "residual"
    if effect.kind == "periodic" or (effect.kind == "speed_law" and effect.detail.get("analysis") == "spectrum"):
        f = effect.frequency or effect.detail.get("frequency")
        if f is None:
            return None
        fig, axes = plt.subplots(1, 2, figsize=(13, 4.2))
        ax = axes[0]
        if spectrum is not None:
            lo, hi = max(spectrum.frequency[0], f / 4), min(spectrum.frequency[-1], f * 4)
            near = (spectrum.frequency >= lo / 1.01) & (spectrum.frequency <= hi * 1.01)   # the window drawn
            ax.semilogy(*_drawn(spectrum.frequency[near], spectrum.amplitude[near]), lw=0.6,
                        color=POS if spectrum.direction > 0 else NEG, label="residual")
            ax.semilogy(*_drawn(spectrum.frequency[near], spectrum.noise[near]), "k--", lw=0.8, label="local noise")
            ax.axvline(f, color="tab:green" if effect.accepted else "0.5", lw=1.2, zorder=0,
                       label=f"{f:.6g} cycles/{dd.unit}")
            ax.set_xlim(lo, hi)
            ax.set_xscale("log")
            plain_log_axis(ax.xaxis)
            ax.set_title(f"residual spectrum of the baseline: {spectrum.label}", fontsize=9)
        ax.set_xlabel(f"frequency (cycles/{dd.unit})")
        ax.set_ylabel(f"amplitude ({tu})")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
        ax = axes[1]
        amp = _line_amplitudes(dd, residual, contribution, f)
        for direction, name, color, _ in DIRS if len(amp) else ():
            a = amp[amp["direction"] == direction].sort_values("speed")
            if not len(a):
                continue
            ax.errorbar(a["speed"], a["amplitude"], yerr=2 * a["se"], fmt="o", color=color, mfc="none", ms=4,
                        label=f"{name}: {what}")
            ax.plot(a["speed"], a["model"], "-", color=color, lw=1.2, label=f"{name}: the term")
        ax.set_xlabel(f"speed ({dd.unit}/s)")
        ax.set_ylabel(f"amplitude of the line ({tu})")
        ax.set_title("amplitude against speed, per segment (95 % bars)", fontsize=9)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
        lab = effect.label or (f"unknown order, {effect.hint}" if effect.hint else "unknown order")
        fig.suptitle(f"{effect.name} ({lab}): {'accepted' if effect.accepted else 'rejected'}", fontsize=10)
        fig.tight_layout()
        return save(fig, path)
    cur = effect_curve(dd, residual, contribution, effect.kind)
    if not cur or not cur["series"]:
        return None
    fig, ax = plt.subplots(figsize=(8, 4.2))
    for s in cur["series"]:
        ax.errorbar(s["x"], s["residual"], yerr=2 * np.nan_to_num(s["se"]), fmt="o", ms=4, mfc="none",
                    color=s["color"], label=f"{s['name']}: {what}")
        ax.plot(s["x"], s["contribution"], "-", color=s["color"], lw=1.3, label=f"{s['name']}: the term")
    if effect.kind == "hysteresis" or (effect.kind in ("speed_law", "asymmetry") and dd.kind == "plateaus"):
        ax.set_xscale("log")
        plain_log_axis(ax.xaxis)
    ax.axhline(0, color="k", lw=0.6)
    ax.set_xlabel(cur["xlabel"])
    ax.set_ylabel(f"{'drive torque' if effect.kind == 'inertia' else 'friction'} ({tu})")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    ax.set_title(f"{effect.kind}: {effect.name} -- {'accepted' if effect.accepted else 'rejected'}", fontsize=10)
    fig.tight_layout()
    return save(fig, path)


def plot_segment_errors(table: pd.DataFrame, path, *, torque_unit: str = "Nm", unit: str = "rad") -> Path:
    """Held-out rmse of every group before and after (and in-sample), against speed per direction."""
    from ..spectrum.results import speed_groups

    # one panel per direction that has groups (an empty panel for a direction never driven says
    # nothing the title cannot)
    present = present_dirs(table["direction"])
    fig, axes = plt.subplots(1, len(present), figsize=(6 * len(present), 4), sharey=True, squeeze=False)
    axes = axes[0]
    for ax, (direction, name, color, _) in zip(axes, present):
        t = table[table["direction"] == direction].sort_values("speed")
        if t.empty:
            ax.text(0.5, 0.5, "no held-out group", ha="center", transform=ax.transAxes)
            ax.set_title(f"{name} direction")
            continue
        # each group a marker; a line only through the median of the groups at one speed (joining the
        # repetitions of a speed in speed order drew a tangle)
        med = (t.assign(g=speed_groups(t["speed"], t["direction"]))
               .groupby("g")[["speed", "rmse_holdout_before", "rmse_holdout_after"]].median().sort_values("speed"))
        ax.plot(t["speed"], t["rmse_holdout_before"], "o", color="0.5", mfc="none", label="held-out, before")
        ax.plot(t["speed"], t["rmse_holdout_after"], "o", color=color, ms=5, label="held-out, after")
        ax.plot(t["speed"], t["rmse_after"], "x", color=color, label="in-sample, after")
        if len(med) < len(t):
            ax.plot(med["speed"], med["rmse_holdout_before"], "--", color="0.5", lw=1.0,
                    label="held-out, before (median per speed)")
            ax.plot(med["speed"], med["rmse_holdout_after"], "-", color=color, lw=1.2,
                    label="held-out, after (median per speed)")
        else:
            ax.plot(t["speed"], t["rmse_holdout_before"], "--", color="0.5", lw=1.0)
            ax.plot(t["speed"], t["rmse_holdout_after"], "-", color=color, lw=1.2)
        ax.set_xscale("log")
        plain_log_axis(ax.xaxis)
        ax.set_xlabel(f"speed ({unit}/s)")
        ax.set_title(f"{name} direction", fontsize=10)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    axes[0].set_ylabel(f"rmse ({torque_unit})")
    fig.suptitle("Error per held-out group, before and after the loop" + one_direction_note(present), fontsize=10)
    fig.tight_layout()
    return save(fig, path)


def plot_time_series(t, y, before, after, path, *, torque_unit: str = "N", title: str = "", window=None,
                     labels=("measured", "baseline", "final")) -> Path:
    """Measured drive torque against time with two models' predictions and their errors."""
    t = np.asarray(t)
    sel = np.ones(len(t), bool) if window is None else (t >= window[0]) & (t <= window[1])
    fig, axes = plt.subplots(2, 1, figsize=(12, 6), sharex=True, gridspec_kw={"height_ratios": [2, 1]})
    axes[0].plot(t[sel], y[sel], "k", lw=1.0, label=labels[0])
    axes[0].plot(t[sel], before[sel], color="0.55", lw=1.0, ls="--", label=labels[1])
    axes[0].plot(t[sel], after[sel], color="tab:green", lw=1.0, label=labels[2])
    axes[1].plot(t[sel], (y - before)[sel], color="0.55", lw=0.8, label=f"error, {labels[1]}")
    axes[1].plot(t[sel], (y - after)[sel], color="tab:green", lw=0.8, label=f"error, {labels[2]}")
    axes[1].set_xlabel("time (s)")
    for ax, what in zip(axes, ("force / torque", "error")):
        ax.set_ylabel(f"{what} ({torque_unit})")
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return save(fig, path)
