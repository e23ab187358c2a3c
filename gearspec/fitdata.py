"""The data a friction model is fitted to and scored on: the samples inside constant-speed segments,
each with its segment (so that held-out errors leave out whole segments or runs, never interleaved
samples), and their plateau averages (the Stribeck curve of SILO4 Fig. 4)."""

from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np
import pandas as pd

from .core.reduction import group_rows, unique_ids
from .errors import InputError
from .recording import Recording
from .segment import Segmentation, find_segments, free_motion
from .segment.kinematics import fit_derivatives

__all__ = ["FitData"]

_ARRAYS = ("theta", "v", "y", "acc", "load", "temperature", "t", "run", "segment", "direction", "group", "speed")


@dataclass
class FitData:
    """Samples for identification, arrays of one length (optional channels None): ``theta`` rad (m);
    ``v`` the laws' velocity, rad/s (segment mean or measured); ``y`` friction torque, Nm (N), with
    the sign of the motion (``J thetadd`` removed when the gear gives ``J``); ``acc`` rad/s^2;
    ``load`` Nm, ``temperature`` degC, ``t`` s; ``run``, ``segment`` ids; ``direction`` +1 / -1;
    ``speed``: |velocity| of each sample (the derivative; None when not derived), for the change of
    speed within a block of free motion; ``group``: the held-out unit of "segment" cross-validation
    (the segment, or for blocks of free motion their whole stretch of motion; None: the segment).  ``segments``: one row per segment
    (``segment, run, direction, speed, velocity, n``, and ``t0, t1, kind``: "plateau",
    "quasi_static" or "free").  ``inertia``: the ``J`` removed from ``y`` (None: none removed)."""

    theta: np.ndarray | None
    v: np.ndarray
    y: np.ndarray
    acc: np.ndarray | None = None
    load: np.ndarray | None = None
    temperature: np.ndarray | None = None
    t: np.ndarray | None = None
    run: np.ndarray | None = None
    segment: np.ndarray | None = None
    direction: np.ndarray | None = None
    group: np.ndarray | None = None
    speed: np.ndarray | None = None
    unit: str = "rad"
    inertia: float | None = None
    segments: pd.DataFrame = field(default_factory=pd.DataFrame)
    notes: list = field(default_factory=list)
    #: per-segment results computed once (keyed by what), shared with subsets (segments keep their ids)
    cache: dict = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self):
        n = len(self.v)
        for name in _ARRAYS:
            a = getattr(self, name)
            if a is not None:
                a = np.asarray(a)
                if a.shape != (n,):
                    raise InputError(f"fit data: '{name}' has {a.shape} values, velocity has {n}")
                setattr(self, name, a)
        if self.direction is None:
            self.direction = np.where(self.v >= 0, 1, -1).astype(np.int8)
        if self.segment is None:
            self.segment = np.zeros(n, np.int64)
        if self.run is None:
            self.run = np.zeros(n, np.int64)

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_recording(cls, rec: Recording, segmentation: Segmentation | None = None, *, velocity: str = "segment",
                       inertia: bool = True, load_ratio: float | None = None, motion: str = "plateaus",
                       lines=None, **segment_options) -> "FitData":
        """Samples inside the segments of ``rec`` (``segmentation`` default:
        :func:`~gearspec.segment.find_segments` with ``segment_options``, then free-motion blocks by
        :func:`~gearspec.segment.free_motion` with ``motion``: "plateaus", "auto" or "free").
        A free-motion block's velocity is its mean, its acceleration sample by sample.

        ``velocity``: ``"segment"`` (each segment's mean: robust to speed ripple and encoder noise,
        as the papers do) or ``"measured"`` (the ``velocity`` channel, else a Savitzky-Golay
        derivative).  ``inertia``: subtract ``J thetadd`` when the gear gives ``J``.  ``load_ratio``:
        subtract ``|load| / load_ratio`` against the motion (Lola/CROPS eq. 12: a brake opposing the
        motion, torque measured at the motor of a gear of that ratio).  ``lines``: the frequencies
        (cycles per unit of theta) of the lines the fit models: on plateaus where one makes a full
        cycle the acceleration is that of the position-locked motion
        (:func:`~gearspec.segment.kinematics.fit_derivatives`); None: the Savitzky-Golay one everywhere.
        """
        if velocity not in ("segment", "measured"):
            raise InputError(f"velocity must be 'segment' or 'measured', got '{velocity}'")
        seg = segmentation if segmentation is not None else \
            free_motion(rec, find_segments(rec, **segment_options), motion=motion)
        if len(seg) == 0:
            raise InputError(f"{', '.join(rec.sources)}: no constant-speed segment or free motion found "
                             f"(rows: {dict(seg.excluded)})")
        vel, acc, n_locked, rows_locked = fit_derivatives(rec, seg.segments, lines)
        J = rec.gear.inertia if (inertia and rec.gear is not None and rec.gear.inertia) else None
        # per-segment values repeated over each segment's rows (one np.repeat each, not one array per
        # segment); a row array of the recording gathered slice by slice (no index array of the rows),
        # each full-length temporary freed once gathered: on 10^7 rows the peak of this construction
        # was 0.5 GB above the arrays it returns
        ns = np.array([s.n for s in seg.segments], dtype=np.intp)
        per = lambda values, dtype=None: np.repeat(np.array(values, dtype=dtype), ns)  # noqa: E731
        gather = lambda a: _gather(a, seg.segments)  # noqa: E731
        sid = per(range(len(ns)), np.int64)
        d = per([s.direction for s in seg.segments], np.int8)
        # held-out unit: the segment; a block of free motion: its stretch (numbered after the segments)
        S = len(seg.segments)
        units = [i if s.unit < 0 else S + s.unit for i, s in enumerate(seg.segments)]
        # no block of free motion: every unit is its segment, and the array is ``sid`` itself (one
        # full-length array less; nothing writes into either)
        group = sid if units == list(range(S)) else per(units, np.int64)
        # quasi-static sweeps were taken at rest: no time derivative is used there (acceleration 0,
        # no inertia torque; the velocity is the sweep's nominal one, travel over duration)
        qs = per([s.kind == "quasi_static" for s in seg.segments], bool)
        v = per([s.velocity for s in seg.segments], float)
        speed = gather(vel)
        del vel
        if velocity == "measured" and not qs.all():
            v = np.where(qs, v, gather(rec.data["velocity"].to_numpy(dtype=float)) if "velocity" in rec.data
                         else speed)
        a = gather(acc)
        del acc
        no_deriv = int(np.count_nonzero(np.isnan(a) & ~qs))
        np.nan_to_num(a, copy=False)
        a[qs] = 0.0
        y = gather(rec.tau)
        if J:
            y -= J * a
        # |velocity| of each sample; a sweep's, or where no derivative is, |v|
        no_speed = qs | np.isnan(speed)
        np.abs(speed, out=speed)
        speed[no_speed] = np.abs(v[no_speed])
        del no_speed
        get = lambda c: gather(rec.data[c].to_numpy(dtype=float)) if c in rec.data else None  # noqa: E731
        notes = []
        if load_ratio:
            if "load" not in rec.data:
                raise InputError(f"{', '.join(rec.sources)}: no 'load' column to subtract (load_ratio given)")
            y = y - d * np.abs(get("load")) / float(load_ratio)
            notes.append(f"load torque at the motor subtracted: |load| / {load_ratio:g} against the motion (eq. 12)")
        rows = [{"segment": i, "run": s.run, "direction": s.direction, "speed": s.speed, "velocity": s.velocity,
                 "n": s.n, "t0": float(rec.t[s.start]), "t1": float(rec.t[s.stop - 1]), "kind": s.kind}
                for i, s in enumerate(seg.segments)]
        notes.insert(0, f"{len(y)} samples in {len(seg)} segments; velocity: {velocity}")
        n_free = sum(s.kind == "free" for s in seg.segments)
        if n_free:
            stretches = len({s.unit for s in seg.segments if s.kind == "free"})
            notes.append(f"free motion: {n_free} blocks of nearly constant speed in {stretches} stretches of motion "
                         f"({sum(s.n for s in seg.segments if s.kind == 'free')} rows; each law evaluated at a "
                         f"block's mean speed, positions and accelerations sample by sample)")
        n_qs = sum(s.kind == "quasi_static" for s in seg.segments)
        if n_qs:
            notes.append(f"{n_qs} quasi-static sweep(s) ({int(qs.sum())} rows taken at rest): torque against "
                         f"position, no time derivative; their speed is nominal (travel over duration)")
        if J and no_deriv:
            notes.append(f"{no_deriv} rows in segments are in pieces too short for the derivative filter: "
                         f"no acceleration there, inertia not removed")
        if J:
            notes.append(f"inertia removed: tau - {J:g} x thetadd" + (" (plateaus only)" if n_qs else ""))
        if n_locked:
            notes.append(f"acceleration of the position-locked motion on {n_locked} plateaus ({rows_locked} rows; "
                         f"time fitted over position at the lines), a Savitzky-Golay derivative elsewhere")
        return cls(theta=gather(rec.theta), v=v, y=y, acc=a, load=get("load"), temperature=get("temperature"),
                   t=gather(rec.t), run=gather(rec.run), segment=sid, direction=d, group=group, unit=rec.unit,
                   speed=speed, segments=pd.DataFrame(rows), notes=notes, inertia=J)

    @classmethod
    def from_points(cls, v, y, *, load=None, temperature=None, theta=None, unit: str = "rad") -> "FitData":
        """Quasi-static operating points (e.g. the Lola/CROPS testbed's means), one segment each."""
        v = np.asarray(v, dtype=float)
        n = len(v)
        if n == 0:
            raise InputError("fit data: no points")
        sid = np.arange(n)
        d = np.where(v >= 0, 1, -1).astype(np.int8)
        seg = pd.DataFrame({"segment": sid, "run": 0, "direction": d, "speed": np.abs(v), "velocity": v, "n": 1})
        f = lambda x: None if x is None else np.asarray(x, dtype=float)  # noqa: E731
        return cls(theta=f(theta), v=v, y=np.asarray(y, dtype=float), load=f(load), temperature=f(temperature),
                   segment=sid, run=np.zeros(n, np.int64), direction=d, unit=unit, segments=seg)

    # ------------------------------------------------------------------ views
    def __len__(self) -> int:
        lazy = self.__dict__.get("_lazy")
        return lazy[0] if lazy is not None else len(self.v)

    def values_at(self, name: str, idx) -> np.ndarray:
        """``getattr(self, name)[idx]`` (a sample array at the rows ``idx``) without gathering the
        whole array of a :meth:`subset` that has not read it yet."""
        lazy = self.__dict__.get("_lazy")
        if lazy is not None and name not in self.__dict__ and name in lazy[1]:
            source, rows = lazy[1][name]
            return source[rows[idx]]
        return getattr(self, name)[idx]

    @property
    def n_segments(self) -> int:
        return int(len(unique_ids(self.segment)))

    @property
    def free_motion(self) -> bool:
        """Whether the data hold blocks of free motion (segments of kind "free")."""
        return bool(len(self.segments)) and "kind" in self.segments and bool((self.segments["kind"] == "free").any())

    def speed_change(self) -> np.ndarray | None:
        """Per sample, its speed minus the mean speed of its segment, in data that hold free motion
        (0 in quasi-static sweeps); None in other data.  The fits take its first-order effect out of
        every segment (:func:`gearspec.core.reduction.partial_out_last`): a law evaluated at a
        segment's mean speed would leave ``f'(v) x`` this in the residual, where partial cycles of a
        line would take it up (viscous x the change of speed within a block is as large as the noise)."""
        if not self.free_motion or self.speed is None:
            return None
        ids, inv = unique_ids(self.segment, return_inverse=True)
        dev = self.speed - (np.bincount(inv, weights=self.speed) / np.bincount(inv))[inv]
        qs = self.segments.loc[self.segments["kind"] == "quasi_static", "segment"].to_numpy()
        if len(qs):
            dev[np.isin(self.segment, qs)] = 0.0
        return dev

    def inputs(self) -> dict:
        """Keyword inputs of :meth:`gearspec.model.FrictionModel.evaluate`: the laws' velocity ``v``
        (a segment's mean), or in data that hold free motion each sample's own velocity (a model
        of free motion is judged by the torque it predicts at the speed of every sample)."""
        v = self.direction * self.speed if (self.speed is not None and self.free_motion) else self.v
        return {"theta": self.theta, "v": v, "load": self.load, "temperature": self.temperature,
                "t": self.t, "acc": self.acc, "run": self.run}

    def subset(self, mask) -> "FitData":
        """The samples where ``mask`` is true (a boolean array, or an index array).

        The subset's sample arrays are gathered when they are first read (its ``segment`` at
        once unless the rows' segments are known, :meth:`segment_groups`): a held-out fold's fit
        reads the per-segment statistics cached on the data
        (:func:`gearspec.identify.stats.segment_stats`), not the samples, so it copies none of the
        ten or more arrays of a long recording (10^7 rows: 0.7 GB per copy).  The values are those
        of ``getattr(self, name)[mask]``."""
        mask = np.asarray(mask)
        rows = np.flatnonzero(mask) if mask.dtype == bool else mask
        new = self._lazy_subset(rows, len(rows), lambda at: at[rows])
        lay = self._layout() if mask.dtype == bool or _increasing(rows) else None
        if lay is not None:     # rows in order: the subset's segments and their rows from this one's
            ids, bounds, dirs = lay
            counts = np.diff(np.searchsorted(rows, bounds))
            has = counts > 0
            keep = ids[has]
            new.__dict__["_segment_layout"] = (keep, np.concatenate(([0], np.cumsum(counts[has]))),
                                               None if dirs is None else dirs[has])
        else:
            keep = unique_ids(new.segment)
        return self._with_segments(new, keep)

    def _lazy_subset(self, here, n: int, compose) -> "FitData":
        """A subset of ``n`` rows whose sample arrays are gathered when first read: an array read
        here by the rows ``here`` (an index or :class:`_Ranges`), one not read yet from its source
        by ``compose(at)`` of the rows ``at`` it has there (once per distinct ``at``)."""
        lazy = self.__dict__.get("_lazy")
        new = object.__new__(_Subset)
        pending, composed = {}, {}
        for f in fields(self):
            name = f.name
            if name not in _ARRAYS:
                new.__dict__[name] = getattr(self, name)
            elif lazy is not None and name not in self.__dict__:     # not read here yet: from its source
                source, at = lazy[1][name]
                if id(at) not in composed:
                    composed[id(at)] = compose(at)
                pending[name] = (source, composed[id(at)])
            elif self.__dict__[name] is None:
                new.__dict__[name] = None
            else:
                pending[name] = (self.__dict__[name], here)
        new.__dict__["_lazy"] = (n, pending)
        return new

    def _with_segments(self, new, keep) -> "FitData":
        """``new`` with this data's segment table rows of the segments ``keep``, notes and cache."""
        new.segments = self.segments[self.segments["segment"].isin(keep)].reset_index(drop=True) \
            if len(self.segments) else self.segments
        new.notes = list(self.notes)
        new.cache = self.cache
        return new

    def direction_subset(self, direction: int) -> "FitData":
        """:meth:`subset` of the samples moving in ``direction`` (+1 / -1); when every segment moves
        one way (:meth:`segment_groups`), :meth:`segment_subset` of those segments, without reading
        the samples' directions."""
        lay = self._layout()
        if lay is not None and lay[2] is not None:
            return self.segment_subset(lay[2] == direction)
        return self.subset(self.direction == direction)

    def segment_subset(self, select) -> "FitData":
        """The samples of the segments ``select`` (a boolean array over the segments of
        :meth:`segment_groups`, whose rows must be in segment order): :meth:`subset` of their rows,
        the same values, with the rows themselves worked out only when a sample array is read (a
        held-out fold's fit reads the cached per-segment statistics, not the samples)."""
        lay = self._layout()
        if lay is None:
            raise ValueError("segment_subset needs rows in segment order")
        ids, bounds, dirs = lay
        sel = np.asarray(select, bool)
        own = _Ranges(bounds[:-1][sel], bounds[1:][sel])       # in this data's rows
        # ranges of this data's segments in the source: taken
        new = self._lazy_subset(own, len(own), lambda at: at.take(sel) if isinstance(at, _Ranges) else at[own.array()])
        sizes = np.diff(bounds)[sel]
        new.__dict__["_segment_layout"] = (ids[sel], np.concatenate(([0], np.cumsum(sizes))),
                                           None if dirs is None else dirs[sel])
        return self._with_segments(new, ids[sel])

    def segment_groups(self) -> tuple[np.ndarray | None, np.ndarray, np.ndarray]:
        """The rows of every segment: ``(order, ids, bounds)`` as
        :func:`gearspec.core.reduction.group_rows` gives them for ``segment``, with ``order`` None
        when the rows are in ascending segment order (segment ``ids[j]`` is rows
        ``bounds[j]:bounds[j + 1]``).  Known without reading the samples in a subset of data
        whose rows were in that order (as :meth:`from_recording` writes them)."""
        lay = self._layout()
        if lay is not None:
            return None, lay[0], lay[1]
        return group_rows(self.segment)

    def _layout(self):
        """``(ids, bounds, dirs)`` of the segments when the rows are in ascending segment order
        (``dirs``: each segment's direction, None when one moves both ways), else None; computed
        once (one pass over ``segment`` and ``direction``), a subset's from its source's."""
        d = self.__dict__
        if "_segment_layout" not in d:
            seg = self.segment
            n = len(seg)
            lay = None
            if n and (n == 1 or bool(np.all(seg[1:] >= seg[:-1]))):
                new = np.empty(n, bool)
                new[0] = True
                np.not_equal(seg[1:], seg[:-1], out=new[1:])
                starts = np.flatnonzero(new)
                dr = self.direction
                one_way = np.array_equal(np.minimum.reduceat(dr, starts), np.maximum.reduceat(dr, starts))
                lay = (seg[starts], np.append(starts, n), dr[starts] if one_way else None)
            d["_segment_layout"] = lay
        return d["_segment_layout"]

    def groups(self, by: str = "segment") -> np.ndarray:
        """Group id per sample for held-out folds: ``"segment"`` (blocks of free motion: their whole
        stretch of motion) or ``"run"``."""
        if by == "segment":
            group = getattr(self, "group", None)  # (discover's Moments borrow this rule: no blocks there)
            return self.segment if group is None else group
        if by == "run":
            return self.run
        raise InputError(f"held-out groups must be 'segment' or 'run', got '{by}'")

    def plateaus(self, blocks: int = 8) -> pd.DataFrame:
        """One row per segment: mean speed, mean friction magnitude ``level`` and its standard
        error (from ``blocks`` consecutive block means, so that ripple and coloured noise count),
        mean load and temperature.  Sorted by direction and speed.

        A segment's row is computed once and kept in :attr:`cache` (shared with the subsets, whose
        segments keep their ids), as :func:`gearspec.identify.stats.segment_stats` keeps its numbers:
        the held-out folds of the published procedure and the checks of every model read them again."""
        order, sids, bounds = self.segment_groups()
        edge = np.concatenate((bounds[:-1], bounds[1:] - 1))
        ends = self.values_at("y", edge if order is None else order[edge]) if len(sids) else []
        tags = [(int(sid), int(b - a), float(y0), float(y1))
                for sid, a, b, y0, y1 in zip(sids, bounds[:-1], bounds[1:], ends[:len(sids)], ends[len(sids):])]
        channels = tuple(c for c in ("load", "temperature", "t") if self.has(c))
        cache = self.cache.setdefault(("plateaus", int(blocks), channels), {})
        info = self.segments.set_index("segment") if len(self.segments) else None
        for j, tag in enumerate(tags):
            if tag not in cache:
                ii = np.arange(bounds[j], bounds[j + 1]) if order is None else order[bounds[j]:bounds[j + 1]]
                cache[tag] = self._plateau_row(ii, tag[0], blocks, channels, info)
        df = pd.DataFrame([cache[tag] for tag in tags])
        return df.sort_values(["direction", "speed"], ascending=[False, True]).reset_index(drop=True)

    def _plateau_row(self, ii, sid, blocks, channels, info) -> dict:
        """:meth:`plateaus`' row of segment ``sid``, its rows ``ii`` in time order."""
        m = self.values_at("direction", ii) * self.values_at("y", ii)
        nb = min(blocks, len(m))
        if nb >= 2:
            bm = np.array([x.mean() for x in np.array_split(m, nb)])
            se = float(bm.std(ddof=1) / np.sqrt(nb))
        else:
            se = float("nan")
        row = {"segment": int(sid), "run": int(self.values_at("run", ii[:1])[0]),
               "direction": int(self.values_at("direction", ii[:1])[0]),
               "speed": float(np.mean(np.abs(self.values_at("v", ii)))), "n": len(ii), "level": float(m.mean()),
               "level_se": se}
        if info is not None and sid in info.index:
            row["speed"] = float(info.loc[sid, "speed"])
        for c in channels:
            row[c] = float(np.mean(self.values_at(c, ii)))
        return row

    def has(self, name: str) -> bool:
        """Whether the sample array ``name`` is given (not None), without gathering it in a subset."""
        if name in self.__dict__:
            return self.__dict__[name] is not None
        lazy = self.__dict__.get("_lazy")
        return lazy is not None and name in lazy[1]

    def channels(self) -> list[str]:
        return [f.name for f in fields(self) if f.name in _ARRAYS and getattr(self, f.name) is not None]


class _Ranges:
    """Rows of a source array as consecutive ranges ``starts[j]:stops[j]`` (one per segment of a
    :meth:`FitData.segment_subset`, in order): indexed like the array of those rows
    (``ranges[idx]``), which is made (:meth:`array`) only when a whole sample array is gathered."""

    def __init__(self, starts, stops):
        self.starts, self.stops = np.asarray(starts, np.intp), np.asarray(stops, np.intp)
        self.cum = np.concatenate(([0], np.cumsum(self.stops - self.starts)))
        self._rows = None

    def __len__(self) -> int:
        return int(self.cum[-1])

    def array(self) -> np.ndarray:
        """The rows, ascending (the ``flatnonzero`` of a mask of these segments)."""
        if self._rows is None:
            n = self.stops - self.starts
            self._rows = np.arange(len(self), dtype=np.intp) + np.repeat(self.starts - self.cum[:-1], n)
        return self._rows

    def take(self, sel) -> "_Ranges":
        """The ranges of the segments ``sel`` (a boolean array over these)."""
        return _Ranges(self.starts[sel], self.stops[sel])

    def __getitem__(self, idx):
        if self._rows is not None:
            return self._rows[idx]
        idx = np.asarray(idx)
        if idx.dtype == bool or idx.size > 4096:     # many rows (a pass over the samples): the rows once
            return self.array()[idx]
        j = np.searchsorted(self.cum, idx, side="right") - 1
        return self.starts[j] + (idx - self.cum[j])


def _increasing(rows) -> bool:
    """Whether the index array ``rows`` is strictly increasing (rows in their order, none twice)."""
    rows = np.asarray(rows)
    return rows.ndim == 1 and (len(rows) < 2 or bool(np.all(rows[1:] > rows[:-1])))


class _Gathered:
    """A sample array of a :class:`_Subset`: gathered from its source array when first read, then kept."""

    def __set_name__(self, owner, name):
        self.name = name

    def __get__(self, obj, objtype=None):
        if obj is None:
            return None          # the class attribute (a dataclass field's default)
        d = obj.__dict__
        if self.name not in d:
            source, rows = d["_lazy"][1][self.name]
            d[self.name] = source[rows.array() if isinstance(rows, _Ranges) else rows]
        return d[self.name]

    def __set__(self, obj, value):
        obj.__dict__[self.name] = value


class _Subset(FitData):
    """What :meth:`FitData.subset` returns: a FitData whose sample arrays are gathered when read."""


for _name in _ARRAYS:
    _g = _Gathered()
    _g.__set_name__(_Subset, _name)
    setattr(_Subset, _name, _g)


def _gather(a: np.ndarray, segments) -> np.ndarray:
    """The rows of ``a`` inside ``segments``, in their order: ``a[idx]`` for ``idx`` the segments'
    row indices one after the other (a new array; the same values), one slice per segment."""
    if not segments:
        return a[:0].copy()
    return np.concatenate([a[s.start:s.stop] for s in segments])
