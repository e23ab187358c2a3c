"""Figures of ``gearspec spectrum``."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..recording import Recording
from ..segment import Segmentation
from ..spectrum.analysis import SpectrumResult
from . import DIRS, NEG as _NEG, POS as _POS, plt, save as _save

__all__ = ["plot_segments", "plot_order_spectra", "plot_amplitude_vs_speed", "plot_unexplained"]


def plot_segments(rec: Recording, seg: Segmentation, path, max_points: int = 200_000) -> Path:
    """Position-derived speed over time for every run, with the segments shaded per direction."""
    pieces = rec.pieces()
    runs = sorted({r for r, _, _ in pieces})
    ncol = 1 if len(runs) <= 4 else 2
    nrow = min(math.ceil(len(runs) / ncol), 12)
    runs = runs[: nrow * ncol]
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
            ax.plot(tt[k // 2: k // 2 + len(v)], v, color="0.35", lw=0.6)
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
    fig.suptitle("Constant-speed segments (blue: positive, red: negative direction)", fontsize=11)
    fig.tight_layout()
    return _save(fig, path)


def plot_order_spectra(result: SpectrumResult, path_pattern: str, per_page: int = 8) -> list[Path]:
    """Order spectrum of every segment (FFT and Lomb-Scargle amplitude, noise floor, lines)."""
    unit = result.unit
    tu = "Nm" if unit == "rad" else "N"
    paths = []
    segs = [s for s in result.segments if s.fft_frequency is not None]
    for page in range(math.ceil(len(segs) / per_page)):
        chunk = segs[page * per_page:(page + 1) * per_page]
        nrow = math.ceil(len(chunk) / 2)
        fig, axes = plt.subplots(nrow, 2, figsize=(13, 3.0 * nrow + 0.6), squeeze=False)
        for ax, s in zip(axes.ravel(), chunk):
            i = result.segments.index(s)
            f, a = s.fft_frequency, s.fft_amplitude
            ok = f > 0
            ax.loglog(f[ok], np.maximum(a[ok], 1e-12), color="0.55", lw=0.5, label="FFT (Hann), over position")
            if s.ls_frequency is not None:
                ax.loglog(s.ls_frequency, np.maximum(s.ls_amplitude, 1e-12), color="#2ca02c", lw=0.6, alpha=0.8,
                          label="Lomb-Scargle, raw samples")
                ax.loglog(s.ls_frequency, np.maximum(s.ls_residual_amplitude, 1e-12), color="#8c564b", lw=0.5,
                          alpha=0.7, label="Lomb-Scargle of the residual of the declared lines")
                ax.loglog(s.ls_frequency, s.noise_amplitude, color="k", lw=0.8, ls=":", label="local noise level")
            for p in s.peaks:
                color = ("#9467bd" if p.declared else "#17becf" if p.aliased_from else
                         "#ff7f0e" if p.label else "#d62728")
                ax.errorbar([p.frequency], [max(p.amplitude, 1e-12)], yerr=[[0], [p.amplitude_se]], fmt="o",
                            ms=4, color=color, mfc=color if p.fap < 0.01 else "none", zorder=5)
            for p in sorted(s.peaks, key=lambda q: -q.amplitude)[:5]:
                txt = p.label.split(" = ")[0] if p.label else (p.hint or "?")
                ax.annotate(txt[:28], (p.frequency, max(p.amplitude, 1e-12)), fontsize=6, xytext=(3, 4),
                            textcoords="offset points")
            if np.isfinite(s.nyquist) and s.nyquist > 0:  # nothing beyond is measured
                ax.axvline(s.nyquist, color="k", lw=0.8, ls="-.", alpha=0.6, label="position Nyquist frequency")
            ax.set_title(f"segment {i}: run {s.segment.run}, dir {s.direction:+d}, "
                         f"{s.speed:.4g} {unit}/s, {s.segment.n} samples", fontsize=8, loc="left")
            ax.set_xlabel(f"frequency (cycles/{unit})", fontsize=8)
            ax.set_ylabel(f"amplitude ({tu})", fontsize=8)
            ax.tick_params(labelsize=7)
        for ax in axes.ravel()[len(chunk):]:
            ax.set_visible(False)
        handles, labels = axes[0, 0].get_legend_handles_labels()
        from matplotlib.lines import Line2D

        handles += [Line2D([], [], marker="o", ls="", color="#9467bd", label="declared line (fit, +1 s.e.)"),
                    Line2D([], [], marker="o", ls="", color="#ff7f0e", label="found: harmonic/sideband"),
                    Line2D([], [], marker="o", ls="", color="#17becf", label="found: alias of a line above Nyquist"),
                    Line2D([], [], marker="o", ls="", color="#d62728", label="found: unexplained"),
                    Line2D([], [], marker="o", ls="", color="0.3", mfc="none", label="hollow: fap >= 0.01")]
        fig.legend(handles=handles, loc="upper center", ncol=5, fontsize=8, frameon=False)
        fig.tight_layout(rect=(0, 0, 1, 0.95))
        paths.append(_save(fig, Path(path_pattern.format(page + 1))))
    return paths


def plot_amplitude_vs_speed(result: SpectrumResult, path, relative: bool = False) -> Path | None:
    """Amplitude of every declared line against speed, both directions (the SILO4 Fig. 7 view)."""
    labels = list(dict.fromkeys(p.label for s in result.segments for p in s.peaks if p.declared))
    if not labels:
        return None
    unit = result.unit
    tu = "Nm" if unit == "rad" else "N"
    n = len(labels)
    ncol = min(n, 3)
    nrow = math.ceil(n / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.6 * ncol, 3.4 * nrow), squeeze=False)
    for ax, lab in zip(axes.ravel(), labels):
        df = result.amplitude_vs_speed(lab)
        df = df[df["frequency"].notna()]
        for d, name, color, mk in DIRS:
            sub = df[df["direction"] == d].sort_values("speed")
            if sub.empty:
                continue
            scale = sub["level"].abs() if relative else 1.0
            y, e = sub["amplitude"] / scale, sub["amplitude_se"] / scale
            ax.errorbar(sub["speed"], y * (100 if relative else 1), yerr=1.96 * e * (100 if relative else 1),
                        fmt=mk + "-", color=color, ms=4, lw=0.8, capsize=2, mfc=color if d > 0 else "none",
                        label=f"{name} direction")
        ax.set_title(lab if len(lab) < 45 else lab[:42] + "...", fontsize=9)
        ax.set_xlabel(f"speed ({unit}/s)")
        ax.set_ylabel("amplitude (% of mean friction)" if relative else f"amplitude ({tu})")
        if (df["speed"] > 0).all() and len(df) and df["speed"].max() / max(df["speed"].min(), 1e-300) > 20:
            ax.set_xscale("log")
        ax.set_ylim(bottom=0)
        ax.legend(fontsize=7)
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    fig.suptitle("Ripple amplitude against speed per declared line (error bars: 95 %)", fontsize=11)
    fig.tight_layout()
    return _save(fig, path)


def plot_unexplained(result: SpectrumResult, path, max_fap: float = 0.01) -> Path | None:
    """Peaks found that no declared line explains: frequency against speed, size = amplitude."""
    t = result.peaks_table()
    t = t if t.empty else t[(~t["declared"]) & (t["fap"] <= max_fap)]
    if t.empty:
        return None
    unit = result.unit
    tu = "Nm" if unit == "rad" else "N"
    fig, ax = plt.subplots(figsize=(9, 5))
    amax = t["amplitude"].max()
    for lab, color in ((True, "#ff7f0e"), (False, "#d62728")):
        sub = t[t["label"].notna() == lab]
        if sub.empty:
            continue
        ax.scatter(sub["speed"] * np.sign(sub["direction"]), sub["frequency"], s=15 + 300 * sub["amplitude"] / amax,
                   color=color, alpha=0.6, edgecolor="k", lw=0.3,
                   label="harmonic or sideband of a declared line" if lab else "unexplained")
    # one annotation per frequency band (within 15 %), at its strongest peak
    done: list[float] = []
    for _, r in t.sort_values("amplitude", ascending=False).iterrows():
        f = r["frequency"]
        if any(abs(math.log(f / g)) < math.log(1.15) for g in done) or len(done) >= 10:
            continue
        done.append(f)
        txt = (r["label"].split(" = ")[0] if isinstance(r["label"], str) else
               r["hint"] if isinstance(r.get("hint"), str) else f"{f:.4g} cycles/{unit}")
        ax.annotate(f"{txt} (up to {r['amplitude']:.2g} {tu})", (r["speed"] * np.sign(r["direction"]), f),
                    fontsize=7, xytext=(6, 3), textcoords="offset points")
    if result.gear is not None:
        for ln in result.gear.declared_lines():
            ax.axhline(ln.frequency, color="#9467bd", lw=0.6, ls="--")
            ax.annotate(ln.label.split(" (")[0], (ax.get_xlim()[0], ln.frequency), fontsize=6, color="#9467bd",
                        xytext=(2, 2), textcoords="offset points")
    ax.set_yscale("log")
    ax.set_xlabel(f"segment velocity ({unit}/s)")
    ax.set_ylabel(f"frequency (cycles/{unit})")
    ax.set_title(f"Peaks no declared line explains (fap <= {max_fap:g}); marker area ~ amplitude; "
                 "dashed: declared lines", fontsize=9)
    ax.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    return _save(fig, path)
