"""The line screen: every ripple line (declared, found by the spectrum, given) tested on its own by
the held-out rule of the closed loop before it may enter the library.

Each segment's friction level (its own constant, and its own load, temperature, acceleration and
speed-change coefficients) is profiled out per segment, so a line is judged by what it adds to any
level law: ``sin`` / ``cos`` columns with one amplitude and phase per direction, fitted on the
training folds, predicting the held-out segments.  The held-out Z of
:func:`gearspec.core.crossval.z_statistic` (each held-out group one cluster) must reach
:func:`~gearspec.core.crossval.critical_z` at ``alpha`` over the number of lines tried (Bonferroni).
One pass over the samples, segment by segment: the cost grows with rows x lines, the memory with
segments x lines, never with rows x lines.  A screen, not the verdict: a line that passes it
still has to pass the same rule inside the selected law (:mod:`.accept`).
"""

from __future__ import annotations

import math

import numpy as np

from ..core.crossval import critical_z
from ..core.reduction import harmonic_columns
from ..fitdata import FitData
from .forked import fits_map, segment_chunks
from .moments import _sample_bases

__all__ = ["line_statistics", "screen_lines"]

#: rows x lines of sin/cos values held at once
_CHUNK = 2_000_000


def line_statistics(data: FitData, freqs, *, inertia="auto", min_cycles: float = 1.0):
    """Per segment and line, the normal equations of the line's sin/cos columns with the
    segment's level bases profiled out: ``(sids, G (S, F, 2, 2), g (S, F, 2), cycles (S, F))``;
    ``G`` and ``g`` are 0 where the line completes fewer than ``min_cycles`` cycles (there it
    cannot be told from the level)."""
    freqs = np.asarray(freqs, dtype=float)
    F = len(freqs)
    order, starts, stops, chans = _segments(data, inertia)
    sids = np.unique(data.segment)
    th_all, y_all = np.asarray(data.theta, dtype=float), np.asarray(data.y, dtype=float)

    def chunk(az):          # the segments az[0]:az[1] (chunks of segments in forked workers)
        a0, z0 = az
        G, g, cycles = np.zeros((z0 - a0, F, 2, 2)), np.zeros((z0 - a0, F, 2)), np.zeros((z0 - a0, F))
        for s, (a, z) in enumerate(zip(starts[a0:z0], stops[a0:z0])):
            idx = order[a:z]
            L = np.column_stack([c[idx] for c in chans])
            y, th = y_all[idx], th_all[idx]
            cycles[s] = freqs * float(np.ptp(th))
            iL = np.linalg.pinv(L.T @ L, rcond=1e-10, hermitian=True)
            ly = iL @ (L.T @ y)
            step = max(1, _CHUNK // max(len(idx), 1))
            for f0 in range(0, F, step):
                sl = slice(f0, min(F, f0 + step))
                sn, cs = harmonic_columns(th, freqs[sl])
                for k, (u, v) in enumerate(((sn, sn), (sn, cs), (cs, cs))):
                    # profiled cross products: u'v - (L'u)' iL (L'v)
                    Lu, Lv = L.T @ u, L.T @ v
                    val = np.einsum("nf,nf->f", u, v) - np.einsum("kf,kl,lf->f", Lu, iL, Lv)
                    if k == 0:
                        G[s, sl, 0, 0] = val
                    elif k == 1:
                        G[s, sl, 0, 1] = G[s, sl, 1, 0] = val
                    else:
                        G[s, sl, 1, 1] = val
                g[s, sl, 0] = sn.T @ y - (L.T @ sn).T @ ly
                g[s, sl, 1] = cs.T @ y - (L.T @ cs).T @ ly
        return G, g, cycles

    G, g, cycles = _joined(fits_map(chunk, segment_chunks(stops - starts, F)), ((0, F, 2, 2), (0, F, 2), (0, F)))
    bad = cycles < min_cycles
    G[bad], g[bad] = 0.0, 0.0
    return sids, G, g, cycles


def joint_statistics(data: FitData, freqs, *, inertia="auto", min_cycles: float = 1.0):
    """As :func:`line_statistics` for a few lines together: ``(G (S, 2F, 2F), g (S, 2F))``, columns
    ``sin0, cos0, sin1, ...``, the level profiled out per segment; a line's rows and columns are 0
    in the segments where it completes fewer than ``min_cycles`` cycles."""
    freqs = np.asarray(freqs, dtype=float)
    F = len(freqs)
    order, starts, stops, chans = _segments(data, inertia)
    th_all, y_all = np.asarray(data.theta, dtype=float), np.asarray(data.y, dtype=float)

    def chunk(az):          # the segments az[0]:az[1] (chunks of segments in forked workers)
        a0, z0 = az
        G, g = np.zeros((z0 - a0, 2 * F, 2 * F)), np.zeros((z0 - a0, 2 * F))
        for s, (a, z) in enumerate(zip(starts[a0:z0], stops[a0:z0])):
            idx = order[a:z]
            L = np.column_stack([c[idx] for c in chans])
            y, th = y_all[idx], th_all[idx]
            sn, cs = harmonic_columns(th, freqs)
            H = np.empty((len(idx), 2 * F))
            H[:, 0::2], H[:, 1::2] = sn, cs
            live = np.repeat(freqs * float(np.ptp(th)) >= min_cycles, 2)
            H[:, ~live] = 0.0
            iL = np.linalg.pinv(L.T @ L, rcond=1e-10, hermitian=True)
            LH = L.T @ H
            G[s] = H.T @ H - LH.T @ iL @ LH
            g[s] = H.T @ y - LH.T @ (iL @ (L.T @ y))
        return G, g

    return _joined(fits_map(chunk, segment_chunks(stops - starts, 2 * F)), ((0, 2 * F, 2 * F), (0, 2 * F)))


def _joined(chunks, empty) -> tuple:
    """The per-segment arrays of consecutive chunks of segments, concatenated (``empty``: their
    shapes for no segment)."""
    if not chunks:
        return tuple(np.zeros(e) for e in empty)
    return tuple(np.concatenate([c[k] for c in chunks]) for k in range(len(empty)))


def _segments(data: FitData, inertia):
    """Sample order by segment, segment bounds in it, and the level channels profiled out."""
    order = np.argsort(data.segment, kind="stable")
    _, starts = np.unique(data.segment[order], return_index=True)
    stops = np.append(starts[1:], len(order))
    _, load, temp, t_ref, acc = _sample_bases(data, inertia, [])
    chans = [np.ones(len(data))] + [x for x in (load, None if temp is None else temp - t_ref, acc) if x is not None]
    change = data.speed_change()
    if change is not None:
        chans.append(change)
    return order, starts, stops, chans


def _training_sums(G, g, fold, direction) -> dict:
    """``{(fold, direction): (sum of G, sum of g)}`` over every fold's training segments of that
    direction (the held-out segments of the fold and direction exist): what :func:`_held_out_z`
    fits on, summed once for all the lines and rounds of the screen.  numpy sums over the segments
    (axis 0) entry by entry in segment order when two columns or more are kept (a line is two), so
    the kept columns of these sums equal the sums of those columns bit for bit (one column alone
    would be summed pairwise)."""
    out = {}
    for f in np.unique(fold):
        test = fold == f
        for d in (1, -1):
            tr, te = ~test & (direction == d), test & (direction == d)
            if te.any() and tr.any():
                out[(f, d)] = (G[tr].sum(0), g[tr].sum(0))
    return out


def _held_out_z(G, g, cols0, cols1, fold, direction, group, sums=None) -> float:
    """Held-out Z (one cluster per held-out group, :func:`~gearspec.core.crossval.z_statistic` with
    one block) of the lines' columns ``cols1`` against ``cols0`` (a subset), one coefficient set per
    direction fitted on the training folds; from the segments' normal equations ``G`` (S, K, K),
    ``g`` (S, K) of those columns alone: with ``d`` the change of a segment's coefficients, its
    ``<r0, delta> = g.d - b0' G d`` and ``|delta|^2 = d' G d`` (cost segments x columns used^2).
    ``group``: the held-out group (0..n-1) of every segment; ``sums``: :func:`_training_sums` of
    ``G`` and ``g`` (computed here when not given)."""
    cols = list(cols1)
    pos0 = [cols.index(c) for c in cols0]
    Gc, gc = G[:, cols][:, :, cols], g[:, cols]
    S, k = gc.shape
    beta0, beta1 = np.zeros((S, k)), np.zeros((S, k))
    sums = _training_sums(G, g, fold, direction) if sums is None else sums
    for f in np.unique(fold):
        test = fold == f
        for d in (1, -1):
            te = test & (direction == d)
            if (f, d) not in sums:
                continue
            Gt, gt = sums[(f, d)][0][np.ix_(cols, cols)], sums[(f, d)][1][cols]
            beta1[te] = np.linalg.lstsq(Gt, gt, rcond=1e-10)[0]
            if pos0:
                beta0[np.ix_(te, pos0)] = np.linalg.lstsq(Gt[np.ix_(pos0, pos0)], gt[pos0], rcond=1e-10)[0]
    dl = beta1 - beta0
    Gd = np.einsum("skl,sl->sk", Gc, dl)
    a = np.einsum("sk,sk->s", gc, dl) - np.einsum("sk,sk->s", beta0, Gd)     # <r0, delta> per segment
    c = np.einsum("sk,sk->s", dl, Gd)                                           # |delta|^2 per segment
    n_groups = int(group.max()) + 1 if len(group) else 0
    num = np.bincount(group, weights=a, minlength=n_groups)
    e = num - np.bincount(group, weights=c, minlength=n_groups)                # <r0 - delta, delta> per group
    var = float(np.sum(e * e))
    total = float(np.sum(num))
    if var > 0:
        return total / math.sqrt(var)
    return math.copysign(math.inf, total) if total != 0 else 0.0


def screen_lines(data: FitData, freqs, fold_of_segment: np.ndarray, group_of_segment: np.ndarray, *,
                 alpha: float, inertia="auto", min_cycles: float = 1.0, max_lines: int | None = None,
                 progress=None) -> list[dict]:
    """The held-out test of every line (module docstring): ``[{"z", "z_crit", "passed", "round", "cycles"}]``
    (``cycles``: the most cycles of the line in a segment),
    one per frequency.  First each line alone; then the lines that pass alone, in rounds: the one
    with the largest Z that passes enters, the others are tested again beside the lines in (a weak
    line next to a strong one is judged by what it adds to it, not by the strong one's leakage into
    its columns over a short segment).  Bonferroni over the lines still in play.  ``inside``: the
    line entered in a round.  ``max_lines``: the rounds stop once that many lines are in (a law holds
    no more; the lines still out keep the verdict of the last round, beside the lines in).
    ``progress``: called with a line of text after the lines alone are tested and after every round.
    ``fold_of_segment``, ``group_of_segment``: fold and held-out group of every segment, in the
    order of the sorted segment ids."""
    freqs = np.asarray(freqs, dtype=float)
    F = len(freqs)
    if F == 0:
        return []
    direction = _segment_direction(data)
    ug, group = np.unique(group_of_segment, return_inverse=True)
    n_groups = len(ug)
    _, G1, g1, cyc = line_statistics(data, freqs, inertia=inertia, min_cycles=min_cycles)
    zc = critical_z(alpha, F, n_groups)
    out = []
    for i in range(F):
        z = _held_out_z(G1[:, i], g1[:, i], [], [0, 1], fold_of_segment, direction, group)
        out.append({"z": float(z), "z_crit": zc, "passed": bool(z >= zc), "round": 0, "inside": False,
                    "cycles": float(cyc[:, i].max()) if len(cyc) else 0.0})
    alive = [i for i in range(F) if out[i]["passed"]]
    if progress is not None:
        progress(f"line screen: {F} lines tested alone, {len(alive)} pass" + (
            "; testing them beside each other" if len(alive) > 1 else ""))
    if len(alive) < 2:
        return out
    G, g = joint_statistics(data, freqs[alive], inertia=inertia, min_cycles=min_cycles)
    sums = _training_sums(G, g, fold_of_segment, direction)      # once for every line and round
    inside: list[int] = []
    rest = list(range(len(alive)))
    rnd = 0
    while rest and (max_lines is None or len(inside) < max_lines):
        rnd += 1
        zc = critical_z(alpha, F - len(inside), n_groups)
        cols0 = [c for j in inside for c in (2 * j, 2 * j + 1)]
        zs = {j: _held_out_z(G, g, cols0, cols0 + [2 * j, 2 * j + 1], fold_of_segment, direction, group, sums)
              for j in rest}
        for j, z in zs.items():
            out[alive[j]].update(z=float(z), z_crit=zc, passed=bool(z >= zc), round=rnd)
        best = max(rest, key=lambda j: zs[j])
        if not zs[best] >= zc:
            break
        inside.append(best)
        rest.remove(best)
        out[alive[best]]["inside"] = True
        if progress is not None:
            progress(f"line screen round {rnd}: {freqs[alive[best]]:.6g} cycles/{data.unit} enters "
                     f"(held-out Z {zs[best]:.1f} beside the lines in)")
    return out


def _segment_direction(data: FitData) -> np.ndarray:
    """Direction (+1 / -1) of every segment, sorted segment ids (the sign of its summed directions)."""
    ids, inv = np.unique(data.segment, return_inverse=True)
    d = np.sign(np.bincount(inv, weights=data.direction, minlength=len(ids)))
    return np.where(d == 0, 1, d).astype(int)
