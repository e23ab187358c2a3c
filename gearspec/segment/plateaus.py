"""Constant-speed segments, direction split, derivatives and inertia removal.

Segments are found from position alone (no commanded speed is needed):

1. The recording is cut into *pieces* at run boundaries and time gaps; nothing spans a cut.
2. Each piece is averaged over short blocks of ``b`` samples (block-mean time and position).
3. Over a window of ``K = 4`` blocks (``window`` seconds) the speed is the least-squares slope of
   position against time, before, across and after every block.  A block is *steady* when the
   speed before it and after it agree within ``rel_tol`` of the speed across it, all three have
   the same sign, and the speed is above ``min_speed``.  Averaging over a window makes the test
   blind to closed-loop ripple that is faster than the window; ramps between plateaus fail it.
4. Runs of steady blocks become candidate segments.  Two candidates separated by an excursion of
   at most two windows, moving at the same speed (within ``rel_tol``), are joined: the drive left
   the plateau briefly and came back.  A candidate whose speed drifts by more than
   ``2 * rel_tol`` (a slow ramp) is split where its speed changes most (CUSUM), recursively, and
   edge blocks whose window speed is more than ``rel_tol`` off the candidate's median speed (the
   end of a gentle ramp) are dropped.
5. The ends of each candidate are trimmed where position leaves the band around the straight line
   fitted to the candidate's middle 60 % (the band is 1.5 times the largest deviation there): this
   removes a transient that a long window could not see, and nothing from a clean plateau.
   Candidates shorter than ``min_duration`` (default two windows, at least 0.1 s) are dropped.
   A candidate whose block-to-block speed follows a smooth curve (a cubic in time that stands
   out of the position noise and explains more than the ripple beside it) spanning more than a
   third of ``rel_tol`` is a ramp, a bell's top or a creeping tail: it is split, and only parts
   shown flat are kept (:func:`_split_smooth`).
6. With ``window="auto"`` steps 2-5 are repeated for windows of 0.02 ... 2 s and each piece keeps
   the shortest window whose segments cover at least 80 % of the most any window covers.
   Slow, stick-slipping plateaus thereby get long windows, brisk bang-bang profiles short ones
   (a long window would hide a short transient at the start of a plateau).

Quasi-static sweeps come first (:func:`quasi_static_sweeps`): per run, over position (time gaps do
not cut them), a monotonic sweep whose rows were stored at rest after each step of a position loop
becomes one segment of kind ``"quasi_static"`` (recognised, or every sweep with
``quasi_static=True``); the plateau search runs on the rows outside them.

Every row of the recording ends in exactly one segment or is counted under one reason:
``standstill`` (speed below ``min_speed``; a forced sweep without travel), ``transient`` (ramps,
reversals, unsteady speed and the edges of pieces), ``short_plateau`` (steady, but shorter than
``min_duration``), ``short_sweep`` (a forced quasi-static sweep of fewer than ``min_samples`` rows).

Derivatives for inertia removal use a Savitzky-Golay filter (``scipy.signal.savgol_filter``,
polynomial order 2, ``deriv_window`` samples, default about 20 ms and at least 7 samples) on each
piece, on a uniform time grid (resampled linearly when the sampling jitters by more than 1 %).
A piece too short for the filter (in samples, or in points of that grid) gets no derivative (NaN),
never an error.  Quasi-static segments use no derivative at all.
"""

from __future__ import annotations

import math
import os
from collections import Counter
from dataclasses import dataclass, field

import numpy as np
from scipy.signal import savgol_filter

from ..errors import InputError
from ..recording import Recording

__all__ = ["Segment", "Segmentation", "find_segments", "quasi_static_sweeps", "derivatives", "friction_torque",
           "FrictionTorque"]

_K = 4  # blocks per speed window
_WINDOW_LADDER = (0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0)
_COVER_FRACTION = 0.8
#: pieces at least this long try the windows of the "auto" ladder in two threads (by default)
PARALLEL_MIN_SAMPLES = 1_000_000


@dataclass(frozen=True)
class Segment:
    """A constant-speed stretch of one run, in one direction, or a quasi-static sweep.

    ``start``/``stop`` index rows of ``Recording.data`` (stop exclusive).  ``speed`` is the mean
    speed (travel over duration, always >= 0, unit/s); ``direction`` is +1 or -1.  ``kind`` is
    ``"plateau"`` (constant speed) or ``"quasi_static"`` (a monotonic sweep whose rows were taken
    at rest: there ``speed`` is nominal, travel over the sweep's duration, and nothing depends on
    it; no time derivative is used).
    """

    run: int
    start: int
    stop: int
    direction: int
    speed: float
    speed_ripple: float = 0.0  # relative std of the window speed inside the segment
    window: float = 0.0        # the speed window (s) used to find it
    kind: str = "plateau"      # "plateau" (constant speed) or "quasi_static" (a sweep at rest)

    @property
    def n(self) -> int:
        return self.stop - self.start

    @property
    def rows(self) -> slice:
        return slice(self.start, self.stop)

    @property
    def velocity(self) -> float:
        """Signed mean velocity (unit/s)."""
        return self.direction * self.speed

    def to_dict(self) -> dict:
        return {"run": self.run, "start": self.start, "stop": self.stop, "direction": self.direction,
                "speed": self.speed, "n": self.n, "speed_ripple": self.speed_ripple, "window": self.window,
                "kind": self.kind}

    @property
    def quasi_static(self) -> bool:
        return self.kind == "quasi_static"


@dataclass
class Segmentation:
    """The segments of a recording and the ledger of rows outside them."""

    segments: list[Segment]
    excluded: Counter
    n_rows: int
    settings: dict = field(default_factory=dict)

    def __iter__(self):
        return iter(self.segments)

    def __len__(self) -> int:
        return len(self.segments)

    def check_ledger(self) -> None:
        """Assert that every row is in one segment or counted once (an internal invariant)."""
        covered = sum(s.n for s in self.segments) + sum(self.excluded.values())
        if covered != self.n_rows:
            raise AssertionError(f"row ledger broken: {covered} accounted for, {self.n_rows} rows")


# ---------------------------------------------------------------------- segmentation
def find_segments(rec: Recording, *, window: float | str = "auto", rel_tol: float = 0.15,
                  min_speed: float | None = None, min_duration: float | None = None,
                  min_samples: int = 32, workers: int | str = "auto",
                  quasi_static: bool | None = None) -> Segmentation:
    """Find constant-speed segments per direction, and quasi-static sweeps (see the module docstring).

    Parameters
    ----------
    rec : Recording
    window : float or "auto"
        Speed-averaging window in seconds (four blocks); "auto" picks it per piece.
    rel_tol : float
        Allowed relative change of the window speed across a block, and half the allowed drift
        of speed within a segment.
    min_speed : float, optional
        Speeds below this (unit/s) count as standstill.  Default: ten times the speed noise that
        the position noise of the piece produces over one window.
    min_duration : float, optional
        Shortest segment kept, seconds.  Default: two windows, and at least 0.1 s.
    min_samples : int
        Shortest segment kept, samples.
    workers : int or "auto"
        Windows of the ``"auto"`` ladder tried at once, in threads (numpy releases the GIL for
        the bulk of the work; the result is the same whatever the number).  ``"auto"``: two on a
        machine with two or more CPUs for pieces of at least ``PARALLEL_MIN_SAMPLES`` samples.
    quasi_static : bool or None
        ``None`` (default): recognise quasi-static sweeps (rows stored at rest, position rather
        than time setting the motion; see :func:`quasi_static_sweeps`) and look for plateaus in
        the rest.  ``True`` (``--quasi-static``): every monotonic sweep of each run is a
        quasi-static segment.  ``False``: plateaus only.

    Returns
    -------
    Segmentation
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
    segments: list[Segment] = []
    excluded: Counter = Counter()
    chosen = {}
    qs_segments, qs_excluded, taken = ([], Counter(), []) if quasi_static is False else \
        _quasi_static_segments(rec, force=bool(quasi_static), min_samples=min_samples)
    segments += qs_segments
    excluded += qs_excluded
    for run, a, b in _outside(rec.pieces(), taken):
        ladder = [window] if window != "auto" else list(_WINDOW_LADDER)
        noise = _position_noise(theta[a:b]) if b - a >= 3 else None
        dt = float(np.median(np.diff(t[a:min(b, a + 100_000)]))) if b - a >= 2 else None  # once per piece

        def one(w, a=a, b=b, noise=noise, dt=dt):
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
            results = [one(w) for w in ladder]
        tried = [(sum(e - s for s, e, *_ in res[0]), w, res) for w, res in zip(ladder, results) if res is not None]
        if not tried:  # piece too short for any window
            excluded["transient"] += b - a
            continue
        # the shortest window that finds nearly as much plateau as any: long windows would
        # also swallow short transients at the edges of plateaus
        top = max(c for c, _, _ in tried)
        _, w, (segs, labels) = next(x for x in tried if x[0] >= _COVER_FRACTION * top)
        chosen[(run, a)] = w
        for s, e, direction, speed, ripple in segs:
            segments.append(Segment(int(run), int(a + s), int(a + e), int(direction), float(speed), ripple, float(w)))
        for reason, count in labels.items():
            excluded[reason] += count
    segments.sort(key=lambda x: x.start)
    seg = Segmentation(segments, excluded, len(rec), {"window": window, "rel_tol": rel_tol,
                                                      "min_speed": min_speed, "min_duration": min_duration,
                                                      "windows_chosen": sorted(set(chosen.values())),
                                                      "quasi_static": ("auto" if quasi_static is None
                                                                       else bool(quasi_static)),
                                                      "quasi_static_segments": len(qs_segments)})
    seg.check_ledger()
    return seg

# ---------------------------------------------------------------------- quasi-static sweeps
#: a sweep is recognised as quasi-static when it has at least this many steps (moves between rows):
#: enough distinct positions for the joint fit of a level and a few lines with dozens of degrees
#: of freedom left, and for the spread statistics below to mean something
QS_MIN_STEPS = 50
#: ... when the speed between rows (step / time step) varies over at least a factor of 2 (10-90 %
#: range) ...
QS_MIN_SPEED_SPREAD = math.log(2.0)
#: ... at least this many times more than the steps themselves do (in log, 10-90 % range): rows
#: stored when the shaft came to rest after a step of the position loop have a steady step and
#: an irregular time step, continuous motion sampled by a clock has steps that follow the time
#: steps (or a regular clock)
QS_SPREAD_RATIO = 2.0
#: ... and at most this fraction of its rows repeats the previous position
QS_MAX_REPEATS = 0.5
#: a reversal is a return of more than this many median steps (smaller returns are jitter)
QS_REVERSAL_STEPS = 3.0


def _spread(x: np.ndarray) -> float:
    """10-90 % range of log(x) (x > 0)."""
    if len(x) < 2:
        return 0.0
    lo, hi = np.percentile(x, [10, 90])
    return float(math.log(hi / lo)) if lo > 0 else float("inf")


def _at_rest_statistics(t: np.ndarray, theta: np.ndarray) -> dict:
    """Steps, repeats and the spread of steps and of row-to-row speeds of a stretch of rows."""
    dth = np.abs(np.diff(theta))
    dt = np.diff(t)
    move = dth > 0
    steps, speeds = dth[move], dth[move] / np.maximum(dt[move], 1e-300)
    return {"steps": int(move.sum()), "repeats": float(1 - move.mean()) if len(move) else 1.0,
            "step_spread": _spread(steps), "speed_spread": _spread(speeds)}


def _run_statistics(t: np.ndarray, theta: np.ndarray, chunks: int = 20, size: int = 10_000) -> dict:
    """:func:`_at_rest_statistics` of a whole run, from up to ``chunks`` contiguous stretches of
    ``size`` rows (row-to-row statistics: a stride would sum steps and average time steps)."""
    n = len(t)
    if n <= chunks * size:
        return _at_rest_statistics(t, theta)
    starts = np.linspace(0, n - size, chunks).astype(int)
    dth = np.concatenate([np.diff(theta[s:s + size]) for s in starts])
    dt = np.concatenate([np.diff(t[s:s + size]) for s in starts])
    return _at_rest_statistics(np.concatenate(([0.0], np.cumsum(dt))), np.concatenate(([0.0], np.cumsum(dth))))


def _looks_at_rest(st: dict) -> bool:
    """The recognition rule (see the constants above)."""
    return (st["steps"] >= QS_MIN_STEPS and st["repeats"] <= QS_MAX_REPEATS
            and st["speed_spread"] >= QS_MIN_SPEED_SPREAD
            and st["speed_spread"] >= QS_SPREAD_RATIO * st["step_spread"])


def _sweeps(theta: np.ndarray, tol: float) -> list[tuple[int, int, int]]:
    """Monotonic sweeps ``(start, stop, direction)`` of one run, split at reversals of more than
    ``tol`` (hysteresis: smaller returns are jitter and stay in the sweep).  The row at a turning
    point ends the sweep before it; every row is in one sweep; direction 0: no travel of ``tol``."""
    n = len(theta)
    if n == 0:
        return []
    th = theta.tolist()
    turns = []
    d = 0
    hi = lo = 0
    first = 0
    for i in range(1, n):
        x = th[i]
        if d == 0:
            if x > th[hi]:
                hi = i
            if x < th[lo]:
                lo = i
            if th[hi] - th[lo] >= tol:
                d = 1 if hi > lo else -1
                first = d
        elif d > 0:
            if x > th[hi]:
                hi = i
            elif th[hi] - x >= tol:
                turns.append(hi)
                d, lo = -1, i
        else:
            if x < th[lo]:
                lo = i
            elif x - th[lo] >= tol:
                turns.append(lo)
                d, hi = 1, i
    bounds = [0] + [k + 1 for k in turns] + [n]
    out = []
    direction = first
    for a, b in zip(bounds[:-1], bounds[1:]):
        if b > a:
            out.append((a, b, direction))
        direction = -direction
    return out


def quasi_static_sweeps(rec: Recording, *, force: bool = False) -> list[dict]:
    """The monotonic sweeps of each run, with the statistics of the recognition rule.

    Works over position, per run: time gaps do not split a sweep (at rest, time is irrelevant).
    A sweep ends at a reversal of more than ``QS_REVERSAL_STEPS`` median steps.  It is
    *quasi-static* (``"at_rest"``) when it has at least ``QS_MIN_STEPS`` steps, at most
    ``QS_MAX_REPEATS`` of its rows repeat a position, and the speed between rows varies over a
    factor of two or more and ``QS_SPREAD_RATIO`` times more than the steps do (log 10-90 %
    ranges): rows stored by position (at rest after each step of a position loop), not by a
    clock.  On a plateau the speed between rows is steady (or, on a regular clock, varies exactly
    as the steps do: stick-slip, encoder noise), so no plateau recording passes.  Without
    ``force`` a run whose rows as a whole do not pass is not searched (the cheap common case).

    Returns
    -------
    list of dict
        ``run, start, stop, direction`` (rows of the recording, stop exclusive) and ``at_rest``,
        plus the statistics.
    """
    t, theta, run = rec.t, rec.theta, rec.run
    out = []
    if len(t) == 0:
        return out
    cuts = np.flatnonzero(np.diff(run) != 0) + 1
    bounds = np.concatenate(([0], cuts, [len(run)]))
    for a, b in zip(bounds[:-1], bounds[1:]):
        a, b = int(a), int(b)
        if b - a < 2:
            continue
        if not force and not _looks_at_rest(_run_statistics(t[a:b], theta[a:b])):
            continue
        d = np.abs(np.diff(theta[a:b]))
        nz = d[d > 0]
        if not len(nz):
            continue
        tol = QS_REVERSAL_STEPS * float(np.median(nz))
        for s, e, direction in _sweeps(theta[a:b], tol):
            st = _at_rest_statistics(t[a + s:a + e], theta[a + s:a + e])
            out.append({"run": int(run[a]), "start": a + s, "stop": a + e, "direction": int(direction),
                        "at_rest": bool(direction != 0 and _looks_at_rest(st)), **st})
    return out


def _quasi_static_segments(rec: Recording, *, force: bool, min_samples: int):
    """Quasi-static segments (recognised, or every sweep when ``force``), their ledger, and the
    row ranges they take."""
    segments, excluded, taken = [], Counter(), []
    t, theta = rec.t, rec.theta
    for sw in quasi_static_sweeps(rec, force=force):
        a, b, d = sw["start"], sw["stop"], sw["direction"]
        if not (sw["at_rest"] or force):
            continue
        taken.append((a, b))
        if d == 0:
            excluded["standstill"] += b - a
            continue
        if b - a < min_samples:
            excluded["short_sweep"] += b - a
            continue
        dur = float(t[b - 1] - t[a])
        speed = abs(float(theta[b - 1] - theta[a])) / dur if dur > 0 else float("nan")
        segments.append(Segment(sw["run"], a, b, d, speed, 0.0, 0.0, "quasi_static"))
    return segments, excluded, sorted(taken)


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
    """Least-squares slope of thb against tb over every window of k consecutive blocks.

    Written as k shifted slices (in-place operations on arrays of the number of windows) rather
    than reductions over a sliding-window view, whose rows of k elements numpy reduces slowly."""
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


def _segment_piece(t, theta, window, rel_tol, min_speed, min_duration, min_samples, noise=None, dt=None):
    n = len(t)
    if n < 2:
        return None
    if dt is None:
        dt = float(np.median(np.diff(t[: min(n, 100_000)])))
    if dt <= 0:
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
    sigma = noise if noise is not None else _position_noise(theta)
    if min_speed is None:
        nw = _K * b
        v_noise = sigma * math.sqrt(12.0 / (nw * (nw * nw - 1))) / dt
        v_floor = 10 * v_noise
    else:
        v_floor = float(min_speed)
    valid = np.ones(m, bool)
    moving = valid & (np.abs(across) > v_floor)
    same_sign = moving & (np.sign(before) == np.sign(across)) & (np.sign(after) == np.sign(across))
    steady = same_sign & (np.abs(after - before) <= rel_tol * np.abs(across))
    min_dur = max(2 * window, 0.1) if min_duration is None else float(min_duration)
    block_label = np.where(valid & ~moving, 1, 0)  # 1 standstill, 0 transient; steady handled below
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
    vnoise2 = 2.0 * sigma * sigma / b / (b * dt) ** 2  # variance of a block speed from position noise
    runs_ = [r for s, e in runs_ for r in _split_smooth(tmid, vblock, s, e, rel_tol, vnoise2)]
    segs = []
    short_blocks = []
    for s2, e2 in runs_:
        rows_s, rows_e = _trim_to_line(t, theta, s2 * b, e2 * b, b)
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
    labels = Counter()
    in_seg = np.zeros(m, bool)
    for rs, re_, *_ in segs:
        in_seg[rs // b: re_ // b] = True
    short = np.zeros(m, bool)
    for s2, e2 in short_blocks:
        short[s2:e2] = True
    labels["short_plateau"] += int(short.sum()) * b
    standstill = (block_label == 1) & ~in_seg & ~short
    labels["standstill"] += int(standstill.sum()) * b
    labels["transient"] += int((~in_seg & ~short & ~standstill).sum()) * b + (n - used)
    labels = Counter({k: v for k, v in labels.items() if v})
    return segs, labels


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


def _trim_to_line(t, theta, a, z, b):
    """Trim rows a..z at both ends (by whole blocks) where position leaves the straight-line band.

    Works on every ``max(1, b // 4)``-th sample: the band and the trim are at block resolution.
    """
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
    band = 1.5 * float(np.max(np.abs(dev))) + 1e-12
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
    """Join consecutive block runs of one plateau separated by a short excursion.

    Two runs are joined when they move the same way at speeds within ``rel_tol``, the excursion
    between them lasts no longer than two windows, and its mean speed (travel over time) is within
    ``2 * rel_tol`` of theirs: the drive left the plateau briefly and came back.
    """
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


#: a candidate whose smooth speed curve changes by more than this fraction of ``rel_tol`` over
#: its length is a ramp, not a plateau (the rest of the tolerance is left to ripple) ...
_SMOOTH_SPREAD = 1.0 / 3.0
#: ... when that curve stands out of the position noise (its sum of squares, 3 degrees of freedom
#: beyond the mean, exceeds this many noise variances: chi-square tail below 1e-4) ...
_SMOOTH_CHI2 = 20.0
#: degree of the smooth curve (a cubic in time: a ramp, a bell's top, one swing of a sine)
_SMOOTH_DEGREE = 3


def _split_smooth(tb: np.ndarray, v: np.ndarray, s: int, e: int, rel_tol: float, vnoise2: float = 0.0,
                  prove_flat: bool = False, depth: int = 0):
    """Blocks s..e without a systematic speed change.

    The before/after test bounds the speed change over one window only; along an acceleration
    ramp, the top of a bell-shaped move, a creeping tail or a slow sine the speed changes little
    per window but steadily, and a run of "steady" blocks results.  The smooth curve is a cubic in
    time fitted to the block-to-block speeds ``v`` (variance ``vnoise2`` from position noise
    alone).  A run is a ramp when that curve spans more than ``_SMOOTH_SPREAD * rel_tol`` of the
    mean speed, stands out of the noise (``_SMOOTH_CHI2``) and explains more of the speed's
    variation than what is left beside it beyond the noise.  Ripple (closed-loop, stick-slip,
    position-locked) is not smooth in time over a plateau: the cubic explains little of it, and
    the rule leaves such plateaus alone however large the ripple.

    A ramp is split (CUSUM) recursively; a part of a ramp is kept only where it is shown flat
    (``prove_flat``: its spread plus two standard errors within the limit), so that the plateau
    beside a ramp stays and the ramp's own fragments go.  Runs never judged a ramp are kept, unless
    the position noise alone is too large to show a change of the limit (a crawl near the noise
    floor, such as the end of a creeping tail)."""
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
    c = np.polynomial.legendre.legfit(x, seg, _SMOOTH_DEGREE)
    f = np.polynomial.legendre.legval(x, c)
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


# ---------------------------------------------------------------------- derivatives
def derivatives(rec: Recording, deriv_window: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Velocity and acceleration of ``theta`` by a Savitzky-Golay filter, piece by piece.

    Parameters
    ----------
    rec : Recording
    deriv_window : int, optional
        Filter length in samples (odd, >= 5).  Default: about 20 ms, at least 7 samples.

    Returns
    -------
    velocity, acceleration : ndarray
        In unit/s and unit/s^2, one value per row; pieces shorter than the window (in samples,
        or on the uniform grid a jittered piece is resampled to) get NaN: no derivative.
    """
    t, theta = rec.t, rec.theta
    vel = np.full(len(t), np.nan)
    acc = np.full(len(t), np.nan)
    for _, a, b in rec.pieces():
        tt, th = t[a:b], theta[a:b]
        params = _filter_params(tt, deriv_window)
        if params is None:
            continue
        dt, w, uniform = params
        if uniform:
            vel[a:b] = savgol_filter(th, w, 2, deriv=1, delta=dt)
            acc[a:b] = savgol_filter(th, w, 2, deriv=2, delta=dt)
        else:
            grid = np.arange(tt[0], tt[-1] + dt / 2, dt)
            thg = np.interp(grid, tt, th)
            vel[a:b] = np.interp(tt, grid, savgol_filter(thg, w, 2, deriv=1, delta=dt))
            acc[a:b] = np.interp(tt, grid, savgol_filter(thg, w, 2, deriv=2, delta=dt))
    return vel, acc


def _filter_params(tt: np.ndarray, deriv_window: int | None):
    """``(dt, window, uniform)`` of the Savitzky-Golay filter on one piece with sample times
    ``tt``, or None when the piece is too short for it: fewer samples than the window, or (for a
    jittered piece, resampled to a uniform grid of the median step first) fewer grid points."""
    n = len(tt)
    if n < 5:
        return None
    d = np.diff(tt)
    dt = float(np.median(d))
    if not dt > 0:
        return None
    w = deriv_window or max(7, int(round(0.02 / dt)) | 1)
    w = int(w) | 1
    if w > n:
        return None
    np.subtract(d, dt, out=d)
    uniform = bool(np.max(np.abs(d)) <= 0.01 * dt)
    if not uniform and math.ceil((tt[-1] + dt / 2 - tt[0]) / dt) < w:  # len(np.arange(...)) of the grid
        return None
    return dt, w, uniform


def friction_torque(rec: Recording, inertia: float | None = None, deriv_window: int | None = None) -> np.ndarray:
    """Drive torque minus inertia torque, ``tau - J * thetadd`` (SILO4 eq. 2).

    ``inertia`` defaults to the gear spec's; without one the drive torque is returned unchanged.
    """
    J = inertia if inertia is not None else (rec.gear.inertia if rec.gear is not None else None)
    if not J:
        return rec.tau
    _, acc = derivatives(rec, deriv_window)
    out = rec.tau - J * np.nan_to_num(acc)
    return out


class FrictionTorque:
    """``friction_torque(rec, inertia, deriv_window)[rows]`` on demand, for one stretch of rows at
    a time (a segment), without the whole-recording arrays.

    The Savitzky-Golay acceleration is computed only over the rows asked for plus one filter
    length on each side (or up to the piece's edge, where the filter's own edge treatment then
    applies exactly as on the whole piece): the values are the same as :func:`friction_torque`'s,
    bit for bit, while the memory is that of the rows asked for, not three copies of the
    recording.  Pieces whose sampling jitters (resampled to a uniform grid first) are computed
    whole, once.  Without an inertia the rows of the drive torque are returned (a view).
    """

    def __init__(self, rec: Recording, inertia: float | None = None, deriv_window: int | None = None):
        self.rec = rec
        self.J = inertia if inertia is not None else (rec.gear.inertia if rec.gear is not None else None)
        self.deriv_window = deriv_window
        self.tau = rec.tau
        self._pieces = None
        self._whole = {}

    def _piece_params(self):
        if self._pieces is None:
            t = self.rec.t
            out = []
            for _, a, b in self.rec.pieces():
                params = _filter_params(t[a:b], self.deriv_window)
                out.append((a, b, None, None, None) if params is None else (a, b, *params))
            self._pieces = out
        return self._pieces

    def __getitem__(self, rows: slice) -> np.ndarray:
        start, stop, _ = rows.indices(len(self.tau))
        tau = self.tau[start:stop]
        if not self.J:
            return tau
        piece = next((p for p in self._piece_params() if p[0] <= start and stop <= p[1]), None)
        if piece is None:  # rows across pieces: the whole-recording computation
            return friction_torque(self.rec, self.J, self.deriv_window)[start:stop]
        a, b, dt, w, uniform = piece
        if dt is None:  # too short for the filter: no acceleration (as friction_torque)
            return tau.copy()
        if not uniform:
            if a not in self._whole:
                rec = self.rec
                tt, th = rec.t[a:b], rec.theta[a:b]
                grid = np.arange(tt[0], tt[-1] + dt / 2, dt)
                thg = np.interp(grid, tt, th)
                self._whole[a] = np.interp(tt, grid, savgol_filter(thg, w, 2, deriv=2, delta=dt))
            acc = self._whole[a][start - a:stop - a]
        else:
            lo, hi = max(a, start - w), min(b, stop + w)
            acc = savgol_filter(self.rec.theta[lo:hi], w, 2, deriv=2, delta=dt)[start - lo:stop - lo]
        return tau - self.J * np.nan_to_num(acc)
