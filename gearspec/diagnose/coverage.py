"""Where the data measure a line: the position Nyquist frequency of every segment, the samples
that resolve a frequency and hold enough of its cycles, and the speeds they span."""

from __future__ import annotations

import numpy as np

from ..spectrum import MEASURABLE_FRACTION, position_nyquist
from .data import DiagnoseData

__all__ = ["segment_nyquist", "resolved", "measurable", "segment_span", "line_speed_range"]


def _segment_bounds(f) -> list:
    seg = f.segment
    bounds = np.flatnonzero(np.diff(seg) != 0) + 1
    return list(zip(np.concatenate(([0], bounds)), np.concatenate((bounds, [len(seg)]))))


def segment_nyquist(dd: DiagnoseData) -> np.ndarray:
    """Position Nyquist frequency of the segment of every sample
    (:func:`gearspec.spectrum.position_nyquist` of the segment's positions), cached on the data."""
    hit = dd.cache.get("nyquist")
    if hit is not None:
        return hit
    f = dd.fit
    out = np.full(len(f), np.inf)
    if f.theta is not None:
        for a, z in _segment_bounds(f):
            if z - a > 1:
                nyq = position_nyquist(f.theta[a:z])
                if nyq > 0:
                    out[a:z] = nyq
    dd.cache["nyquist"] = out
    return out


def resolved(dd: DiagnoseData, frequency: float, fraction: float = MEASURABLE_FRACTION) -> np.ndarray:
    """Samples whose segment resolves a line at ``frequency`` (below ``fraction`` of its position
    Nyquist frequency)."""
    return frequency < fraction * segment_nyquist(dd)


def measurable(dd: DiagnoseData, frequency: float) -> np.ndarray:
    """Samples (of ``dd.fit``) whose segment measures a line at ``frequency``: resolved
    (:func:`resolved`) and at least :data:`gearspec.identify.MIN_CYCLES` of its cycles within the
    segment's travel (the rule of :func:`gearspec.identify.fit`).  An amplitude law is chosen and
    fitted from these samples only, and held at the edges of their speeds elsewhere."""
    from ..identify import MIN_CYCLES

    if dd.fit.theta is None:
        return np.zeros(len(dd.fit), bool)
    return resolved(dd, frequency) & (frequency * segment_span(dd) >= MIN_CYCLES)


def segment_span(dd: DiagnoseData) -> np.ndarray:
    """Travel (largest minus smallest position) of the segment of every sample of ``dd.fit``,
    cached on the data."""
    span = dd.cache.get("segment_span")
    if span is None:
        f = dd.fit
        span = dd.cache["segment_span"] = np.zeros(len(f))
        for a, z in _segment_bounds(f):
            span[a:z] = float(np.ptp(f.theta[a:z])) if z > a else 0.0
    return span


def line_speed_range(dd: DiagnoseData, frequency: float, direction: int = 0) -> tuple | None:
    """``(min, max)`` of |v| where ``dd`` measures a line at ``frequency`` (:func:`measurable`) in
    ``direction`` (0: both); None where it measures it nowhere.  Whole trajectories (reduced
    data, where the lines are fitted on every sample): the range of the moving samples."""
    f = dd.fit
    sel = (f.direction == direction) if direction else np.ones(len(f), bool)
    sel = sel & (f.v != 0)
    if dd.reduce is None:
        sel = sel & measurable(dd, frequency)
    if not sel.any():
        return None
    sp = np.abs(f.v[sel])
    return float(np.min(sp)), float(np.max(sp))
