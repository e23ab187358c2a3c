"""Memory budgets of the closed loop's caches, in bytes: what the loop keeps on the data
(columns of blocks, sines and cosines of lines) is bounded by a fixed number of bytes, not a
number of columns, so that it does not grow with rows x terms on a long recording (issue 13).
A cache keeps at least its newest entry, whatever its size."""

from __future__ import annotations

from collections import OrderedDict

__all__ = ["CACHE_BYTES", "TRIG_BYTES", "DESIGN_BYTES", "LAZY_BYTES", "bounded", "nbytes"]

#: columns of blocks kept on the data (:meth:`~.design.Block.columns`; on short recordings at most
#: 64 columns' worth, as before: no more memory than that where the budget would allow it)
CACHE_BYTES = 256 * 2 ** 20
#: sines and cosines of the lines kept on the data (:meth:`~.design.HarmonicBlock._trig`)
TRIG_BYTES = 64 * 2 ** 20
#: a round's design larger than this is let go while a candidate's extended round holds its own
#: (:meth:`~.context.Round.release_design`)
DESIGN_BYTES = 256 * 2 ** 20
#: a block whose columns (rows x columns, with its Taylor columns when asked, 8-byte floats) would
#: hold more than this computes them a range of rows at a time when asked (:mod:`.rowcols`), if its
#: kind can; at most two such blocks' columns fit in :data:`CACHE_BYTES`
LAZY_BYTES = CACHE_BYTES // 2


def nbytes(value) -> int:
    """Bytes of the arrays in ``value`` (an array, or a tuple / list of them and other things)."""
    if hasattr(value, "nbytes"):
        return int(value.nbytes)
    if isinstance(value, (tuple, list)):
        return sum(nbytes(v) for v in value)
    return 0


def bounded(cache: OrderedDict, budget: int, size=nbytes, count: int | None = None) -> None:
    """Drop the oldest entries of ``cache`` until it holds at most ``budget`` bytes (``size`` of
    each value) and at most ``count`` entries; the newest entry stays whatever its size."""
    held = sum(size(v) for v in cache.values())
    while len(cache) > 1 and (held > budget or (count is not None and len(cache) > count)):
        held -= size(cache.popitem(last=False)[1])
