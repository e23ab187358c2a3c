"""The block-wise read of a large numeric csv (gearspec.recording.csvchunks) gives pandas' frame."""

import numpy as np
import pandas as pd
import pytest

from gearspec.recording import csvchunks, readers
from gearspec.recording.csvchunks import line_blocks, read_numeric_chunks

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


@pytest.mark.parametrize("workers", [1, 2])
@pytest.mark.parametrize("block", [1, 60, 333, 1000, 1 << 20])
def test_blocks_equal_one_read(tmp_path, block, workers):
    p = _write(tmp_path / "a.csv", _table())
    blocks = line_blocks(p, block)
    assert blocks[0][0] == 0 and blocks[-1][1] == p.stat().st_size
    assert all(a[1] == b[0] for a, b in zip(blocks, blocks[1:]))          # they tile the file
    assert sum(n for _, _, n in blocks) == 104                            # header + 103 rows
    got = read_numeric_chunks(p, block_bytes=block, workers=workers, **KW)
    assert got is not None and len(got) == 103
    _same(got, pd.read_csv(p, **KW))
    assert got["run"].dtype == np.int64 and got["theta"].dtype == np.float64


@pytest.mark.parametrize("block", [1, 45, 200])
def test_blank_lines_and_no_final_newline(tmp_path, block):
    text = _table(40).rstrip("\n").split("\n")
    for i in (10, 11, 12, 25, 26):
        text.insert(i, "")
    p = _write(tmp_path / "b.csv", "\n".join(text) + "\n\n\n" + "1.5,2.5,3.5,3")  # no newline at the end
    assert sum(n for _, _, n in line_blocks(p, block)) == 49
    got = read_numeric_chunks(p, block_bytes=block, workers=2, **KW)
    assert got is not None and len(got) == 41
    _same(got, pd.read_csv(p, **KW))


def test_quotes_and_bare_carriage_returns_are_left_to_one_read(tmp_path):
    quoted_header = _write(tmp_path / "q.csv", '"t","theta"\n' + "".join(f"{i * 0.1!r},{i * 0.5!r}\n" for i in range(9)))
    got = read_numeric_chunks(quoted_header, block_bytes=30, **KW)
    _same(got, pd.read_csv(quoted_header, **KW))
    assert list(got.columns) == ["t", "theta"]
    quoted = _write(tmp_path / "r.csv", 't,theta\n0.1,"0.5"\n0.2,0.7\n')
    assert line_blocks(quoted) is None and read_numeric_chunks(quoted, **KW) is None
    cr = _write(tmp_path / "s.csv", "t,theta\r0.1,0.5\r0.2,0.7\r")
    assert line_blocks(cr) is None
    crlf = _write(tmp_path / "u.csv", "t,theta\r\n0.1,0.5\r\n0.2,0.7\r\n")
    _same(read_numeric_chunks(crlf, block_bytes=12, **KW), pd.read_csv(crlf, **KW))


def test_type_changing_between_chunks_is_left_to_one_read(tmp_path):
    # 'x' holds whole numbers in the first chunk and a decimal later: one read makes it float
    rows = ["x,y"] + [f"{i},{i * 0.5}" for i in range(20)] + ["2.75,1.0"]
    p = _write(tmp_path / "c.csv", "\n".join(rows) + "\n")
    assert read_numeric_chunks(p, block_bytes=40, **KW) is None
    whole = pd.read_csv(p, **KW)
    assert whole["x"].dtype == np.float64 and whole["x"].iloc[-1] == 2.75


def test_text_column_is_left_to_one_read(tmp_path):
    rows = ["t,label"] + [f"{i * 0.1},a{i}" for i in range(12)]
    p = _write(tmp_path / "d.csv", "\n".join(rows) + "\n")
    assert read_numeric_chunks(p, block_bytes=20, **KW) is None


def test_reader_uses_chunks_above_the_size_and_gives_the_same_frame(tmp_path, monkeypatch):
    """readers._read_csv on a numeric file takes the chunked path (counted) when the file is large
    enough, and returns pandas' frame; on a file whose types change it falls back to one read."""
    calls = []
    real = csvchunks.read_numeric_chunks

    def counted(*a, **k):
        out = real(*a, block_bytes=50, **k)
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
                        lambda *a, **k: csvchunks.read_numeric_chunks(*a, **{**k, "block_bytes": 70}))
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
