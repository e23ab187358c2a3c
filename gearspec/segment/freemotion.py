"""Free motion: the moving rows outside plateaus and sweeps (ramps, bell-shaped moves, chirps, sums
of sines) cut into short *blocks* within which the speed stays in a narrow band, one segment of
kind ``"free"`` each (:func:`free_motion`).

A law is evaluated at each block's mean speed, as on a plateau: exact for the terms linear in speed
(Coulomb, viscous), and for the others wrong only to second order in the band (a 3 % band moves a
Stribeck or decay term by well under 0.1 % of itself).  Positions, accelerations and the lines'
phases stay sample by sample, so the per-block reduction of :mod:`gearspec.identify` is exact.
Consecutive blocks of one *stretch* of motion (one direction, no standstill, plateau or gap between
them) share a held-out unit (``Segment.unit``): cross-validation leaves out whole stretches of
time, never interleaved blocks.
"""

from __future__ import annotations

import math
from collections import Counter

import numpy as np

from ..errors import InputError
from ..recording import Recording
from .kinematics import _filter_params, derivatives
from .plateaus import _position_noise
from .segmentation import Segment, Segmentation

__all__ = ["free_motion", "FREE_BAND", "FREE_SHARE", "CHAIN_SPEED_STEP", "MOTIONS"]

#: relative width of the speed band of a block (bins of constant width in log speed above the
#: noise floor, of constant width in speed near it: see :func:`_speed_bins`)
FREE_BAND = 0.03
#: free motion below this fraction of a piece's top speed counts as standstill (by default)
FREE_FLOOR = 0.01
#: ``motion="auto"`` uses free motion when it holds at least this share of the moving rows (most of
#: them): a plateau experiment's ramps between plateaus are left out as before, a recording of
#: moves, ramps or chirps is used whole
FREE_SHARE = 0.5
#: consecutive plateaus of one run and direction whose speeds differ by less than this (relative) and
#: that are closer than their own length are a *chain*: a slow ramp found as a row of short
#: "plateaus" (a plateau experiment's speeds differ by tens of percent, or are held in runs of their
#: own); in ``motion="auto"`` a chain's rows count as free motion in the share
CHAIN_SPEED_STEP = 0.25
#: what a segmentation may use: ``auto`` (plateaus and sweeps, plus free motion where it is a
#: large part of the recording), ``plateaus`` (plateaus and sweeps only), ``free`` (every moving
#: row as free motion, plateaus included)
MOTIONS = ("auto", "plateaus", "free")
#: order in which the rows now in free blocks leave the ledger's reasons
_REASONS = ("transient", "short_plateau", "standstill", "short_sweep")


def _speed_bins(speed: np.ndarray, band: float, scale: float) -> np.ndarray:
    """Bin of every speed: ``asinh(speed / scale)`` in steps of ``log(1 + band)`` -- relative bins
    of ``band`` well above ``scale``, bins of ``scale * band`` in speed below it (so that speed
    noise near the floor does not chop a block into single rows)."""
    return np.floor(np.arcsinh(speed / scale) / math.log1p(band)).astype(np.int64)


def _piece_floor(t: np.ndarray, theta: np.ndarray, speed: np.ndarray, min_speed: float | None):
    """``(floor, noise)`` of one piece: standstill below ``floor``, ``noise`` the speed noise that
    the position noise gives through the derivative filter.  Default floor: ten times that noise,
    and at least :data:`FREE_FLOOR` of the piece's top speed (around standstill and turning points
    the sign of friction is not known: a row at rest just before a move has a filtered speed)."""
    params = _filter_params(t, None)
    if params is None:
        return None
    dt, w, _ = params
    noise = _position_noise(theta) * math.sqrt(12.0 / (w * (w * w - 1))) / dt
    if min_speed is not None:
        return float(min_speed), noise
    top = float(np.nanmax(speed)) if np.isfinite(speed).any() else 0.0
    return max(10 * noise, FREE_FLOOR * top), noise


def free_motion(rec: Recording, seg: Segmentation, *, motion: str = "auto", band: float = FREE_BAND,
                min_speed: float | None = None, velocity: np.ndarray | None = None) -> Segmentation:
    """``seg`` with the free motion of ``rec`` added as blocks (segments of kind ``"free"``).

    ``motion`` (:data:`MOTIONS`): ``"plateaus"`` returns ``seg`` unchanged (as does a ``seg`` that
    already holds free blocks); ``"free"`` replaces
    its plateaus by free blocks (sweeps taken at rest are kept); ``"auto"`` adds the free blocks
    when they (with plateaus chained along a slow ramp, :data:`CHAIN_SPEED_STEP`) hold at least
    :data:`FREE_SHARE` of the moving rows, else returns ``seg``.
    ``band``: relative speed band of a block; ``min_speed`` (unit/s): standstill below (default ten
    times the derivative's speed noise); ``velocity``: per-row speed to cut by (default the
    Savitzky-Golay derivative of :func:`~gearspec.segment.derivatives`).  Rows whose derivative
    is undefined (pieces shorter than the filter) stay out.  The ledger stays whole: rows now in
    blocks leave the reasons they were counted under.
    """
    if motion not in MOTIONS:
        raise InputError(f"motion must be one of {', '.join(MOTIONS)}, got '{motion}'")
    if not 0 < band < 1:
        raise InputError(f"the speed band of a free-motion block must be between 0 and 1, got {band}")
    if motion == "plateaus" or any(s.kind == "free" for s in seg.segments):
        return seg
    kept = [motion == "auto" or s.kind == "quasi_static" for s in seg.segments]
    keep = [s for s, k in zip(seg.segments, kept) if k]
    excluded = Counter(seg.excluded)
    excluded["transient"] += sum(s.n for s, k in zip(seg.segments, kept) if not k)
    taken = np.zeros(len(rec), bool)
    for s in keep:
        taken[s.start:s.stop] = True
    vel = derivatives(rec)[0] if velocity is None else np.asarray(velocity, dtype=float)
    pieces, moving_plateau = _free_rows(rec, vel, taken, min_speed)
    # every free row is in exactly one block: the count needs no blocks (a plateau recording's
    # ramps would give thousands, built for nothing when the share decides against free motion)
    n_free = sum(int(np.count_nonzero(p[3])) for p in pieces)
    settings = {**seg.settings, "motion": motion, "free_band": band, "free_rows": n_free}
    if motion == "auto":
        # plateaus chained along a slow ramp count as free motion in the share (they stay plateaus)
        share = (n_free + _chained_rows(keep)) / max(n_free + moving_plateau, 1)
        settings["free_share"] = share
        if share < FREE_SHARE:
            return Segmentation(list(seg.segments), Counter(seg.excluded), seg.n_rows, settings)
    blocks = _blocks(pieces, band, unit0=len(keep))
    left = n_free
    for reason in _REASONS:
        take = min(left, excluded.get(reason, 0))
        excluded[reason] -= take
        left -= take
    if left:  # cannot happen while every row is in the ledger: a broken invariant, not user input
        raise AssertionError(f"free motion took {left} rows the ledger does not hold")
    out = Segmentation(sorted(keep + blocks, key=lambda s: s.start), +excluded, seg.n_rows, settings)
    out.check_ledger()
    return out


def _chained_rows(segments) -> int:
    """Rows of the plateaus of ``segments`` that belong to a chain (:data:`CHAIN_SPEED_STEP`)."""
    pl = sorted((s for s in segments if s.kind == "plateau"), key=lambda s: s.start)
    chained = set()
    for i, (a, b) in enumerate(zip(pl, pl[1:])):
        near = a.run == b.run and a.direction == b.direction and b.start - a.stop < min(a.n, b.n)
        if near and abs(b.speed - a.speed) < CHAIN_SPEED_STEP * max(a.speed, b.speed):
            chained.update((i, i + 1))
    return sum(pl[i].n for i in chained)


def _free_rows(rec: Recording, vel: np.ndarray, taken: np.ndarray, min_speed):
    """Per piece ``(run, a, v, free, floor, noise)`` (``v`` its velocities, ``free`` its moving rows
    outside ``taken``; pieces without free rows left out), and the number of moving rows in ``taken``."""
    t, theta = rec.t, rec.theta
    out = []
    moving_taken = 0
    for run, a, b in rec.pieces():
        v = vel[a:b]
        sp = np.abs(v)
        fl = _piece_floor(t[a:b], theta[a:b], sp, min_speed)
        if fl is None:
            continue
        floor, noise = fl
        moving = np.isfinite(v) & (sp > floor)
        moving_taken += int(np.count_nonzero(moving & taken[a:b]))
        free = moving & ~taken[a:b]
        if free.any():
            out.append((run, a, v, free, floor, noise))
    return out, moving_taken


def _blocks(pieces, band: float, unit0: int) -> list[Segment]:
    """The free blocks of the pieces of :func:`_free_rows`."""
    blocks: list[Segment] = []
    unit = unit0
    for run, a, v, free, floor, noise in pieces:
        sp = np.abs(v)
        # stretches: runs of free rows of one sign; blocks: runs of one speed bin within a stretch
        sign = np.where(v > 0, 1, -1)
        key = np.where(free, sign, 0)
        new_stretch = np.r_[True, (key[1:] != key[:-1])]
        bins = _speed_bins(np.where(free, sp, 0.0), band, max(100 * noise, floor))
        new_block = new_stretch | np.r_[True, bins[1:] != bins[:-1]]
        starts = np.flatnonzero(new_block)
        stops = np.r_[starts[1:], len(v)]
        stretch_id = np.cumsum(new_stretch) - 1
        last_stretch = -1
        for s, e in zip(starts.tolist(), stops.tolist()):
            if not free[s]:
                continue
            if stretch_id[s] != last_stretch:
                unit += 1
                last_stretch = stretch_id[s]
            blocks.append(Segment(int(run), int(a + s), int(a + e), int(sign[s]), float(np.mean(sp[s:e])),
                                  kind="free", unit=unit - 1))
    return blocks
