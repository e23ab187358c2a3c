"""Recordings: load, map, scale and validate measured data (``CONTRACTS.md`` section 1).

A :class:`Recording` holds the rows that can be analysed, in canonical columns and SI units, plus a
ledger of every row that was excluded and why (``excluded``), and notes of everything that was done
to the data on the way in (unwrapping, current-to-torque conversion, ...).  Nothing is dropped
silently: ``n_read == len(data) + sum(excluded.values())``.

Bad input raises :class:`~gearspec.errors.InputError` with one sentence naming the file, the column
and the reason.  Doubtful input gives a :class:`~gearspec.errors.GearspecWarning`.
"""

from __future__ import annotations

import math
import warnings
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Mapping, Sequence

import numpy as np
import pandas as pd

from ..errors import InputError, warn
from ..gears import GearTrain, load_gear

__all__ = ["Recording", "load_recording", "CANONICAL", "parse_assignments", "auto_max_gap"]

CANONICAL = ("t", "theta", "torque", "current", "velocity", "load", "temperature", "run")
_NUMERIC_REQUIRED = ("t", "theta", "torque", "current")
_SUFFIXES = {".csv": "csv", ".txt": "csv", ".dat": "csv", ".tsv": "csv", ".parquet": "parquet",
             ".pq": "parquet", ".mat": "mat", ".npz": "npz"}
#: rows repeating a time stamp (and not copies of their predecessor) in at least this fraction of a
#: run's rows are read as a coarse logger clock and spread; rarer ones are isolated and excluded
CLOCK_BURST_FRACTION = 0.01
#: largest plausible speed of a rotary reference shaft, rad/s (about 19 000 rpm)
MAX_PLAUSIBLE_RAD_S = 2000.0
#: largest plausible speed of a linear axis, m/s
MAX_PLAUSIBLE_M_S = 10.0


@dataclass
class Recording:
    """Validated measurements of one drive, possibly over several runs.

    Attributes
    ----------
    data : pandas.DataFrame
        The usable rows: canonical columns (``t`` s, ``theta`` rad or m, ``torque`` Nm or N and/or
        ``current`` A, optional ``velocity``, ``load``, ``temperature``), an integer ``run`` column
        that is always present, and every other column of the source as an extra channel.
    unit : {"rad", "m"}
        Unit of ``theta``.
    signal : {"torque", "current"}
        The channel analysed; :attr:`tau` is it expressed as torque at the reference shaft.
    excluded : collections.Counter
        Rows excluded while loading, counted per reason.
    n_read : int
        Rows read from the sources.
    notes : list of str
        What was done to the data (unwrapping, conversions, gaps found, ...).
    meta : dict
        Scalars found in the source files (e.g. ``gtau`` in a .mat file).
    gear : GearTrain or None
    sources : list of str
    max_gap : float or None
        Longest time step (s) still taken as continuous sampling; a longer step is a gap that splits a
        run (:meth:`pieces`).  None: chosen per run from the data (:func:`auto_max_gap`).
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
            if self.signal == "torque":
                self._tau = self.data["torque"].to_numpy(dtype=float)
            else:
                self._tau = np.asarray(self.gear.torque_from_current(self.data["current"].to_numpy(dtype=float)))
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
        """The longest step (s) taken as continuous sampling, per run: :attr:`max_gap` when it is set,
        otherwise :func:`auto_max_gap` of the run's time steps."""
        return self._gaps()[1]

    def pieces(self, max_gap: float | None = None) -> list[tuple[int, int, int]]:
        """Contiguous stretches ``(run, start, stop)``: split at run boundaries and at time gaps.

        A gap is a step in ``t`` longer than ``max_gap`` seconds (default: the recording's rule,
        :meth:`gap_limits`); nothing downstream treats data on both sides of a gap as continuous.
        """
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
        n_runs = len(np.unique(self.run)) if len(self) else 0
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
    """The default longest continuous step (s) of a run with time steps ``dt`` (all > 0).

    A gap is an *outlier* of the run's own step distribution: a step more than ``GAP_FACTOR`` (5)
    times longer than the run's 99th-percentile step (the lower order statistic, so that at least
    the longest step is always left out of it).  A steady log (1 kHz with jitter) has its 99th
    percentile near the nominal period, so a dropout of more than about 5 periods splits it, as
    before; a logger whose steps are broadly spread (rows stored only at rest: many short steps and
    many long ones) has a long 99th percentile, so its regular long steps do not split it: only a
    pause far beyond any regular step does.  A dropout is rare (under 1 % of the steps); steps that
    are more common than that are part of how the file was logged.
    """
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


# ---------------------------------------------------------------------- parsing helpers
def parse_assignments(text: str | None, option: str, numeric: bool = False) -> dict:
    """Parse ``a=b,c=d`` (as given to ``--map`` and ``--scale``) into a dict."""
    out: dict = {}
    if not text:
        return out
    for part in str(text).split(","):
        part = part.strip()
        if not part:
            continue
        if "=" not in part:
            raise InputError(f"{option}: '{part}' is not of the form name=value")
        k, v = (s.strip() for s in part.split("=", 1))
        if not k or not v:
            raise InputError(f"{option}: '{part}' is not of the form name=value")
        if k in out:
            raise InputError(f"{option}: '{k}' is given twice ({k}={out[k]} and {k}={v}); give it once")
        if numeric:
            try:
                v = float(v)
            except ValueError:
                pass  # may name a scalar stored in the file (e.g. gtau in a .mat file)
        out[k] = v
    return out


def _names(names, limit: int = 12) -> str:
    """Names for a message, at most ``limit`` of them (a message listing thousands helps nobody)."""
    names = [str(n) for n in names]
    if len(names) <= limit:
        return ", ".join(names)
    return ", ".join(names[:limit]) + f", ... ({len(names)} in all)"


def _refuse_duplicate_names(path, names, where: str = "header") -> None:
    seen: dict = {}
    for raw in names:
        key = str(raw).strip()
        if key == "":
            continue  # pandas names an empty header field 'Unnamed: k'
        if key in seen:
            same = "" if str(raw) == seen[key] else f" ('{seen[key]}' and '{raw}' differ only in blanks)"
            raise InputError(f"{path}: column '{key}' appears twice in the {where}{same}; give every column "
                             "its own name")
        seen[key] = str(raw)


def _sniff_sep(path: Path) -> str:
    with open(path, "r", errors="replace") as fh:
        for line in fh:
            if line.strip():
                break
        else:
            return ","
    for sep in (",", ";", "\t"):
        if sep in line:
            return sep
    return r"\s+"


def _read_file(path: Path, sep: str | None, header: bool, names: Sequence[str] | None):
    """Read one file into (frame, meta)."""
    if not path.exists():
        raise InputError(f"{path}: no such file")
    if path.is_dir():
        raise InputError(f"{path}: is a folder (folders are expanded by load_recording)")
    if path.stat().st_size == 0:
        raise InputError(f"{path}: the file is empty")
    kind = _SUFFIXES.get(path.suffix.lower())
    if kind is None:
        raise InputError(f"{path}: unknown file type '{path.suffix}' (accepted: .csv, .parquet, .mat, .npz)")
    meta: dict = {}
    if kind == "csv":
        if sep == "":
            raise InputError(f"{path}: the separator given with --sep is empty")
        given_sep = sep
        sep = sep if sep is not None else _sniff_sep(path)
        if sep in (" ", "whitespace", r"\s+"):
            sep = r"\s+"
        if names is not None:
            _refuse_duplicate_names(path, names, "--names")
        if names is not None and header:
            raise InputError(f"{path}: --names is for files without a header row; add --no-header")
        if not header and names is None:
            raise InputError(f"{path}: --no-header needs --names to say what the columns are")
        try:
            frame = _read_csv(path, sep, header, names)
        except pd.errors.EmptyDataError:
            raise InputError(f"{path}: the file is empty") from None
        except (pd.errors.ParserError, UnicodeDecodeError) as exc:
            raise InputError(f"{path}: cannot be read as a table ({str(exc).splitlines()[0]}); "
                             "check --sep") from None
        frame.columns = [str(c).strip() for c in frame.columns]
        if frame.shape[1] == 1 and len(frame):
            how = "with the separator sniffed" if given_sep is None else f"with --sep '{given_sep}'"
            raise InputError(f"{path}: only one column ('{str(frame.columns[0])[:60]}') was found {how}; "
                             "if the file uses another separator, give --sep")
    elif kind == "parquet":
        try:
            import pyarrow.parquet as pq

            _refuse_duplicate_names(path, pq.read_schema(path).names, "file's schema")
            frame = pd.read_parquet(path)
        except InputError:
            raise
        except Exception as exc:  # pyarrow raises many types, with messages of many lines
            raise InputError(f"{path}: cannot be read as parquet ({str(exc).strip().splitlines()[0][:200]})") from None
        if not isinstance(frame.index, pd.RangeIndex) or any(n is not None for n in frame.index.names):
            frame = frame.reset_index()  # a stored index (e.g. time) is a column like any other
        frame.columns = [str(c) for c in frame.columns]
    elif kind == "npz":
        try:
            with np.load(path, allow_pickle=False) as z:
                arrays = {k: z[k] for k in z.files}
        except Exception as exc:
            raise InputError(f"{path}: cannot be read as .npz ({exc})") from None
        frame, meta = _vectors_to_frame(path, arrays)
    else:  # mat
        import scipy.io

        try:
            arrays = {k: v for k, v in scipy.io.loadmat(path).items() if not k.startswith("__")}
        except NotImplementedError:
            raise InputError(f"{path}: MATLAB v7.3 (HDF5) files are not supported; save it with "
                             "save(..., '-v7') or export csv") from None
        except Exception as exc:
            raise InputError(f"{path}: cannot be read as a MATLAB file ({exc})") from None
        frame, meta = _vectors_to_frame(path, arrays)
    if len(frame) == 0:
        raise InputError(f"{path}: the file has a header but no data rows")
    return frame, meta


def _read_csv(path: Path, sep: str, header: bool, names: Sequence[str] | None) -> pd.DataFrame:
    """pandas.read_csv that never shifts columns silently.

    Left to itself, pandas takes the leading columns as the index when the header (or ``names``) has
    fewer fields than the data rows, so every column would get its neighbour's values.  A trailing
    separator at the end of every line (an empty last field) is accepted; any other extra field is
    refused.
    """
    kw = dict(sep=sep, skipinitialspace=True)
    if len(sep) > 1 and sep != r"\s+":
        kw["engine"] = "python"  # a separator of several characters is a regular expression to pandas
    if not header:
        frame = pd.read_csv(path, header=None, **kw)
        if names is not None:
            if frame.shape[1] == len(names) + 1 and frame.iloc[:, -1].isna().all():
                frame = frame.iloc[:, :-1]  # a separator at the end of every line
            if frame.shape[1] != len(names):
                raise InputError(f"{path}: --names gives {len(names)} names but the file has {frame.shape[1]} columns")
            frame.columns = list(names)
        return frame
    header_row = pd.read_csv(path, header=None, nrows=1, dtype=str, keep_default_na=False, **kw)
    _refuse_duplicate_names(path, header_row.iloc[0].tolist() if len(header_row) else [])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", pd.errors.ParserWarning)
        frame = pd.read_csv(path, header=0, index_col=False, **kw)
    if any(issubclass(w.category, pd.errors.ParserWarning) for w in caught):
        # data rows have more fields than the header: allowed only if the extra ones are all empty
        rows = pd.read_csv(path, header=None, skiprows=1, **kw)
        if rows.iloc[:, frame.shape[1]:].notna().any().any():
            raise InputError(f"{path}: the header row names {frame.shape[1]} columns but data rows have "
                             f"{rows.shape[1]} fields; give every column a name in the header, or check --sep")
    return frame


def _vectors_to_frame(path: Path, arrays: Mapping[str, np.ndarray]):
    """Vectors of the common (longest) length become columns, scalars become meta."""
    vectors, meta, other = {}, {}, []
    for k, v in arrays.items():
        v = np.asarray(v)
        if v.dtype.kind not in "biuf":
            other.append(k)
            continue
        if v.size == 1:
            meta[k] = float(v.reshape(()))
        elif v.ndim == 1 or (v.ndim == 2 and 1 in v.shape):
            vectors[k] = v.reshape(-1)
        elif v.ndim == 2:
            if v.shape[1] > v.shape[0]:
                warn(f"{path}: variable '{k}' is a {v.shape[0]} x {v.shape[1]} matrix; read as {v.shape[1]} rows of "
                     f"{v.shape[0]} columns ({k}_0 ... {k}_{v.shape[0] - 1}), one row per sample")
                v = v.T
            for j in range(v.shape[1]):
                vectors[f"{k}_{j}"] = v[:, j]
        else:
            other.append(k)
    if not vectors:
        raise InputError(f"{path}: holds no numeric vectors (variables: {_names(arrays) or 'none'})")
    n = max(len(v) for v in vectors.values())
    short = sorted(k for k, v in vectors.items() if len(v) != n)
    frame = pd.DataFrame({k: v for k, v in vectors.items() if len(v) == n})
    for k in short:
        meta[k] = vectors[k]
    if short:
        warn(f"{path}: variables {_names(short)} are not vectors of length {n}; kept in meta, not as columns")
    if other:
        warn(f"{path}: variables {_names(other)} are not numeric vectors or matrices (text, structs, cells, "
             "3-D arrays); ignored")
    return frame, meta


def _first_bad_cell(series: pd.Series) -> tuple[int, str] | None:
    coerced = pd.to_numeric(series, errors="coerce")
    bad = coerced.isna() & series.notna() & (series.astype(str).str.strip() != "")
    if not bad.any():
        return None
    i = int(np.flatnonzero(bad.to_numpy())[0])
    return i + 1, str(series.iloc[i])


# ---------------------------------------------------------------------- main entry point
def load_recording(paths: "str | Path | Iterable[str | Path]", gear=None, *,
                   map: Mapping[str, str] | str | None = None, scale: Mapping[str, float | str] | str | None = None,
                   fs: float | None = None, sep: str | None = None, header: bool = True,
                   names: Sequence[str] | str | None = None, signal: str | None = None,
                   max_bad_fraction: float = 0.05, max_gap: float | None = None) -> Recording:
    """Load one or more recording files (or folders of them) into a validated :class:`Recording`.

    Parameters
    ----------
    paths : path or list of paths
        ``.csv`` (``.txt``, ``.dat``, ``.tsv``), ``.parquet``, ``.mat`` (v5/v7) or ``.npz`` files, or
        folders holding them.  Each file is one experiment: it gets its own ``run`` unless it has a
        ``run`` column.
    gear : GearTrain, preset name or TOML path, optional
        Gives the unit of ``theta`` and the torque constant for ``current``.
    map : dict or "canonical=source,..."
        Source column names for canonical columns, e.g. ``{"theta": "qm", "torque": "vir"}``.
    scale : dict or "column=factor,..."
        Factors applied after mapping, e.g. ``{"torque": 35.15}``; a factor may name a scalar stored
        in the file (``torque=gtau`` for the EMPS .mat files).
    fs : float, optional
        Sample rate in Hz, for files without a time column.
    sep, header, names
        For csv: separator (sniffed when None; "whitespace" for runs of blanks), whether the first
        row is a header, and the column names when it is not.
    signal : {"torque", "current"}, optional
        The channel to analyse when both are present (default torque).
    max_bad_fraction : float
        Rows with NaN/inf, duplicate or backward times are excluded and counted; if more than this
        fraction of a file's rows are bad, the file is refused instead.
    max_gap : float, optional
        A time step longer than this (s) is a gap that splits a run.  Default: chosen per run from
        its own step distribution (:func:`auto_max_gap`: 5 x its 99th-percentile step) and reported
        in ``notes``.
    """
    if isinstance(paths, (str, Path)):
        paths = [paths]
    files: list[Path] = []
    for p in paths:
        p = Path(p)
        if p.is_dir():
            found = sorted(q for q in p.iterdir() if q.suffix.lower() in _SUFFIXES)
            if not found:
                raise InputError(f"{p}: the folder holds no recording files (.csv, .parquet, .mat, .npz)")
            files += found
        else:
            files.append(p)
    if not files:
        raise InputError("no recording files given")
    gear = load_gear(gear)
    mapping = parse_assignments(map, "--map") if isinstance(map, str) or map is None else dict(map)
    scaling = parse_assignments(scale, "--scale", numeric=True) if isinstance(scale, str) or scale is None else dict(scale)
    if isinstance(names, str):
        names = [n.strip() for n in names.split(",")]
    bad_canon = [k for k in mapping if k not in CANONICAL]
    if bad_canon:
        raise InputError(f"--map: '{bad_canon[0]}' is not a canonical column ({', '.join(CANONICAL)})")
    by_source: dict = {}
    for canon, src in mapping.items():
        if src in by_source:
            raise InputError(f"--map: column '{src}' is given for both {by_source[src]} and {canon}; "
                             "each source column can be mapped to one canonical column only")
        by_source[src] = canon
    parts = []
    for path in files:
        frame, meta = _read_file(path, sep, header, names)
        frame = _map_and_scale(path, frame, meta, mapping, scaling)
        parts.append((str(path), frame, meta))
    return _assemble(parts, gear=gear, unit=None, signal=signal, fs=fs, max_bad_fraction=max_bad_fraction,
                     max_gap=max_gap)


def _map_and_scale(path: Path, frame: pd.DataFrame, meta: dict, mapping: dict, scaling: dict) -> pd.DataFrame:
    cols = list(frame.columns)
    rename = {}
    for canon, src in mapping.items():
        if src not in frame.columns:
            raise InputError(f"{path}: no column '{src}' (given in --map {canon}={src}); columns are: {_names(cols)}")
        rename[src] = canon
    clash = [c for c in rename.values() if c in frame.columns and c not in rename]
    if clash:
        # the file already has a column with the canonical name: keep it as an extra channel
        frame = frame.rename(columns={c: f"{c}_original" for c in clash})
    frame = frame.rename(columns=rename)
    for col, factor in scaling.items():
        if col not in frame.columns:
            hint = "".join(f"; --scale applies after --map: use --scale {canon}=..." for canon, src in mapping.items()
                           if src == col)
            raise InputError(f"{path}: --scale names column '{col}', which is not there "
                             f"(columns: {_names(frame.columns)}){hint}")
        given = factor
        if isinstance(factor, str):
            try:
                factor = float(factor)
            except ValueError:
                if factor not in meta:
                    raise InputError(f"{path}: --scale {col}={factor}: '{factor}' is neither a number nor a scalar "
                                     "stored in the file") from None
                if np.size(meta[factor]) != 1:
                    raise InputError(f"{path}: --scale {col}={factor}: '{factor}' holds {np.size(meta[factor])} values, "
                                     "not a single number") from None
                factor = float(np.asarray(meta[factor]).reshape(()))
        try:
            factor = float(factor)
        except (TypeError, ValueError):
            raise InputError(f"{path}: --scale {col}={given!r}: the factor is not a number") from None
        if not math.isfinite(factor) or factor == 0:
            raise InputError(f"{path}: --scale {col}={given}: the factor must be a finite, non-zero number, got {factor:g}")
        frame[col] = _numeric_column(path, frame, col) * factor
    return frame


def _numeric_column(path, frame: pd.DataFrame, col: str) -> pd.Series:
    s = frame[col]
    if s.dtype.kind in "biuf":
        return s.astype(float)
    bad = _first_bad_cell(s)
    if bad is not None:
        line, value = bad
        raise InputError(f"{path}: column '{col}', data row {line}: '{value}' is not a number")
    return pd.to_numeric(s, errors="coerce").astype(float)


def _assemble(parts, *, gear: GearTrain | None, unit: str | None, signal: str | None, fs: float | None,
              max_bad_fraction: float = 0.05, max_gap: float | None = None) -> Recording:
    unit = unit or (gear.unit if gear is not None else "rad")
    if max_gap is not None:
        try:
            max_gap = float(max_gap)
        except (TypeError, ValueError):
            raise InputError(f"--max-gap must be a time in seconds, got {max_gap!r}") from None
        if not (math.isfinite(max_gap) and max_gap > 0):
            raise InputError(f"--max-gap must be a positive time in seconds, got {max_gap:g}")
    if unit not in ("rad", "m"):
        raise InputError(f"unit must be 'rad' or 'm', got '{unit}'")
    if fs is not None and not (math.isfinite(fs) and fs > 0):
        raise InputError(f"--fs must be a positive sample rate in Hz, got {fs}")
    if signal not in (None, "torque", "current"):
        raise InputError(f"--signal must be 'torque' or 'current', got '{signal}'")
    excluded: Counter = Counter()
    notes: list[str] = []
    frames = []
    meta_all: dict = {}
    n_read = 0
    sig_used = None
    run_offset = 0
    auto_gaps: dict = {}
    for path, frame, meta in parts:
        frame = frame.reset_index(drop=True)  # index = data row - 1, kept through exclusions for messages
        n_read += len(frame)
        meta_all.update(meta)
        cols = list(frame.columns)
        # --- required columns
        if "theta" not in frame:
            raise InputError(f"{path}: no column 'theta' (position); columns are: {_names(cols)}; "
                             "name the position column with --map theta=NAME")
        has_t = "t" in frame
        if not has_t and fs is None:
            raise InputError(f"{path}: no time column 't' and no --fs; columns are: {_names(cols)}; "
                             "map the time column with --map t=NAME or give the sample rate with --fs HZ")
        if has_t and fs is not None:
            warn(f"{path}: has a time column 't'; --fs {fs:g} is ignored")
        if "torque" not in frame and "current" not in frame:
            raise InputError(f"{path}: neither 'torque' nor 'current' is there; columns are: {_names(cols)}; "
                             "map one with --map torque=NAME or --map current=NAME")
        this_sig = signal or ("torque" if "torque" in frame else "current")
        if this_sig not in frame:
            raise InputError(f"{path}: --signal {this_sig} but the file has no '{this_sig}' column")
        if sig_used is not None and this_sig != sig_used:
            raise InputError(f"{path}: analyses '{this_sig}' but earlier files analyse '{sig_used}'; "
                             "give --signal to choose one for all files")
        sig_used = this_sig
        if this_sig == "current":
            if gear is None or gear.torque_constant is None:
                raise InputError(f"{path}: the analysed signal is motor current, which needs the gear spec's "
                                 "torque_constant (Nm/A); give --gear with torque_constant, or record torque")
        for col in ("t", "theta", "torque", "current", "velocity", "load", "temperature", "run"):
            if col in frame:
                frame[col] = _numeric_column(path, frame, col)
        n = len(frame)
        if not has_t:
            frame.insert(0, "t", np.arange(n) / fs)
            notes.append(f"{path}: no time column; t = sample index / {fs:g} Hz")
        # --- run ids
        if "run" in frame:
            r = frame["run"].to_numpy()
            ok = np.isfinite(r)
            if not ok.all():
                raise InputError(f"{path}: column 'run', data row {int(np.flatnonzero(~ok)[0]) + 1}: run ids must be integers, not NaN")
            if np.any(r != np.round(r)):
                raise InputError(f"{path}: column 'run' holds non-integer values; run ids must be integers")
            uniq, inv = np.unique(r.astype(np.int64), return_inverse=True)
            frame["run"] = inv + run_offset
            if len(parts) > 1:
                notes.append(f"{path}: runs {list(uniq)} renumbered {run_offset}..{run_offset + len(uniq) - 1}")
            run_offset += len(uniq)
        else:
            frame["run"] = run_offset
            run_offset += 1
        frame["run"] = frame["run"].astype(np.int64)
        auto_gaps.update(_logged_gap_limits(frame))
        # --- NaN / inf in the columns the analysis needs
        need = ["t", "theta", this_sig]
        finite = np.ones(n, bool)
        for col in need:
            v = frame[col].to_numpy()
            fin = np.isfinite(v)
            if not fin.any():
                raise InputError(f"{path}: column '{col}' holds no finite number")
            frac = 1 - fin.mean()
            if frac > max_bad_fraction:
                raise InputError(f"{path}: column '{col}' is NaN or inf in {frac:.0%} of rows "
                                 f"(first at data row {int(np.flatnonzero(~fin)[0]) + 1}); too many to exclude")
            finite &= fin
        n_bad = int((~finite).sum())
        if n_bad:
            excluded["nan_or_inf"] += n_bad
            warn(f"{path}: {n_bad} rows with NaN or inf in {', '.join(need)} excluded")
            frame = frame.loc[finite]
        # --- time: backward steps, copies, repeated stamps of a coarse clock; per run
        frame = _clean_times(path, frame, this_sig, excluded, notes, max_bad_fraction)
        # --- saturation of the analysed signal
        frame, n_sat = _exclude_saturation(path, frame, this_sig)
        if n_sat:
            excluded["saturation"] += n_sat
        # --- position: unwrap, plausibility
        frame = _unwrap_theta(path, frame, unit, notes)
        frames.append(frame)
    data = pd.concat(frames, ignore_index=True) if len(frames) > 1 else frames[0].reset_index(drop=True)
    rec = Recording(data=data, unit=unit, signal=sig_used, excluded=excluded, n_read=n_read, notes=notes,
                    meta=meta_all, gear=gear, sources=[p for p, _, _ in parts], max_gap=max_gap,
                    _auto_gaps=auto_gaps)
    _check_time_unit(rec)
    _check_motion(rec)
    _check_signal(rec)
    _check_units(rec)
    if sig_used == "current":
        factor = float(gear.torque_from_current(1.0))   # the conversion tau uses, said once
        rec.notes.append(f"torque = {factor:g} Nm/A x current (torque constant {gear.torque_constant:g} Nm/A"
                         + (f" x ratio {gear.total_ratio:g}, ideal gear" if gear.reference == "output" else "") + ")")
    n_gaps = len(rec.pieces()) - len(rec.gap_limits())
    if n_gaps:
        rec.notes.append(_gap_note(rec, n_gaps))
    return rec


def _gap_note(rec: Recording, n_gaps: int) -> str:
    limits = [v for v in rec.gap_limits().values() if math.isfinite(v)]
    lo, hi = min(limits), max(limits)
    span = f"{lo:.3g} s" if math.isclose(lo, hi, rel_tol=1e-3) else f"{lo:.3g} to {hi:.3g} s (per run)"
    how = ("--max-gap" if rec.max_gap is not None else
           f"{GAP_FACTOR:g} x the run's {GAP_QUANTILE:.0%} step; set it with --max-gap")
    return f"gaps longer than {span} ({how}) split runs: {n_gaps} gap(s); nothing is analysed across them"


def _clean_times(path, frame: pd.DataFrame, sig: str, excluded: Counter, notes: list[str],
                 max_bad_fraction: float) -> pd.DataFrame:
    """Backward and repeated time stamps, per run.

    * A row stamped before an earlier row (``t`` below the running maximum) is excluded
      (``non_increasing_time``); more than ``max_bad_fraction`` of them is refused (a file holding
      several experiments without a ``run`` column).
    * A row that repeats the previous row's stamp *and* its position and signal is a copy of it:
      excluded (``duplicate_time``).
    * Other rows that repeat a stamp are samples of a logger whose clock is coarser than its sample
      rate.  When they are systematic (at least ``CLOCK_BURST_FRACTION`` of the run's rows), each
      burst of rows sharing a stamp is spread evenly from that stamp towards the next distinct one
      (no further than the run's typical sample period), with a note; nothing is lost.  When they
      are isolated (rarer than that) there is no clock to read them by: excluded (``duplicate_time``).
    * Times in whole seconds of a fast log (many repeats, distinct stamps 1 s or more apart) are the
      unit mistake they look like: refused.
    """
    t = frame["t"].to_numpy()
    runs = frame["run"].to_numpy()
    cols = [frame[c].to_numpy() for c in ("theta", sig)]
    keep = np.ones(len(frame), bool)
    new_t = t.astype(float, copy=True)
    n_spread = 0
    n_copy = n_isolated = n_back = 0
    for rid, idx in _run_rows(runs):
        tr = t[idx]
        prev_max = np.concatenate(([-np.inf], np.maximum.accumulate(tr)[:-1]))
        back = tr < prev_max
        if back.mean() > max_bad_fraction:
            first = idx[np.flatnonzero(back)[0]]
            raise InputError(
                f"{path}: column 't' goes backwards in {int(back.sum())} of {len(tr)} rows (first at data "
                f"row {frame.index[first] + 1}: t = {t[first]:g} after {prev_max[np.flatnonzero(back)[0]]:g}); if the file holds "
                "several experiments, give each its own file or a 'run' column")
        keep[idx[back]] = False
        n_back += int(back.sum())
        ok = idx[~back]  # non-decreasing stamps from here on
        to = t[ok]
        rep = np.concatenate(([False], to[1:] == to[:-1]))
        if not rep.any():
            continue
        same = np.concatenate(([False], np.all([c[ok][1:] == c[ok][:-1] for c in cols], axis=0)))
        copy = rep & same
        keep[ok[copy]] = False
        n_copy += int(copy.sum())
        ok, to, rep = ok[~copy], to[~copy], rep[~copy]
        n_rep = int(rep.sum())
        if not n_rep:
            continue
        distinct = np.unique(to)
        med_step = float(np.median(np.diff(distinct))) if len(distinct) > 1 else math.inf
        if med_step >= 1.0 and n_rep > max_bad_fraction * len(idx):
            raise InputError(f"{path}: column 't' repeats the previous time in {n_rep} of {len(idx)} rows; "
                             "is the time column in the right unit (not rounded to whole seconds)?")
        if n_rep < CLOCK_BURST_FRACTION * len(idx) or len(distinct) < 2:
            keep[ok[rep]] = False
            n_isolated += n_rep
            continue
        # bursts: rows [s, e) share the stamp to[s]; spread them towards the next distinct stamp
        starts = np.flatnonzero(~rep)
        ends = np.concatenate((starts[1:], [len(to)]))
        size = ends - starts
        nxt = np.concatenate((to[starts[1:]], [np.nan]))
        span = nxt - to[starts]
        period = float(np.median(span[:-1] / size[:-1]))  # the typical sample period of the run
        even = span / size
        # a burst before a gap (or the last one) takes the typical period, not the gap
        step = np.where(np.isfinite(even) & (even <= 2 * period), even, period)
        offset = np.arange(len(to)) - np.repeat(starts, size)
        new_t[ok] = to + offset * np.repeat(step, size)
        n_spread += n_rep
    n_drop = n_copy + n_isolated
    if n_copy:
        excluded["duplicate_time"] += n_copy
    if n_isolated:
        excluded["duplicate_time"] += n_isolated
    if n_back:
        excluded["non_increasing_time"] += n_back
    if n_drop or n_back:
        warn(f"{path}: {n_drop + n_back} rows with duplicate or backward time excluded")
    if n_spread:
        notes.append(f"{path}: {n_spread} rows repeat the time stamp of the row before (a logger clock coarser than "
                     "its sample rate); each burst of equal stamps is spread evenly up to the next stamp, no row lost")
    if n_spread or not keep.all():
        frame = frame.copy() if keep.all() else frame.loc[keep].copy()
        frame["t"] = new_t[keep]
    return frame


def _exclude_saturation(path, frame: pd.DataFrame, col: str):
    v = frame[col].to_numpy()
    n = len(v)
    if n < 100:
        return frame, 0
    # Saturation shows as a signal that varies from sample to sample but sticks at its extreme.  A
    # signal that often holds its value anyway (noise-free simulation, coarse quantisation) sits at
    # its extremes by nature: that is no evidence of saturation, and nothing is excluded.
    at_end = (v == v.max()) | (v == v.min())
    inner = ~at_end[:-1] & ~at_end[1:]
    if inner.sum() < 20 or np.mean(np.diff(v)[inner] == 0) > 0.2:
        return frame, 0
    mask = np.zeros(n, bool)
    for extreme in (v.max(), v.min()):
        at = v == extreme
        count = int(at.sum())
        if count < max(5, 0.002 * n):
            continue
        # longest run of consecutive samples at the extreme
        edges = np.diff(np.concatenate(([0], at.astype(np.int8), [0])))
        longest = int((np.flatnonzero(edges == -1) - np.flatnonzero(edges == 1)).max())
        if longest >= 5:
            mask |= at
    n_sat = int(mask.sum())
    if n_sat:
        warn(f"{path}: column '{col}' sits at its extreme value in {n_sat} rows; they look saturated and are excluded")
        frame = frame.loc[~mask]
    return frame, n_sat


def _unwrap_theta(path, frame: pd.DataFrame, unit: str, notes: list[str]) -> pd.DataFrame:
    if unit != "rad":
        return frame
    theta = frame["theta"].to_numpy(dtype=float)
    runs = frame["run"].to_numpy()
    out = theta.copy()
    changed = False
    for rid, idx in _run_rows(runs):
        th = theta[idx]
        if len(th) < 3:
            continue
        d = np.diff(th)
        lo, hi = th.min(), th.max()
        for period, what in ((2 * np.pi, "2*pi"), (360.0, "360")):
            big = np.abs(d) > 0.5 * period
            if not big.any() or hi - lo > period * 1.02:
                continue
            if not np.all(np.abs(np.abs(d[big]) - period) < 0.25 * period):
                continue
            # typical step far below the jumps: it is a wrap, not fast motion
            typical = np.median(np.abs(d[~big])) if (~big).any() else 0.0
            if typical > 0.05 * period:
                continue
            out[idx] = np.unwrap(th, period=period)
            changed = True
            msg = f"{path}: theta wraps into a range of {what} ({int(big.sum())} wraps in run {rid}); unwrapped"
            if what == "360":
                warn(f"{path}: theta wraps at 360: it looks like degrees, not radians; unwrapped with period 360, "
                     "but frequencies will be per degree: convert with --scale theta=0.0174533")
            notes.append(msg)
            break
    if changed:
        frame = frame.copy()
        frame["theta"] = out
    return frame


def _check_time_unit(rec: Recording) -> None:
    t = rec.t
    if len(t) < 2:
        raise InputError(f"{', '.join(rec.sources)}: fewer than two usable rows")
    dts = []
    for _, s, e in rec.pieces():
        if e - s > 1:
            dts.append(np.median(np.diff(t[s:e])))
    med = float(np.median(dts)) if dts else 0.0
    if dts and med < MIN_TIME_STEP:
        raise InputError(f"{', '.join(rec.sources)}: column 't' steps by {med:.3g} s (median), faster than any logger "
                         "samples; the time column is in the wrong unit (--scale t=...) or is not a time")
    if med >= 1.0:
        warn(f"{', '.join(rec.sources)}: the median time step is {med:g} s; if 't' is in ms or sample numbers, "
             "use --scale t=0.001 or --fs HZ")


#: shortest plausible sample period, s (a 1 GHz logger): below it the time column is not in seconds
MIN_TIME_STEP = 1e-9
#: smallest change of position any encoder resolves (rad or m): a 32-bit encoder's count is 1.5e-9 rad,
#: an interferometer's 1e-12 m; a theta whose whole range is below this is in the wrong unit or noise
MIN_POSITION_RANGE = 1e-12
#: a signal whose range is below this fraction of its magnitude (or below 1e-15 absolute) never changes
MIN_SIGNAL_CHANGE = 1e-12


def _check_signal(rec: Recording) -> None:
    """The analysed channel must change: a constant (or denormal) torque holds no friction to fit."""
    col = rec.signal
    v = rec.data[col].to_numpy(dtype=float)
    src = ", ".join(rec.sources)
    rng = float(np.ptp(v))
    if rng == 0:
        raise InputError(f"{src}: column '{col}' never changes (always {v[0]:g}); it holds no friction to analyse: "
                         "check which column is mapped to it")
    if rng < max(1e-15, MIN_SIGNAL_CHANGE * float(np.max(np.abs(v)))):
        raise InputError(f"{src}: column '{col}' changes only by {rng:.3g} in all (below any sensor's resolution); "
                         "check the column and its unit (--scale)")


def _check_motion(rec: Recording) -> None:
    theta = rec.theta
    src = ", ".join(rec.sources)
    if np.ptp(theta) == 0:
        raise InputError(f"{src}: column 'theta' never changes (always {theta[0]:g}): the drive did not move, "
                         "or the wrong column is mapped to theta")
    if np.ptp(theta) < MIN_POSITION_RANGE:
        raise InputError(f"{src}: column 'theta' moves by only {np.ptp(theta):.3g} {rec.unit} in all, less than any "
                         "encoder step: the drive did not move, or theta is in the wrong unit (--scale)")
    moved = False
    pieces = rec.pieces()
    longest = max(e - s for _, s, e in pieces)
    if longest < 20:
        lost = ", ".join(f"{k} {v}" for k, v in sorted(rec.excluded.items())) or "none"
        raise InputError(f"{src}: no stretch of at least 20 contiguous usable rows (longest {longest}, "
                         f"{len(rec)} usable of {rec.n_read}; excluded: {lost}); nothing can be analysed")
    for _, s, e in pieces:
        th = theta[s:e]
        if len(th) < 20:
            continue
        d = np.diff(th)
        nz = np.abs(d[d != 0])
        quantum = nz.min() if len(nz) else 0.0
        noise = 1.4826 * np.median(np.abs(np.diff(d) - np.median(np.diff(d)))) / math.sqrt(6) if len(d) > 2 else 0.0
        # two block lengths (not multiples of each other): a back-and-forth motion whose period is the
        # block length returns to the same place every block and would look like no motion at one
        for block in {max(10, len(th) // 200), max(10, len(th) // 1409)}:
            disp = np.abs(th[block::block] - th[:-block:block]) if len(th) > block else np.array([abs(th[-1] - th[0])])
            # slow motion seen by a coarse encoder moves less than a few counts per block: compare block
            # means too (averaging takes jitter down, a steady drift stays)
            nb = len(th) // block
            means = th[:nb * block].reshape(nb, block).mean(axis=1) if nb > 1 else th[:1]
            if max(disp.max(initial=0.0), np.ptp(means)) > 5 * max(noise * math.sqrt(2), quantum):
                moved = True
                break
        if moved:
            break
    if not moved:
        raise InputError(f"{src}: no motion: 'theta' only jitters (range {np.ptp(theta):.3g} {rec.unit}) without "
                         "moving; friction needs the drive to turn")


def _check_units(rec: Recording) -> None:
    theta, t = rec.theta, rec.t
    speeds = []
    for _, s, e in rec.pieces():
        if e - s < 20:
            continue
        step = max(1, (e - s) // 500)
        th, tt = theta[s:e:step], t[s:e:step]
        speeds.append(np.abs(np.diff(th) / np.diff(tt)))
    if not speeds:
        return
    v99 = float(np.percentile(np.concatenate(speeds), 99))
    src = ", ".join(rec.sources)
    if rec.unit == "rad" and v99 > MAX_PLAUSIBLE_RAD_S:
        warn(f"{src}: theta moves at up to {v99:.3g} rad/s ({v99 * 60 / (2 * math.pi):.3g} rpm), faster than any robot "
             "drive; if it is in degrees use --scale theta=0.0174533, if in encoder counts scale by 2*pi/counts")
    if rec.unit == "m" and v99 > MAX_PLAUSIBLE_M_S:
        warn(f"{src}: theta moves at up to {v99:.3g} m/s; if it is in mm use --scale theta=0.001")
