"""Residual analyses of a fitted model: where the structure is that the model does not explain
(over position, against speed, a channel, acceleration, the travel since a reversal).

Every function takes a :class:`~gearspec.diagnose.data.DiagnoseData` and a residual ``r`` (data
minus model, torque units).  Statistics that decide between "structure" and "noise" treat whole
held-out groups (segments, runs, moves) as the independent units: friction residuals are coloured.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from scipy import stats

from ..spectrum import MEASURABLE_FRACTION, LombScargle, false_alarm_probability, local_noise
from .data import DiagnoseData

__all__ = ["ResidualSpectrum", "position_spectra", "speed_groups", "speed_analysis", "channel_analysis",
           "acceleration_analysis", "acc_roundoff", "reversal_analysis", "magnitude_residual"]


def magnitude_residual(dd: DiagnoseData, r: np.ndarray) -> np.ndarray:
    """The residual in the friction magnitude (``direction * r``): positive where the drive needs
    more than the model says, in both directions (as SILO4 writes friction)."""
    return dd.at("direction") * r


# ---------------------------------------------------------------------- over position
@dataclass
class ResidualSpectrum:
    """A Lomb-Scargle periodogram of the residual over position (one segment or a pool)."""

    direction: int
    speed_min: float
    speed_max: float
    segments: list
    n: int
    span: float
    frequency: np.ndarray = field(repr=False)
    amplitude: np.ndarray = field(repr=False)      # sqrt(4 P / N), torque units
    noise: np.ndarray = field(repr=False)          # the same of the local noise level
    peaks: pd.DataFrame = field(repr=False, default=None)   # frequency, amplitude, z, fap
    pooled: bool = True

    @property
    def label(self) -> str:
        dn = "positive" if self.direction > 0 else "negative"
        if not self.pooled:
            return f"segment {self.segments[0]} ({dn}, speed {self.speed_min:.4g})"
        return f"{dn}, speeds {self.speed_min:.4g}-{self.speed_max:.4g} ({len(self.segments)} segments)"

    def power_z(self, frequency: float) -> float:
        """Power over local noise at a frequency (interpolated)."""
        if not len(self.frequency):
            return float("nan")
        return float(np.interp(frequency, self.frequency, (self.amplitude / np.maximum(self.noise, 1e-300)) ** 2))


def speed_groups(dd: DiagnoseData, ratio: float = 1.6, min_speed_fraction: float = 0.05) -> list[tuple[int, np.ndarray]]:
    """Observations grouped by direction and similar speed (within ``ratio`` of the slowest of the
    group): ``[(direction, indices), ...]``.  Standstill (below ``min_speed_fraction`` of the top
    speed) is left out."""
    v = dd.at("v")
    s = np.abs(v)
    d = dd.at("direction")
    top = float(np.max(s)) if len(s) else 0.0
    cut = min_speed_fraction * top if dd.kind == "trajectory" else 0.0
    out = []
    for direction in dd.directions():
        sel = np.flatnonzero((d == direction) & (s > cut))
        if not len(sel):
            continue
        order = sel[np.argsort(s[sel], kind="stable")]
        ss = s[order]
        start = 0
        while start < len(order):
            stop = int(np.searchsorted(ss, ratio * ss[start] * (1 + 1e-12), side="right"))
            out.append((direction, np.sort(order[start:stop])))
            start = stop
    return out


def _segment_slices(seg: np.ndarray) -> list[slice]:
    """The observations of every segment id in ``seg`` (ascending ids) as slices, when each id is
    one contiguous run (as the loop's data keep them): the same elements in the same order as the
    mask ``seg == id``, found in one pass instead of one per segment; else the masks."""
    bounds = np.flatnonzero(np.diff(seg) != 0) + 1
    starts = np.concatenate(([0], bounds)) if len(seg) else np.zeros(0, int)
    stops = np.concatenate((bounds, [len(seg)])) if len(seg) else np.zeros(0, int)
    ids = seg[starts]
    if len(np.unique(ids)) != len(ids):
        return [seg == sid for sid in np.unique(seg)]
    return [slice(int(starts[i]), int(stops[i])) for i in np.argsort(ids, kind="stable")]


def _demean_by_segment(seg: np.ndarray, y: np.ndarray, parts: list | None = None) -> np.ndarray:
    out = y.astype(float).copy()
    for m in (_segment_slices(seg) if parts is None else parts):
        out[m] -= out[m].mean()
    return out


def _spacing(theta: np.ndarray, seg: np.ndarray, parts: list | None = None) -> float:
    """The 90th percentile of the position step between consecutive observations of a segment."""
    parts = _segment_slices(seg) if parts is None else parts
    steps = [np.abs(np.diff(theta[m])) for m in parts if len(theta[m]) > 2]
    st = np.concatenate(steps) if steps else np.zeros(0)
    st = st[st > 0]
    return float(np.percentile(st, 90)) if len(st) else float("nan")


def _channels(dd: DiagnoseData) -> dict:
    """The channels a residual spectrum reads, at the observations (read once per analysis)."""
    return {"theta": dd.at("theta"), "segment": dd.at("segment"), "direction": dd.at("direction"),
            "speed": np.abs(dd.at("v"))}


def _spectrum(dd: DiagnoseData, r: np.ndarray, idx: np.ndarray, *, oversample: float, fap_threshold: float,
              max_peaks: int, fmax: float | None, pooled: bool, max_bins: int = 400_000,
              channels: dict | None = None) -> ResidualSpectrum | None:
    ch = _channels(dd) if channels is None else channels
    theta, seg, d, s = ch["theta"], ch["segment"], ch["direction"], ch["speed"]
    th, sg = theta[idx], seg[idx]
    parts = _segment_slices(sg)
    y = _demean_by_segment(sg, d[idx] * r[idx], parts)
    span = float(np.ptp(th)) if len(th) > 1 else 0.0
    seg_spans = [float(np.ptp(th[m])) for m in parts]
    longest = max(seg_spans) if seg_spans else 0.0
    step = _spacing(th, sg, parts)
    if not (span > 0 and longest > 0 and np.isfinite(step) and step > 0) or len(idx) < 32:
        return None
    nyq = 0.5 / step
    f_hi = MEASURABLE_FRACTION * nyq if fmax is None else min(fmax, MEASURABLE_FRACTION * nyq)
    f_lo = max(2.0 / longest, 1.0 / span)   # slower lines cannot be told from a level or a drift
    df = 1.0 / (span * oversample)
    nf = int((f_hi - f_lo) / df) + 1
    if nf < 16:
        return None
    if nf > max_bins:
        nf = max_bins
        df = (f_hi - f_lo) / (nf - 1)
    power = LombScargle(th, y).power_grid(f_lo, df, nf)
    noise, bins = local_noise(power, return_bins=True)
    z = power / np.maximum(noise, 1e-300)
    m_indep = max(1.0, span * (f_hi - f_lo))
    freqs = f_lo + df * np.arange(nf)
    # peaks: local maxima, strongest first, separated by 3 resolution steps
    loc = np.flatnonzero((z[1:-1] > z[:-2]) & (z[1:-1] >= z[2:])) + 1
    fap = false_alarm_probability(z[loc], m_indep, noise_bins=bins[loc], oversample=oversample)
    keep = loc[fap < fap_threshold]
    keep = keep[np.argsort(-z[keep])]
    chosen = []
    for i in keep:
        if all(abs(freqs[i] - freqs[j]) > 3.0 / span for j in chosen):
            chosen.append(i)
        if len(chosen) >= max_peaks:
            break
    rows = []
    for i in chosen:
        # parabolic interpolation of the peak in log power
        off = 0.0
        if 0 < i < nf - 1:
            a, b, c = np.log(power[i - 1:i + 2] + 1e-300)
            den = a - 2 * b + c
            off = 0.5 * (a - c) / den if den < 0 else 0.0
        f = float(freqs[i] + np.clip(off, -0.5, 0.5) * df)
        fp = float(false_alarm_probability(z[i], m_indep, noise_bins=bins[i], oversample=oversample))
        rows.append({"frequency": f, "amplitude": float(np.sqrt(4 * power[i] / len(y))), "z": float(z[i]),
                     "fap": fp, "resolution": 1.0 / span})
    amp = np.sqrt(4 * np.maximum(power, 0) / len(y))
    nz = np.sqrt(4 * np.maximum(noise, 0) / len(y))
    ss = s[idx]
    return ResidualSpectrum(int(np.sign(np.mean(d[idx]))), float(ss.min()), float(ss.max()),
                            sorted(int(k) for k in np.unique(sg)), len(idx), span, freqs, amp, nz,
                            pd.DataFrame(rows, columns=["frequency", "amplitude", "z", "fap", "resolution"]), pooled)


def position_spectra(dd: DiagnoseData, r: np.ndarray, *, per_segment: bool = True, oversample: float = 5.0,
                     fap_threshold: float = 0.01, max_peaks: int = 6, fmax: float | None = None,
                     ratio: float = 1.6) -> dict:
    """Residual periodograms over position.

    Returns ``{"pooled": [...], "segments": [...]}``: one :class:`ResidualSpectrum` per direction
    and speed group (speeds within ``ratio`` of each other, :func:`speed_groups`; every segment of
    a group pooled, so that a line too weak for one segment adds up coherently over many), one
    per direction over all speeds, and (``per_segment``) one per segment.  Peaks are local maxima
    with false-alarm probability below ``fap_threshold`` (local noise, F-corrected, every
    independent frequency searched).  Frequencies below two cycles of the longest segment are not
    searched (they cannot be told from a level or a drift).
    """
    d = dd.at("direction")
    s = np.abs(dd.at("v"))
    top = float(np.max(s)) if len(s) else 0.0
    cut = 0.05 * top if dd.kind == "trajectory" else 0.0
    pools = [np.flatnonzero((d == direction) & (s > cut)) for direction in dd.directions()]
    groups = speed_groups(dd, ratio)
    if len(groups) > len(dd.directions()):
        pools += [idx for _, idx in groups]
    ch = _channels(dd)
    seg = ch["segment"]
    rows = np.arange(len(seg))      # one array: each segment's indices a view of it (not one per segment)
    singles = [rows[m] for m in _segment_slices(seg)] if per_segment and dd.kind == "plateaus" else []
    kw = dict(oversample=oversample, fap_threshold=fap_threshold, fmax=fmax, channels=ch)
    pooled = [_spectrum(dd, r, idx, max_peaks=max_peaks, pooled=True, **kw) for idx in pools]
    segments = [_spectrum(dd, r, idx, max_peaks=3, pooled=False, **kw) for idx in singles]
    return {"pooled": [sp for sp in pooled if sp is not None], "segments": [sp for sp in segments if sp is not None]}


# ---------------------------------------------------------------------- against speed
def _block_se(x: np.ndarray, blocks: int = 8) -> float:
    nb = min(blocks, len(x))
    if nb < 2:
        return float("nan")
    bm = np.array([b.mean() for b in np.array_split(x, nb)])
    return float(bm.std(ddof=1) / math.sqrt(nb))


def speed_analysis(dd: DiagnoseData, r: np.ndarray, *, bins: int = 12, n_params: int = 0) -> tuple[pd.DataFrame, dict]:
    """Residual means (friction magnitude) against speed, per direction.

    Plateau data: one row per segment (its speed; standard error from 8 block means, so that
    coloured noise counts).  Trajectories: quantile bins of the speed (standard error from the
    spread of the per-move means in the bin).  Returns the table and, per direction, the lack-of-fit
    statistic ``chi2 = sum (mean/se)^2`` with ``rows - n_params`` degrees of freedom and its
    p-value; ``"asymmetry"``: Welch's test of the mean residual of the two directions.
    """
    m = magnitude_residual(dd, r)
    s = np.abs(dd.at("v"))
    d = dd.at("direction")
    grp = dd.group
    rows = []
    if dd.kind == "plateaus":
        for g, (a, z) in enumerate(zip(dd.starts, dd.stops)):
            rows.append({"direction": int(d[a]), "speed": float(np.mean(s[a:z])), "mean": float(np.mean(m[a:z])),
                         "se": _block_se(m[a:z]), "n": int(z - a), "group": g})
    else:
        top = float(np.max(s)) if len(s) else 0.0
        for direction in dd.directions():
            sel = np.flatnonzero((d == direction) & (s > 0.02 * top))
            if len(sel) < 2 * bins:
                continue
            edges = np.quantile(s[sel], np.linspace(0, 1, bins + 1))
            which = np.clip(np.searchsorted(edges, s[sel], side="right") - 1, 0, bins - 1)
            for k in range(bins):
                ii = sel[which == k]
                if len(ii) < 4:
                    continue
                per_group = pd.Series(m[ii]).groupby(grp[ii]).mean()
                se = float(per_group.std(ddof=1) / math.sqrt(len(per_group))) if len(per_group) > 1 else _block_se(m[ii])
                rows.append({"direction": direction, "speed": float(np.mean(s[ii])), "mean": float(np.mean(m[ii])),
                             "se": se, "n": len(ii), "group": -1})
    df = pd.DataFrame(rows, columns=["direction", "speed", "mean", "se", "n", "group"])
    out = {}
    for direction in (1, -1):
        t = df[(df["direction"] == direction) & (df["se"] > 0)]
        if len(t) < 2:
            continue
        chi2 = float(np.sum((t["mean"] / t["se"]) ** 2))
        dof = max(len(t) - n_params, 1)
        out[direction] = {"chi2": chi2, "dof": dof, "p": float(stats.chi2.sf(chi2, dof))}
    a, b = df[df["direction"] == 1]["mean"], df[df["direction"] == -1]["mean"]
    if len(a) >= 2 and len(b) >= 2:
        res = stats.ttest_ind(a, b, equal_var=False)
        out["asymmetry"] = {"difference": float(a.mean() - b.mean()), "t": float(res.statistic), "p": float(res.pvalue)}
    return df.sort_values(["direction", "speed"], ascending=[False, True]).reset_index(drop=True), out


# ---------------------------------------------------------------------- against a channel
def channel_analysis(dd: DiagnoseData, r: np.ndarray, channel: str, *, transform=None) -> tuple[pd.DataFrame, dict] | None:
    """Residual means (friction magnitude) against the group means of a channel (``load``,
    ``temperature``, ``t``), per direction; the regression slope across groups with its
    t statistic and p-value (groups are the units).  ``transform`` (e.g. ``np.abs``) is applied to
    the channel first.  None when the channel is absent or constant."""
    x = dd.at(channel)
    if x is None:
        return None
    x = np.asarray(x, dtype=float)
    if transform is not None:
        x = transform(x)
    if not np.all(np.isfinite(x)) or np.ptp(x) <= 1e-12 * max(1.0, float(np.max(np.abs(x)))):
        return None
    m = magnitude_residual(dd, r)
    d = dd.at("direction")
    rows = []
    for g, (a, z) in enumerate(zip(dd.starts, dd.stops)):
        rows.append({"group": g, "direction": int(np.sign(np.sum(d[a:z])) or d[a]), "x": float(np.mean(x[a:z])),
                     "mean": float(np.mean(m[a:z])), "se": _block_se(m[a:z]), "n": int(z - a)})
    df = pd.DataFrame(rows)
    out = {}
    ps = []
    for direction in (1, -1):
        t = df[df["direction"] == direction]
        if len(t) < 3 or np.ptp(t["x"]) <= 0:
            continue
        res = stats.linregress(t["x"], t["mean"])
        tt = res.slope / res.stderr if res.stderr > 0 else (np.inf if res.slope != 0 else 0.0)
        out[direction] = {"slope": float(res.slope), "t": float(tt), "p": float(res.pvalue), "r": float(res.rvalue)}
        ps.append(float(res.pvalue))
    # both directions together (the group means of the magnitude residual)
    if len(df) >= 3 and np.ptp(df["x"]) > 0:
        res = stats.linregress(df["x"], df["mean"])
        out["both"] = {"slope": float(res.slope), "p": float(res.pvalue), "r": float(res.rvalue)}
        ps.append(float(res.pvalue))
    out["p"] = min(1.0, min(ps) * len(ps)) if ps else 1.0
    return df, out


# ---------------------------------------------------------------------- against acceleration
def _within(dd: DiagnoseData, a: np.ndarray) -> np.ndarray:
    """``a`` with the mean of each held-out group removed."""
    out = np.asarray(a, dtype=float).copy()
    for s0, s1 in zip(dd.starts, dd.stops):
        out[s0:s1] -= out[s0:s1].mean()
    return out


def _cluster_slope(dd: DiagnoseData, x: np.ndarray, y: np.ndarray) -> tuple | None:
    """``(slope, se, t)`` of ``y`` on ``x`` (both within groups), the standard error cluster-robust
    over the held-out groups; None when ``x`` is zero."""
    sxx = float(x @ x)
    if sxx <= 0:
        return None
    b = float(x @ y) / sxx
    e = y - b * x
    score = np.array([float(x[a:z] @ e[a:z]) for a, z in zip(dd.starts, dd.stops)])
    se = math.sqrt(float(score @ score)) / sxx
    return b, se, (b / se if se > 0 else 0.0)


#: accelerations within the groups smaller than this many float64 round-offs of the position,
#: over the squared sampling step, are the derivative filter's round-off on exact plateaus: no data
ACC_ROUNDOFF = 1e3


def acc_roundoff(dd: DiagnoseData) -> float:
    """The acceleration (unit/s^2) below which a derivative of ``dd``'s positions is round-off:
    ``ACC_ROUNDOFF * eps * max|theta| / dt^2`` with ``dt`` the median sampling step (0 without
    positions or times)."""
    th, t = dd.at("theta"), dd.at("t")
    if th is None or t is None or len(t) < 2:
        return 0.0
    steps = np.diff(t)
    steps = steps[steps > 0]
    if not len(steps):
        return 0.0
    dt = float(np.median(steps))
    return ACC_ROUNDOFF * float(np.finfo(float).eps) * float(np.max(np.abs(th))) / (dt * dt)


def acceleration_analysis(dd: DiagnoseData, r: np.ndarray, bins: int = 15) -> tuple[pd.DataFrame, dict] | None:
    """Residual (drive torque, signed) against acceleration, both taken relative to their group
    means (so that a level misfit does not count): binned means for the figure, and the slope
    (a missing inertia, kg m^2 or kg) with a cluster-robust t statistic over groups; None without
    accelerations.  When the accelerations within the groups are round-off (:func:`acc_roundoff`:
    exact plateaus, their ramps trimmed) a slope against them would be one against numerical
    noise: no test is made (empty table, slope NaN, ``p`` 1, ``roundoff`` True)."""
    acc = dd.at("acc")
    if acc is None or not np.any(np.abs(acc) > 0):
        return None
    a_d, r_d = _within(dd, acc), _within(dd, r)
    if float(np.max(np.abs(a_d))) <= acc_roundoff(dd):
        # no test made: no evidence of a missing inertia (and no inertia candidate, ``roundoff``)
        return (pd.DataFrame(columns=["acc", "mean", "se", "n"]),
                {"slope": float("nan"), "se": float("nan"), "t": 0.0, "p": 1.0, "roundoff": True})
    fit = _cluster_slope(dd, a_d, r_d)
    if fit is None:
        return None
    slope, se, t = fit
    G = dd.n_groups
    p = float(2 * stats.t.sf(abs(t), max(G - 1, 1)))
    edges = np.quantile(a_d, np.linspace(0, 1, bins + 1))
    which = np.clip(np.searchsorted(edges, a_d, side="right") - 1, 0, bins - 1)
    rows = [{"acc": float(a_d[which == k].mean()), "mean": float(r_d[which == k].mean()),
             "se": float(r_d[which == k].std(ddof=1) / math.sqrt(max((which == k).sum(), 1))) if (which == k).sum() > 1
             else float("nan"), "n": int((which == k).sum())} for k in range(bins) if (which == k).any()]
    return pd.DataFrame(rows), {"slope": slope, "se": se, "t": t, "p": p}


# ---------------------------------------------------------------------- near reversals
def reversal_analysis(dd: DiagnoseData, r: np.ndarray, bins: int = 12) -> tuple[pd.DataFrame, dict] | None:
    """Residual (friction magnitude) against the travel since the last reversal: binned means for
    the figure (log-spaced travel bins, and the samples with no reversal before them), and the best
    fit of a presliding profile ``-exp(-travel/L)`` over a grid of ``L`` (cluster-robust t
    statistic over groups, Bonferroni over the grid).  None when the data have no reversal."""
    tr = dd.at("travel")
    if tr is None:
        return None
    fin = np.isfinite(tr) & (tr > 0)
    if fin.sum() < 16:
        return None
    m = magnitude_residual(dd, r)
    lo, hi = np.quantile(tr[fin], [0.01, 0.99])
    lo = max(lo, 1e-12)
    edges = np.geomspace(lo, max(hi, lo * 1.01), bins + 1)
    which = np.searchsorted(edges, tr, side="right") - 1
    rows = []
    for k in range(bins):
        ii = fin & (which == k)
        if ii.sum() >= 4:
            per = pd.Series(m[ii]).groupby(dd.group[ii]).mean()
            rows.append({"travel": float(np.exp(np.mean(np.log(tr[ii])))), "mean": float(m[ii].mean()),
                         "se": float(per.std(ddof=1) / math.sqrt(len(per))) if len(per) > 1 else float("nan"),
                         "n": int(ii.sum())})
    far = ~fin
    if far.sum() >= 4:
        rows.append({"travel": float("inf"), "mean": float(m[far].mean()), "se": _block_se(m[far]),
                     "n": int(far.sum())})
    best = {"t": 0.0, "p": 1.0, "length": float("nan")}
    grid = np.geomspace(lo, hi, 8)
    md = _within(dd, m)   # the profile within a segment, not its level
    for L in grid:
        fit = _cluster_slope(dd, _within(dd, np.where(fin, -np.exp(-np.where(fin, tr, 0) / L), 0.0)), md)
        if fit is None:
            continue
        b, _, t = fit
        if abs(t) > abs(best["t"]):
            best = {"t": float(t), "scale": b, "length": float(L)}
    G = dd.n_groups
    best["p"] = float(min(1.0, len(grid) * 2 * stats.t.sf(abs(best["t"]), max(G - 1, 1))))
    return pd.DataFrame(rows), best
