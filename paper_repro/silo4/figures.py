"""The SILO4 paper's data figures (3, 4, 5, 6, 7, 9) redrawn from the twin's analysis, and the
measurement-chain figure.  Presentation only: every number comes from the public API."""

from __future__ import annotations

import numpy as np
import pandas as pd

from gearspec.model import RPM
from gearspec.plots import NEG, POS, plt, save
from gearspec.simulate.silo4 import RATIO

LABELS = {1: "output shaft", 2: "planetary output shaft", 3: "motor shaft"}
F_JOINT = {1: 1.0 / (2 * np.pi), 2: 20.5 / (2 * np.pi), 3: RATIO / (2 * np.pi)}  # cycles per joint rad
_DIRS = ((1, "positive", POS, "-"), (-1, "negative", NEG, ":"))


def fig3_stick_slip(rec, truth_model, path, zoom: float = 1.0):
    """Fig. 3: joint speed and drive torque against joint position while creeping at 1e-4 rad/s,
    and a ``zoom`` s window of the slips against time."""
    from gearspec.segment import derivatives

    th, t, tau = rec.theta, rec.t, rec.tau
    q = th / RATIO
    v_true = rec.channel("velocity") / RATIO if "velocity" in rec.data else None
    v_enc, _ = derivatives(rec, deriv_window=51)  # 0.2 s Savitzky-Golay on the encoder counts
    held = t > 1.0
    fig, axes = plt.subplots(3, 1, figsize=(10, 8.5))
    ax = axes[0]
    if v_true is not None:
        ax.plot(q[held], v_true[held], color="0.6", lw=0.5, label="true joint speed (twin only)")
    ax.plot(q[held], v_enc[held] / RATIO, color="k", lw=1.0, label="from the encoder (0.2 s Savitzky-Golay)")
    ax.axhline(1e-4, color=POS, ls="--", lw=0.8, label="commanded 1e-4 rad/s")
    ax.set_ylabel("joint speed (rad/s)")
    ax.set_xlabel("joint position (rad)")
    ax.legend(fontsize=7, loc="upper right")
    ax.set_title("(a) joint speed over joint position", fontsize=9, loc="left")
    ax = axes[1]
    t0 = t[held][0] + 0.5 * (t[-1] - t[held][0])
    w = (t >= t0) & (t <= t0 + zoom)
    if v_true is not None:
        ax.plot(t[w] - t0, v_true[w], color="0.4", lw=0.8, label="true joint speed")
    ax.set_ylabel("joint speed (rad/s)")
    ax.set_xlabel("time (s)")
    ax2 = ax.twinx()
    ax2.step(t[w] - t0, (th[w] - th[w][0]) / (2 * np.pi / 2000), where="post", color=NEG, lw=1.0)
    ax2.set_ylabel("encoder counts", color=NEG)
    ax.set_title(f"(b) {zoom:g} s of it: slips and encoder counts", fontsize=9, loc="left")
    ax = axes[2]
    ax.plot(q[held], 1e3 * tau[held], color="0.4", lw=0.5, label="drive torque k_M I (measured)")
    grid = np.linspace(th[held].min(), th[held].max(), 2000)
    stat = truth_model.friction(grid, np.full(len(grid), 1e-9))
    ax.plot(grid / RATIO, 1e3 * stat, color=POS, lw=1.2, label="static friction at each position (Table 2, v -> 0+)")
    ax.set_ylabel("torque at the motor (mNm)")
    ax.set_xlabel("joint position (rad)")
    ax.legend(fontsize=7, loc="upper right")
    ax.set_title("(c) drive torque over joint position", fontsize=9, loc="left")
    fig.suptitle("Fig. 3: stick-slip at a commanded joint speed of 1e-4 rad/s (0.27 rpm at the motor)", fontsize=11)
    fig.tight_layout()
    return save(fig, path)


def fig4_stribeck(plateaus, models: dict, path, max_rpm: float = 1000.0, boundary_rpm: float = 100.0):
    """Fig. 4: plateau friction against motor speed at low speed, per direction, with the models."""
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.4))
    styles = ("-", "--", ":", "-.")
    for ax, (d, name, color, _) in zip(axes, _DIRS):
        pl = plateaus[(plateaus["direction"] == d) & (plateaus["speed"] / RPM <= max_rpm * 1.02)]
        if pl.empty:
            continue
        ax.plot(pl["speed"] / RPM, 1e3 * pl["level"], "o", color=color, ms=3, mfc="none", alpha=0.7,
                label="plateau averages (every repetition)")
        grid = np.geomspace(max(pl["speed"].min() / RPM / 1.5, 0.5), max_rpm * 1.1, 300)
        for (label, m), ls in zip(models.items(), styles):
            try:
                y = m.mean_level(grid * RPM, d)
            except Exception:  # a model without this direction's Stribeck part
                continue
            ax.plot(grid, 1e3 * y, ls, color="k", lw=1.0, label=label)
        ax.axvline(boundary_rpm, color="0.6", lw=0.6)
        ax.text(boundary_rpm, 0.98, " 100 rpm", transform=ax.get_xaxis_transform(), fontsize=7, va="top")
        ax.set_xscale("log")
        ax.set_xlabel("motor speed (rpm)")
        ax.set_ylabel("mean friction (mNm)")
        ax.set_title(f"{name} direction", fontsize=10)
        lo, hi = 1e3 * pl["level"].min(), 1e3 * pl["level"].max()
        ax.set_ylim(lo - 0.1 * (hi - lo), hi + 0.1 * (hi - lo))
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    fig.suptitle("Fig. 4: average friction against motor speed (Stribeck curve), twin plateaus and models",
                 fontsize=11)
    fig.tight_layout()
    return save(fig, path)


def fig5_position_spectra(spectrum, data, targets_rpm, path):
    """Fig. 5: friction against joint position and its order spectrum at the given speeds."""
    segs = [_segment_at(spectrum, r, 1) for r in targets_rpm]
    fig, axes = plt.subplots(len(targets_rpm), 2, figsize=(12, 2.9 * len(targets_rpm)), squeeze=False)
    for row, (r, s) in enumerate(zip(targets_rpm, segs)):
        ax1, ax2 = axes[row]
        if s is None:
            ax1.text(0.5, 0.5, f"no segment near {r} rpm", ha="center", transform=ax1.transAxes)
            continue
        sub = data.subset((data.run == s.segment.run) & (data.direction == s.direction))
        ax1.plot(sub.theta / RATIO, 1e3 * sub.direction * sub.y, ".", ms=1.2, color="0.3")
        ax1.set_ylabel("friction (mNm)")
        ax1.set_xlabel("joint position (rad)")
        ax1.set_title(f"({'abc'[row]}) {s.speed / RPM:.0f} rpm: friction over joint position", fontsize=9, loc="left")
        if s.fft_frequency is not None:
            f = s.fft_frequency * RATIO
            ax2.plot(f, 1e3 * s.fft_amplitude, color="k", lw=0.7)
            for k in (1, 2, 3):
                ax2.axvline(F_JOINT[k], color=POS, ls="--", lw=0.6)
                ax2.text(F_JOINT[k], 0.97, f" F{k}", transform=ax2.get_xaxis_transform(), fontsize=7, va="top")
            ax2.set_xscale("log")
            ax2.set_xlim(0.05, max(60.0, f.max()))
        ax2.set_ylabel("amplitude (mNm)")
        ax2.set_xlabel("frequency (cycles per joint rad)")
        ax2.set_title("order spectrum (Hann FFT over position)", fontsize=9, loc="left")
    fig.suptitle("Fig. 5: friction against joint position and its spectrum (twin, positive direction)", fontsize=11)
    fig.tight_layout()
    return save(fig, path)


def fig6_f3(spectrum, truth_model, targets_rpm, path):
    """Fig. 6: the spectral component at F3 at the given speeds, beside the truth (Table 2)."""
    fig, axes = plt.subplots(1, len(targets_rpm), figsize=(4.3 * len(targets_rpm), 3.6), squeeze=False)
    h_true = next(h for h in truth_model.harmonics("positive") if h["label"] == LABELS[3])
    for ax, r in zip(axes[0], targets_rpm):
        s = _segment_at(spectrum, r, 1)
        if s is None or s.fft_frequency is None:
            ax.text(0.5, 0.5, f"no segment near {r} rpm", ha="center", transform=ax.transAxes)
            continue
        f = s.fft_frequency * RATIO
        band = (f > 0.8 * F_JOINT[3]) & (f < 1.2 * F_JOINT[3])
        ax.plot(f[band], 1e3 * s.fft_amplitude[band], color="k", lw=0.9, label="spectrum (Hann FFT)")
        a_true = h_true["amplitude"] * np.exp(-h_true["decay"] * s.speed)
        ax.axhline(1e3 * a_true, color=POS, ls="--", lw=1.0, label=f"Table 2: {1e3 * a_true:.3f} mNm")
        p = s.peak(LABELS[3])
        if p is not None:
            ax.errorbar([p.frequency * RATIO], [1e3 * p.amplitude], yerr=[1.96e3 * p.amplitude_se], fmt="o",
                        color=NEG, ms=5, label=f"fitted line: {1e3 * p.amplitude:.3f} mNm")
        else:
            why = next((k["reason"] for k in s.skipped if k.get("label") == LABELS[3]), "not fitted")
            ax.text(0.02, 0.9, f"line not fitted: {why}"[:70], transform=ax.transAxes, fontsize=6)
        ax.axvline(F_JOINT[3], color="0.6", lw=0.5)
        ax.set_title(f"{s.speed / RPM:.0f} rpm", fontsize=10)
        ax.set_xlabel("frequency (cycles per joint rad)")
        ax.set_ylabel("amplitude (mNm)")
        ax.set_ylim(bottom=0)
        ax.legend(fontsize=7)
    fig.suptitle("Fig. 6: the component at F3 = 45.6 cycles/rad (motor shaft), positive direction", fontsize=11)
    fig.tight_layout()
    return save(fig, path)


def fig7_percent(spectrum, truth_model, path, claims=(25.0, 4.0)):
    """Fig. 7: amplitude at F2 and F3 in % of the mean friction against motor speed, forwards
    (solid) and backwards (dotted), with Table 2's law and the text's claims."""
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.3))
    grid = np.geomspace(5, 6500, 300)
    for ax, k, claim in zip(axes, (2, 3), claims):
        df = spectrum.amplitude_vs_speed(LABELS[k])
        for d, name, color, ls in _DIRS:
            sub = df[df["direction"] == d]
            if not sub.empty:
                g = sub.assign(rpm=(sub["speed"] / RPM).round(-1)).assign(pct=100 * sub["amplitude"] / sub["level"])
                g = g.groupby("rpm")["pct"].agg(["mean", "std", "count"]).reset_index()
                ax.errorbar(g["rpm"], g["mean"], yerr=g["std"].fillna(0), fmt="o", ls=ls, color=color, ms=3.5,
                            lw=1.2, capsize=2, mfc="none", label=f"twin, {'forwards' if d > 0 else 'backwards'}")
            h = next(h for h in truth_model.harmonics(name) if h["label"] == LABELS[k])
            lvl = truth_model.mean_level(grid * RPM, d)
            ax.plot(grid, 100 * h["amplitude"] * np.exp(-h["decay"] * grid * RPM) / lvl, ls, color="k", lw=0.8,
                    label=f"Table 2 law, {name}")
        ax.axhline(claim, color="0.5", ls="--", lw=0.8)
        ax.text(6, claim, f"text: {claim:g} % at low speed", fontsize=7, va="bottom", color="0.3")
        ax.set_xscale("log")
        ax.set_xlabel("motor speed (rpm)")
        ax.set_ylabel("amplitude (% of mean friction)")
        ax.set_title(f"({'ab'[k - 2]}) F{k}: {LABELS[k]}", fontsize=10)
        ax.set_ylim(0, max(claim * 1.15, ax.get_ylim()[1]))
        ax.legend(fontsize=7)
    fig.suptitle("Fig. 7: ripple amplitude in % of the mean friction (mean and sd over repetitions)", fontsize=11)
    fig.tight_layout()
    return save(fig, path)


def fig9_model_vs_data(data, models: dict, targets_rpm, path, cycles: float = 2.0):
    """Fig. 9: model against data over joint position at the given speeds, both directions."""
    fig, axes = plt.subplots(len(targets_rpm), 2, figsize=(13, 2.8 * len(targets_rpm)), squeeze=False)
    styles = ("-", "--", ":")
    seg = data.segments
    for row, r in enumerate(targets_rpm):
        for col, (d, name, color, _) in enumerate(_DIRS):
            ax = axes[row, col]
            cand = seg[(seg["direction"] == d)]
            if cand.empty:
                continue
            near = cand[np.abs(cand["speed"] / RPM / r - 1) <= 0.05]
            if near.empty:
                ax.text(0.5, 0.5, f"no {name} segment near {r} rpm", ha="center", transform=ax.transAxes)
                continue
            # the repetition whose mean friction is the median of those at this speed
            lv = np.array([np.mean(d * data.y[data.segment == s_]) for s_ in near["segment"]])
            sid = int(near["segment"].iloc[int(np.argsort(lv)[len(lv) // 2])])
            sub = data.subset(data.segment == sid)
            order = np.argsort(d * sub.theta)
            sub = sub.subset(order)
            x = d * (sub.theta - sub.theta[0])
            keep = x <= cycles * 2 * np.pi * 14  # two worm-shaft turns of travel
            sub = sub.subset(np.flatnonzero(keep))
            xq = d * (sub.theta - sub.theta[0]) / RATIO
            ax.plot(xq, 1e3 * d * sub.y, color="0.55", lw=0.5, label="twin data")
            for (label, m), ls in zip(models.items(), styles):
                ax.plot(xq, 1e3 * d * m.evaluate(**sub.inputs()), ls, color=color if ls == "-" else "k", lw=1.1,
                        label=label)
            first = next(iter(models.values()))
            off = 1e3 * np.mean(d * (sub.y - first.evaluate(**sub.inputs())))
            ax.set_title(f"{'abc'[row]}) {r} rpm, {name}: this repetition {off:+.2f} mNm from the "
                         f"{next(iter(models))}", fontsize=9, loc="left")
            ax.set_ylabel("friction (mNm)")
            ax.legend(fontsize=6, loc="upper right")
        axes[row, 0].set_xlabel("joint travel (rad)")
        axes[row, 1].set_xlabel("joint travel (rad)")
    fig.suptitle("Fig. 9: model against data over two worm-shaft turns (the repetition of median level)", fontsize=11)
    fig.tight_layout()
    return save(fig, path)


def fig_chain(transfer: pd.DataFrame, passband_rpm: float, path):
    """Measured / true amplitude of lines that do not decay, against speed (the control run)."""
    fig, ax = plt.subplots(figsize=(8, 4.2))
    for k, mk in ((2, "o"), (3, "s")):
        for d, name, color, ls in _DIRS:
            sub = transfer[(transfer["k"] == k) & (transfer["direction"] == d)]
            if sub.empty:
                continue
            g = sub.groupby("rpm")["ratio"].mean()
            ax.plot(g.index, g.values, marker=mk, ls=ls, color=color, mfc="none" if k == 2 else color, ms=5,
                    label=f"F{k} ({LABELS[k]}), {name}")
    ax.axhline(1.0, color="0.5", lw=0.6)
    ax.axvspan(0, passband_rpm, color="0.9", zorder=0, label=f"pass band of the chain (<= {passband_rpm:.0f} rpm)")
    ax.set_xscale("log")
    ax.set_xlabel("motor speed (rpm)")
    ax.set_ylabel("measured / true amplitude")
    ax.set_title("What the measurement chain does to a line that does not decay (control run, b = 0)", fontsize=10)
    ax.legend(fontsize=7)
    fig.tight_layout()
    return save(fig, path)


def _segment_at(spectrum, rpm, direction):
    """The segment of ``spectrum`` nearest ``rpm`` in ``direction`` with the longest travel (or None)."""
    best = None
    for s in spectrum.segments:
        if s.direction != direction or abs(s.speed / RPM / rpm - 1) > 0.05:
            continue
        if best is None or s.span > best.span:
            best = s
    return best
