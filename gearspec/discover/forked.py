"""discover's independent law fits in forked workers (:func:`gearspec.core.parallel.forked_map`),
run in a loop here where a map would not pay."""

from __future__ import annotations

from ..core import parallel

__all__ = ["fits_map", "MIN_QUICK"]

#: a map costs about 0.09 s of CPU however small its tasks (two workers forked, started, ended;
#: measured on a 300 MB discover process): batches of quick tasks (a few refinement steps each)
#: run in a loop below this many
MIN_QUICK = 8


def fits_map(fn, items, min_items: int = 2) -> list:
    """``[fn(x) for x in items]`` by :func:`~gearspec.core.parallel.forked_map` (a loop here for
    fewer than ``min_items`` items or one worker)."""
    return parallel.forked_map(fn, items, min_items=min_items)
