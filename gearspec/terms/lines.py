"""Position-locked lines evaluated together, and a model's base law with its lines compiled for fast
evaluation (what :meth:`FrictionModel.evaluate <gearspec.model.FrictionModel.evaluate>` and the
registry's ``periodic`` term compute).

A line (SILO4 eqs. 6, 8 and 14) is ``(A + k load^2) g(|v|) sin(2 pi f theta + phi)`` with ``g`` an
amplitude law of :mod:`.shapes` evaluated at ``|v|`` held within the line's ``speed_range``.
:class:`Lines` holds K lines as parameter arrays and evaluates them in a few array operations,
whatever K; :class:`CompiledFriction` holds both directions of a model and evaluates the signed
friction ``sign(v) [base(|v|, load) + sum_k line_k]`` in blocks of samples, each direction on its own
samples.  Units: SI (rad, rad/s, Nm; frequencies in cycles per unit of theta, decays in s/rad).
"""

from __future__ import annotations

import contextvars
import itertools
import os
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Mapping, Sequence

import numpy as np

from ..errors import InputError
from .shapes import AMPLITUDE_LAWS, amplitude_law, clamp_speed, load_amplitude, sinusoid

__all__ = ["Lines", "CompiledDirection", "CompiledFriction", "default_threads", "check_threads", "THREADS_ENV",
           "MAX_THREADS", "PARALLEL_MIN_SAMPLES"]

#: samples per block times lines: arrays of a block stay in the processor's cache, and the Python
#: work per block (some 40 numpy calls) is spread over enough samples to cost < 5 % of the numpy work
_BLOCK = 65536
#: blocks up to this many samples that move both ways are evaluated for both directions at once
_SMALL = 256
#: environment variable giving the default number of threads of :meth:`CompiledFriction.__call__`
THREADS_ENV = "GEARSPEC_THREADS"
#: the default number of threads is the CPUs this process may use, at most this many
MAX_THREADS = 4
#: inputs shorter than this many samples are evaluated in the calling thread only: below it the
#: pool's hand-over (some 50-100 us) is not small against the work (~10 us per 100 samples)
PARALLEL_MIN_SAMPLES = 1 << 17

_pool_lock = threading.Lock()
_pool: ThreadPoolExecutor | None = None


def _forget_pool() -> None:
    """In a child process made by ``fork``: the parent's pool threads do not exist there, so its
    pool is dropped and a new one started on first use."""
    global _pool, _pool_lock
    _pool, _pool_lock = None, threading.Lock()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_pool)


def default_threads() -> int:
    """Threads a long evaluation uses when none is given: the environment variable ``GEARSPEC_THREADS``
    (an integer >= 1) when set, else the CPUs this process may run on (``os.sched_getaffinity``,
    else ``os.cpu_count()``) capped at :data:`MAX_THREADS`."""
    env = os.environ.get(THREADS_ENV, "").strip()
    if env:
        try:
            n = int(env)
        except ValueError:
            n = 0
        if n < 1:
            raise InputError(f"the environment variable {THREADS_ENV} must be a whole number of threads >= 1, "
                             f"got {env!r}")
        return n
    try:
        cpus = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        cpus = os.cpu_count() or 1
    return max(1, min(MAX_THREADS, cpus))


def check_threads(threads) -> int:
    """``threads`` (None: :func:`default_threads`) as a number >= 1, or an InputError naming it."""
    if threads is None:
        return default_threads()
    if isinstance(threads, bool) or not isinstance(threads, (int, np.integer)) or threads < 1:
        raise InputError(f"threads must be a whole number >= 1 (or None for the default), got {threads!r}")
    return int(threads)


def _shared_pool(workers: int) -> ThreadPoolExecutor:
    """The module's thread pool, grown to at least ``workers`` threads (daemon threads of the
    standard executor, started on first use and reused by every later call)."""
    global _pool
    with _pool_lock:
        if _pool is None or _pool._max_workers < workers:
            # a smaller pool is dropped, not shut down: a call may still be submitting to it (its idle
            # threads end when it is garbage-collected)
            _pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="gearspec-evaluate")
        return _pool


class Lines:
    """K position-locked lines, each given in the ``periodic`` term's form: ``frequency``,
    ``amplitude``, ``decay`` (default 0), ``phase`` (default 0), ``law`` (default ``"exp"``),
    ``load_coefficient`` (default 0), ``speed_range`` (default None: not clamped).

    The lines are stored grouped by (law, speed range, load coefficient or not), so that each group
    is one slice of the parameter arrays; :meth:`__call__` returns them in the order given.
    """

    def __init__(self, lines: Sequence[Mapping]):
        keyed = []
        self.given = list(lines)
        for i, h in enumerate(lines):
            for name in ("frequency", "amplitude", "decay", "phase"):
                if name in h and h[name] is None:
                    raise InputError(f"a position-locked line has no value for its {name} (null in the model)")
            law = h.get("law") or "exp"
            if law not in AMPLITUDE_LAWS:
                raise InputError(f"unknown amplitude law '{law}' ({', '.join(AMPLITUDE_LAWS)})")
            rng = h.get("speed_range")
            rng = None if not rng else tuple(rng)
            k = h.get("load_coefficient", 0.0) or 0.0
            keyed.append(((law, rng, bool(k)), i, h, k))
        keyed.sort(key=lambda x: (x[0][0], repr(x[0][1]), x[0][2], x[1]))
        self.n = len(keyed)
        col = lambda vals: np.array(vals, dtype=float)[:, None]  # noqa: E731
        self.frequency = col([h["frequency"] for _, _, h, _ in keyed])
        self.amplitude = col([h["amplitude"] for _, _, h, _ in keyed])
        self.decay = col([h.get("decay", 0.0) for _, _, h, _ in keyed])
        self.phase = col([h.get("phase", 0.0) for _, _, h, _ in keyed])
        self.load_coefficient = col([k for _, _, _, k in keyed])
        #: row of each line in the order given
        self.order = [row for row, _ in sorted(enumerate(x[1] for x in keyed), key=lambda r: r[1])]
        #: per group of rows: (rows, law, speed range, with load, amplitudes, decays, load coefficients)
        self.groups = []
        for row, (key, *_rest) in enumerate(keyed):
            if self.groups and self.groups[-1][1:] == key:
                self.groups[-1][0][1] = row + 1
            else:
                self.groups.append(([row, row + 1], *key))
        self.groups = [(slice(a, b), law, rng, wl, self.amplitude[a:b], self.decay[a:b], self.load_coefficient[a:b])
                       for (a, b), law, rng, wl in self.groups]
        self.needs_load = any(g[3] for g in self.groups)

    def __call__(self, theta, speed, load=None) -> np.ndarray:
        """The lines at samples: ``theta`` (rad or m) and ``speed = |v|`` (rad/s or m/s), 1-D arrays of
        one length n, ``load`` (Nm) as well when a line has a load coefficient.  Returns (K, n) in
        the internal row order (rows of the lines as given: :attr:`order`)."""
        out = sinusoid(theta[None, :], self.frequency, self.phase)
        clamped = {}
        for rows, law, rng, with_load, amp, decay, coef in self.groups:
            if with_load:
                if load is None:
                    raise InputError("a periodic term with a load coefficient (SILO4 eq. 14) needs the 'load' channel")
                amp = load_amplitude(load[None, :], amp, coef)
            if law != "const":      # const: g = 1, and A * 1 * s is A * s exactly
                s = clamped.get(rng)
                if s is None:
                    s = clamped[rng] = clamp_speed(speed, rng)[None, :]
                amp = amp * amplitude_law(law, s, decay)
            out[rows] *= amp
        return out


class CompiledDirection:
    """One direction of a model ready to evaluate: its base law with the parameter values ``params``
    (in the law's order) and its lines (:class:`Lines`, or None).  ``error``: why the direction cannot
    be evaluated (a parameter not identified, an unknown amplitude law), raised when samples move
    that way."""

    def __init__(self, law, params: Sequence, lines: Sequence[Mapping], error: str | None = None):
        self.law, self.params, self.error, self.lines = law, list(params), error, None
        if lines and error is None:
            try:
                self.lines = Lines(lines)
            except InputError as exc:
                self.error = str(exc)

    def magnitude(self, theta, speed, load) -> np.ndarray:
        """Friction magnitude ``base(|v|, load) + sum_k line_k`` at the samples (1-D arrays), the lines
        added one after the other in their order: a new array."""
        mag = self.law.magnitude(speed, load, *self.params)
        if self.lines is None:
            out = np.empty(len(speed))
            out[...] = mag
            return out
        rows = self.lines(theta, speed, load)
        order = self.lines.order
        out = np.add(mag, rows[order[0]])
        for r in order[1:]:
            out += rows[r]
        return out


class CompiledFriction:
    """Both directions of a model (:class:`CompiledDirection` ``positive`` and ``negative``):
    :meth:`__call__` gives the signed friction of the base law and lines."""

    def __init__(self, positive: CompiledDirection, negative: CompiledDirection):
        self.directions = ((1.0, positive), (-1.0, negative))
        self.block = _BLOCK // max(1, positive.lines.n if positive.lines else 1,
                                   negative.lines.n if negative.lines else 1)
        self.stacked = _Stacked(positive, negative)
        if not self.stacked.usable:
            self.stacked = None

    def check(self, theta, v, load) -> None:
        """InputError when samples move in a direction that cannot be evaluated with these inputs."""
        for d, c in self.directions:
            needs_theta = c.lines is not None and theta is None
            needs_load = c.lines is not None and c.lines.needs_load and load is None
            if (c.error or needs_theta or needs_load) and np.any(v * d > 0):
                if c.error:
                    raise InputError(c.error)
                if needs_theta:
                    raise InputError("the model has position-locked harmonics and needs theta")
                raise InputError("a periodic term with a load coefficient (SILO4 eq. 14) needs the 'load' channel")

    def __call__(self, theta, v, load=None, threads: int = 1) -> np.ndarray:
        """``sign(v) * magnitude`` at 1-D samples ``theta`` (None when no line needs it), ``v``, ``load``
        (None when not needed); 0 where v is 0 or NaN.  Blocks of samples; in each, the samples of
        each direction gathered (all of them, without a copy, when the block moves one way).

        ``threads`` > 1: inputs of at least :data:`PARALLEL_MIN_SAMPLES` samples have their blocks
        shared among that many threads (the calling one and a shared pool; numpy releases the GIL in
        its loops).  The blocks are the same whatever the number of threads, so each value is
        bit-identical to the single-thread result."""
        self.check(theta, v, load)
        n = len(v)
        if n <= self.block:
            return self._block(theta, v, load, None)
        out = np.zeros(n)         # 0 where v is 0 or NaN
        starts = range(0, n, self.block)
        threads = min(threads, len(starts))
        if threads <= 1 or n < PARALLEL_MIN_SAMPLES:
            for i in starts:
                self._slice(theta, v, load, out, i)
            return out
        following = itertools.count()       # the next block to take: next() is atomic under the GIL

        def work():
            for k in following:
                if k >= len(starts):
                    return
                self._slice(theta, v, load, out, starts[k])

        # each helper thread runs in a copy of the caller's context: numpy's errstate (a context
        # variable) and anything else the caller set apply to its blocks too
        pool = _shared_pool(threads - 1)
        futures = [pool.submit(contextvars.copy_context().run, work) for _ in range(threads - 1)]
        try:
            work()
        finally:
            for f in futures:       # a helper not started yet (its thread busy elsewhere) is not waited for
                if not f.cancel():
                    f.result()
        return out

    def _slice(self, theta, v, load, out, i) -> None:
        """The block starting at sample ``i`` into ``out``."""
        j = min(len(v), i + self.block)
        self._block(None if theta is None else theta[i:j], v[i:j], None if load is None else load[i:j], out[i:j])

    def _block(self, theta, v, load, out):
        """One block into ``out`` (zeros; None: a new array)."""
        n = len(v)
        first = True
        for d, c in self.directions:
            sel = v > 0 if d > 0 else v < 0
            cnt = int(np.count_nonzero(sel))
            if cnt == n:            # the whole block moves this way
                mag = c.magnitude(theta, np.abs(v), load)
                if d < 0:
                    np.negative(mag, out=mag)
                if out is None:
                    return mag
                out[...] = mag
                return out
            if first:
                if self.stacked is not None and out is None and n <= _SMALL and self.stacked.can(theta, load):
                    return self.stacked(theta, v, load)
                out = np.zeros(n) if out is None else out
                first = False
            if cnt:
                idx = np.flatnonzero(sel)
                mag = c.magnitude(None if theta is None else theta.take(idx), np.abs(v.take(idx)),
                                  None if load is None else load.take(idx))
                out[idx] = np.negative(mag) if d < 0 else mag
        return out


class _Stacked:
    """Both directions evaluated at once on every sample of a short block that moves both ways, then
    each sample's own taken: one pass of numpy calls instead of two, cheaper below ~``_SMALL`` samples
    (a simulation's vector of runs).  The parameters of both directions stacked along a first axis of
    length 2; a direction with fewer lines gets lines of amplitude 0 (which add +0).  ``usable``:
    False when the directions cannot be stacked (a parameter given in one direction only, an error)."""

    def __init__(self, positive: CompiledDirection, negative: CompiledDirection):
        self.usable = False
        self.law = positive.law
        if positive.error or negative.error:
            return
        params = []
        for a, b in zip(positive.params, negative.params):
            if (a is None) != (b is None):
                return
            params.append(None if a is None else np.array([[a], [b]], dtype=float))
        self.params, self.usable = params, True
        self.lines, self.pairs = None, []
        k = max(c.lines.n if c.lines else 0 for c in (positive, negative))
        if not k:
            return
        pad = {"frequency": 0.0, "amplitude": 0.0, "law": "const"}
        given = []
        for c in (positive, negative):
            mine = c.lines.given if c.lines else []
            given += list(mine) + [pad] * (k - len(mine))
        self.lines = Lines(given)
        self.pairs = [np.array([self.lines.order[i], self.lines.order[k + i]]) for i in range(k)]

    def can(self, theta, load) -> bool:
        return self.lines is None or (theta is not None and (load is not None or not self.lines.needs_load))

    def __call__(self, theta, v, load) -> np.ndarray:
        speed = np.abs(v)
        mag = self.law.magnitude(speed, load, *self.params)
        if self.lines is not None:
            rows = self.lines(theta, speed, load)
            mag = np.add(mag, rows[self.pairs[0]])
            for p in self.pairs[1:]:
                mag += rows[p]
        if np.ndim(mag) < 2:       # a law without parameters
            mag = np.broadcast_to(mag, (2, len(v)))
        return np.where(v > 0, mag[0], np.where(v < 0, np.negative(mag[1]), 0.0))
