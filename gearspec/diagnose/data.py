"""The data the closed loop works on (:class:`DiagnoseData`): samples, the unit they are held out
by, the travel since the last reversal, and an optional linear reduction of every column (IDIM
filtering and decimation, :func:`trajectory_data`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np
import pandas as pd

from ..errors import InputError
from ..fitdata import FitData
from ..recording import Recording
from ..segment import Segmentation, find_segments, free_motion
from ..segment.trim import edge_rows
from ..signals import butter_filtfilt, central_difference, decimate, decimation_index

__all__ = ["DiagnoseData", "trajectory_data", "travel_since_reversal", "reversal_travel", "moves", "per_speed",
           "speed_keys"]


# ---------------------------------------------------------------------- reversals
def travel_since_reversal(theta, v, run=None, deadband: float = 0.0) -> np.ndarray:
    """Distance travelled since the last reversal of the motion, per sample (``inf`` before the
    first reversal of a run).

    A reversal is a sample whose sign of ``v`` differs from the last nonzero sign before it in the
    same run; speeds at or below ``deadband`` count as standstill (no sign: jitter at rest is not a
    reversal).  The turning point is the extreme position reached between the last sample of the
    old direction and the first of the new one.  Samples must be in time order within each run.
    """
    theta = np.asarray(theta, dtype=float)
    v = np.asarray(v, dtype=float)
    s = np.where(np.abs(v) > deadband, np.sign(v), 0.0)
    n = len(theta)
    out = np.full(n, np.inf)
    if n == 0:
        return out
    run = np.zeros(n, int) if run is None else np.asarray(run)
    nz = np.flatnonzero(s != 0)
    if len(nz) < 2:
        return out
    # reversals: consecutive nonzero-sign samples of one run with opposite signs
    a, b = nz[:-1], nz[1:]
    rev = (s[a] != s[b]) & (run[a] == run[b])
    turn_at = b[rev].astype(np.int64)
    turn_pos = [float(np.max(theta[j:i + 1]) if s[j] > 0 else np.min(theta[j:i + 1])) for j, i in zip(a[rev], b[rev])]
    starts = np.flatnonzero(np.concatenate(([True], run[1:] != run[:-1])))
    ev = np.concatenate((turn_at, starts))
    pos = np.concatenate((np.asarray(turn_pos, dtype=float), np.full(len(starts), np.nan)))
    order = np.argsort(ev, kind="stable")
    ev, pos = ev[order], pos[order]
    # every sample takes the turning point of the last event at or before it (a run start: none yet)
    fill = pos[np.searchsorted(ev, np.arange(n), side="right") - 1]
    has = np.isfinite(fill)
    out[has] = np.abs(theta[has] - fill[has])
    return out


def reversal_travel(rec: Recording, seg: Segmentation) -> np.ndarray:
    """Distance since the last reversal for every row of ``rec`` inside a segment of ``seg``, in
    the order of :meth:`FitData.from_recording` (segment by segment), from the whole recording:
    the turning point between two consecutive segments of opposite directions in one run is the
    extreme position reached between them.  ``inf`` before the first reversal of a run."""
    theta = rec.theta
    segs = list(seg.segments)
    order = sorted(range(len(segs)), key=lambda i: (segs[i].run, segs[i].start))
    turn = {}  # segment index -> turning position before it (None: no reversal yet in the run)
    prev = None
    current = None
    for i in order:
        s = segs[i]
        if prev is None or segs[prev].run != s.run:
            current = None
        elif segs[prev].direction != s.direction:
            a, b = segs[prev].stop - 1, s.start + 1
            piece = theta[a:b]
            current = float(np.max(piece) if segs[prev].direction > 0 else np.min(piece))
        turn[i] = current
        prev = i
    out = [np.full(s.n, np.inf) if turn[i] is None else np.abs(theta[s.start:s.stop] - turn[i])
           for i, s in enumerate(segs)]
    return np.concatenate(out) if out else np.zeros(0)


def moves(v, run=None, min_speed: float | None = None) -> np.ndarray:
    """Move id of every sample of a whole trajectory: a new move starts when the speed rises above
    ``min_speed`` (default 5 % of the largest speed) after a standstill, or the direction reverses;
    standstills belong to the move before them.  Moves are the held-out unit of trajectories."""
    v = np.asarray(v, dtype=float)
    n = len(v)
    run = np.zeros(n, int) if run is None else np.asarray(run)
    if min_speed is None:
        min_speed = 0.05 * float(np.max(np.abs(v))) if n else 0.0
    moving = np.abs(v) > min_speed
    ids = np.zeros(n, np.int64)
    cur, last_dir, was_moving, last_run = 0, 0, False, None
    for i in range(n):
        if last_run is not None and run[i] != last_run:
            cur += 1
            last_dir, was_moving = 0, False
        if moving[i]:
            d = 1 if v[i] > 0 else -1
            if (not was_moving and last_dir != 0) or (last_dir != 0 and d != last_dir):
                cur += 1
            last_dir = d
        was_moving = bool(moving[i])
        ids[i] = cur
        last_run = run[i]
    return ids


# ---------------------------------------------------------------------- the data
@dataclass
class DiagnoseData:
    """Samples the closed loop fits, scores and holds out: ``fit`` (the samples at their own rate,
    segments contiguous and in time order), ``by`` (the held-out unit, "segment" or "run"; on a
    whole trajectory the segments are moves), ``travel`` (distance since the last reversal per
    sample, inf before the first), ``reduce`` (a linear map from an array over the samples to the
    *observations* the loop fits, e.g. IDIM filtering and decimation; None: the samples
    themselves), ``index`` (the sample every observation stands for), ``kind`` ("plateaus" or
    "trajectory")."""

    fit: FitData
    by: str = "segment"
    travel: np.ndarray | None = None
    reduce: Callable | None = None
    index: np.ndarray | None = None
    kind: str = "plateaus"
    name: str = ""
    notes: list = field(default_factory=list)
    gear: object = None
    cache: dict = field(default_factory=dict, repr=False)

    def __post_init__(self):
        f = self.fit
        if self.reduce is None and f.free_motion and f.speed is not None:
            # data that hold free motion: the laws at the speed of every sample, as a model of free
            # motion is judged (:meth:`FitData.inputs`).  A block's mean speed leaves f'(v) x the
            # change of speed within it in the residual (the fit takes it out of each block's normal
            # equations; the loop fits samples): on complete-model twins of bell moves a speed law
            # was then "accepted" in 3 of 40 (tests/test_false_discoveries_free.py)
            v = f.inputs()["v"]
            if not np.array_equal(v, f.v):
                self.fit = f = replace(f, v=v, cache={})
        if self.by not in ("segment", "run"):
            raise InputError(f"held-out unit must be 'segment' or 'run', got '{self.by}'")
        seg = f.segment
        change = np.flatnonzero(np.diff(seg) != 0) + 1
        if len(np.unique(seg)) != len(change) + 1:  # not contiguous: order by segment, stably
            order = np.argsort(seg, kind="stable")
            self.fit = f = f.subset(order)
            if self.travel is not None:
                self.travel = np.asarray(self.travel)[order]
        if self.travel is not None and len(self.travel) != len(f):
            raise InputError("travel since reversal: one value per sample is needed")
        if self.index is None:
            self.index = np.arange(len(f)) if self.reduce is None else np.arange(len(self.R(np.zeros(len(f)))))
        self.index = np.asarray(self.index, dtype=np.int64)
        # the observations are the samples, in order: :meth:`at` gives views, not copies
        self._identity = (self.reduce is None and len(self.index) == len(f)
                          and bool(np.array_equal(self.index, np.arange(len(f)))))
        g = f.groups(self.by)[self.index]
        # group ids 0..G-1 in order of appearance; observations of a group contiguous
        _, first, inv = np.unique(g, return_index=True, return_inverse=True)
        rank = np.argsort(np.argsort(first))
        self.group = rank[inv]
        if np.any(np.diff(self.group) < 0) and len(self.group) > 1:
            jumps = np.flatnonzero(np.diff(self.group) != 0)
            if len(jumps) + 1 != len(first):
                raise InputError(f"held-out groups ('{self.by}') are not contiguous in time; use by='segment'")
        bounds = np.flatnonzero(np.diff(self.group) != 0) + 1
        self.starts = np.concatenate(([0], bounds))
        self.stops = np.concatenate((bounds, [len(self.group)]))
        self.y = self.R(f.y)
        if not np.all(np.isfinite(self.y)):
            raise InputError("the friction signal has non-finite values in the samples to diagnose")

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_recording(cls, rec: Recording, segmentation: Segmentation | None = None, *, by: str = "segment",
                       inertia: bool = True, load_ratio: float | None = None, motion: str = "plateaus",
                       **segment_options) -> "DiagnoseData":
        """Samples inside the constant-speed segments of ``rec`` (laws evaluated at each segment's
        mean velocity, as :func:`gearspec.identify.fit`) and, by ``motion``
        (:func:`~gearspec.segment.free_motion`), blocks of its free motion; held out by whole
        segments (stretches of free motion) or runs, with the travel since the last reversal from
        the whole recording."""
        seg = free_motion(rec, segmentation if segmentation is not None else find_segments(rec, **segment_options),
                          motion=motion)
        fd = FitData.from_recording(rec, seg, inertia=inertia, load_ratio=load_ratio)
        travel = reversal_travel(rec, seg)
        name = ", ".join(rec.sources) if rec.sources else ""
        return cls(fd, by=by, travel=travel, kind="plateaus", name=name, notes=list(fd.notes), gear=rec.gear)

    @classmethod
    def from_fitdata(cls, fd: FitData, *, by: str = "segment", travel=None, gear=None) -> "DiagnoseData":
        """Any FitData (travel since reversal from its own samples when not given: the turning
        point is then the last sample before the new direction)."""
        if travel is None and fd.theta is not None:
            travel = travel_since_reversal(fd.theta, fd.v, fd.run)
        return cls(fd, by=by, travel=travel, kind="plateaus", notes=list(fd.notes), gear=gear)

    def without_edges(self) -> "DiagnoseData":
        """These data without the rows at each plateau's ends whose acceleration filter reaches
        into the transient beside it (:func:`~gearspec.segment.trim.edge_rows`: half the
        Savitzky-Golay window, 5 rows at 500 Hz); the closed loop works on these.  Plateaus that
        would lose more than half their rows, quasi-static sweeps, free-motion blocks and reduced
        (trajectory) data are kept whole."""
        f = self.fit
        if self.kind != "plateaus" or self.reduce is not None or f.t is None or not len(f):
            return self
        kinds = dict(zip(f.segments["segment"], f.segments["kind"])) if "kind" in f.segments else {}
        seg = f.segment
        bounds = np.flatnonzero(np.diff(seg) != 0) + 1
        keep = np.ones(len(f), bool)
        for a, z in zip(np.r_[0, bounds], np.r_[bounds, len(f)]):
            h = edge_rows(f.t[a:z]) if kinds.get(seg[a], "plateau") == "plateau" else 0
            if h and (z - a) - 2 * h >= (z - a) / 2:
                keep[a:a + h] = keep[z - h:z] = False
        if keep.all():
            return self
        note = (f"{int((~keep).sum())} rows at the ends of plateaus left out: their acceleration filter reaches into "
                f"the ramp beside them")
        return DiagnoseData(replace(f.subset(keep), cache={}), by=self.by, kind=self.kind, name=self.name,
                            travel=None if self.travel is None else np.asarray(self.travel)[keep],
                            notes=self.notes + [note], gear=self.gear)

    # ------------------------------------------------------------------ views
    def R(self, a) -> np.ndarray:
        """Observations of a per-sample array (the reduction, or the array itself)."""
        a = np.asarray(a, dtype=float)
        return a if self.reduce is None else self.reduce(a)

    def at(self, name: str):
        """A channel of ``fit`` at the observations (None if absent); when the observations are the
        samples themselves, a read-only view of the channel (no copy of rows per call)."""
        a = self.travel if name == "travel" else getattr(self.fit, name)
        if a is None:
            return None
        a = np.asarray(a)
        if not self._identity:
            return a[self.index]
        view = a.view()
        view.flags.writeable = False
        return view

    def __len__(self) -> int:
        return len(self.y)

    @property
    def n_groups(self) -> int:
        return len(self.starts)

    @property
    def unit(self) -> str:
        return self.fit.unit

    @property
    def torque_unit(self) -> str:
        return "Nm" if self.unit == "rad" else "N"

    def group_table(self) -> pd.DataFrame:
        """One row per held-out group: ``group, segment, run, direction, speed, n, t0, t1``."""
        seg = self.at("segment")
        d = self.at("direction")
        v = np.abs(self.at("v"))
        run = self.at("run")
        t = self.at("t")
        rows = []
        for gi, (a, b) in enumerate(zip(self.starts, self.stops)):
            dd = d[a:b]
            rows.append({"group": gi, "segment": int(seg[a]), "run": int(run[a]),
                         "direction": int(np.sign(np.sum(dd)) or dd[0]), "speed": float(np.mean(v[a:b])),
                         "n": int(b - a), "t0": float(t[a]) if t is not None else np.nan,
                         "t1": float(t[b - 1]) if t is not None else np.nan})
        return pd.DataFrame(rows)

    def directions(self) -> list[int]:
        """Directions with observations (+1 / -1)."""
        d = self.at("direction")
        return [x for x in (1, -1) if np.any(d == x)]


# ---------------------------------------------------------------------- per speed
def per_speed(dd: DiagnoseData, fn) -> np.ndarray:
    """``fn(|v|)`` at every sample of ``dd.fit`` for a function of the speed alone, elementwise
    (an amplitude law, a base law without load): evaluated once per distinct speed when the samples
    share few (plateaus: one speed per segment) and gathered, else on the samples.  The same
    numbers either way; the cost then grows with the segments, not the samples."""
    v = dd.fit.v
    hit = dd.cache.get("speeds")
    if hit is None or hit[0] is not v:
        sp = np.abs(v)
        u, inv = np.unique(sp, return_inverse=True)
        hit = dd.cache["speeds"] = (v, u, inv) if 4 * len(u) <= len(sp) else (v, None, None)
    _, u, inv = hit
    return fn(np.abs(v)) if u is None else np.take(np.asarray(fn(u)), inv, axis=0)


def speed_keys(dd: DiagnoseData):
    """The distinct (speed, sign of the velocity, direction) of the samples of ``dd.fit`` when they
    are few (plateaus: one per segment), cached on the data: ``(u, kidx, ksign, kdir, kinv)`` with
    ``u`` the distinct speeds of :func:`per_speed`, ``u[kidx]`` the speed of every key, ``ksign`` and
    ``kdir`` its sign of ``v`` and direction, and ``kinv`` the key of every sample; None when the
    samples share few speeds no more (then :func:`per_speed` evaluates on the samples).

    A column that depends on the sample only through these three (a base law's column with the
    sign of the motion in one direction, a line's amplitude factor) is built at the keys and
    gathered once: the same numbers, elementwise, as built on the samples."""
    f = dd.fit
    hit = dd.cache.get("speed_keys")
    if hit is not None and hit[0] is f.v and hit[1] is f.direction:
        return hit[2]
    per_speed(dd, np.abs)     # fills the distinct speeds
    _, u, inv = dd.cache["speeds"]
    keys = None
    if u is not None:
        sg = np.sign(f.v)
        di = np.asarray(f.direction)
        code = (inv.astype(np.int64) * 3 + (sg.astype(np.int64) + 1)) * 3 + (di.astype(np.int64) + 1)
        uc, first, kinv = np.unique(code, return_index=True, return_inverse=True)
        if 4 * len(uc) <= len(code):
            keys = (u, inv[first], sg[first], di[first], kinv.reshape(-1))
    dd.cache["speed_keys"] = (f.v, f.direction, keys)
    return keys


# ---------------------------------------------------------------------- whole trajectories
def trajectory_data(rec: Recording, *, cutoff: float = 100.0, order: int = 4, decimate_by: int = 10,
                    border: int = 49, min_speed: float | None = None, fs: float | None = None,
                    name: str = "") -> DiagnoseData:
    """Every sample of a whole trajectory, prepared as the inverse dynamic identification model
    (IDIM) is: the position low-pass filtered (``order``-order Butterworth at ``cutoff`` Hz,
    zero-phase), velocity and acceleration by central differences, the first ``border`` samples
    of each run dropped (filter and difference edge effects), and every column of the observation
    matrix and the measured torque decimated by ``decimate_by`` (MATLAB's ``decimate``), so that
    relative errors are those of the reference procedure (EMPS: 4.08 %, 3.11 %).

    Held-out unit: the *moves* (:func:`moves`).  ``fs`` (Hz): the nominal sample rate of the filter
    and the differences (default: from the median time step; EMPS's clock steps are 1.00002 ms, its
    reference procedure uses 1 ms).  ``decimate_by=1`` keeps every sample.  A piece whose time steps
    are not uniform is resampled first, or refused (README, "Uniform grids").
    """
    pieces = rec.pieces()
    if not pieces:
        raise InputError("the recording has no samples")
    extra = [c for c in ("load", "temperature") if c in rec.data]
    parts: dict = {c: [] for c in ("theta", "v", "acc", "y", "t", "run", *extra)}
    resampled = []
    for run, a, b in pieces:
        t = rec.t[a:b]
        if b - a <= border + 4 * max(decimate_by, 1):
            continue
        steps = np.diff(t)
        dt = float(np.median(steps))
        cols = {"theta": rec.theta[a:b], "y": rec.tau[a:b]}
        cols.update({c: rec.data[c].to_numpy(dtype=float)[a:b] for c in extra})
        if np.max(np.abs(steps - dt)) > 0.01 * dt:
            k = int(np.argmax(steps))
            if steps[k] > 0.25 / cutoff:
                raise InputError(
                    f"{', '.join(rec.sources)}: run {run}: the sample times are not uniform and the step of "
                    f"{steps[k]:.3g} s at t = {t[k]:.6g} s is longer than a quarter period of the {cutoff:g} Hz filter "
                    f"({0.25 / cutoff:.3g} s), too long to resample across honestly; lower --cutoff, or split the run "
                    "there with --max-gap")
            grid = t[0] + dt * np.arange(int(math.floor((t[-1] - t[0]) / dt + 1e-9)) + 1)
            cols = {c: np.interp(grid, t, x) for c, x in cols.items()}
            resampled.append((run, float(steps.min()), float(steps.max()), dt))
            t = grid
            if len(t) <= border + 4 * max(decimate_by, 1):
                continue
        if fs is not None:
            dt = 1.0 / float(fs)
        qf = butter_filtfilt(cols["theta"], cutoff, 1.0 / dt, order)
        dq = central_difference(qf, dt)
        ddq = central_difference(dq, dt)
        for c, x in (("theta", qf), ("v", dq), ("acc", ddq), ("t", t), ("run", np.full(len(t), run)),
                     *((c, cols[c]) for c in ("y", *extra))):
            parts[c].append(x[border:])
    if not parts["theta"]:
        raise InputError("every run is too short for the filter and decimation")
    cat = {c: np.concatenate(x) for c, x in parts.items()}
    theta, v, acc, y, t, run = (cat[c] for c in ("theta", "v", "acc", "y", "t", "run"))
    notes_resampled = []
    if resampled:
        lo = min(r[1] for r in resampled)
        hi = max(r[2] for r in resampled)
        notes_resampled.append(
            f"sample times not uniform (steps {lo:.3g} to {hi:.3g} s) in {len(resampled)} piece(s): each resampled to a "
            f"uniform grid at its median step ({', '.join(f'{r[3]:.4g}' for r in resampled[:5])}"
            f"{', ...' if len(resampled) > 5 else ''} s) by linear interpolation of position, torque"
            + "".join(f", {c}" for c in extra) + " before filtering")
    mv = moves(v, run, min_speed)
    seg_rows = []
    for m in np.unique(mv):
        sel = np.flatnonzero(mv == m)
        vv = v[sel]
        d = 1 if np.sum(vv) >= 0 else -1
        seg_rows.append({"segment": int(m), "run": int(run[sel[0]]), "direction": d,
                         "speed": float(np.max(np.abs(vv))), "velocity": float(d * np.max(np.abs(vv))),
                         "n": len(sel), "t0": float(t[sel[0]]), "t1": float(t[sel[-1]])})
    fd = FitData(theta=theta, v=v, y=y, acc=acc, load=cat.get("load"), temperature=cat.get("temperature"), t=t, run=run,
                 segment=mv, unit=rec.unit, segments=pd.DataFrame(seg_rows),
                 notes=[f"whole trajectory: position filtered ({order}th-order Butterworth, {cutoff:g} Hz, "
                        f"zero phase), central differences, first {border} samples of each run dropped, "
                        f"decimation by {decimate_by}; {len(np.unique(mv))} moves"] + notes_resampled)
    # the reduction: decimate each run piece (a linear map), observations = kept samples
    runs = np.unique(run)
    bounds = [(np.flatnonzero(run == r)[0], np.flatnonzero(run == r)[-1] + 1) for r in runs]
    if decimate_by > 1:
        index = np.concatenate([a + decimation_index(b - a, decimate_by) for a, b in bounds])

        def reduce(x, _b=tuple(bounds), _q=int(decimate_by)):
            x = np.asarray(x, dtype=float)
            return np.concatenate([decimate(x[a:b], _q) for a, b in _b])
    else:
        index, reduce = None, None
    travel = travel_since_reversal(theta, v, run, deadband=0.02 * float(np.max(np.abs(v))))
    return DiagnoseData(fd, by="segment", travel=travel, reduce=reduce, index=index, kind="trajectory",
                        name=name or ", ".join(rec.sources), notes=list(fd.notes), gear=rec.gear)
