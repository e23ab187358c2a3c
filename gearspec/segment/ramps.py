"""Candidate plateaus refined: fragments joined, drifts split, ramp tails trimmed, smooth speed
curves split until only parts shown flat remain (:mod:`gearspec.segment`)."""

from __future__ import annotations

import math

import numpy as np

_K = 4  # blocks per speed window


def _trim_speed(v, s, e, rel_tol):
    """Drop edge blocks whose window speed is off the run's median by more than ``rel_tol``: the
    tail of a ramp that was gentle enough to pass the before/after test."""
    if e - s < 3:
        return s, e
    med = np.median(v[s:e])
    lim = rel_tol * abs(med)
    while s < e and abs(v[s] - med) > lim:
        s += 1
    while e > s and abs(v[e - 1] - med) > lim:
        e -= 1
    return s, e


#: the straight-line band is never narrower than this many position noises (``noise``, the
#: piece's :func:`~gearspec.segment.plateaus._position_noise`): a row off the line by less is not
#: shown to leave it.  Without the floor a position that is a line to round-off (noise-free, as a
#: simulation or an integrated command writes it) gets a band of round-off, and the round-off's own
#: random walk (1e-13 of the travel) cut up to 40 % of 25 s plateaus (1.4 M of 10 M rows).
_LINE_NOISE = 1.0


def _trim_to_line(t, theta, a, z, b, noise: float = 0.0):
    """Trim rows a..z at both ends (by whole blocks) where position leaves the straight-line band,
    from every ``max(1, b // 4)``-th sample: 1.5 times the largest deviation in the middle 60 %,
    at least ``_LINE_NOISE * noise``."""
    n = z - a
    if n < 10 * b:
        return a, z
    stride = max(1, b // 4)
    tt_all, th_all = t[a:z:stride], theta[a:z:stride]
    m = len(tt_all)
    mid = slice(m // 5, m - m // 5)
    tt, th = tt_all[mid], th_all[mid]
    t0 = tt.mean()
    c = float(th.mean())
    dtt = tt - t0
    # sums rather than BLAS dot products: OpenBLAS splits long ones across threads, which costs
    # more than it gains here, and a great deal on a busy machine
    v = float(np.sum(dtt * (th - c)) / np.sum(dtt * dtt))
    dev = th - c
    dev -= v * dtt
    band = max(1.5 * float(np.max(np.abs(dev))) + 1e-12, _LINE_NOISE * noise)
    del dtt, dev
    edge = m // 5

    def off_line(sl):  # only the two edges can be trimmed: the middle is never looked at again
        d = th_all[sl] - (c + v * (tt_all[sl] - t0))
        return np.abs(d) > band

    head = np.flatnonzero(off_line(slice(0, edge)))
    tail = np.flatnonzero(off_line(slice(m - edge, m)))
    new_a = a + (head[-1] + 1) * stride if len(head) else a
    new_z = a + (m - edge + tail[0]) * stride if len(tail) else z
    # whole blocks, so that the ledger stays block-exact
    new_a = a + -(-(new_a - a) // b) * b
    new_z = a + ((new_z - a) // b) * b
    return new_a, max(new_z, new_a)


def _merge_fragments(runs_, t, theta, b, rel_tol):
    """Join consecutive block runs moving the same way at speeds within ``rel_tol``, separated by an
    excursion of at most two windows whose mean speed is within ``2 * rel_tol`` of theirs."""
    def mean_speed(s, e):
        a, z = s * b, e * b - 1
        return (theta[z] - theta[a]) / (t[z] - t[a])

    out = []
    for s, e in runs_:
        if out:
            ps, pe = out[-1]
            v1, v2 = mean_speed(ps, pe), mean_speed(s, e)
            vg = (theta[s * b] - theta[pe * b - 1]) / (t[s * b] - t[pe * b - 1])
            vm = 0.5 * (v1 + v2)
            if (np.sign(v1) == np.sign(v2) and abs(v1 - v2) <= rel_tol * abs(vm)
                    and (s - pe) <= 2 * _K and abs(vg - vm) <= 2 * rel_tol * abs(vm)):
                out[-1] = (ps, e)
                continue
        out.append((s, e))
    return out


def _split_drift(v: np.ndarray, s: int, e: int, rel_tol: float, depth: int = 0):
    """Split blocks s..e where the speed changes most (CUSUM), while the two sides differ by more
    than ``rel_tol`` in mean speed: a slow ramp or a step, not ripple (which averages out)."""
    seg = v[s:e]
    if e - s < 2 * _K or depth > 20:
        return [(s, e)]
    c = np.cumsum(seg - seg.mean())
    k = int(np.argmax(np.abs(c[:-1]))) + 1
    v1, v2 = seg[:k].mean(), seg[k:].mean()
    if abs(v1 - v2) <= rel_tol * abs(seg.mean()):
        return [(s, e)]
    return _split_drift(v, s, s + k, rel_tol, depth + 1) + _split_drift(v, s + k, e, rel_tol, depth + 1)


#: a candidate whose smooth speed curve changes by more than this fraction of ``rel_tol`` is a
#: ramp (the rest of the tolerance is left to ripple) ...
_SMOOTH_SPREAD = 1.0 / 3.0
#: ... when that curve's sum of squares (3 dof) exceeds this many noise variances (tail < 1e-4) ...
_SMOOTH_CHI2 = 20.0
#: degree of the smooth curve (a cubic in time: a ramp, a bell's top, one swing of a sine)
_SMOOTH_DEGREE = 3


def _cubic_values(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The least-squares cubic (``_SMOOTH_DEGREE``) of ``y`` at ``x`` in [-1, 1]: the four Legendre
    columns and their 4 x 4 normal equations (nearly orthogonal columns on [-1, 1], condition about
    10).  The values of ``legval(x, legfit(x, y, 3))`` to 1e-14 of ``max |y|``, at a fifth of its
    cost (no Vandermonde scaling, no SVD)."""
    cols = np.empty((4, len(x)))
    cols[0] = 1.0
    cols[1] = x
    x2 = x * x
    np.multiply(x2, 1.5, out=cols[2])
    cols[2] -= 0.5                      # P2 = (3 x^2 - 1) / 2
    np.multiply(x2, 2.5, out=cols[3])
    cols[3] -= 1.5
    cols[3] *= x                        # P3 = (5 x^3 - 3 x) / 2
    return np.linalg.solve(cols @ cols.T, cols @ y) @ cols


def _split_smooth(tb: np.ndarray, v: np.ndarray, s: int, e: int, rel_tol: float, vnoise2: float = 0.0,
                  prove_flat: bool = False, depth: int = 0):
    """Blocks s..e without a systematic speed change.

    The before/after test bounds the speed change over one window only; along a ramp, a bell's
    top or a creeping tail the speed changes little per window but steadily.  A run is a ramp when
    a cubic in time fitted to the block speeds ``v`` (noise variance ``vnoise2``) spans more than
    ``_SMOOTH_SPREAD * rel_tol`` of the mean speed, stands out of the noise (``_SMOOTH_CHI2``) and
    explains more than the ripple beside it (ripple is not smooth in time: plateaus keep it).
    A ramp is split (CUSUM) recursively and its parts kept only where shown flat (``prove_flat``:
    spread plus two standard errors within the limit).  Runs where position noise alone could hide
    a change of the limit (a crawl near the noise floor) are dropped."""
    n = e - s
    limit = _SMOOTH_SPREAD * rel_tol
    if n < 2 + _SMOOTH_DEGREE:
        return [] if prove_flat else [(s, e)]
    seg = v[s:e - 1]  # block speeds between the blocks of the run
    x = tb[s:e - 1]
    if len(seg) > 4096:  # a long run: its shape is as clear from every k-th block speed
        k = -(-len(seg) // 4096)
        seg, x = seg[::k], x[::k]
    x = (x - x[0]) / max(x[-1] - x[0], 1e-300) * 2.0 - 1.0
    f = _cubic_values(x, seg)
    mean = float(np.mean(seg))
    ss_res = float(np.sum((seg - f) ** 2))
    ss_fit = float(np.sum((f - mean) ** 2))
    dof = max(len(seg) - _SMOOTH_DEGREE - 1, 1)
    # the noise variance predicted from position noise, never above the scatter actually seen (a
    # quantised encoder in steady motion dithers: its block means are better than q / sqrt(12))
    vnoise2 = min(vnoise2, ss_res / dof)
    ss_rest = max(ss_res - dof * vnoise2, 0.0)  # ripple beyond noise
    scale = max(abs(mean), 1e-300)
    spread = float(f.max() - f.min()) / scale
    k_se = 4.0 * math.sqrt((_SMOOTH_DEGREE + 1) / len(seg))  # two standard errors of a range of the curve
    if k_se * math.sqrt(vnoise2) / scale > limit:
        # position noise alone hides a change of the limit over this run: not shown constant
        return []
    if prove_flat:
        s_res = math.sqrt(ss_res / dof)
        upper = spread + k_se * s_res / scale
        if upper <= limit:
            return [(s, e)]
    else:
        smooth = ss_fit > _SMOOTH_CHI2 * vnoise2 and ss_fit > ss_rest
        if spread <= limit or not smooth:
            return [(s, e)]
    if n < 2 * _K or depth > 30:
        return []
    cs = np.cumsum(seg - mean)
    k = int(np.argmax(np.abs(cs[:-1]))) + 1
    k = min(max(k, 1), n - 1)
    return (_split_smooth(tb, v, s, s + k, rel_tol, vnoise2, True, depth + 1)
            + _split_smooth(tb, v, s + k, e, rel_tol, vnoise2, True, depth + 1))
