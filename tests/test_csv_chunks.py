"""The chunked read of a large numeric csv (gearspec.recording.csvchunks) gives pandas' frame."""

import numpy as np
import pandas as pd
import pytest

from gearspec.recording import csvchunks, readers
from gearspec.recording.csvchunks import count_lines, read_numeric_chunks

KW = dict(sep=",", skipinitialspace=True, decimal=".", header=0, index_col=False)


def _write(path, text):
    path.write_text(text)
    return path


def _table(n=103, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 1e-3
    theta = np.cumsum(rng.normal(size=n)) * 0.37
    tau = rng.normal(size=n) * 1e-3
    run = np.repeat(np.arange(4), -(-n // 4))[:n]
    lines = ["t,theta,torque,run"] + [f"{a!r},{b!r},{c!r},{d}" for a, b, c, d in zip(t.tolist(), theta.tolist(), tau.tolist(), run.tolist())]
    return "\n".join(lines) + "\n"


def _same(a, b):
    assert list(a.columns) == list(b.columns)
    assert isinstance(a.index, pd.RangeIndex) and a.index.equals(b.index)
    for c in a.columns:
        assert a[c].dtype == b[c].dtype, c
        assert np.array_equal(a[c].to_numpy(), b[c].to_numpy()), c  # bit for bit (no NaN here)


@pytest.mark.parametrize("chunk", [1, 7, 50, 103, 1000])
def test_chunks_equal_one_read(tmp_path, chunk):
    p = _write(tmp_path / "a.csv", _table())
    got = read_numeric_chunks(p, chunk_rows=chunk, **KW)
    assert got is not None and len(got) == 103
    _same(got, pd.read_csv(p, **KW))
    assert got["run"].dtype == np.int64 and got["theta"].dtype == np.float64


def test_blank_lines_and_no_final_newline(tmp_path):
    text = _table(40).rstrip("\n").split("\n")
    text.insert(10, "")
    text.insert(25, "")
    p = _write(tmp_path / "b.csv", "\n".join(text))  # no newline after the last row
    assert count_lines(p) == 43
    got = read_numeric_chunks(p, chunk_rows=6, **KW)
    assert got is not None and len(got) == 40
    _same(got, pd.read_csv(p, **KW))


def test_type_changing_between_chunks_is_left_to_one_read(tmp_path):
    # 'x' holds whole numbers in the first chunk and a decimal later: one read makes it float
    rows = ["x,y"] + [f"{i},{i * 0.5}" for i in range(20)] + ["2.75,1.0"]
    p = _write(tmp_path / "c.csv", "\n".join(rows) + "\n")
    assert read_numeric_chunks(p, chunk_rows=8, **KW) is None
    whole = pd.read_csv(p, **KW)
    assert whole["x"].dtype == np.float64 and whole["x"].iloc[-1] == 2.75


def test_text_column_is_left_to_one_read(tmp_path):
    rows = ["t,label"] + [f"{i * 0.1},a{i}" for i in range(12)]
    p = _write(tmp_path / "d.csv", "\n".join(rows) + "\n")
    assert read_numeric_chunks(p, chunk_rows=5, **KW) is None


def test_reader_uses_chunks_above_the_size_and_gives_the_same_frame(tmp_path, monkeypatch):
    """readers._read_csv on a numeric file takes the chunked path (counted) when the file is large
    enough, and returns pandas' frame; on a file whose types change it falls back to one read."""
    calls = []
    real = csvchunks.read_numeric_chunks

    def counted(*a, **k):
        out = real(*a, chunk_rows=9, **{kk: v for kk, v in k.items() if kk != "chunk_rows"})
        calls.append(out is not None)
        return out

    monkeypatch.setattr(readers, "read_numeric_chunks", counted)
    monkeypatch.setattr(readers, "_CHUNKED_BYTES", 0)
    p = _write(tmp_path / "e.csv", _table(57, seed=3))
    _same(readers._read_csv(p, ",", True, None), pd.read_csv(p, **KW))
    rows = ["x,y"] + [f"{i},{i * 0.5}" for i in range(20)] + ["2.75,1.0"]
    q = _write(tmp_path / "f.csv", "\n".join(rows) + "\n")
    got = readers._read_csv(q, ",", True, None)
    assert got["x"].dtype == np.float64 and got["x"].iloc[-1] == 2.75
    assert calls == [True, False]


def test_trailing_separator_and_extra_fields_as_one_read(tmp_path, monkeypatch):
    """A separator at the end of every line is read as one read reads it (the empty last field
    dropped); a named-less extra field is refused with the same message, read in chunks or not."""
    monkeypatch.setattr(readers, "read_numeric_chunks",
                        lambda *a, **k: csvchunks.read_numeric_chunks(*a, **{**k, "chunk_rows": 7}))
    trail = _write(tmp_path / "g.csv", "t,theta,torque\n" + "".join(f"{i * 0.001!r},{i * 0.5!r},{i % 7 - 3.25!r},\n"
                                                                   for i in range(30)))
    extra = _write(tmp_path / "h.csv", "t,theta,torque\n" + "".join(f"{i * 0.001!r},{i * 0.5!r},{i % 7 - 3.25!r},{i}\n"
                                                                   for i in range(30)))
    monkeypatch.setattr(readers, "_CHUNKED_BYTES", 1 << 40)
    whole = readers._read_csv(trail, ",", True, None)
    with pytest.raises(readers.InputError) as e1:
        readers._read_csv(extra, ",", True, None)
    monkeypatch.setattr(readers, "_CHUNKED_BYTES", 0)
    _same(readers._read_csv(trail, ",", True, None), whole)
    assert list(whole.columns) == ["t", "theta", "torque"]
    with pytest.raises(readers.InputError) as e2:
        readers._read_csv(extra, ",", True, None)
    assert str(e1.value) == str(e2.value) and "data rows have 4 fields" in str(e2.value)
