"""Reading recording files: csv (separator sniffed, header checked), parquet, .mat (v5/v7) and .npz,
each into a table of columns plus the scalars the file holds; nothing is mapped or cleaned here."""

from __future__ import annotations

import re
import warnings
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
import pandas as pd

from ..errors import InputError, warn
from .csvchunks import read_numeric_chunks

_SUFFIXES = {".csv": "csv", ".txt": "csv", ".dat": "csv", ".tsv": "csv", ".parquet": "parquet",
             ".pq": "parquet", ".mat": "mat", ".npz": "npz"}


#: csv files at least this large (bytes) return the parser's freed memory to the system after the read
_TRIM_BYTES = 64 << 20
#: csv files with a header row at least this large (bytes) are read in chunks when they hold numbers
#: only (:func:`.csvchunks.read_numeric_chunks`): the same frame with half the peak memory
_CHUNKED_BYTES = 64 << 20


def _release_freed_memory() -> bool:
    """Hand the heap memory freed after a large read back to the system (glibc's ``malloc_trim``).

    pandas' parallel csv reader parses in threads; what their chunks used stays in those threads'
    heaps after it is freed and counts in the process's resident memory: 0.72 GB held after
    reading a 10^7-row file of 320 MB, 0.44 GB after the trim.  Returns whether a trim ran (False
    where the C library has no ``malloc_trim``: nothing else is tried)."""
    import ctypes
    import ctypes.util

    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        trim = libc.malloc_trim
    except (OSError, AttributeError):
        return False
    trim.argtypes = [ctypes.c_size_t]
    trim(0)
    return True


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


def _sniff_sep(path: Path, decimal: str | None = None) -> str:
    """The column separator of a csv from its first non-blank line: ',', ';', a tab or blanks.  A line
    holding both ';' and a digit, a comma and a digit (0,5;1,25) is ';'-separated with decimal commas."""
    with open(path, "r", errors="replace") as fh:
        for line in fh:
            if line.strip():
                break
        else:
            return ","
    if ";" in line and (decimal == "," or re.search(r"\d,\d", line)):
        return ";"
    return next((sep for sep in (",", ";", "\t") if sep in line and not (sep == "," and decimal == ",")), r"\s+")


def _read_file(path: Path, sep: str | None, header: bool, names: Sequence[str] | None, decimal: str | None = None):
    """Read one file into (frame, meta); ``decimal``: the csv's decimal separator ("." when None, or ",")."""
    if not path.exists():
        raise InputError(f"{path}: no such file")
    if path.is_dir():
        raise InputError(f"{path}: is a folder (folders are expanded by load_recording)")
    if path.stat().st_size == 0:
        raise InputError(f"{path}: the file is empty")
    kind = _SUFFIXES.get(path.suffix.lower())
    if kind is None:
        raise InputError(f"{path}: unknown file type '{path.suffix}' (accepted: .csv, .parquet, .mat, .npz); "
                         "ROS bags: .bag, .mcap, .db3 or a rosbag2 folder with metadata.yaml")
    meta: dict = {}
    if kind == "csv":
        if sep == "":
            raise InputError(f"{path}: the separator given with --sep is empty")
        given_sep = sep
        sep = sep if sep is not None else _sniff_sep(path, decimal)
        if sep in (" ", "whitespace", r"\s+"):
            sep = r"\s+"
        decimal = _decimal_option(path, decimal, sep)
        if names is not None:
            _refuse_duplicate_names(path, names, "--names")
        if names is not None and header:
            raise InputError(f"{path}: --names is for files without a header row; add --no-header")
        if not header and names is None:
            raise InputError(f"{path}: --no-header needs --names to say what the columns are")
        try:
            frame = _read_csv(path, sep, header, names, decimal)
            if path.stat().st_size >= _TRIM_BYTES:
                _release_freed_memory()
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
        if decimal == ".":
            _refuse_decimal_commas(path, frame)
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


def _decimal_option(path: Path, decimal: str | None, sep: str) -> str:
    """The decimal separator ("." or ","), refused when it is not one or is the column separator."""
    decimal = "." if decimal is None else decimal
    if decimal not in (".", ","):
        raise InputError(f"{path}: --decimal must be '.' or ',', got '{decimal}'")
    if decimal == sep:
        raise InputError(f"{path}: --decimal '{decimal}' is also the column separator; a file with decimal commas "
                         "separates its columns by ';' or tabs (give --sep)")
    return decimal


#: a number written with a decimal comma (1,25 or -0,5e-3), which "." reading leaves as text
_DECIMAL_COMMA = r"^\s*[-+]?\d*,\d+([eE][-+]?\d+)?\s*$"


def _refuse_decimal_commas(path: Path, frame: pd.DataFrame) -> None:
    """A text column whose cells are numbers with a decimal comma is refused with the fix (--decimal ,)."""
    for col in frame.columns:
        s = frame[col]
        if pd.api.types.is_numeric_dtype(s) or pd.api.types.is_bool_dtype(s):
            continue
        cells = s.dropna().astype(str)
        cells = cells[cells.str.strip() != ""]
        if len(cells) and cells.str.match(_DECIMAL_COMMA).mean() > 0.5:
            raise InputError(f"{path}: column '{col}' holds numbers with a decimal comma "
                             f"(e.g. '{cells.iloc[0].strip()}'); read the file with --decimal ,")


def _read_csv(path: Path, sep: str, header: bool, names: Sequence[str] | None, decimal: str = ".") -> pd.DataFrame:
    """pandas.read_csv that never shifts columns silently.

    Left to itself, pandas takes the leading columns as the index when the header (or ``names``) has
    fewer fields than the data rows, so every column would get its neighbour's values.  A trailing
    separator at the end of every line (an empty last field) is accepted; any other extra field is
    refused.
    """
    kw = dict(sep=sep, skipinitialspace=True, decimal=decimal)
    if len(sep) > 1 and sep != r"\s+":
        kw["engine"] = "python"  # a separator of several characters is a regular expression to pandas
    # ``dtype={}`` asks for nothing (every column's type is inferred as without it), but pandas 3.1's
    # parallel reader then builds the columns one by one instead of gathering them into 2-D blocks
    # beside the parsed chunks: the same frame, with a peak of 1.03 GB instead of 1.32 GB for a
    # 10^7-row file of four columns (320 MB of data)
    data_kw = dict(kw, dtype={})
    if not header:
        frame = pd.read_csv(path, header=None, **data_kw)
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
        frame = None
        if "engine" not in kw and path.stat().st_size >= _CHUNKED_BYTES:
            # a large file of numbers: read in chunks into its columns (the same frame, half the peak)
            frame = read_numeric_chunks(path, header=0, index_col=False, **kw)
        if frame is None:
            frame = pd.read_csv(path, header=0, index_col=False, **data_kw)
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
