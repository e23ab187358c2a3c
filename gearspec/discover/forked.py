"""discover's independent law fits in forked workers (:func:`gearspec.core.parallel.forked_map`),
run in a loop here where a map would not pay."""

from __future__ import annotations

from ..core import parallel

__all__ = ["fits_map", "MIN_QUICK"]

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
