"""discover's independent law fits in forked workers (:func:`gearspec.core.parallel.forked_map`),
with what makes a fork cheap here: the moments each fit restricts itself to made once in this
process (:meth:`.moments.Moments.restrict` caches them; a worker's own copies would be lost with it
and made again in the next map), and the interpreter's objects frozen out of the workers' garbage
collection while they run (a collection in a worker walks every object it inherited, writing to
their pages: each page copied, in every worker of every map)."""

from __future__ import annotations

import gc

from ..core import parallel
from .law import _layout
from .moments import Moments

__all__ = ["fits_map", "restricted", "MIN_QUICK"]


def restricted(M: Moments, laws) -> None:
    """The restricted moments of every law of ``laws`` made (and cached) in ``M`` here."""
    for parts in laws:
        M.restrict({b for _, _, b in _layout(tuple(parts), M).cols})


#: a map costs about 0.09 s of CPU however small its tasks (two workers forked, started, ended;
#: measured on a 300 MB discover process): batches of quick tasks (a screen, a few refinement steps)
#: run in a loop below this many
MIN_QUICK = 8


def fits_map(fn, items, M: Moments | None = None, laws=(), min_items: int = 2) -> list:
    """``[fn(x) for x in items]`` by :func:`~gearspec.core.parallel.forked_map` (a loop here for
    fewer than ``min_items``); ``M``, ``laws``: the moments and the laws the tasks fit on them
    (:func:`restricted` first)."""
    items = list(items)
    if len(items) < max(min_items, 2) or parallel.worker_count() < 2:
        return [fn(x) for x in items]
    if M is not None:
        restricted(M, laws)
    frozen = gc.get_freeze_count() == 0          # (objects frozen by someone else stay so)
    if frozen:
        gc.freeze()
    try:
        return parallel.forked_map(fn, items, min_items=min_items)
    finally:
        if frozen:
            gc.unfreeze()
