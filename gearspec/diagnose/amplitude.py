"""The amplitude-vs-speed law of a line the residual supports (:func:`choose_amplitude_law`), on
per-segment sums (moved out of :mod:`.candidates`, which re-exports its names)."""

from __future__ import annotations

import math

import numpy as np
from scipy import stats

from ..terms import amplitude_law
from .design import solve_normal

__all__ = ["EXP_GRID", "RAT_GRID", "POW_GRID", "segment_index", "choose_amplitude_law"]

_TWO_PI = 2.0 * math.pi
EXP_GRID = (-1.0, -0.5, 0.25, 0.5, 1.0, 2.0, 3.0, 5.0)      # decay x top speed
RAT_GRID = (0.25, 0.5, 1.0, 2.0, 4.0)                          # decay x top speed
POW_GRID = (0.25, 0.5, 1.0, 2.0, 3.0)                          # exponent


def segment_index(seg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(np.unique(seg), np.searchsorted(that, seg))``: the distinct segment ids and every sample's
    index into them, without a sort when ``seg`` is in order (the rows of plateaus are: one pass)."""
    seg = np.asarray(seg)
    if seg.ndim != 1 or seg.dtype.kind not in "iu" or (len(seg) > 1 and not np.all(seg[1:] >= seg[:-1])):
        sids = np.unique(seg)
        return sids, np.searchsorted(sids, seg)
    new = np.empty(len(seg), bool)
    new[:1] = True
    np.not_equal(seg[1:], seg[:-1], out=new[1:])
    return seg[new], np.cumsum(new, dtype=np.intp) - 1


def choose_amplitude_law(theta, speed, seg, r, frequency, *, alpha: float = 0.01) -> tuple[str, float, dict]:
    """The amplitude-vs-speed law of a line at ``frequency`` that the residual ``r`` supports:
    least squares of ``g(|v|) (a sin + c cos)`` (each segment's mean removed) for a constant
    amplitude and each decaying law over a grid of its constant; a decaying law is chosen only when
    it beats the constant amplitude by a likelihood-ratio test at ``alpha`` (and the line is seen
    at two speeds or more).  Returns ``(law, decay, rss_by_law)``."""
    x = _TWO_PI * frequency * theta
    sn, cs = np.sin(x), np.cos(x)
    sids, inv = segment_index(seg)
    cnt = np.bincount(inv).astype(float)

    def dm(a):
        return a - (np.bincount(inv, weights=a) / cnt)[inv]

    rr = dm(r)
    yy = float(rr @ rr)
    # a speed per segment (plateaus): g(|v|) is constant within each, dm(g sn) = g dm(sn), and the
    # normal equations of every law are weighted sums of five per-segment sums (equal to the
    # stacked ones up to the order of the additions): one pass over the samples, not one per law
    seg_speed = np.zeros(len(sids))
    seg_speed[inv] = speed
    if np.array_equal(seg_speed[inv], speed):
        S, C = dm(sn), dm(cs)
        sums = [np.bincount(inv, weights=a * b, minlength=len(sids)) for a, b in ((S, S), (S, C), (C, C), (S, rr),
                                                                                  (C, rr))]

        def rss_of(g_seg):
            g2 = g_seg * g_seg
            G = np.array([[g2 @ sums[0], g2 @ sums[1]], [g2 @ sums[1], g2 @ sums[2]]])
            b = np.array([g_seg @ sums[3], g_seg @ sums[4]])
            return yy - float(solve_normal(G, b) @ b)

        speed_of = seg_speed
    else:
        def rss_of(g):
            A = np.column_stack([dm(g * sn), dm(g * cs)])
            b = A.T @ rr
            return yy - float(solve_normal(A.T @ A, b) @ b)

        speed_of = speed

    def rss(law, b):
        return rss_of(amplitude_law(law, speed_of, b))

    top = float(np.max(speed)) if len(speed) else 1.0
    out = {"const": (rss_of(np.ones_like(speed_of)), 0.0)}
    speeds = np.unique(np.round(speed, 9))
    if len(speeds) >= 2 and top > 0:
        for law, grid in (("exp", EXP_GRID), ("rational", RAT_GRID), ("power", POW_GRID)):
            consts = [g if law == "power" else g / top for g in grid]
            out[law] = min(((rss(law, b), b) for b in consts), key=lambda vb: vb[0])
    law, (val, dec) = min(out.items(), key=lambda kv: kv[1][0])
    s2 = val / max(len(r) - 3 - len(sids), 1)
    if law != "const" and (out["const"][0] - val) < stats.chi2.isf(alpha, 1) * s2:
        law, dec = "const", 0.0
    return law, float(dec), {k: v[0] for k, v in out.items()}
