"""Figures of the order analysis over varying speed: the order map (order x speed, colour =
amplitude) and the order tracks (amplitude against speed with its band, one panel per direction)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.colors import LogNorm
from matplotlib.ticker import FuncFormatter

from . import DIRS, plt, save as _save

__all__ = ["plot_order_map", "plot_order_tracks"]


def _scale(values, unit: str) -> tuple[float, str]:
    """A factor and unit that read best: m-units below 1."""
    finite = np.asarray(values, dtype=float)
    finite = finite[np.isfinite(finite)]
    top = float(finite.max()) if len(finite) else 1.0
    return (1e3, f"m{unit}") if top < 1.0 else (1.0, unit)


def plot_order_map(maps, path, lines=None) -> Path:
    """One panel per direction: amplitude over speed (x) and frequency (y), cells not measurable
    left blank (grey), the highest measurable frequency of each speed bin as a
    curve; ``lines``: ``[(frequency, label)]`` marked at the right edge."""
    maps = [m for m in maps if m is not None]
    fig, axes = plt.subplots(1, max(len(maps), 1), figsize=(6.2 * max(len(maps), 1), 4.8), squeeze=False)
    if not maps:
        axes[0, 0].text(0.5, 0.5, "no direction has enough motion for an order map", ha="center",
                        transform=axes[0, 0].transAxes)
        return _save(fig, path)
    factor, tu = _scale(np.concatenate([m.amplitude.ravel() for m in maps]), maps[0].torque_unit)
    # a logarithmic colour scale (as order maps are read in dB): from a third of the lowest noise
    # level (median cell) to the largest cell, so that lines stand out of the noise at every speed
    cells = np.concatenate([m.amplitude[np.isfinite(m.amplitude)] for m in maps]) * factor
    floor = [np.nanmin(m.noise) for m in maps if np.isfinite(m.noise).any()]
    vmax = float(cells.max()) if len(cells) and cells.max() > 0 else 1.0
    vmin = min(vmax / 10, (min(floor) * factor / 3) if floor else vmax / 1e3)
    norm = LogNorm(vmin=max(vmin, vmax * 1e-6), vmax=vmax)
    for ax, m in zip(axes[0], maps):
        name = {1: "positive", -1: "negative"}[m.direction]
        ax.set_facecolor("0.88")
        df = m.frequency[1] - m.frequency[0] if len(m.frequency) > 1 else m.frequency[0]
        f_edges = np.concatenate([m.frequency - df / 2, [m.frequency[-1] + df / 2]])
        amp = np.ma.masked_invalid(m.amplitude * factor)
        cmap = plt.get_cmap("viridis").copy()
        cmap.set_bad("0.88")  # masked cells grey, like the background outside the measured speeds
        mesh = ax.pcolormesh(m.speed_edges, f_edges, amp.T, cmap=cmap, norm=norm, shading="flat",
                             edgecolors="none", antialiased=False)
        ok = np.flatnonzero(np.isfinite(m.limit))
        ax.hlines(m.limit[ok], m.speed_edges[ok], m.speed_edges[ok + 1], color="w", lw=1.6,
                  label="highest measurable frequency (0.8 x position Nyquist)")
        ax.set_xlim(m.speed_edges[0], m.speed_edges[-1])
        top = float(np.nanmax(m.limit)) * 1.25 if np.isfinite(m.limit).any() else f_edges[-1]
        ax.set_ylim(0, min(f_edges[-1], top))
        _mark_lines(ax, lines, f_edges[-1], m.speed_edges[0], m.speed_edges[-1], min(f_edges[-1], top))
        ax.set_xlabel(f"speed |v| ({m.unit}/s)")
        ax.set_ylabel(f"frequency (cycles/{m.unit})")
        ax.set_title(f"{name} direction ({int(np.sum(m.samples)):,} samples, "
                     f"{np.isfinite(m.speed).sum()} of {len(m.speed)} speed bins)",
                     fontsize=9)
        ax.legend(loc="upper right", fontsize=7, framealpha=0.6)
        cb = fig.colorbar(mesh, ax=ax, label=f"amplitude ({tu}, rms over windows, log scale)")
        plain = FuncFormatter(lambda x, _: f"{x:.3g}")
        cb.ax.yaxis.set_major_formatter(plain)
        cb.ax.yaxis.set_minor_formatter(FuncFormatter(lambda x, _: f"{x:.2g}" if str(f"{x:.2g}")[0] in "25" else ""))
    fig.suptitle("Order map: amplitude over speed and frequency (grey: not measurable)", fontsize=11)
    fig.tight_layout()
    return _save(fig, path)


def _mark_lines(ax, lines, f_max, x_left, x_right, y_top) -> None:
    """Each line of ``lines`` ``[(frequency, label)]`` below ``f_max`` as a dotted line, labelled at
    the left edge; a label closer than a text height (5 % of the axis) to the one below it goes to
    the right edge instead, so that close lines (an output shaft and a planetary carrier) stay legible."""
    last = {"left": -np.inf, "right": -np.inf}
    for f, lab in sorted(lines or [], key=lambda x: x[0]):
        if f > f_max:
            continue
        ax.axhline(f, color="w", lw=0.6, ls=":")
        side = "left" if f - last["left"] >= 0.05 * y_top else "right"
        last[side] = f
        x, dx, ha = (x_left, 3, "left") if side == "left" else (x_right, -3, "right")
        ax.annotate(lab, (x, f), xytext=(dx, 2), textcoords="offset points", fontsize=7, ha=ha,
                    va="bottom", color="k", bbox={"fc": "w", "ec": "none", "alpha": 0.7, "pad": 1})


def plot_order_tracks(tracks, path) -> Path:
    """Amplitude against speed with its band, one line per tracked frequency, one panel per direction."""
    dirs = [(d, name) for d, name, _, _ in DIRS]
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.2), sharey=True)
    allv = [t.upper for t in tracks] or [np.zeros(1)]
    factor, tu = _scale(np.concatenate(allv), tracks[0].torque_unit if tracks else "Nm")
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    labels = sorted({(t.frequency, t.label) for t in tracks}, key=lambda x: x[0])
    colour = {fl: colours[i % len(colours)] for i, fl in enumerate(labels)}
    for ax, (d, name) in zip(axes, dirs):
        mine = [t for t in tracks if t.direction == d]
        for t in mine:
            c = colour[(t.frequency, t.label)]
            lab = f"{t.frequency:.4g} cycles/{t.unit}"
            lab = f"{t.label.split(' = ')[0]} ({lab})" if t.label else lab
            ax.fill_between(t.speed, t.lower * factor, t.upper * factor, color=c, alpha=0.25, lw=0)
            ax.plot(t.speed, t.amplitude * factor, color=c, lw=1.4, label=lab.strip())
        if not mine:
            ax.text(0.5, 0.5, f"no line tracked in the {name} direction\n(too little motion below the position "
                    "Nyquist frequency)", ha="center", va="center", transform=ax.transAxes, fontsize=9)
        else:
            ax.legend(fontsize=7, loc="best")
        unit = mine[0].unit if mine else (tracks[0].unit if tracks else "rad")
        ax.set_xlabel(f"speed |v| ({unit}/s)")
        ax.set_title(f"{name} direction", fontsize=10)
        ax.grid(alpha=0.3)
    axes[0].set_ylim(bottom=0)  # after both panels are drawn: the shared top then holds both directions
    axes[0].set_ylabel(f"amplitude ({tu})")
    level = tracks[0].level if tracks else 0.95
    fig.suptitle(f"Order tracks: amplitude against speed, {level:.0%} pointwise band (errors assumed white: "
                 "noise coloured near a line makes the band too narrow)", fontsize=10)
    fig.tight_layout()
    return _save(fig, path)
