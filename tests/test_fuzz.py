"""Property-based tests over corrupted recordings (issue 10, item 9).

A small valid recording is corrupted the ways real files are (rows dropped, duplicated or shuffled;
NaN, inf, text, huge, denormal or negative cells; columns renamed, duplicated, missing or constant;
an empty file, a truncated last line, the wrong separator; repeated stamps of a coarse clock; gaps)
and run through the command line in-process.  Whatever happens, the outcome is one of two:

* exit 0, with the JSON ledger intact: every row read is in exactly one segment's ``n`` or counted
  under one reason in ``excluded``, and the rows read are the rows the file holds;
* exit 2, with exactly one ``gearspec: error:`` line on stderr (warnings aside) and nothing else.

Never exit 1 (an internal error), never a traceback.  ``derandomize=True`` makes the examples the
same on every run, so CI is deterministic; the bound on examples keeps the file under ~40 s.
"""

from __future__ import annotations

import json
import os
import warnings

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gearspec.cli import main
from gearspec.simulate import Ripple, plateau_recording

COLUMNS = ("t", "theta", "torque")
SETTINGS = dict(deadline=None, derandomize=True, suppress_health_check=list(HealthCheck), database=None)
#: examples per property; a bigger run by hand: GEARSPEC_FUZZ_EXAMPLES=2000 (and GEARSPEC_FUZZ_SEED to vary them)
N_EXAMPLES = int(os.environ.get("GEARSPEC_FUZZ_EXAMPLES", "70"))
if os.environ.get("GEARSPEC_FUZZ_SEED"):
    SETTINGS["derandomize"] = False


def _base(speeds) -> pd.DataFrame:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec, _ = plateau_recording(speeds, ripples=[Ripple(1 / (2 * np.pi), 1e-3, 0.5)], level=0.01,
                                   duration=0.3, fs=1000, noise=1e-4, seed=4)
    return rec.data[list(COLUMNS)].copy()


BASE_SPECTRUM = _base([40, -40, 80])
BASE_FIT = _base([40, -40, 60, -60, 80, -80])


# ---------------------------------------------------------------------- corruptions
def _rows(n):
    return st.tuples(st.integers(0, n - 1), st.integers(1, max(1, n // 4)))


ROW_OPS = st.one_of(
    st.tuples(st.just("drop"), _rows(2000)),
    st.tuples(st.just("duplicate"), _rows(2000)),
    st.tuples(st.just("shuffle"), _rows(2000)),
    st.tuples(st.just("gap"), st.integers(1, 1999), st.sampled_from([0.003, 0.05, 2.0, 1e4])),
    st.tuples(st.just("clock"), st.sampled_from([0.002, 0.004, 0.02, 1.0])),  # repeated stamps
)
CELL_OPS = st.tuples(
    st.just("cells"), st.sampled_from(COLUMNS), _rows(2000),
    st.sampled_from(["nan", "inf", "-inf", "text", "huge", "denormal", "negative", "zero", "empty"]))
COLUMN_OPS = st.one_of(
    st.tuples(st.just("rename"), st.sampled_from(COLUMNS), st.sampled_from(["theta ", " t", "Theta", "x", "torque",
                                                                            "theta", "t.1", ""])),
    st.tuples(st.just("duplicate_column"), st.sampled_from(COLUMNS)),
    st.tuples(st.just("missing"), st.sampled_from(COLUMNS)),
    st.tuples(st.just("constant"), st.sampled_from(COLUMNS), st.sampled_from([0.0, 1.5, np.nan])),
    st.tuples(st.just("scale"), st.sampled_from(COLUMNS), st.sampled_from([1e-310, 1e300, -1.0, 1e-3, 1e3])),
)
FILE_OPS = st.sampled_from(["csv", "csv", "csv", "semicolon", "truncated", "empty", "header_only", "parquet", "npz",
                            "npz_wide"])


def _pos(df, col) -> int:
    return list(df.columns).index(col)  # the first of a name that may be there twice


def _num(df, col) -> np.ndarray:
    return pd.to_numeric(df.iloc[:, _pos(df, col)], errors="coerce").to_numpy(dtype=float, copy=True)


def _set(df, col, values) -> None:
    df.isetitem(_pos(df, col), np.asarray(values, dtype=object))


def corrupt(frame: pd.DataFrame, ops) -> pd.DataFrame:
    """Apply the operations to a copy of ``frame`` (object dtype, so text can go in)."""
    df = frame.copy().astype(object)
    for op in ops:
        n = len(df)
        kind = op[0]
        if n == 0:
            break
        if kind in ("drop", "duplicate", "shuffle"):
            a, k = op[1]
            a, b = a % n, min(n, a % n + k)
            if kind == "drop":
                df = df.drop(df.index[a:b])
            elif kind == "duplicate":
                df = pd.concat([df.iloc[:b], df.iloc[a:b], df.iloc[b:]])
            else:
                block = df.iloc[a:b].sample(frac=1.0, random_state=a)
                df = pd.concat([df.iloc[:a], block, df.iloc[b:]])
            df = df.reset_index(drop=True)
        elif kind == "gap" and "t" in df:
            i = op[1] % n
            num = _num(df, "t")
            num[i:] += op[2]
            _set(df, "t", num)
        elif kind == "clock" and "t" in df:
            _set(df, "t", np.floor(_num(df, "t") / op[1]) * op[1])
        elif kind == "cells" and op[1] in df:
            col, (a, k), what = op[1], op[2], op[3]
            a, b = a % n, min(n, a % n + k)
            num = _num(df, col)
            cells = df.iloc[:, _pos(df, col)].to_numpy(dtype=object).copy()
            value = {"nan": np.nan, "inf": np.inf, "-inf": -np.inf, "text": "abc", "huge": 1e300, "zero": 0.0,
                     "empty": ""}.get(what)
            if what == "denormal":
                cells[a:b] = num[a:b] * 1e-310
            elif what == "negative":
                cells[a:b] = -num[a:b]
            else:
                cells[a:b] = value
            _set(df, col, cells)
        elif kind == "rename" and op[1] in df:
            df.columns = [op[2] if j == _pos(df, op[1]) else c for j, c in enumerate(df.columns)]
        elif kind == "duplicate_column" and op[1] in df:
            df = pd.concat([df, df.iloc[:, [_pos(df, op[1])]]], axis=1)
        elif kind == "missing" and op[1] in df:
            df = df.drop(columns=[op[1]])
        elif kind == "constant" and op[1] in df:
            _set(df, op[1], np.full(n, op[2]))
        elif kind == "scale" and op[1] in df:
            _set(df, op[1], _num(df, op[1]) * op[2])
        df = df.astype(object)
    return df


def write(df: pd.DataFrame, fmt: str, folder) -> tuple[str, int | None]:
    """Write ``df`` as ``fmt``; return the path and the data rows it holds (None: not known)."""
    if fmt in ("csv", "semicolon", "truncated", "empty", "header_only"):
        path = folder / "rec.csv"
        if fmt == "empty":
            path.write_text("")
            return str(path), None
        if fmt == "header_only":
            path.write_text(",".join(map(str, df.columns)) + "\n")
            return str(path), None
        text = df.to_csv(index=False, sep=";" if fmt == "semicolon" else ",", float_format="%.17g")
        if fmt == "truncated":
            text = text.rstrip("\n")
            text = text[: max(len(text.splitlines()[0]) + 1, len(text) - 7)]
        path.write_text(text)
        return str(path), (None if fmt == "truncated" else len(df))
    if fmt == "parquet":
        import pyarrow as pa
        import pyarrow.parquet as pq

        arrays = [pa.array(pd.to_numeric(df.iloc[:, j], errors="coerce").to_numpy(dtype=float))
                  for j in range(df.shape[1])]
        path = folder / "rec.parquet"
        pq.write_table(pa.Table.from_arrays(arrays, names=[str(c) for c in df.columns]), path)
        return str(path), len(df)
    path = folder / "rec.npz"
    num = {}
    for j, c in enumerate(df.columns):
        num.setdefault(str(c) or "unnamed", pd.to_numeric(df.iloc[:, j], errors="coerce").to_numpy(dtype=float))
    if fmt == "npz_wide":
        np.savez(path, data=np.vstack(list(num.values())))  # a k x N matrix: rows are channels
        return str(path), len(df)
    np.savez(path, **num)
    return str(path), len(df)


def check_outcome(code: int, out: str, err: str, json_path, rows) -> None:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert "Traceback" not in err, err
    assert code in (0, 2), err
    others = [ln for ln in lines if not ln.startswith("gearspec: warning: ")]
    if code == 2:
        assert len(others) == 1 and others[0].startswith("gearspec: error: "), err
        return
    assert others == [], err
    d = json.loads(json_path.read_text())
    if "segments" in d:
        in_segments = sum(s["n"] for s in d["segments"])
        assert in_segments + sum(d["excluded"].values()) == d["n_rows"], d["excluded"]
        if rows is not None:
            assert d["n_rows"] == rows


OPS = st.lists(st.one_of(ROW_OPS, CELL_OPS, COLUMN_OPS), min_size=1, max_size=3)


@settings(max_examples=N_EXAMPLES, **SETTINGS)
@given(ops=OPS, fmt=FILE_OPS)
def test_spectrum_on_corrupted_recordings_exits_0_with_the_ledger_or_2_with_one_sentence(ops, fmt, tmp_path_factory,
                                                                                       capsys):
    folder = tmp_path_factory.mktemp("fuzz")
    path, rows = write(corrupt(BASE_SPECTRUM, ops), fmt, folder)
    capsys.readouterr()
    code = main(["spectrum", path, "--quiet", "--json", str(folder / "s.json")])
    captured = capsys.readouterr()
    check_outcome(code, captured.out, captured.err, folder / "s.json", rows)


@settings(max_examples=max(12, N_EXAMPLES // 6), **SETTINGS)
@given(ops=OPS, law=st.sampled_from(["coulomb_viscous", "silo4"]))
def test_fit_on_corrupted_recordings_never_fails_internally(ops, law, tmp_path_factory, capsys):
    folder = tmp_path_factory.mktemp("fuzzfit")
    path, rows = write(corrupt(BASE_FIT, ops), "csv", folder)
    capsys.readouterr()
    code = main(["fit", path, "--law", law, "--gear", "silo4-joint3", "--quiet", "--no-published",
                 "--json", str(folder / "f.json")])
    captured = capsys.readouterr()
    check_outcome(code, captured.out, captured.err, folder / "f.json", rows)


@pytest.mark.parametrize("fmt", ["csv", "parquet", "npz"])
def test_the_uncorrupted_recording_passes_in_every_format(fmt, tmp_path, capsys):
    """The baseline of the property: a clean file succeeds, so refusals above come from the corruption."""
    path, rows = write(BASE_SPECTRUM.astype(object), fmt, tmp_path)
    code = main(["spectrum", path, "--quiet", "--json", str(tmp_path / "s.json")])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    check_outcome(code, captured.out, captured.err, tmp_path / "s.json", rows)
    assert json.loads((tmp_path / "s.json").read_text())["n_rows"] == len(BASE_SPECTRUM)
