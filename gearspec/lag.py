"""Channel lag: a torque (or current) channel logged later than the position channel.

A torque sample stored at ``t`` but measured at ``t - L`` (``L > 0``: torque behind position)
shows a position-locked line ``A sin(2 pi f theta + phi)`` at signed velocity ``v`` as
``A sin(2 pi f theta + phi - 2 pi f v L)``: its phase falls linearly with velocity.
:func:`lag_from_phases` fits that slope to per-segment phases, :func:`estimate_lag` takes them
from the declared lines of a recording's segments, :func:`apply_lag` shifts the torque back.

Why phases and not a cross-correlation: torque is not a delayed copy of position (friction is a
nonlinear function of position and velocity), so a correlation of the two channels has no peak
at the lag; the phases of position-locked lines are exactly what a lag moves, with errors the
harmonic fit gives.
"""

from __future__ import annotations

import dataclasses
import math
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from .errors import InputError

__all__ = ["LagEstimate", "lag_from_phases", "estimate_lag", "apply_lag", "lag_option", "MIN_SPEEDS"]

_TWO_PI = 2.0 * math.pi
#: a lag is estimated only from a (line, direction) seen at this many distinct speeds or more
MIN_SPEEDS = 3


@dataclass
class LagEstimate:
    """A channel lag (s, ``> 0``: torque behind position) with its standard error; ``groups``: the
    (line, direction) series used; ``chi2``: the weighted phase misfit over ``dof`` (about 1 per
    dof when the phase errors are honest)."""

    lag: float
    se: float
    n_points: int
    groups: list = field(default_factory=list)
    chi2: float = float("nan")
    dof: int = 0
    max_lag: float = float("nan")

    @property
    def z(self) -> float:
        return self.lag / self.se if self.se > 0 else (math.inf if self.lag else 0.0)

    @property
    def p(self) -> float:
        """Two-sided p-value of the lag against no lag (normal)."""
        return float(math.erfc(abs(self.z) / math.sqrt(2.0)))

    def describe(self) -> str:
        return (f"lag {1e3 * self.lag:.4g} ms +- {1e3 * self.se:.2g} ms (torque behind position; from the phases of "
                f"{len(self.groups)} line/direction series, {self.n_points} segments; chi2 {self.chi2:.1f} on "
                f"{self.dof} dof)")

    def to_dict(self) -> dict:
        return {"lag": float(self.lag), "lag_se": float(self.se), "n_points": int(self.n_points),
                "groups": self.groups, "chi2": float(self.chi2), "dof": int(self.dof)}


def lag_from_phases(frequency, velocity, phase, phase_se, group, *, max_lag: float,
                    min_speeds: int = MIN_SPEEDS) -> LagEstimate | None:
    """The lag from phases ``phase`` (rad, of ``sin(2 pi f theta + phase)``) of lines at
    ``frequency`` (cycles per unit of theta) measured at signed velocities ``velocity`` with
    standard errors ``phase_se``; ``group`` labels the series that share one true phase (one line
    in one direction).  Searched within ``|lag| <= max_lag``.

    Model: ``phase_i = c_group(i) - 2 pi f_i v_i lag + noise_i``.  Only groups with at least
    ``min_speeds`` distinct speeds take part (a group at one speed says nothing about a slope).
    Phases wrap: a grid search of the weighted circular misfit comes first (no unwrapping that
    could slip a cycle; when speeds share a common step the misfit repeats every ``1/(f step)``
    and the smallest equally good lag is taken), then weighted least squares on the phases
    unwrapped about it gives the standard error (scaled up when the phases scatter more than
    their errors say).  Returns None when no group qualifies."""
    f, v, ph, se = (np.asarray(x, float) for x in (frequency, velocity, phase, phase_se))
    grp = np.asarray(group, object)
    ok = np.isfinite(f) & np.isfinite(v) & np.isfinite(ph) & np.isfinite(se) & (se > 0)
    keep = np.zeros(len(f), bool)
    used = []
    for g in dict.fromkeys(grp[ok].tolist()):
        sel = ok & (grp == g)
        if len(np.unique(np.round(v[sel], 6))) >= min_speeds:
            keep |= sel
            used.append({"series": str(g), "segments": int(sel.sum()), "frequency": float(f[sel][0])})
    if not used or not max_lag > 0:
        return None
    f, v, ph, se, grp = f[keep], v[keep], ph[keep], se[keep], grp[keep]
    w = 1.0 / se ** 2
    k = _TWO_PI * f * v                       # d phase / d lag = -k
    _, gi = np.unique(grp.astype(str), return_inverse=True)
    ng = int(gi.max()) + 1

    def misfit(lags):
        # weighted circular misfit 2 sum_g (W_g - |sum_i w_i exp(i psi_i)|) of the phases with
        # the lag taken out (psi = phase + k lag), per group about its best phase: ~ weighted SS
        psi = ph[None, :] + np.outer(lags, k)
        z = w[None, :] * np.exp(1j * psi)
        R = np.zeros((len(lags), ng), complex)
        for j in range(ng):
            R[:, j] = z[:, gi == j].sum(axis=1)
        return 2.0 * (w.sum() - np.abs(R).sum(axis=1))

    # grid fine enough that the largest phase step is 0.05 rad
    step = 0.05 / max(float(np.max(np.abs(k))), 1e-300)
    n = int(min(max(2 * math.ceil(max_lag / step) + 1, 3), 200_001))
    grid = np.linspace(-max_lag, max_lag, n)
    cost = np.concatenate([misfit(grid[a:a + 4096]) for a in range(0, n, 4096)])
    # speeds with a common step leave the lag ambiguous (2 pi f v L repeats every 1/(f dv)):
    # among the local minima as good as the best (within 4 in chi2 units, scaled by the misfit per
    # degree of freedom when the phases scatter more than their errors say), the smallest lag
    cmin = float(cost.min())
    dof0 = max(len(ph) - 1 - ng, 1)
    loc = np.flatnonzero((cost <= cmin + 4.0 * max(1.0, cmin / dof0))
                         & (cost <= np.concatenate(([np.inf], cost[:-1])))
                         & (cost <= np.concatenate((cost[1:], [np.inf]))))
    lag = float(grid[loc[np.argmin(np.abs(grid[loc]))]]) if len(loc) else float(grid[int(np.argmin(cost))])
    def residual(lag):  # about each group's mean phase, unwrapped near 0
        psi = ph + k * lag
        c = np.angle(np.bincount(gi, weights=w * np.cos(psi), minlength=ng)
                     + 1j * np.bincount(gi, weights=w * np.sin(psi), minlength=ng))
        return (psi - c[gi] + math.pi) % _TWO_PI - math.pi

    # weighted least squares on the phases unwrapped about the grid solution:
    # r_i(lag + d) = r_i + k_i d - delta c_g, solved for d and the group phases jointly
    X = np.zeros((len(ph), 1 + ng))
    X[:, 0] = k
    X[np.arange(len(ph)), 1 + gi] = -1.0
    G = X.T @ (w[:, None] * X)
    for _ in range(3):
        lag += float(np.linalg.lstsq(G, X.T @ (w * -residual(lag)), rcond=None)[0][0])
    r = residual(lag)
    chi2 = float(np.sum(w * r ** 2))
    dof = len(r) - 1 - ng
    cov = np.linalg.pinv(G)
    s2 = max(chi2 / dof, 1.0) if dof > 0 else 1.0   # phases scattering more than their errors: honest se
    se_lag = float(math.sqrt(max(cov[0, 0], 0.0) * s2))
    return LagEstimate(lag, se_lag, len(r), used, chi2, max(dof, 0), float(max_lag))


def estimate_lag(rec, gear=None, *, segmentation=None, min_snr: float = 5.0, max_lag: float | None = None,
                 min_speeds: int = MIN_SPEEDS, spectrum=None, **segment_options) -> LagEstimate:
    """The lag of the torque channel behind position, from the phases of the gear's declared lines
    across constant-speed segments.  ``min_snr``: a segment's line takes part when its amplitude is
    at least this many standard errors (phase error below ``1/min_snr`` rad).  ``max_lag``: the
    search range (default 20 median sample intervals, at least 50 ms).  ``spectrum``: a
    :class:`~gearspec.spectrum.SpectrumResult` already computed (else :func:`~gearspec.spectrum.analyze`
    runs with ``segmentation`` or ``segment_options``).  :class:`InputError` when the data cannot
    show a lag."""
    from .gears import load_gear
    from .spectrum import analyze

    g = load_gear(gear) if gear is not None else rec.gear
    src = ", ".join(rec.sources) if rec.sources else "the recording"
    if g is None or not g.declared_lines():
        raise InputError(f"{src}: estimating a lag needs position-locked lines at known frequencies; give a gear spec "
                         "(--gear) that declares them, or give the lag in seconds")
    if spectrum is None:
        spectrum = analyze(rec, g, segmentation=segmentation, max_peaks=0, **segment_options)
    if max_lag is None:
        dts = [np.diff(rec.t[a:b]) for _, a, b in rec.pieces() if b - a > 1]
        dt = np.concatenate(dts) if dts else np.zeros(0)
        med = float(np.median(dt[dt > 0])) if np.any(dt > 0) else math.nan
        max_lag = max(20 * med, 0.05) if math.isfinite(med) else 0.05
    rows = [(p.frequency, s.direction * s.speed, p.phase, p.phase_se, f"{p.label} ({'+' if s.direction > 0 else '-'})")
            for s in spectrum.segments for p in s.peaks
            if p.declared and p.amplitude_se > 0 and not p.amplitude < min_snr * p.amplitude_se]
    est = None
    if rows:
        f, v, ph, se, grp = map(list, zip(*rows))
        est = lag_from_phases(f, v, ph, se, grp, max_lag=max_lag, min_speeds=min_speeds)
    if est is None:
        raise InputError(f"{src}: cannot estimate a lag: no declared line stands {min_snr:g} standard errors above the "
                         f"noise in segments at {min_speeds} or more different speeds of one direction; give the lag "
                         "in seconds")
    return est


def apply_lag(rec, seconds: float, *, channels=("torque", "current")):
    """A copy of ``rec`` with its torque (and current) shifted *earlier* by ``seconds`` (``> 0`` undoes
    a torque logged behind position), interpolated in time within each piece
    (:meth:`Recording.pieces`); rows whose partner falls outside their piece are excluded under
    ``lag_edge``; the recording gets a note and ``meta["lag"]``."""
    L = float(seconds)
    if not math.isfinite(L):
        raise InputError(f"the lag must be a finite number of seconds, got {seconds!r}")
    src = ", ".join(rec.sources) if rec.sources else "the recording"
    data = rec.data.copy()
    t = rec.t.astype(float)
    keep = np.ones(len(data), bool)
    cols = [c for c in channels if c in data.columns]
    if not cols:
        raise InputError(f"{src}: no torque or current column to shift by the lag")
    if L != 0.0:
        new = {c: data[c].to_numpy(dtype=float).copy() for c in cols}
        for _, a, b in rec.pieces():
            tp = t[a:b]
            dt = np.diff(tp)
            tol = 1e-9 * (float(np.median(dt)) if len(dt) else 1.0)
            tq = tp + L
            keep[a:b] = (tq >= tp[0] - tol) & (tq <= tp[-1] + tol)
            tq = np.clip(tq, tp[0], tp[-1])
            for c in cols:
                new[c][a:b] = np.interp(tq, tp, data[c].to_numpy(dtype=float)[a:b])
        for c in cols:
            data[c] = new[c]
    lost = int((~keep).sum())
    if lost == len(data):
        raise InputError(f"{src}: a lag of {L:g} s is longer than every contiguous piece of the recording")
    data = data.loc[keep].reset_index(drop=True)
    excluded = Counter(rec.excluded)
    if lost:
        excluded["lag_edge"] += lost
    note = (f"lag: {', '.join(cols)} shifted {'earlier' if L >= 0 else 'later'} by {abs(L):.6g} s (torque was logged "
            f"{'behind' if L >= 0 else 'ahead of'} position); {lost} row(s) at the edges of pieces lost their partner "
            "(lag_edge)")
    return dataclasses.replace(rec, data=data, excluded=excluded, notes=list(rec.notes) + [note],
                               meta={**rec.meta, "lag": L}, _tau=None)


def lag_option(rec, value, *, say=print, **segment_options):
    """The ``--lag SECONDS|auto`` option: ``auto`` estimates the lag, reports it with ``say`` and
    applies it; a number is applied as given; None leaves ``rec`` as it is."""
    if value is None:
        return rec
    text = str(value).strip().lower()
    if text == "auto":
        opts = {k: v for k, v in segment_options.items() if v is not None}
        if str(opts.get("window", "auto")) != "auto":
            try:
                opts["window"] = float(opts["window"])
            except ValueError:
                raise InputError(f"--window takes seconds or 'auto', got '{opts['window']}'") from None
        est = estimate_lag(rec, segmentation=None, **opts)
        say(f"--lag auto: {est.describe()}")
        out = apply_lag(rec, est.lag)
        out.meta["lag_se"] = est.se
        out.meta["lag_estimate"] = est.to_dict()
        return out
    try:
        L = float(text)
    except ValueError:
        raise InputError(f"--lag takes a number of seconds or 'auto', got '{value}'") from None
    if not math.isfinite(L):
        raise InputError(f"--lag takes a finite number of seconds or 'auto', got '{value}'")
    out = apply_lag(rec, L)
    say(f"lag (--lag): {1e3 * L:.4g} ms applied; {out.excluded.get('lag_edge', 0) - rec.excluded.get('lag_edge', 0)} "
        "row(s) at piece edges excluded (lag_edge)")
    return out
