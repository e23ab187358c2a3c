"""Where the data measure a line: the position Nyquist frequency of every segment, the samples
that resolve a frequency and hold enough of its cycles, and the speeds they span.

Every rule here is a property of a segment (a run of equal ``segment`` in ``dd.fit``): the tables
of :func:`_runs` hold one row per segment (its Nyquist frequency, travel and the smallest and
largest moving speed of each direction), computed once per data set and cached on it, so that a
question about one frequency costs the number of segments, not of samples.
"""

from __future__ import annotations

import numpy as np

from ..spectrum import MEASURABLE_FRACTION, position_nyquist
from .data import DiagnoseData

__all__ = ["segment_nyquist", "resolved", "measurable", "segment_span", "line_speed_range"]


def _segment_bounds(f) -> list:
    seg = f.segment
    bounds = np.flatnonzero(np.diff(seg) != 0) + 1
    return list(zip(np.concatenate(([0], bounds)), np.concatenate((bounds, [len(seg)]))))


def _runs(dd: DiagnoseData) -> dict:
    """Per segment of ``dd.fit`` (cached on the data): ``starts``, ``lengths`` (samples),
    ``nyquist`` (cycles per unit; inf where unknown), ``span`` (travel, unit) and, per direction
    ``d`` in (0, 1, -1) (0: both), ``vmin[d]`` / ``vmax[d]``: the smallest and largest |v| of its
    samples moving in that direction (inf / -inf where none; in data with free motion, whose samples
    keep their own speeds, the segment's mean speed ``speed``) and ``free``: a block of free motion."""
    hit = dd.cache.get("coverage_runs")
    if hit is not None:
        return hit
    f = dd.fit
    bounds = _segment_bounds(f) if len(f) else []
    starts = np.array([a for a, _ in bounds], dtype=np.int64)
    lengths = np.array([z - a for a, z in bounds], dtype=np.int64)
    nyq = np.full(len(bounds), np.inf)
    span = np.zeros(len(bounds))
    if f.theta is not None:
        for i, (a, z) in enumerate(bounds):
            if z - a > 1:
                q = position_nyquist(f.theta[a:z])
                if q > 0:
                    nyq[i] = q
            span[i] = float(np.ptp(f.theta[a:z])) if z > a else 0.0
    vmin, vmax = {}, {}
    speed = np.zeros(len(bounds))
    free = np.zeros(len(bounds), bool)
    if len(f):
        sp = np.abs(f.v)
        for d in (0, 1, -1):
            sel = f.v != 0 if d == 0 else (f.direction == d) & (f.v != 0)
            vmin[d] = np.minimum.reduceat(np.where(sel, sp, np.inf), starts)
            vmax[d] = np.maximum.reduceat(np.where(sel, sp, -np.inf), starts)
        speed = np.add.reduceat(sp, starts) / lengths
        if f.free_motion and "kind" in f.segments:
            ids = f.segments.loc[f.segments["kind"] == "free", "segment"].to_numpy()
            free = np.isin(f.segment[starts], ids)
            # samples at their own speeds (DiagnoseData): a segment's speed is their mean, as in the fit
            # (identify.stats), not the extremes of its samples
            for d in (0, 1, -1):
                vmin[d] = np.where(np.isfinite(vmin[d]), speed, np.inf)
                vmax[d] = np.where(np.isfinite(vmax[d]), speed, -np.inf)
    out = dd.cache["coverage_runs"] = {"starts": starts, "lengths": lengths, "nyquist": nyq, "span": span,
                                       "vmin": vmin, "vmax": vmax, "speed": speed, "free": free}
    return out


def segment_nyquist(dd: DiagnoseData) -> np.ndarray:
    """Position Nyquist frequency of the segment of every sample
    (:func:`gearspec.spectrum.position_nyquist` of the segment's positions), cached on the data."""
    hit = dd.cache.get("nyquist")
    if hit is None:
        t = _runs(dd)
        hit = dd.cache["nyquist"] = np.repeat(t["nyquist"], t["lengths"])
    return hit


def _resolved_runs(dd: DiagnoseData, frequency: float, fraction: float = MEASURABLE_FRACTION) -> np.ndarray:
    return frequency < fraction * _runs(dd)["nyquist"]


def resolved(dd: DiagnoseData, frequency: float, fraction: float = MEASURABLE_FRACTION) -> np.ndarray:
    """Samples whose segment resolves a line at ``frequency`` (below ``fraction`` of its position
    Nyquist frequency)."""
    return np.repeat(_resolved_runs(dd, frequency, fraction), _runs(dd)["lengths"])


def _measurable_runs(dd: DiagnoseData, frequency: float) -> np.ndarray:
    from ..identify import MIN_CYCLES

    t = _runs(dd)
    if dd.fit.theta is None:
        return np.zeros(len(t["starts"]), bool)
    return _resolved_runs(dd, frequency) & (frequency * t["span"] >= MIN_CYCLES)


def measurable(dd: DiagnoseData, frequency: float) -> np.ndarray:
    """Samples (of ``dd.fit``) whose segment measures a line at ``frequency``: resolved
    (:func:`resolved`) and at least :data:`gearspec.identify.MIN_CYCLES` of its cycles within the
    segment's travel (the rule of :func:`gearspec.identify.fit`).  An amplitude law is chosen and
    fitted from these samples only, and held at the edges of their speeds elsewhere."""
    return np.repeat(_measurable_runs(dd, frequency), _runs(dd)["lengths"])


def segment_span(dd: DiagnoseData) -> np.ndarray:
    """Travel (largest minus smallest position) of the segment of every sample of ``dd.fit``,
    cached on the data."""
    span = dd.cache.get("segment_span")
    if span is None:
        t = _runs(dd)
        span = dd.cache["segment_span"] = np.repeat(t["span"], t["lengths"])
    return span


def line_speed_range(dd: DiagnoseData, frequency: float, direction: int = 0) -> tuple | None:
    """``(min, max)`` of |v| where ``dd`` measures a line at ``frequency`` (:func:`measurable`) in
    ``direction`` (0: both), widened, as :func:`gearspec.identify.speed_ranges` widens it, to the
    speeds below (above) which the blocks of free motion that resolve the line together hold one
    cycle of it (:func:`~gearspec.identify.stats.free_speed_range`: a block of a few samples holds
    a fraction of a cycle, and the law is held at the range's edges outside it); None where it
    measures it nowhere.  Whole trajectories (reduced data, where the lines are fitted on every
    sample): the range of the moving samples.  From the per-segment table of :func:`_runs` (the
    same minimum and maximum as over the samples)."""
    from ..identify.stats import free_speed_range

    t = _runs(dd)
    if not len(t["starts"]):
        return None
    lo, hi = t["vmin"][direction], t["vmax"][direction]
    free = None
    if dd.reduce is None:
        meas = _measurable_runs(dd, frequency)
        blocks = t["free"] & _resolved_runs(dd, frequency) & np.isfinite(lo)
        if blocks.any() and dd.fit.theta is not None:
            free = free_speed_range(t["speed"][blocks], frequency * t["span"][blocks])
        lo, hi = lo[meas], hi[meas]
    if not len(lo) or not np.isfinite(lo).any():
        return free
    if free is not None:
        return min(float(np.min(lo)), free[0]), max(float(np.max(hi)), free[1])
    return float(np.min(lo)), float(np.max(hi))
