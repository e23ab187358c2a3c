"""A large numeric csv read in blocks into its final columns (:func:`read_numeric_chunks`): the same
table as one ``pandas.read_csv`` call, with a peak memory of the columns plus a block per thread.

pandas' parallel reader (pandas 3.1, used for a whole file) parses parts of the file in threads and
then concatenates them: the parsed parts and the concatenated columns are both alive at the end,
and the threads' heaps keep more.  On a 10^7-row file of four columns (320 MB of data) that is a
peak of 1.13 GB for the whole load.  Here the file is cut into blocks of whole lines
(:data:`BLOCK_BYTES`), each parsed by the same C parser in one of two threads (the parser releases
the GIL while it tokenises and converts) and written straight into columns allocated once (their
length bounded by the blocks' line counts): 0.67 GB, with the same CPU time.
"""

from __future__ import annotations

import io
import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pandas as pd

__all__ = ["read_numeric_chunks", "line_blocks", "BLOCK_BYTES"]

#: bytes of the file parsed at once by one thread (about half a million rows of four numbers)
BLOCK_BYTES = 32 << 20
#: column kinds kept as they are read (integers and floats); any other kind (text, booleans, dates)
#: leaves the file to the whole-file read, which infers one type over all rows
_KINDS = "iuf"


def line_blocks(path, block_bytes: int = BLOCK_BYTES) -> list[tuple[int, int, int]] | None:
    """Byte ranges ``(start, stop, lines)`` of about ``block_bytes`` each that cover ``path`` and
    end after a line end (``\\n``; the last one at the end of the file; the first holds the header
    and at least one more line), with the number of lines
    each holds (an upper bound of its rows: blank lines are counted, then skipped by the parser).
    None when a line end could hide inside a field or be one the split cannot see: a quote
    character after the header line, or a carriage return not followed by ``\\n``."""
    size = os.path.getsize(path)
    out: list[tuple[int, int, int]] = []
    pos = 0
    with open(path, "rb") as fh:
        while pos < size:
            fh.seek(pos)
            raw = fh.read(block_bytes)
            # whole lines, at least one (the first block: the header and a data line)
            first_end = raw.find(b"\n")
            while pos + len(raw) < size and (first_end < 0 or (pos == 0 and raw.find(b"\n", first_end + 1) < 0)):
                raw += fh.read(block_bytes)
                first_end = raw.find(b"\n")
            cut = len(raw) if pos + len(raw) >= size else raw.rfind(b"\n") + 1   # the last: to the end
            body = first_end + 1 if pos == 0 else 0    # the header line may be quoted
            if raw.find(b'"', body, cut) >= 0 or (raw.find(b"\r", 0, cut) >= 0 and
                                                  raw.count(b"\r", 0, cut) != raw.count(b"\r\n", 0, cut)):
                return None
            lines = int(np.count_nonzero(np.frombuffer(raw, np.uint8, count=cut) == ord("\n")))
            out.append((pos, pos + cut, lines + (0 if raw[cut - 1:cut] == b"\n" else 1)))
            pos += cut
    return out


def _parse(path, start: int, stop: int, read_kw: dict) -> pd.DataFrame:
    with open(path, "rb") as fh:
        fh.seek(start)
        raw = fh.read(stop - start)
    return pd.read_csv(io.BytesIO(raw), **read_kw)


def read_numeric_chunks(path, *, block_bytes: int = BLOCK_BYTES, workers: int | None = None,
                        **read_kw) -> pd.DataFrame | None:
    """``pandas.read_csv(path, header=0, **read_kw)`` (the C engine) read in blocks of whole lines
    (:func:`line_blocks`), ``workers`` threads at a time (default two, or one when ``GEARSPEC_THREADS``
    is 1: :func:`gearspec.terms.lines.default_threads`), into columns allocated once: the same
    frame (columns, values bit for bit, dtypes, a RangeIndex), or None when the file is not one of
    numbers of one type per column (a column of text or booleans, or one whose type changes between
    blocks, e.g. integers first and a decimal or an empty cell later) or cannot be split at its line
    ends: then the caller reads the whole file, whose type inference sees every row at once.
    ``read_kw`` must hold ``header=0``.  Warnings of the parser (:class:`pandas.errors.ParserWarning`)
    are raised as by one call (once per block)."""
    if read_kw.get("header") != 0:
        raise ValueError("read_numeric_chunks reads files with a header row (header=0)")
    blocks = line_blocks(path, block_bytes)
    if not blocks:
        return None
    first = _parse(path, blocks[0][0], blocks[0][1], read_kw)
    dtypes = {c: first[c].dtype for c in first.columns}
    if not len(first) or first.columns.has_duplicates or any(dt.kind not in _KINDS for dt in dtypes.values()):
        return None
    names = list(first.columns)
    # rows each block may hold (its lines; the first less its header) and where its rows go
    caps = np.array([max(blocks[0][2] - 1, 0)] + [n for _, _, n in blocks[1:]], dtype=np.int64)
    at = np.concatenate(([0], np.cumsum(caps)))
    if len(first) > caps[0]:
        return None
    cols = {c: np.empty(int(at[-1]), dtype=dt) for c, dt in dtypes.items()}
    for c, out in cols.items():
        out[:len(first)] = first[c].to_numpy()
    counts = [len(first)]
    del first
    rest_kw = {**read_kw, "header": None, "names": names}

    def one(i: int) -> int | None:
        part = _parse(path, blocks[i][0], blocks[i][1], rest_kw)
        m = len(part)
        if m and (list(part.columns) != names or any(part[c].dtype != dtypes[c] for c in names)) or m > caps[i]:
            return None
        for c, out in cols.items():
            out[at[i]:at[i] + m] = part[c].to_numpy()
        return m

    if workers is None:
        from ..terms.lines import default_threads

        workers = min(2, default_threads())
    if len(blocks) > 1:
        with ThreadPoolExecutor(max_workers=max(1, min(workers, len(blocks) - 1)),
                                thread_name_prefix="gearspec-csv") as pool:
            counts += list(pool.map(one, range(1, len(blocks))))
    if any(m is None for m in counts):
        return None
    # blocks with blank lines hold fewer rows than lines: their successors' rows move up
    pos = 0
    for i, m in enumerate(counts):
        if at[i] != pos:
            for out in cols.values():
                out[pos:pos + m] = out[at[i]:at[i] + m]     # forwards, overlapping: numpy buffers it
        pos += m
    # views of the first ``pos`` rows: pages of an unused tail (blank lines) were never touched
    return pd.DataFrame({c: out[:pos] for c, out in cols.items()}, copy=False)
