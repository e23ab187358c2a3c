"""Constant-speed plateaus: block speeds, the steady-block test and the window per piece
(:mod:`gearspec.segment`)."""

from __future__ import annotations

import math
import os
from collections import Counter

import numpy as np

from ..errors import InputError
from ..recording import Recording
from .quasistatic import _quasi_static_segments
from .ramps import _K, _merge_fragments, _split_drift, _split_smooth, _trim_speed, _trim_to_line
from .segmentation import Segment, Segmentation

__all__ = ["find_segments", "PARALLEL_MIN_SAMPLES"]

_WINDOW_LADDER = (0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0)
_COVER_FRACTION = 0.8
#: pieces at least this long try the windows of the "auto" ladder in two threads (by default)
PARALLEL_MIN_SAMPLES = 1_000_000


def find_segments(rec: Recording, *, window: float | str = "auto", rel_tol: float = 0.15,
                  min_speed: float | None = None, min_duration: float | None = None,
                  min_samples: int = 32, workers: int | str = "auto",
                  quasi_static: bool | None = None) -> Segmentation:
    """Find constant-speed segments per direction, and quasi-static sweeps (:mod:`gearspec.segment`).

    ``window``: speed-averaging window in s (four blocks), or "auto" per piece.  ``rel_tol``:
    allowed relative change of the window speed across a block, and half the allowed drift within
    a segment.  ``min_speed`` (unit/s): standstill below (default ten times the speed noise the
    position noise gives over one window).  ``min_duration`` (s, default two windows and at least
    0.1 s) and ``min_samples``: shortest segment kept.  ``workers``: windows of the "auto" ladder
    tried at once, in threads, with the same result ("auto": two with two CPUs or more for pieces
    of at least ``PARALLEL_MIN_SAMPLES`` samples).  ``quasi_static``: None recognises quasi-static
    sweeps (:func:`quasi_static_sweeps`) and looks for plateaus in the rest; True makes every
    monotonic sweep one; False: plateaus only.  Returns a :class:`Segmentation`.
    """
    if not 0 < rel_tol < 1:
        raise InputError(f"rel_tol must be between 0 and 1, got {rel_tol}")
    if window != "auto":
        window = float(window)
        if not window > 0:
            raise InputError(f"the segment window must be a positive time in s, got {window}")
    if workers != "auto" and (not isinstance(workers, (int, np.integer)) or workers < 1):
        raise InputError(f"workers must be a positive integer or 'auto', got {workers!r}")
    if quasi_static not in (None, True, False):
        raise InputError(f"quasi_static must be None (recognise), True or False, got {quasi_static!r}")
    t, theta = rec.t, rec.theta
    chosen = {}
    segments, excluded, taken = ([], Counter(), []) if quasi_static is False else \
        _quasi_static_segments(rec, force=bool(quasi_static), min_samples=min_samples)
    n_quasi_static = len(segments)
    pieces = list(_outside(rec.pieces(), taken))

    def piece(p):
        return _piece_plateaus(t, theta, *p, window, rel_tol, min_speed, min_duration, min_samples, workers)

    for (run, a, b), found in zip(pieces, _map_pieces(piece, pieces, workers)):
        if found is None:  # piece too short for any window
            excluded["transient"] += b - a
            continue
        w, segs, labels = found
        chosen[(run, a)] = w
        for s, e, direction, speed, ripple in segs:
            segments.append(Segment(int(run), int(a + s), int(a + e), int(direction), float(speed), ripple, float(w)))
        for reason, count in labels.items():
            excluded[reason] += count
    segments.sort(key=lambda x: x.start)
    settings = {"window": window, "rel_tol": rel_tol, "min_speed": min_speed, "min_duration": min_duration,
                "windows_chosen": sorted(set(chosen.values())),
                "quasi_static": "auto" if quasi_static is None else bool(quasi_static),
                "quasi_static_segments": n_quasi_static}
    seg = Segmentation(segments, excluded, len(rec), settings)
    seg.check_ledger()
    return seg


def _piece_plateaus(t, theta, run, a, b, window, rel_tol, min_speed, min_duration, min_samples, workers):
    """The plateaus of one piece ``(run, a, b)``: ``(window chosen, segments, excluded rows by
    reason)`` (rows counted from ``a``), or None when the piece is too short for any window."""
    ladder = [window] if window != "auto" else list(_WINDOW_LADDER)
    noise = _position_noise(theta[a:b]) if b - a >= 3 else None
    dt = float(np.median(np.diff(t[a:min(b, a + 100_000)]))) if b - a >= 2 else None  # once per piece

    def one(w):
        return _segment_piece(t[a:b], theta[a:b], w, rel_tol, min_speed, min_duration, min_samples, noise, dt)

    n_workers = ((2 if (os.cpu_count() or 1) >= 2 and b - a >= PARALLEL_MIN_SAMPLES else 1)
                 if workers == "auto" else int(workers))
    if n_workers > 1 and len(ladder) > 1:
        from concurrent.futures import ThreadPoolExecutor

        # the shortest windows (most blocks) are the most work: they go first
        with ThreadPoolExecutor(max_workers=min(n_workers, len(ladder)),
                                thread_name_prefix="gearspec-window") as pool:
            results = list(pool.map(one, ladder))
    else:
        results = _ladder(one, ladder, b - a)
    tried = [(_cover(res), w, res) for w, res in zip(ladder, results) if res is not None]
    if not tried:
        return None
    # the shortest window that finds nearly as much plateau as any: long windows would
    # also swallow short transients at the edges of plateaus
    top = max(c for c, _, _ in tried)
    _, w, (segs, labels) = next(x for x in tried if x[0] >= _COVER_FRACTION * top)
    return w, segs, labels


#: ``workers="auto"``: pieces are segmented in forked worker processes when there are at least this
#: many (a recording of many runs or gaps) holding at least ``FORK_MIN_ROWS`` rows between them
FORK_MIN_PIECES = 8
FORK_MIN_ROWS = 200_000
#: pieces per task of a forked map: a few tasks per worker (one result pickled per task)
_TASKS_PER_WORKER = 4


def _map_pieces(piece, pieces: list, workers) -> list:
    """``[piece(p) for p in pieces]``; with ``workers="auto"`` and many pieces
    (:data:`FORK_MIN_PIECES`, :data:`FORK_MIN_ROWS`) in contiguous chunks by
    :func:`~gearspec.core.parallel.forked_map` (the same results: each piece is segmented alone)."""
    from ..core.parallel import forked_map_chunked, worker_count

    rows = sum(b - a for _, a, b in pieces)
    n = worker_count() if workers == "auto" and len(pieces) >= FORK_MIN_PIECES and rows >= FORK_MIN_ROWS else 1
    return forked_map_chunked(piece, pieces, workers=n, tasks_per_worker=_TASKS_PER_WORKER)


def _cover(res) -> int:
    """Rows in the segments of one window's result."""
    return sum(e - s for s, e, *_ in res[0])


def _ladder(one, ladder, n: int) -> list:
    """``one(w)`` for the windows of ``ladder`` in order, stopped once the choice of
    :func:`find_segments` is settled whatever the windows not tried would give: the first window
    covering at least ``_COVER_FRACTION`` of the most covered so far (``top``) covers that fraction
    of ``n`` (the piece's rows, more than any window can cover) too.  It stays the first to pass
    however far a later window raised ``top`` (at most to ``n``), and no earlier window can pass
    (``top`` only grows).  The same choice as trying every window; on a plateau experiment most
    pieces stop after the second window of the ladder."""
    results = []
    top = 0
    for w in ladder:
        res = one(w)
        results.append(res)
        if res is not None:
            top = max(top, _cover(res))
        if top > 0:
            first = next(c for c in (_cover(r) for r in results if r is not None) if c >= _COVER_FRACTION * top)
            if first >= _COVER_FRACTION * max(top, n):
                break
    return results


def _outside(pieces, taken):
    """The pieces ``(run, a, b)`` with the row ranges ``taken`` cut out."""
    if not taken:
        yield from pieces
        return
    for run, a, b in pieces:
        pos = a
        for s, e in taken:
            if e <= pos or s >= b:
                continue
            if s > pos:
                yield run, pos, s
            pos = max(pos, e)
        if pos < b:
            yield run, pos, b


def _block_slopes(tb: np.ndarray, thb: np.ndarray, k: int) -> np.ndarray:
    """Least-squares slope of thb against tb over every window of k consecutive blocks (k shifted
    slices: numpy reduces the short rows of a sliding-window view slowly)."""
    m = len(tb) - k + 1
    if m <= 0:
        return np.empty(0)
    mt = tb[:m].copy()
    my = thb[:m].copy()
    for j in range(1, k):
        mt += tb[j:j + m]
        my += thb[j:j + m]
    mt /= k
    my /= k
    num = np.zeros(m)
    den = np.zeros(m)
    tc = np.empty(m)
    yc = np.empty(m)
    for j in range(k):
        np.subtract(tb[j:j + m], mt, out=tc)
        np.subtract(thb[j:j + m], my, out=yc)
        yc *= tc
        num += yc
        tc *= tc
        den += tc
    num /= den
    return num


def _block_means(x: np.ndarray, m: int, b: int) -> np.ndarray:
    """Means of m consecutive blocks of b samples (einsum: several times faster than
    ``reshape(m, b).mean(axis=1)`` for short blocks)."""
    out = np.einsum("ij->i", x[: m * b].reshape(m, b))
    out /= b
    return out


def _position_noise(theta: np.ndarray, chunks: int = 20, size: int = 5000) -> float:
    """Noise of a position signal: robust sd of second differences / sqrt(6), floored by the
    encoder quantum / sqrt(12); from up to ``chunks`` contiguous stretches of ``size`` samples."""
    n = len(theta)
    if n <= chunks * size:
        parts = [theta]
    else:
        starts = np.linspace(0, n - size, chunks).astype(int)
        parts = [theta[s:s + size] for s in starts]
    d2 = np.concatenate([np.diff(p, 2) for p in parts])
    d1 = np.abs(np.concatenate([np.diff(p) for p in parts]))
    sigma = 1.4826 * np.median(np.abs(d2 - np.median(d2))) / math.sqrt(6) if len(d2) else 0.0
    q = d1[d1 > 0].min() if np.any(d1 > 0) else 0.0
    return max(float(sigma), q / math.sqrt(12))


def _segment_piece(t, theta, window, rel_tol, min_speed, min_duration, min_samples, noise, dt):
    """The plateaus of one piece for one window, ``(segments, excluded rows by reason)``, or None when
    the piece is too short for the window; ``noise``: its position noise, ``dt``: its median step."""
    n = len(t)
    if n < 2 or dt <= 0:
        return None
    b = int(round(window / _K / dt))
    if b < 2 or n < b * (2 * _K + 1):
        return None
    m = n // b
    used = m * b
    tb = _block_means(t, m, b)
    thb = _block_means(theta, m, b)
    # slope over K blocks: v_win[i] covers blocks i .. i+K-1
    v_win = _block_slopes(tb - tb[0], thb - thb[0], _K)
    # per block j: the window ending at j ("before") and the window starting at j ("after"); near
    # the ends of a piece, where one of them does not exist, the first (last) two non-overlapping
    # windows stand in, so a piece that ends on a plateau keeps it and one that starts with a
    # ramp does not
    before, after = _before_after(v_win, m)
    across = 0.5 * (before + after)
    # speed noise of a window from position noise (second differences), for the default min_speed
    if min_speed is None:
        nw = _K * b
        v_noise = noise * math.sqrt(12.0 / (nw * (nw * nw - 1))) / dt
        v_floor = 10 * v_noise
    else:
        v_floor = float(min_speed)
    moving = np.abs(across) > v_floor
    same_sign = moving & (np.sign(before) == np.sign(across)) & (np.sign(after) == np.sign(across))
    steady = same_sign & (np.abs(after - before) <= rel_tol * np.abs(across))
    min_dur = max(2 * window, 0.1) if min_duration is None else float(min_duration)
    # runs of steady blocks, split where the speed drifts, then fragments of one plateau (broken
    # by a ripple excursion shorter than a window) merged again
    edges = np.diff(np.concatenate(([0], steady.astype(np.int8), [0])))
    # runs shorter than a window are too short to know their speed: treated as part of a hole
    runs_ = [(s, e) for s, e in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)) if e - s >= _K]
    runs_ = _merge_fragments(runs_, t, theta, b, rel_tol)
    runs_ = [r for s, e in runs_ for r in _split_drift(across, s, e, rel_tol)]
    runs_ = [_trim_speed(across, s, e, rel_tol) for s, e in runs_]
    # block-to-block speeds (the finest the blocks resolve): a ramp is smooth at this scale, ripple is not
    tmid = 0.5 * (tb[1:] + tb[:-1])
    vblock = np.diff(thb) / np.maximum(np.diff(tb), 1e-300)
    vnoise2 = 2.0 * noise * noise / b / (b * dt) ** 2  # variance of a block speed from position noise
    runs_ = [r for s, e in runs_ for r in _split_smooth(tmid, vblock, s, e, rel_tol, vnoise2)]
    segs = []
    short_blocks = []
    for s2, e2 in runs_:
        rows_s, rows_e = _trim_to_line(t, theta, s2 * b, e2 * b, b, noise)
        s2, e2 = rows_s // b, -(-rows_e // b)
        dur = t[rows_e - 1] - t[rows_s]
        if dur < min_dur or rows_e - rows_s < min_samples:
            short_blocks.append((s2, e2))
            continue
        speed = abs(theta[rows_e - 1] - theta[rows_s]) / dur
        direction = int(np.sign(theta[rows_e - 1] - theta[rows_s]))
        vs = across[s2:e2]
        ripple = float(np.std(vs) / abs(np.mean(vs))) if len(vs) > 1 else 0.0
        segs.append((rows_s, rows_e, direction, float(speed), ripple))
    in_seg = np.zeros(m, bool)
    for rs, re_, *_ in segs:
        in_seg[rs // b: re_ // b] = True
    short = np.zeros(m, bool)
    for s2, e2 in short_blocks:
        short[s2:e2] = True
    standstill = ~moving & ~in_seg & ~short
    labels = {"short_plateau": int(short.sum()) * b, "standstill": int(standstill.sum()) * b,
              "transient": int((~in_seg & ~short & ~standstill).sum()) * b + (n - used)}
    return segs, Counter({k: v for k, v in labels.items() if v})


def _before_after(v_win: np.ndarray, m: int):
    """For every block j of m: the window speed ending at j (``before``, window j-K+1) and the one
    starting at j (``after``, window j), with the piece's first (last) two non-overlapping windows
    standing in near its ends.  Slices in the interior, index arithmetic only at the ends."""
    K = _K
    top = m - K  # the last window

    def idx(j):  # the rule for a few blocks j, as index arrays
        j = np.asarray(j)
        left = j - K + 1
        right = j.copy()
        at_start = left < 0
        left[at_start] = 0
        right[at_start] = np.maximum(right[at_start], K)
        at_end = right > top
        right[at_end] = top
        left[at_end] = np.minimum(left[at_end], m - 2 * K)
        return np.clip(left, 0, top), np.clip(right, 0, top)

    before = np.empty(m)
    after = np.empty(m)
    # interior: K-1 <= j <= top, where left = j-K+1 and right = j
    a, b = K - 1, top + 1
    if b > a:
        before[a:b] = v_win[0:b - K + 1]
        after[a:b] = v_win[a:b]
    ends = np.concatenate([np.arange(0, min(a, m)), np.arange(max(b, a, 0), m)])
    if len(ends):
        li, ri = idx(ends)
        before[ends] = v_win[li]
        after[ends] = v_win[ri]
    return before, after
