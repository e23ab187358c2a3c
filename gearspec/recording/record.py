"""The :class:`Recording`: validated rows in canonical columns and SI units, the ledger of excluded
rows, and the time gaps that split a run into contiguous pieces (``CONTRACTS.md`` section 1)."""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..core.reduction import unique_ids
from ..errors import InputError
from ..gears import GearTrain, load_gear
from .readers import _SUFFIXES

__all__ = ["Recording", "auto_max_gap", "GAP_FACTOR", "GAP_QUANTILE"]


@dataclass
class Recording:
    """Validated measurements of one drive, possibly over several runs.

    ``data``: the usable rows in canonical columns (``t`` s, ``theta`` rad or m, ``torque`` Nm or N
    and/or ``current`` A, optional ``velocity``, ``load``, ``temperature``), an integer ``run``, and
    every other source column as an extra channel.  ``signal``: the channel analysed (:attr:`tau`).
    ``excluded``: rows excluded while loading, per reason, of ``n_read``; ``notes``: what was done to
    the data; ``meta``: scalars of the source files (e.g. ``gtau``).  ``max_gap``: longest step (s)
    taken as continuous sampling (None: per run, :func:`auto_max_gap`).
    """

    data: pd.DataFrame
    unit: str = "rad"
    signal: str = "torque"
    excluded: Counter = field(default_factory=Counter)
    n_read: int = 0
    notes: list[str] = field(default_factory=list)
    meta: dict = field(default_factory=dict)
    gear: GearTrain | None = None
    sources: list[str] = field(default_factory=list)
    max_gap: float | None = None
    _tau: np.ndarray | None = field(default=None, repr=False)
    _pieces_cache: tuple | None = field(default=None, repr=False)
    _auto_gaps: dict = field(default_factory=dict, repr=False)

    # ------------------------------------------------------------------ views
    @property
    def t(self) -> np.ndarray:
        return self.data["t"].to_numpy()

    @property
    def theta(self) -> np.ndarray:
        return self.data["theta"].to_numpy()

    @property
    def run(self) -> np.ndarray:
        return self.data["run"].to_numpy()

    @property
    def tau(self) -> np.ndarray:
        """The analysed signal as drive torque at the reference shaft (Nm, or N on a linear axis)."""
        if self._tau is None:
            raw = self.data[self.signal].to_numpy(dtype=float)
            self._tau = raw if self.signal == "torque" else np.asarray(self.gear.torque_from_current(raw))
        return self._tau

    def channel(self, name: str) -> np.ndarray:
        """Any column of the recording as an array (``KeyError`` names what is there)."""
        if name not in self.data:
            raise KeyError(f"no channel '{name}' (channels: {', '.join(self.data.columns)})")
        return self.data[name].to_numpy()

    @property
    def torque_unit(self) -> str:
        return "Nm" if self.unit == "rad" else "N"

    @property
    def speed_unit(self) -> str:
        return f"{self.unit}/s"

    def __len__(self) -> int:
        return len(self.data)

    def gap_limits(self) -> dict[int, float]:
        """The longest continuous step (s) per run: :attr:`max_gap`, else :func:`auto_max_gap`."""
        return self._gaps()[1]

    def pieces(self, max_gap: float | None = None) -> list[tuple[int, int, int]]:
        """Contiguous stretches ``(run, start, stop)``, split at runs and at steps in ``t`` longer than
        ``max_gap`` s (default :meth:`gap_limits`): nothing downstream joins data across a gap."""
        if max_gap is not None:
            return _split_pieces(self.t, self.run, lambda dt, r: float(max_gap))[0]
        return list(self._gaps()[0])

    def _gaps(self):
        key = (id(self.data), len(self.data), self.max_gap)
        if self._pieces_cache is None or self._pieces_cache[0] != key:
            if self.max_gap is not None:
                rule = lambda dt, r: float(self.max_gap)  # noqa: E731
            else:
                rule = lambda dt, r: self._auto_gaps[r] if r in self._auto_gaps else auto_max_gap(dt)  # noqa: E731
            self._pieces_cache = (key,) + _split_pieces(self.t, self.run, rule)
        return self._pieces_cache[1], self._pieces_cache[2]

    def summary(self) -> str:
        # the distinct runs in one pass when they are in order (the usual case), not a sorted copy of
        # every row's id (10^7 rows: 0.16 GB and half a second at the report's peak)
        n_runs = len(unique_ids(self.run)) if len(self) else 0
        dur = sum(self.t[e - 1] - self.t[s] for _, s, e in self.pieces() if e - s > 1)
        lines = [f"{len(self)} usable rows of {self.n_read} read, {n_runs} run(s), {dur:.4g} s in all; "
                 f"theta in {self.unit}, analysing {self.signal}"]
        if self.excluded:
            lines.append("excluded while loading: " + ", ".join(f"{k} {v}" for k, v in sorted(self.excluded.items())))
        lines += [f"note: {n}" for n in self.notes]
        return "\n".join(lines)

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_arrays(cls, *, gear=None, unit: str | None = None, signal: str | None = None,
                    source: str = "arrays", max_gap: float | None = None, **columns) -> "Recording":
        """A recording from arrays (``t=..., theta=..., torque=...``), validated like a file."""
        from .load import _assemble  # the loader builds Recordings: imported when called

        frame = pd.DataFrame({k: np.asarray(v) for k, v in columns.items() if v is not None})
        return _assemble([(source, frame, {})], gear=load_gear(gear), unit=unit, signal=signal, fs=None,
                         max_gap=max_gap)

    def save(self, path: str | Path) -> Path:
        """Write the recording in the recording format (.csv, .parquet or .npz by suffix)."""
        path = Path(path)
        kind = _SUFFIXES.get(path.suffix.lower())
        frame = self.data
        if kind == "csv":
            frame.to_csv(path, index=False, float_format="%.17g")
        elif kind == "parquet":
            frame.to_parquet(path, index=False)
        elif kind == "npz":
            np.savez_compressed(path, **{c: frame[c].to_numpy() for c in frame.columns})
        else:
            raise InputError(f"cannot write recordings as '{path.suffix}' (use .csv, .parquet or .npz)")
        return path


# ---------------------------------------------------------------------- gaps
#: a step longer than this many times the run's 99th-percentile step is a gap (see auto_max_gap)
GAP_FACTOR = 5.0
#: quantile of the steps that stands for "the longest regular step" of a run
GAP_QUANTILE = 0.99


def auto_max_gap(dt: np.ndarray) -> float:
    """The default longest continuous step (s) of a run with time steps ``dt`` (all > 0):
    ``GAP_FACTOR`` times the run's 99th-percentile step (lower order statistic, so the longest step
    is never in it).  A gap is an outlier of the run's own steps: a dropout is rare (under 1 %),
    while a logger with broadly spread steps (rows stored only at rest) is not split by its regular
    long steps."""
    dt = np.asarray(dt, dtype=float)
    if len(dt) == 0:
        return math.inf
    if len(dt) == 1:
        return GAP_FACTOR * float(dt[0])
    return GAP_FACTOR * float(np.quantile(dt, GAP_QUANTILE, method="lower"))


def _run_rows(runs: np.ndarray) -> list[tuple[int, np.ndarray]]:
    """``(run id, row indices)`` per run; fast when each run's rows are contiguous (the usual case)."""
    n = len(runs)
    if n == 0:
        return []
    cuts = np.flatnonzero(runs[1:] != runs[:-1]) + 1
    starts = np.concatenate(([0], cuts))
    ends = np.concatenate((cuts, [n]))
    ids = runs[starts]
    if len(set(ids.tolist())) == len(ids):
        return [(int(r), np.arange(a, b)) for r, a, b in zip(ids, starts, ends)]
    return [(int(r), np.flatnonzero(runs == r)) for r in np.unique(runs)]


def _logged_gap_limits(frame: pd.DataFrame) -> dict[int, float]:
    """:func:`auto_max_gap` per run from the distinct finite stamps of every row the file holds."""
    t = frame["t"].to_numpy(dtype=float)
    runs = frame["run"].to_numpy()
    out = {}
    for rid, idx in _run_rows(runs):
        tr = t[idx]
        tr = tr[np.isfinite(tr)]
        d = np.diff(tr)
        steps = d[d > 0] if np.all(d >= 0) else np.diff(np.unique(tr))
        out[int(rid)] = auto_max_gap(steps)
    return out


def _split_pieces(t: np.ndarray, run: np.ndarray, rule) -> tuple[list, dict]:
    """Pieces ``(run, start, stop)`` and the gap limit used per run (``rule(steps, run) -> seconds``)."""
    out: list = []
    limits: dict = {}
    if len(run) == 0:
        return out, limits
    cuts = np.flatnonzero(np.diff(run) != 0) + 1
    bounds = np.concatenate(([0], cuts, [len(run)]))
    for a, b in zip(bounds[:-1], bounds[1:]):
        dt = np.diff(t[a:b])
        limit = rule(dt, int(run[a]))
        limits[int(run[a])] = limit
        gaps = np.flatnonzero(dt > limit) + a + 1
        edges = np.concatenate(([a], gaps, [b]))
        out += [(int(run[a]), int(s), int(e)) for s, e in zip(edges[:-1], edges[1:]) if e > s]
    return out, limits
