"""The residual analyses a round's detectors read: every analysis of :mod:`..residual` on the
round's residual, and the SILO4 eq. 14 analysis of the model's lines (their in-phase amplitude
error against load^2)."""

from __future__ import annotations

import math

import numpy as np
from scipy import stats

from ..context import Round
from ..data import DiagnoseData
from ..residual import (acceleration_analysis, channel_analysis, magnitude_residual, position_spectra,
                        reversal_analysis, speed_analysis)

__all__ = ["analyse", "residual_analyses", "load_line_analysis"]


def analyse(rnd: Round, *, fap: float = 0.01, per_segment: bool = True) -> dict:
    """Every residual analysis of :mod:`~gearspec.diagnose.residual` on the round's residual (Nm):
    ``{"spectra", "speed", "load", "temperature", "t", "acc", "reversal", "load_lines"}`` (the
    channels the data have); ``fap``: the false-alarm probability of a spectrum peak;
    ``per_segment``: spectra of every segment as well as the pooled ones."""
    dd = rnd.dd
    r = rnd.fitted.residual
    base_params = max((len(b.names) // max(len(dd.directions()), 1) for b in rnd.state.blocks if b.key == "base"),
                      default=0)
    out = residual_analyses(dd, r, fap=fap, per_segment=per_segment, n_params=base_params)
    if dd.at("load") is not None and np.ptp(dd.at("load")) > 0:
        out["load_lines"] = load_line_analysis(rnd, r)
    return out


def residual_analyses(dd: DiagnoseData, r: np.ndarray, *, fap: float = 0.01, per_segment: bool = True,
                      n_params: int = 0) -> dict:
    """Every residual analysis of :mod:`~gearspec.diagnose.residual` on a residual ``r`` (Nm) of
    ``dd``: ``{"spectra", "speed", "load", "temperature", "t", "acc", "reversal"}`` (the channels
    the data have); ``n_params``: parameters per direction of the base law (the speed analysis's
    degrees of freedom)."""
    out = {"spectra": position_spectra(dd, r, fap_threshold=fap, per_segment=per_segment) if dd.at("theta") is not None
           else {"pooled": [], "segments": []},
           "speed": speed_analysis(dd, r, n_params=n_params)}
    for ch, tr in (("load", np.abs), ("temperature", None), ("t", None)):
        res = channel_analysis(dd, r, ch, transform=tr)
        if res is not None:
            out[ch] = res
    for name, fn in (("acc", acceleration_analysis), ("reversal", reversal_analysis)):
        res = fn(dd, r)
        if res is not None:
            out[name] = res
    return out


def load_line_analysis(rnd: Round, r: np.ndarray) -> dict:
    """Per line of the model: the residual projected on the line's own shape (its phase, its
    amplitude law) per group, regressed on the group's mean load^2 (SILO4 eq. 14).  Returns
    ``{line key: {"t", "p", "slope" (per Nm^2), "x" (mean load^2 per group), "y" (amplitude error)}}``
    for the lines seen in four groups or more."""
    dd = rnd.dd
    out = {}
    theta = dd.at("theta")
    load = dd.at("load")
    m = magnitude_residual(dd, r)
    s = np.abs(dd.at("v"))
    d = dd.at("direction")
    for blk in [b for b in rnd.lines() if not b.load_phase]:
        phases = dict(rnd.line_phases(blk))
        rng = blk.ranges(dd)
        xs, ys, ws = [], [], []
        for a, z in zip(dd.starts, dd.stops):
            dirn = int(d[a])
            key = 0 if blk.symmetric else dirn
            if key not in phases:
                continue
            g = blk._g(key, s[a:z], rng.get(key))
            shape = g * np.sin(2 * np.pi * blk.frequency * theta[a:z] + phases[key])
            shape = shape - shape.mean()
            den = float(shape @ shape)
            mm = m[a:z] - m[a:z].mean()
            if den <= 0:
                continue
            coef = float(shape @ mm) / den
            var = float(np.var(mm - coef * shape))
            xs.append(float(np.mean(load[a:z] ** 2)))
            ys.append(coef)
            ws.append(den / var if var > 0 else 0.0)
        xs, ys, ws = map(np.asarray, (xs, ys, ws))
        if len(xs) >= 4 and np.ptp(xs) > 0 and np.all(ws > 0):
            # weighted least squares of the in-phase amplitude error on load^2 (weights: precision)
            A = np.column_stack([np.ones(len(xs)), xs]) * np.sqrt(ws)[:, None]
            beta, *_ = np.linalg.lstsq(A, ys * np.sqrt(ws), rcond=None)
            res = ys * np.sqrt(ws) - A @ beta
            s2 = float(res @ res) / max(len(xs) - 2, 1)
            cov = np.linalg.pinv(A.T @ A) * max(s2, 1.0)
            t = beta[1] / math.sqrt(cov[1, 1]) if cov[1, 1] > 0 else 0.0
            p = float(2 * stats.t.sf(abs(t), max(len(xs) - 2, 1)))
            out[blk.key] = {"t": float(t), "p": p, "slope": float(beta[1]), "x": xs.tolist(), "y": ys.tolist()}
    return out
