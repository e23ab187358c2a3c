"""Quasi-static sweeps: monotonic sweeps whose rows were stored at rest after each step of a position
loop (recognised from the spread of steps and of row-to-row speeds), one segment each."""

from __future__ import annotations

import math
from collections import Counter

import numpy as np

from ..recording import Recording
from .segmentation import Segment

__all__ = ["quasi_static_sweeps", "QS_MIN_STEPS", "QS_MIN_SPEED_SPREAD", "QS_SPREAD_RATIO", "QS_MAX_REPEATS",
           "QS_REVERSAL_STEPS"]

#: a sweep is quasi-static with at least this many steps (moves between rows: enough for a level
#: and a few lines with dozens of degrees of freedom left, and for the spreads below) ...
QS_MIN_STEPS = 50
#: ... when the speed between rows varies over at least a factor of 2 (log, 10-90 % range) ...
QS_MIN_SPEED_SPREAD = math.log(2.0)
#: ... this many times more than the steps do: rows stored at rest after each step of a position
#: loop have a steady step and an irregular time step; a clock gives steps that follow time steps
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


class _OnRead(dict):
    """A dict whose missing entries are computed when first read (``compute[key]()``), then kept."""

    def __init__(self, known: dict, compute: dict):
        super().__init__(known)
        self._compute = compute

    def __missing__(self, key):
        value = self[key] = self._compute[key]()
        return value


def _at_rest_statistics(t: np.ndarray, theta: np.ndarray, lazy: bool = False) -> dict:
    """Steps, repeats and the spread of steps and of row-to-row speeds of a stretch of rows.
    ``lazy``: the spreads are computed when first read, so :func:`_looks_at_rest`, which stops at
    the first test that fails, computes only those it needs (the same decision; on a run of
    plateaus, whose row-to-row speeds are steady, one percentile of the two)."""
    dth = np.abs(np.diff(theta))
    dt = np.diff(t)
    move = dth > 0
    known = {"steps": int(move.sum()), "repeats": float(1 - move.mean()) if len(move) else 1.0}
    compute = {"speed_spread": lambda: _spread(dth[move] / np.maximum(dt[move], 1e-300)),
               "step_spread": lambda: _spread(dth[move])}
    st = _OnRead(known, compute)
    if not lazy:
        for key in compute:
            st[key]
    return st


def _run_statistics(t: np.ndarray, theta: np.ndarray, chunks: int = 20, size: int = 10_000,
                    lazy: bool = False) -> dict:
    """:func:`_at_rest_statistics` of a whole run, from up to ``chunks`` contiguous stretches of
    ``size`` rows (not a stride, which would sum steps)."""
    n = len(t)
    if n <= chunks * size:
        return _at_rest_statistics(t, theta, lazy)
    starts = np.linspace(0, n - size, chunks).astype(int)
    dth = np.concatenate([np.diff(theta[s:s + size]) for s in starts])
    dt = np.concatenate([np.diff(t[s:s + size]) for s in starts])
    return _at_rest_statistics(np.concatenate(([0.0], np.cumsum(dt))), np.concatenate(([0.0], np.cumsum(dth))), lazy)


def _looks_at_rest(st: dict) -> bool:
    """The recognition rule (see the constants above), read in this order (see ``lazy`` in
    :func:`_at_rest_statistics`: a spread is computed when this reads it)."""
    return (st["steps"] >= QS_MIN_STEPS and st["repeats"] <= QS_MAX_REPEATS
            and st["speed_spread"] >= QS_MIN_SPEED_SPREAD
            and st["speed_spread"] >= QS_SPREAD_RATIO * st["step_spread"])


def _sweeps(theta: np.ndarray, tol: float) -> list[tuple[int, int, int]]:
    """Monotonic sweeps ``(start, stop, direction)`` of one run, split at reversals of more than
    ``tol`` (smaller returns are jitter); the turning row ends the sweep before it; direction 0:
    no travel of ``tol``."""
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
    bounds = [0] + [k + 1 for k in turns] + [n]  # the direction alternates from the first
    return [(a, b, first * (-1) ** i) for i, (a, b) in enumerate(zip(bounds[:-1], bounds[1:])) if b > a]


def quasi_static_sweeps(rec: Recording, *, force: bool = False) -> list[dict]:
    """The monotonic sweeps of each run (over position: time gaps do not split them; a sweep ends
    at a reversal of more than ``QS_REVERSAL_STEPS`` median steps), each a dict of ``run, start,
    stop, direction`` (rows, stop exclusive), ``at_rest`` (the recognition rule of the ``QS_``
    constants; no plateau passes it) and its statistics.  Without ``force`` a run whose rows as a
    whole do not pass is not searched."""
    t, theta, run = rec.t, rec.theta, rec.run
    out = []
    cuts = np.flatnonzero(np.diff(run) != 0) + 1
    bounds = np.concatenate(([0], cuts, [len(run)]))
    for a, b in zip(bounds[:-1], bounds[1:]):
        a, b = int(a), int(b)
        if b - a < 2:
            continue
        if not force and not _looks_at_rest(_run_statistics(t[a:b], theta[a:b], lazy=True)):
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
