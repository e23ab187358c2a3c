"""Figures of ``gearspec discover``: the Pareto front, the friction levels against speed with the
selected law and the papers' laws, and the inclusion probabilities."""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np

from . import NEG as _NEG, POS as _POS, plt, save as _save

__all__ = ["plot_pareto", "plot_levels", "plot_inclusion"]

_REF_COLORS = ["#2ca02c", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22", "#17becf", "#ff7f0e"]


def plot_pareto(result, path) -> Path:
    """Held-out RMSE against complexity: every law scored (grey), the Pareto front (line), the
    selected law (star) and the papers' laws / published models (labelled markers)."""
    tu = result.torque_unit
    fig, ax = plt.subplots(figsize=(9.5, 5.6))
    cx = np.array([c.complexity for c in result.candidates])
    cy = np.array([c.rmse_holdout for c in result.candidates])
    ax.scatter(cx, cy, s=14, color="0.72", label=f"laws scored ({len(cx)})", zorder=2)
    fy = cy[result.front]
    ax.plot(cx[result.front], fy, "-o", color="#1f77b4", ms=5, lw=1.3, label="Pareto front", zorder=3)
    sel = result.best
    ax.plot([sel.complexity], [sel.rmse_holdout], "*", color="#d62728", ms=17, zorder=5, label="selected")
    refs = [r for r in result.references if r.rmse_holdout is not None and r.complexity is not None]
    for i, r in enumerate(refs):
        ax.plot([r.complexity], [r.rmse_holdout], "D" if r.kind == "paper law" else "s",
                color=_REF_COLORS[i % len(_REF_COLORS)], ms=8, mfc="none", mew=2, zorder=4,
                label=textwrap.shorten(f"{r.name}", 60))
    ys = np.array([y for y in list(cy) + [r.rmse_holdout for r in refs] if np.isfinite(y) and y > 0])
    if len(ys) and ys.max() / ys.min() > 8:
        ax.set_yscale("log")
    # a runaway fit (e.g. a fold extrapolating a decay) would flatten everything else: clip, and say so
    limit = 5 * float(np.max(fy)) if len(fy) else None
    off = [r for r in refs if limit is not None and r.rmse_holdout > limit]
    if limit is not None and len(ys) and ys.max() > limit:
        ax.set_ylim(top=limit)
        text = "off scale: " + "; ".join(f"{textwrap.shorten(r.name, 40)} {r.rmse_holdout:.3g} {tu}" for r in off)
        n_c = int(np.sum(cy > limit))
        if n_c:
            text += ("; " if off else "") + f"{n_c} candidate law(s)"
        ax.annotate(text, xy=(0.01, 0.01), xycoords="axes fraction", ha="left", va="bottom", fontsize=8,
                    color="0.3")
    ax.set_xlabel("complexity (free parameters)")
    ax.set_ylabel(f"held-out RMSE ({tu})")
    ax.set_title(f"Candidate laws: error on held-out {result.settings['by']}s against complexity", fontsize=11)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7.5, loc="upper right", framealpha=0.9)
    fig.tight_layout()
    return _save(fig, path)


def plot_levels(result, path) -> Path:
    """Mean friction of every segment against speed, per direction, with the selected law's and the
    references' segment means (lines) and the residuals of each below."""
    M = result.moments
    lv = result.levels
    tu = result.torque_unit
    unit = result.unit
    names = [k for k in lv if k not in ("data",)]
    fig, (ax, axr) = plt.subplots(2, 1, figsize=(9.5, 7.4), sharex=True, gridspec_kw={"height_ratios": [2.2, 1]})
    dirs = [d for d in (1, -1) if np.any(M.direction == d)]
    logx = M.speed[M.speed > 0].size and M.speed.max() / max(M.speed[M.speed > 0].min(), 1e-300) > 20
    for d in dirs:
        sel = M.direction == d
        order = np.argsort(M.speed[sel])
        sp = M.speed[sel][order]
        data = d * lv["data"][sel][order]
        col = _POS if d > 0 else _NEG
        ax.plot(sp, data, "o", color=col, ms=5, label=f"data, {'positive' if d > 0 else 'negative'}")
        # lines through the mean over segments at the same speed (repeated plateaus)
        u, inv = np.unique(np.round(sp, 9), return_inverse=True)
        cnt = np.bincount(inv)
        for i, k in enumerate(names):
            pred = d * lv[k][sel][order]
            style = dict(color=col, lw=1.8) if k == "selected" else dict(color=_REF_COLORS[i % len(_REF_COLORS)],
                                                                          lw=1.0, ls="--")
            lab = ("selected law" if k == "selected" else textwrap.shorten(k, 55)) if d == dirs[0] else None
            ax.plot(u, np.bincount(inv, weights=pred) / cnt, **style, label=lab)
            res = data - pred
            axr.plot(u, np.bincount(inv, weights=res) / cnt, **style)
            axr.plot(sp, res, "o" if k == "selected" else ".", color=style["color"], ms=4 if k == "selected" else 3)
    ax.set_ylabel(f"mean friction magnitude ({tu})")
    ax.set_title("Friction level of every segment: data and laws (segment means)", fontsize=11)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7.5, ncol=2)
    axr.axhline(0, color="0.5", lw=0.8)
    axr.set_ylabel(f"data - law ({tu})\n(dots: segments)")
    axr.set_xlabel(f"speed ({unit}/s)")
    axr.grid(alpha=0.3)
    if logx:
        axr.set_xscale("log")
    fig.tight_layout()
    return _save(fig, path)


def plot_inclusion(result, path, top: int = 25) -> Path | None:
    """Inclusion probabilities (segment bootstrap) of the terms of the selected law (the law the
    acceptance rule kept: nothing it rejected is shown)."""
    inc = result.inclusion
    if inc is None or len(inc) == 0:
        return None
    inc = inc.sort_values("probability", ascending=False).head(top).iloc[::-1]
    fig, ax = plt.subplots(figsize=(9.5, 0.3 * len(inc) + 1.4))
    cols = ["#1f77b4" if s == "level" else "#ff7f0e" for s in inc["stage"]]
    ax.barh(np.arange(len(inc)), inc["probability"], color=cols)
    ax.set_yticks(np.arange(len(inc)))
    ax.set_yticklabels([textwrap.shorten(t, 60) for t in inc["term"]], fontsize=7.5)
    ax.set_xlim(0, 1)
    ax.set_xlabel(f"inclusion probability (bootstrap over {result.settings.get('by', 'segment')}s)")
    ax.set_title("Terms of the selected law: how often the sparse regression picks each\n"
                 "(any shape of its slot; blue: level terms, orange: ripple terms)", fontsize=10)
    ax.grid(axis="x", alpha=0.3)
    fig.tight_layout()
    return _save(fig, path)
