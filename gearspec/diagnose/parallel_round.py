"""A round's candidates on the CPUs the command may use: every candidate's procedure in every fold
(:func:`~.loop._run_folds`) is independent of the others', so :func:`run_candidates` runs them in
worker processes forked from the loop (:func:`gearspec.core.parallel.forked_map`: the round, the
data and the candidates are inherited, not copied; each result is pickled back).

What a candidate's run leaves behind, and how the loop gets it from a worker:

- its result (:class:`~.loop._Folds`): the held-out prediction with it and its contribution (arrays
  of rows), its proposals per fold (blocks and per-group cross products, no rows; a proposal
  pickles without its fit memo).  The held-out residual without it is the round's, one array shared
  by every candidate: not sent back, set again from the round (:meth:`~.context.Round.held_out_residual`);
- its cache for the round (``cand._cache``: a periodic candidate's all-data proposal, which the loop
  asks for again when it accepts it): sent back and set on the candidate, as the loop would have it;
- the block ids it drew (:class:`~.design.Block` ``uid``, one counter in the process): every
  candidate draws from its own range (:data:`UID_STRIDE` ids after a base taken from the counter,
  in a worker and in the loop alike), and the counter continues after the last range, so that no
  two blocks of the loop ever share an id whichever process made them;
- what the round computes on demand and every candidate reads alike (the held-out prediction, the
  training residual, sums and coefficients of every fold, channels): computed once in the loop
  before the candidates run (:func:`prefetch`), inherited by the workers;
- caches on the data (columns of blocks, sines of lines): a worker's are lost; they are only what
  it would compute again, the same numbers.

Forking pays on the rounds of short and mid-sized recordings; a worker writes its own extended
round's design and column caches, so a round whose design holds more than
:data:`FORK_DESIGN_BYTES` runs its candidates in a loop (one design at a time, as before).
"""

from __future__ import annotations

import itertools
from dataclasses import replace

from ..core.crossval import splits
from ..core.parallel import forked_map
from . import design

__all__ = ["run_candidates", "prefetch", "fork_allowed", "FORK_DESIGN_BYTES", "UID_STRIDE"]

#: a round whose design (rows x columns with the Taylor columns, 8-byte floats) holds more than
#: this runs its candidates in one process: every worker writes an extended round's design of about
#: that size and its column caches (at most :data:`~.budget.CACHE_BYTES` + :data:`~.budget.TRIG_BYTES`),
#: so the forked round holds at most ``workers x (design + 320 MiB)`` more than the loop alone
FORK_DESIGN_BYTES = 256 * 2 ** 20
#: block ids every candidate of a round may draw (a grid candidate draws a few per grid value)
UID_STRIDE = 2 ** 20


def fork_allowed(rnd) -> bool:
    """Whether the round's candidates may run in forked workers: its design's arrays
    (:meth:`~.context.Round.design_bytes`: lazy columns of a long recording hold none) hold at most
    :data:`FORK_DESIGN_BYTES`."""
    return rnd.design_bytes() <= FORK_DESIGN_BYTES


def prefetch(rnd, cands, *, residuals: bool = True) -> None:
    """What every candidate of the round reads alike, computed once on the round: its held-out
    residual, the sums and coefficients of every fold and of all data, and, with ``residuals`` for
    the candidates that search on the training residual (periodic lines), every fold's training
    residual (rows) and the channels they read."""
    from .candidates import PeriodicCandidate

    rnd.held_out_residual()
    rnd.taylor_spans()
    every = rnd.all_groups()
    rnd.beta(every)
    periodic = residuals and any(isinstance(c, PeriodicCandidate) for c in cands)
    for _, test in splits(rnd.fold):
        train = ~test
        rnd.beta(train)
        rnd.rows(test)
        if periodic and train.any():
            rnd.rows(train)
            rnd.train_residual(train)
    if periodic:
        for name in ("theta", "direction", "speed", "segment"):
            rnd.channel(name)


def run_candidates(rnd, cands: list, run, *, workers: int | None = None) -> list:
    """``[run(rnd, c) for c in cands]`` (``run``: :func:`~.loop._run_folds`), in forked workers when
    :func:`fork_allowed` (``workers``: :func:`~gearspec.core.parallel.worker_count`'s), with the
    side effects of the module docstring carried back: the same results, bit for bit, as the loop
    in one process (both run BLAS on one thread)."""
    fork = fork_allowed(rnd)
    # in one process the training residuals are computed when a candidate first asks, as before
    prefetch(rnd, cands, residuals=fork)
    base = next(design._UID)

    def task(i: int):
        first = base + i * UID_STRIDE
        design._UID = itertools.count(first)
        c = cands[i]
        fr = run(rnd, c)
        drawn = next(design._UID) - first
        if drawn > UID_STRIDE:
            raise RuntimeError(f"candidate {c.name!r} drew {drawn} block ids, more than its range of {UID_STRIDE}")
        cache = c._cache
        kept = {k: v for k, v in cache.items() if k != "round"} if cache.get("round") is rnd else None
        shared = fr.r0 is rnd.held_out_residual()
        return replace(fr, r0=None) if shared else fr, shared, kept

    n = workers if fork else 1
    try:
        done = forked_map(task, range(len(cands)), workers=n)
    finally:
        design._UID = itertools.count(base + len(cands) * UID_STRIDE)
    out = []
    for c, (fr, shared, kept) in zip(cands, done):
        if shared:
            fr.r0 = rnd.held_out_residual()
        c._cache = {} if kept is None else {"round": rnd, **kept}
        out.append(fr)
    return out

