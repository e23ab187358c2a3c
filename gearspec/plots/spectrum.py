"""Figures of ``gearspec spectrum``."""

from __future__ import annotations

import math
import textwrap
from pathlib import Path

import numpy as np
import pandas as pd

from ..recording import Recording
from ..segment import Segmentation
from ..spectrum.analysis import SpectrumResult
from . import DIRS, NEG as _NEG, POS as _POS, plain_log_axis, plt, save as _save
from .ordermap import _scale

__all__ = ["PER_PAGE", "plot_segments", "plot_order_spectra", "plot_amplitude_vs_speed", "plot_spectrum_summary",
           "plot_unexplained"]

#: colour of the encoder's own lines (count rate folded by the sampling) and of the quantisation limit
_ENCODER = "#8c564b"


def plot_segments(rec: Recording, seg: Segmentation, path, max_points: int = 20_000, max_rows: int = 12) -> Path:
    """Position-derived speed over time for every run (at most ``2 max_rows`` runs, spread evenly over
    the recording; the title says how many), with the segments shaded per direction; each run's
    curve thinned to about ``max_points`` points."""
    pieces = rec.pieces()
    all_runs = sorted({r for r, _, _ in pieces})
    ncol = 1 if len(all_runs) <= 4 else 2
    nrow = min(math.ceil(len(all_runs) / ncol), max_rows)
    runs = _spread(all_runs, nrow * ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(11 if ncol == 1 else 13, 1.9 * nrow + 0.8), squeeze=False)
    t, theta = rec.t, rec.theta
    for ax, r in zip(axes.ravel(), runs):
        for rr, a, b in pieces:
            if rr != r or b - a < 3:
                continue
            step = max(1, (b - a) // max_points)
            tt, th = t[a:b:step], theta[a:b:step]
            k = max(1, int(round(0.01 / max(np.median(np.diff(tt)), 1e-12))))  # ~10 ms difference
            v = (th[k:] - th[:-k]) / (tt[k:] - tt[:-k])
            ax.plot(tt[k // 2: k // 2 + len(v)], v, color="0.35", lw=0.6, rasterized=len(v) > 5000)
        for s in seg.segments:
            if s.run == r:
                ax.axvspan(t[s.start], t[s.stop - 1], color=_POS if s.direction > 0 else _NEG, alpha=0.18, lw=0)
        ax.axhline(0, color="0.7", lw=0.5)
        ax.set_ylabel(f"speed ({rec.speed_unit})")
        ax.set_title(f"run {r}", fontsize=9, loc="left")
    for ax in axes.ravel()[len(runs):]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    shown = (f"all {len(all_runs)} runs" if len(runs) == len(all_runs) else
             f"{len(runs)} of {len(all_runs)} runs, spread over the recording")
    fig.suptitle(f"Constant-speed segments (blue: positive, red: negative direction); {shown}", fontsize=11)
    height = 1.9 * nrow + 0.8
    fig.subplots_adjust(left=0.08 if ncol == 1 else 0.06, right=0.98, top=1 - 0.95 / height, bottom=0.5 / height,
                        hspace=0.5, wspace=0.18)
    return _save(fig, path, tight=False)


#: panels of spectra on a page (``spectra_NN.png``)
PER_PAGE = 8


def plot_order_spectra(result: SpectrumResult, path_pattern: str, per_page: int = PER_PAGE, indices=None,
                       points: int = 1500, first_page: int = 1) -> list[Path]:
    """Order spectrum of the segments ``indices`` (default every segment that holds its spectra):
    FFT and Lomb-Scargle amplitude, noise floor, lines; ``per_page`` panels a page, each curve drawn
    as its maximum over ``points`` logarithmic frequency bins (every peak stays visible).  Pages are
    numbered from ``first_page`` in ``path_pattern`` (a report draws its pages one task each)."""
    idx = range(len(result.segments)) if indices is None else indices
    segs = [(i, result.segments[i]) for i in idx if result.segments[i].fft_frequency is not None]
    paths = []
    for page in range(math.ceil(len(segs) / per_page)):
        chunk = segs[page * per_page:(page + 1) * per_page]
        nrow = math.ceil(len(chunk) / 2)
        fig, axes = plt.subplots(nrow, 2, figsize=(13, 3.0 * nrow + 0.9), squeeze=False)
        for ax, (i, s) in zip(axes.ravel(), chunk):
            _spectrum_panel(ax, i, s, result.unit, points)
        for ax in axes.ravel()[len(chunk):]:
            ax.set_visible(False)
        _spectra_legend(fig, axes[0, 0])
        # a fixed layout: tight_layout measures every tick label of every log axis (most of the time)
        top = 1 - 0.75 / (3.0 * nrow + 0.9)
        fig.subplots_adjust(left=0.07, right=0.98, bottom=0.45 / (3.0 * nrow + 0.9) + 0.03, top=top - 0.03,
                            hspace=0.55, wspace=0.2)
        paths.append(_save(fig, Path(path_pattern.format(page + first_page)), tight=False))
    return paths


def _envelope(f: np.ndarray, a: np.ndarray, points: int) -> tuple[np.ndarray, np.ndarray]:
    """``(f, a)`` at positive ``f`` (ascending) reduced to the maximum of ``a`` in at most ``points``
    logarithmic bins of ``f`` (at each bin's geometric centre); unchanged when short already."""
    ok = f > 0
    f, a = f[ok], a[ok]
    if len(f) <= 2 * points:
        return f, a
    edges = np.geomspace(f[0], f[-1] * (1 + 1e-9), points + 1)
    start = np.searchsorted(f, edges[:-1])
    keep = np.flatnonzero(np.diff(np.append(start, len(f))) > 0)
    amax = np.maximum.reduceat(a, start[keep])
    return np.sqrt(edges[keep] * edges[keep + 1]), amax


def _spectrum_panel(ax, i: int, s, unit: str, points: int) -> None:
    """One segment's spectra, fitted peaks and position Nyquist frequency on ``ax``."""
    tu = "Nm" if unit == "rad" else "N"
    f, a = _envelope(s.fft_frequency, s.fft_amplitude, points)
    ax.loglog(f, np.maximum(a, 1e-12), color="0.55", lw=0.5, label="FFT (Hann), over position")
    if s.ls_frequency is not None:
        for arr, color, lw, alpha, label in (
                (s.ls_amplitude, "#2ca02c", 0.6, 0.8, "Lomb-Scargle, raw samples"),
                (s.ls_residual_amplitude, "#8c564b", 0.5, 0.7, "Lomb-Scargle of the residual of the declared lines")):
            f, a = _envelope(s.ls_frequency, arr, points)
            ax.loglog(f, np.maximum(a, 1e-12), color=color, lw=lw, alpha=alpha, label=label)
        f, a = _envelope(s.ls_frequency, s.noise_amplitude, points)
        ax.loglog(f, a, color="k", lw=0.8, ls=":", label="local noise level")
    # one errorbar call per colour and fill (each call builds its artists and styles: most of a
    # panel's time when made once per peak)
    groups: dict[tuple[str, bool], list] = {}
    for p in s.peaks:
        color = ("#9467bd" if p.declared else "#17becf" if p.aliased_from else
                 _ENCODER if p.quantisation_harmonic is not None else "#ff7f0e" if p.label else "#d62728")
        groups.setdefault((color, p.fap < 0.01), []).append((p.frequency, max(p.amplitude, 1e-12), p.amplitude_se))
    for (color, filled), pts in groups.items():
        f_, a_, se_ = (list(c) for c in zip(*pts))
        ax.errorbar(f_, a_, yerr=[[0.0] * len(pts), se_], fmt="o", ms=4, color=color,
                    mfc=color if filled else "none", zorder=5)
    # the three strongest peaks named, one a frequency band (a factor 3: labels of close peaks overlap),
    # those near the right edge written leftwards (inside the axes)
    named: list[float] = []
    f_hi = s.fft_frequency[-1] if len(s.fft_frequency) else 1.0
    for p in sorted(s.peaks, key=lambda q: -q.amplitude):
        if len(named) >= 3 or p.frequency <= 0 or any(abs(math.log(p.frequency / g)) < math.log(3.0) for g in named):
            continue
        named.append(p.frequency)
        txt = p.label.split(" = ")[0] if p.label else (p.hint or "?")
        left = p.frequency > f_hi ** 0.75 * float(s.fft_frequency[1]) ** 0.25 if len(s.fft_frequency) > 1 else False
        ax.annotate(txt[:26], (p.frequency, max(p.amplitude, 1e-12)), fontsize=6, xytext=(-3 if left else 3, 4),
                    textcoords="offset points", ha="right" if left else "left")
    if np.isfinite(s.nyquist) and s.nyquist > 0:  # nothing beyond is measured
        ax.axvline(s.nyquist, color="k", lw=0.8, ls="-.", alpha=0.6, label="position Nyquist frequency")
    ql = getattr(s, "quantisation_limit", float("inf"))
    if np.isfinite(ql) and ql > 0 and not (np.isfinite(s.nyquist) and ql >= s.nyquist):
        ax.axvline(ql, color=_ENCODER, lw=0.8, ls="--", alpha=0.8, label="quantisation limit: 1/(8 encoder steps)")
    ax.set_title(f"segment {i}: run {s.segment.run}, dir {s.direction:+d}, "
                 f"{s.speed:.4g} {unit}/s, {s.segment.n} samples", fontsize=8, loc="left")
    ax.set_xlabel(f"frequency (cycles/{unit})", fontsize=8)
    ax.set_ylabel(f"amplitude ({tu})", fontsize=8)
    # from a tenth of the lowest noise level (or of the weakest curve) up: not down to the 1e-12 floor
    lows = [np.nanmin(a) for a in (s.noise_amplitude, s.fft_amplitude) if a is not None and np.any(a > 0)]
    low = 0.1 * min(lows) if lows else None
    if low:
        ax.set_ylim(bottom=max(low, 1e-12))
    ax.minorticks_off()  # tick objects are most of a log axis's drawing time; the majors are labelled
    ax.tick_params(labelsize=7)


def _spectra_legend(fig, ax) -> None:
    from matplotlib.lines import Line2D

    handles, _ = ax.get_legend_handles_labels()
    handles += [Line2D([], [], marker="o", ls="", color="#9467bd", label="declared line (fit, +1 s.e.)"),
                Line2D([], [], marker="o", ls="", color="#ff7f0e", label="found: harmonic/sideband"),
                Line2D([], [], marker="o", ls="", color="#17becf", label="found: alias of a line above Nyquist"),
                Line2D([], [], marker="o", ls="", color=_ENCODER, label="found: encoder count rate, folded"),
                Line2D([], [], marker="o", ls="", color="#d62728", label="found: unexplained"),
                Line2D([], [], marker="o", ls="", color="0.3", mfc="none", label="hollow: fap >= 0.01")]
    fig.legend(handles=handles, loc="upper center", ncol=5, fontsize=8, frameon=False)



def _spread(items: list, k: int) -> list:
    """At most ``k`` of ``items``, evenly spread (first and last kept)."""
    if len(items) <= k:
        return list(items)
    return [items[j] for j in np.unique(np.round(np.linspace(0, len(items) - 1, k)).astype(int))]


def plot_amplitude_vs_speed(result: SpectrumResult, path, relative: bool = False) -> Path | None:
    """Amplitude of every declared line against speed, both directions (the SILO4 Fig. 7 view): each
    segment a point with its 95 % bar, the median of the repetitions of a speed joined by a line."""
    labels = list(dict.fromkeys(p.label for s in result.segments for p in s.peaks if p.declared))
    if not labels:
        return None
    unit = result.unit
    n = len(labels)
    ncol = min(n, 3)
    nrow = math.ceil(n / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.6 * ncol, 3.4 * nrow), squeeze=False)
    group = {i: k for k, (_, _, g) in enumerate(result.speed_groups()) for i in g}
    tables = {lab: result.amplitude_vs_speed(lab) for lab in labels}
    factor, tu = (100.0, "% of mean friction") if relative else _scale(
        np.concatenate([t["amplitude"].to_numpy(float) for t in tables.values()]), "Nm" if unit == "rad" else "N")
    for ax, lab in zip(axes.ravel(), labels):
        df = tables[lab]
        df = df[df["frequency"].notna()]
        for d, name, color, mk in DIRS:
            sub = df[df["direction"] == d].sort_values("speed")
            if sub.empty:
                continue
            scale = sub["level"].abs() if relative else 1.0
            y, e = factor * sub["amplitude"] / scale, factor * sub["amplitude_se"] / scale
            ax.errorbar(sub["speed"], y, yerr=1.96 * e, fmt=mk, color=color, ms=3.5, lw=0.6, capsize=1.5,
                        mfc=color if d > 0 else "none", alpha=0.8, label=f"{name}: per segment")
            med = (pd.DataFrame({"g": sub["segment"].map(group), "v": sub["speed"], "y": y})
                   .groupby("g").median().sort_values("v"))
            if len(med) < len(sub):  # repetitions: their median per speed, joined
                ax.plot(med["v"], med["y"], "-", color=color, lw=1.0, label=f"{name}: median per speed")
        ax.set_title(textwrap.fill(lab, 45), fontsize=9)
        ax.set_xlabel(f"speed ({unit}/s)")
        ax.set_ylabel("amplitude (% of mean friction)" if relative else f"amplitude ({tu})")
        if (df["speed"] > 0).all() and len(df) and df["speed"].max() / max(df["speed"].min(), 1e-300) > 20:
            ax.set_xscale("log")
        else:  # no offset text ("1e-10+6.8e2") over the label: plain numbers, a range of 10 % at least
            ax.ticklabel_format(axis="x", style="plain", useOffset=False)
            if len(df) and df["speed"].max() < 1.1 * df["speed"].min():
                mid = float(df["speed"].median())
                ax.set_xlim(0.95 * mid, 1.05 * mid)
        ax.set_ylim(bottom=0)
        ax.ticklabel_format(axis="y", style="plain", useOffset=False)
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    handles = {h.get_label(): h for ax in axes.ravel()[:n] for h in ax.get_legend_handles_labels()[0]}
    fig.legend(handles=list(handles.values()), loc="lower center", ncol=4, fontsize=8, frameon=False)
    fig.suptitle(f"Ripple amplitude against speed per declared line, {len(result.segments)} segments "
                 "(error bars: 95 %)", fontsize=11)
    fig.tight_layout(rect=(0, 0.35 / (3.4 * nrow) + 0.03 * math.ceil(len(handles) / 4), 1, 1))
    return _save(fig, path, tight=False)   # laid out: one draw, no crop


def plot_spectrum_summary(result: SpectrumResult, path, max_fap: float = 0.01, strongest: int = 3) -> Path | None:
    """Every segment on one figure, one panel per direction: the amplitude of each declared line
    against speed (median over the repetitions of a speed joined, each segment a dot) and the
    ``strongest`` significant peaks of each segment that no declared line fits (crosses)."""
    if not result.segments:
        return None
    unit = result.unit
    t = result.peaks_table()
    if t.empty:
        return None
    factor, tu = _scale(t["amplitude"].to_numpy(float), "Nm" if unit == "rad" else "N")
    group = {i: k for k, (_, _, g) in enumerate(result.speed_groups()) for i in g}
    t = t.assign(group=t["segment"].map(group), y=t["amplitude"] * factor)
    dec = t[t["declared"]]
    labels = list(dict.fromkeys(dec["label"]))
    colors = plt.get_cmap("tab10")
    dirs = [d for d in DIRS if (t["direction"] == d[0]).any()]
    fig, axes = plt.subplots(1, len(dirs), figsize=(6.4 * len(dirs), 4.8), squeeze=False, sharey=True)
    found = t[~t["declared"] & (t["fap"] <= max_fap)]
    found = found.sort_values("amplitude", ascending=False).groupby("segment").head(strongest)
    for ax, (d, name, _, _) in zip(axes[0], dirs):
        for k, lab in enumerate(labels):
            sub = dec[(dec["label"] == lab) & (dec["direction"] == d)]
            if sub.empty:
                continue
            c = colors(k % 10)
            ax.plot(sub["speed"], sub["y"], ".", color=c, ms=3, alpha=0.5, rasterized=len(sub) > 2000)
            med = sub.groupby("group")[["speed", "y"]].median().sort_values("speed")
            ax.plot(med["speed"], med["y"], "-o", color=c, ms=3, lw=1.2, label=textwrap.fill(lab, 34))
        fs = found[found["direction"] == d]
        if len(fs):
            ax.plot(fs["speed"], fs["y"], "x", color="#d62728", ms=4, mew=0.8, alpha=0.7,
                    label=f"not declared: {strongest} strongest per segment (fap <= {max_fap:g})")
        ax.set_yscale("log")
        plain_log_axis(ax.yaxis)
        if (t["speed"] > 0).all() and t["speed"].max() / max(t["speed"].min(), 1e-300) > 20:
            ax.set_xscale("log")
            plain_log_axis(ax.xaxis)
        ax.set_xlabel(f"segment speed ({unit}/s)")
        n_seg = int((np.array([s.direction for s in result.segments]) == d).sum())
        ax.set_title(f"{name} direction: {n_seg} segments", fontsize=10)
        ax.grid(alpha=0.3, which="major")
    axes[0, 0].set_ylabel(f"amplitude ({tu})")
    handles = {h.get_label(): h for ax in axes[0] for h in ax.get_legend_handles_labels()[0]}
    fig.legend(handles=list(handles.values()), loc="lower center", ncol=min(len(handles), 4), fontsize=8,
               frameon=False)
    fig.suptitle("Every segment: declared lines (median per speed, dots: segments) and peaks no declared line fits",
                 fontsize=10)
    fig.tight_layout(rect=(0, 0.04 + 0.035 * math.ceil(len(handles) / 4), 1, 1))
    return _save(fig, path, tight=False)   # laid out: one draw, no crop


def plot_unexplained(result: SpectrumResult, path, max_fap: float = 0.01) -> Path | None:
    """Peaks found that no declared line explains: frequency against speed, size = amplitude."""
    t = result.peaks_table()
    t = t if t.empty else t[(~t["declared"]) & (t["fap"] <= max_fap)]
    if t.empty:
        return None
    unit = result.unit
    factor, tu = _scale(t["amplitude"].to_numpy(float), "Nm" if unit == "rad" else "N")
    fig, ax = plt.subplots(figsize=(9, 5))
    amax = t["amplitude"].max()
    v = (t["speed"] * np.sign(t["direction"])).abs()
    if v.min() > 0 and v.max() / v.min() > 20:  # speeds over decades: logarithmic on either side of 0
        from matplotlib.ticker import FuncFormatter

        # linear up to the decade above the slowest segment: ticks 0 and +-1 decade apart, never crowded
        ax.set_xscale("symlog", linthresh=10.0 ** math.ceil(math.log10(float(v.min()))), linscale=0.5)
        ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x:g}"))
    lim = float(v.max()) * 1.15 if v.max() > 0 else 1.0
    ax.set_xlim(-lim if (t["direction"] < 0).any() else 0, lim if (t["direction"] > 0).any() else 0)
    enc = (t["quantisation_harmonic"].notna() if "quantisation_harmonic" in t
           else pd.Series(False, index=t.index))
    kinds = ((enc, _ENCODER, "encoder count rate, folded by the sampling (not position-locked)"),
             (~enc & t["label"].notna(), "#ff7f0e", "harmonic or sideband of a declared line"),
             (~enc & t["label"].isna(), "#d62728", "unexplained"))
    for rows, color, name in kinds:
        sub = t[rows]
        if sub.empty:
            continue
        ax.scatter(sub["speed"] * np.sign(sub["direction"]), sub["frequency"], s=15 + 300 * sub["amplitude"] / amax,
                   color=color, alpha=0.6, edgecolor="k", lw=0.3, label=name)
    # one annotation per frequency band (a factor 1.4: closer labels overlap), at its strongest peak
    done: list[float] = []
    for _, r in t.sort_values("amplitude", ascending=False).iterrows():
        f = r["frequency"]
        if any(abs(math.log(f / g)) < math.log(1.4) for g in done) or len(done) >= 10:
            continue
        done.append(f)
        txt = (r["label"].split(" = ")[0] if isinstance(r["label"], str) else
               r["hint"] if isinstance(r.get("hint"), str) else f"{f:.4g} cycles/{unit}")
        x = r["speed"] * np.sign(r["direction"])
        # towards the middle of the axes, so that no label runs past its edge
        right = (ax.transScale + ax.transLimits).transform((x, 1.0))[0] < 0.5
        ax.annotate(f"{txt} (up to {factor * r['amplitude']:.2g} {tu})", (x, f), fontsize=7,
                    xytext=(6 if right else -6, 3), textcoords="offset points", ha="left" if right else "right")
    if result.gear is not None:
        for ln in result.gear.declared_lines():
            ax.axhline(ln.frequency, color="#9467bd", lw=0.6, ls="--")
            # at the left edge, in axes coordinates: inside the axes whatever the data's range
            ax.annotate(ln.label.split(" (")[0], (0.005, ln.frequency), xycoords=ax.get_yaxis_transform(),
                        fontsize=6, color="#9467bd", xytext=(2, 2), textcoords="offset points")
    ax.set_yscale("log")
    ax.set_xlabel(f"segment velocity ({unit}/s)")
    ax.set_ylabel(f"frequency (cycles/{unit})")
    ax.set_title(f"Peaks no declared line explains (fap <= {max_fap:g}); marker area ~ amplitude; "
                 "dashed: declared lines", fontsize=9)
    ax.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    return _save(fig, path, tight=False)   # laid out: one draw, no crop
