"""discover's independent law fits in forked workers (:func:`gearspec.core.parallel.forked_map`),
run in a loop here where a map would not pay."""

from __future__ import annotations

import numpy as np

from ..core import parallel

__all__ = ["fits_map", "chunk_count", "segment_chunks", "MIN_QUICK"]

#: a map costs about 0.09 s of CPU however small its tasks (two workers forked, started, ended;
#: measured on a 300 MB discover process): batches of quick tasks (a few refinement steps each)
#: run in a loop below this many
MIN_QUICK = 8


def fits_map(fn, items, min_items: int = 2, cost=None) -> list:
    """``[fn(x) for x in items]`` by :func:`~gearspec.core.parallel.forked_map` (a loop here for
    fewer than ``min_items`` items or one worker).  With ``cost`` (a function of an item: its
    expected work, e.g. a law's complexity), the tasks are handed out the costliest first (ties in
    the order of ``items``), so that a long task does not start last and leave the other worker
    idle at the end of the map; the results come back in the order of ``items`` either way (a
    task's result does not depend on when it runs)."""
    items = list(items)
    if cost is None or len(items) < 2:
        return parallel.forked_map(fn, items, min_items=min_items)
    order = sorted(range(len(items)), key=lambda i: -cost(items[i]))      # stable: ties keep their order
    got = parallel.forked_map(fn, [items[i] for i in order], min_items=min_items)
    out = [None] * len(items)
    for i, r in zip(order, got):
        out[i] = r
    return out


#: chunks of segments per worker in :func:`segment_chunks` (a few, so that the workers finish
#: together though segments differ in length)
CHUNKS_PER_WORKER = 4


#: samples x columns below which a pass over the samples stays one chunk in a loop: a map costs
#: about 0.09 s of CPU, the moments' pass about 0.3 us per cell (default twin, 12 lines: 24 M cells
#: in 8 s), so that a pass this small (about 1 s) gains little from a second worker
MIN_CELLS = 4_000_000


def chunk_count(cells: float | None = None) -> int:
    """Chunks a pass over the segments (``cells``: its samples x columns) is cut into:
    :data:`CHUNKS_PER_WORKER` per worker of a map; 1 when a map would run in a loop or the pass
    has fewer than :data:`MIN_CELLS` cells."""
    n = parallel.worker_count()
    if n < 2 or (cells is not None and cells < MIN_CELLS):
        return 1
    return CHUNKS_PER_WORKER * n


def segment_chunks(sizes, columns: int = 1) -> list[tuple[int, int]]:
    """``(first, stop)`` of consecutive segments (``sizes``: samples of each) holding about equal
    numbers of samples, :data:`CHUNKS_PER_WORKER` per worker of a map (one chunk when a map would
    run in a loop, or for fewer than :data:`MIN_CELLS` samples x ``columns``): the tasks of a pass over the samples segment by segment, whose result for a
    segment does not depend on the chunk it is in."""
    sizes = np.asarray(sizes, dtype=float)
    S = len(sizes)
    k = min(S, chunk_count(float(np.sum(sizes)) * columns))
    if k <= 1:
        return [(0, S)] if S else []
    cum = np.cumsum(sizes)
    cuts = np.searchsorted(cum, cum[-1] * np.arange(1, k) / k, side="left") + 1
    edges = np.unique(np.concatenate([[0], np.clip(cuts, 1, S), [S]]))
    return [(int(a), int(z)) for a, z in zip(edges[:-1], edges[1:])]
