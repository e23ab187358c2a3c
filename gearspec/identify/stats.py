"""What the fits of :mod:`gearspec.identify` start from: the lines to fit (:func:`harmonic_specs`)
and the exact per-segment sufficient statistics of the samples (:class:`SegmentStats`).

Units: speeds in rad/s (m/s on a linear axis), positions rad (m), frequencies in cycles per unit of
position, friction Nm (N).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np

from ..core.reduction import GroupNormals, group_normal_equations, harmonic_columns, partial_out_last
from ..errors import InputError
from ..fitdata import FitData
from ..gears import GearTrain, load_gear
from ..spectrum import MEASURABLE_FRACTION
from ..spectrum.analysis import group_position_nyquist

__all__ = ["MIN_CYCLES", "SIGNIFICANT", "ConvergenceError", "harmonic_specs", "SegmentStats", "segment_stats", "speed_ranges", "free_speed_range",
           "pair_se"]

#: a segment counts towards a line where it covers at least this fraction of a cycle (the default
#: of :func:`fit`; the closed loop uses the same rule for the speed range of an amplitude law)
MIN_CYCLES = 0.1


#: an amplitude is distinguishable from zero when it exceeds this many standard errors (the fit's
#: note on a line that is not significant; a line below it keeps a constant amplitude:
#: :func:`gearspec.identify.jointlines.faint_lines`)
SIGNIFICANT = 2.0


#: the speed range of an amplitude law over free motion reaches the speeds below (above) which the
#: blocks together cover this many cycles of the line
FREE_RANGE_CYCLES = 1.0


class ConvergenceError(InputError):
    """The fit did not converge (too few data for the law, or data the law cannot describe)."""


# ---------------------------------------------------------------------- harmonics to fit
def harmonic_specs(harmonics=None, gear: GearTrain | str | None = None) -> list[dict]:
    """The position-locked lines a model fits: ``[{"frequency", "label"}]``.

    ``harmonics``: None (every declared line of ``gear``: shafts, wave generator, meshes), a
    list of frequencies (cycles per unit of theta), or a list of dicts with ``frequency`` and
    optionally ``label``, ``law`` (amplitude law: exp, const, rational, power) and ``decay``
    (False to keep the amplitude constant, SILO4 eq. 6).
    """
    if harmonics is None:
        g = load_gear(gear) if gear is not None else None
        if g is None:
            return []
        return [{"frequency": ln.frequency, "label": ln.label} for ln in g.declared_lines()]
    out = []
    for h in harmonics:
        if isinstance(h, Mapping):
            if "frequency" not in h:
                raise InputError("a harmonic to fit needs a 'frequency' (cycles per unit of theta)")
            out.append(dict(h))
        else:
            out.append({"frequency": float(h), "label": f"line {float(h):.6g}"})
    for h in out:
        if not (np.isfinite(h["frequency"]) and h["frequency"] > 0):
            raise InputError(f"harmonic frequency must be positive, got {h['frequency']}")
    return out


# ---------------------------------------------------------------------- sufficient statistics
@dataclass
class SegmentStats(GroupNormals):
    """Per-segment sufficient statistics of the samples for one direction.

    ``G[s]``, ``b[s]`` (also ``g[s]``), ``yy[s]``, ``n[s]``: normal equations of the local model
    ``[1, sin_k, cos_k]`` on the friction magnitude (:class:`~gearspec.core.reduction.GroupNormals`);
    ``sampled[s, k]``: harmonic k lies below ``nyquist_fraction`` of the
    segment's position Nyquist frequency (its columns are in ``G``, whatever the number of cycles:
    the global model predicts what a partial cycle does to the segment's level); ``active[s, k]``:
    it can also be measured in the segment on its own (it completes
    at least ``min_cycles`` cycles and lies below ``nyquist_fraction`` of the position Nyquist);
    ``speed``, ``load`` (mean), ``sigma2`` (residual variance of the unrestricted local fit).
    """

    segment: np.ndarray = None
    speed: np.ndarray = None
    load: np.ndarray | None = None
    active: np.ndarray = None     # (S, K) bool
    sampled: np.ndarray = None    # (S, K) bool
    cycles: np.ndarray = None     # (S, K) cycles of each line in each segment
    sigma2: np.ndarray = None     # (S,)
    beta_hat: np.ndarray = None   # (S, P)
    rss_hat: np.ndarray = None    # (S,)
    frequencies: np.ndarray = None
    acc: bool = False             # the last local column is direction x acceleration (inertia identified)
    free: np.ndarray | None = None  # (S,) bool: a block of free motion
    # the Stribeck grid's costs of fits on these statistics (:func:`~.jointlines.grid_starts`); not
    # an init field, so a subset (``dataclasses.replace``) starts with its own, empty
    grid_costs: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    per_group = GroupNormals.per_group + ("segment", "speed", "load", "active", "sampled", "cycles", "sigma2",
                                          "beta_hat", "rss_hat", "free")

    @property
    def g(self) -> np.ndarray:
        """``X^T y`` per segment (``b``)."""
        return self.b


def segment_stats(data: FitData, frequencies: Sequence[float], *, min_cycles: float = 1.0,
                  nyquist_fraction: float = MEASURABLE_FRACTION, acc: bool = False) -> SegmentStats:
    """One pass over the samples of ``data`` (one direction): see :class:`SegmentStats`.
    ``acc``: the local model has a last column ``direction x acceleration`` too, whose coefficient
    is the inertia when it is identified with the friction (the torque still holds ``J thetadd``).

    Results are cached per segment on ``data`` (and shared with its whole-segment subsets), so
    that cross-validation and refits do not pass over the samples again.
    """
    freqs = np.asarray(list(frequencies), dtype=float)
    if acc and not data.has("acc"):
        raise InputError("the inertia cannot be identified: the fit data have no acceleration")
    # one entry per segment whatever min_cycles (it only decides ``active``, from the cached cycles)
    key = (tuple(freqs.tolist()), float(nyquist_fraction), bool(acc))
    cache = data.cache.setdefault(("segment_stats",) + key, {})
    order, sids, bounds = data.segment_groups()
    edge = np.concatenate((bounds[:-1], bounds[1:] - 1))
    ends = data.values_at("y", edge if order is None else order[edge]) if len(sids) else np.zeros(0)
    tags = [(int(sid), int(b - a), float(y0), float(y1))
            for sid, a, b, y0, y1 in zip(sids, bounds[:-1], bounds[1:], ends[:len(sids)], ends[len(sids):])]
    missing = [j for j, tag in enumerate(tags) if tag not in cache]
    if missing:
        change = data.speed_change()
        parts = _chunks([bounds[j + 1] - bounds[j] for j in missing])

        def part_stats(part):
            return _segments_stats(data, [np.arange(bounds[missing[i]], bounds[missing[i] + 1]) if order is None
                                          else order[bounds[missing[i]]:bounds[missing[i] + 1]] for i in part], freqs,
                                   nyquist_fraction, acc, change)

        rows_missing = int(sum(bounds[j + 1] - bounds[j] for j in missing))
        for part, new in zip(parts, _map_chunks(part_stats, parts, rows_missing)):
            for i, r in zip(part, new):
                cache[tags[missing[i]]] = r
    rows = [cache[tag] for tag in tags]
    K, P = len(freqs), 1 + 2 * len(freqs) + int(acc)
    shape = {"G": (0, P, P), "g": (0, P), "beta_hat": (0, P), "sampled": (0, K), "cycles": (0, K)}

    def stack(name):
        return np.array([r[name] for r in rows]) if rows else np.zeros(shape.get(name, (0,)))

    sampled, cycles = stack("sampled").astype(bool), stack("cycles")
    return SegmentStats(stack("G"), stack("g"), stack("yy"), stack("n").astype(int), segment=sids, speed=stack("speed"),
                        load=stack("load") if data.has("load") else None, active=(cycles >= min_cycles) & sampled,
                        sampled=sampled, cycles=cycles, sigma2=stack("sigma2"),
                        beta_hat=stack("beta_hat"), rss_hat=stack("rss_hat"), frequencies=freqs, acc=bool(acc),
                        free=_free_flags(data, sids))


#: the segments' statistics are computed a bounded number of rows at a time (their columns, sines
#: and cosines: about 0.1 GB per 2^20 rows), whole segments each; a segment's numbers do not
#: depend on the segments computed with it.  2^17 rows keeps each temporary under glibc's 32 MB
#: mmap ceiling, so the allocator reuses its heap instead of mapping and zero-filling fresh pages
#: for every chunk (10^7 rows: about 1 s less system time per pass over the samples)
CHUNK_ROWS = 2 ** 17


#: segments' statistics of at least this many rows (and two chunks or more) are computed in forked
#: worker processes (:func:`~gearspec.core.parallel.forked_map`), a chunk per task: the same numbers
FORK_MIN_ROWS = 4 * CHUNK_ROWS


def _map_chunks(fn, parts: list, rows: int) -> list:
    """``[fn(p) for p in parts]``, by :func:`~gearspec.core.parallel.forked_map` when the chunks hold
    at least :data:`FORK_MIN_ROWS` rows between them and BLAS runs on one thread here (as in the
    workers: ``yy`` is a BLAS dot product, whose sum splits by thread count)."""
    from ..core.parallel import forked_map, worker_count
    from ..core.reduction import blas_on_one_thread

    n = worker_count() if rows >= FORK_MIN_ROWS and len(parts) >= 2 and blas_on_one_thread() else 1
    if n < 2:
        return [fn(p) for p in parts]
    return forked_map(fn, parts, workers=n)


def _chunks(sizes) -> list[list[int]]:
    """Consecutive runs of the indices of ``sizes`` (rows per segment) of at most :data:`CHUNK_ROWS`
    rows each (at least one segment per run)."""
    out, cur, rows = [], [], 0
    for i, n in enumerate(sizes):
        if cur and rows + n > CHUNK_ROWS:
            out.append(cur)
            cur, rows = [], 0
        cur.append(i)
        rows += int(n)
    return out + [cur] if cur else out


def _free_flags(data: FitData, sids: np.ndarray) -> np.ndarray | None:
    """Per segment id: a block of free motion (None when the data hold none)."""
    if not data.free_motion:
        return None
    free = set(data.segments.loc[data.segments["kind"] == "free", "segment"].tolist())
    return np.array([int(s) in free for s in sids], bool)


def _segments_stats(data: FitData, groups: list, freqs: np.ndarray, nyquist_fraction: float, acc: bool,
                    change: np.ndarray | None = None) -> list[dict]:
    """The statistics of the segments whose rows (in time order) are ``groups``, all at once: one
    dict per segment (the cached unit).  ``change`` (per sample, :meth:`FitData.speed_change`): a
    column with a coefficient of its own in every segment, taken out of its normal equations
    exactly (only the second-order part of a change of speed within a segment remains)."""
    K = len(freqs)
    T = change is not None
    P = 1 + 2 * K + int(acc) + int(T)
    ii = np.concatenate(groups)
    n = np.array([len(g) for g in groups], dtype=np.int64)
    starts = np.concatenate(([0], np.cumsum(n)[:-1]))
    stops = starts + n
    at = lambda name: data.values_at(name, ii)  # noqa: E731  (the chunk's rows only, not a subset's whole array)
    dr = at("direction")
    y = dr * at("y")
    speed = np.add.reduceat(np.abs(at("v")), starts) / n
    load = np.add.reduceat(np.abs(at("load")), starts) / n if data.has("load") else np.zeros(len(n))
    sampled = np.zeros((len(n), K), bool)
    cycles = np.zeros((len(n), K))
    X = np.ones((len(ii), P))
    if K:
        if not data.has("theta"):
            raise InputError("harmonics need positions (theta) in the fit data")
        th = at("theta")
        cycles = freqs * (np.maximum.reduceat(th, starts) - np.minimum.reduceat(th, starts))[:, None]
        # THE position-Nyquist rule (gearspec.spectrum.position_nyquist), on the samples in time order
        sampled = freqs < nyquist_fraction * group_position_nyquist(th, starts, stops)[:, None]
        center = np.repeat(np.add.reduceat(th, starts) / n, n)
        X[:, 1:1 + 2 * K:2], X[:, 2:2 + 2 * K:2] = harmonic_columns(th, freqs, center)  # phases about each mean
        if not sampled.all():   # (times 1 changes nothing: skipped when every line is sampled)
            X[:, 1:1 + 2 * K] *= np.repeat(np.repeat(sampled, 2, axis=1), n, axis=0)
    if acc:
        X[:, 1 + 2 * K] = dr * at("acc")
    if T:
        X[:, -1] = change[ii]
    G, g, yy = group_normal_equations(X, y, starts, stops)
    if T:
        G_change = G[:, -1, -1]
        G, g, yy = partial_out_last(G, g, yy)
        P -= 1
    try:
        beta = np.einsum("spq,sq->sp", np.linalg.pinv(G, rcond=1e-12, hermitian=True), g)
    except np.linalg.LinAlgError as exc:
        raise ConvergenceError(f"the local fit of a segment did not converge ({exc}) with {K} lines; fit fewer "
                               f"lines (--lines)") from exc
    rss = np.maximum(yy - np.einsum("sp,sp->s", beta, g), 0.0)
    dof = n - (1 + 2 * sampled.sum(axis=1) + int(acc) + (G_change > 0 if T else 0))
    sigma2 = np.where(dof >= 3, rss / np.maximum(dof, 1), np.nan)
    return [{"n": int(n[s]), "speed": float(speed[s]), "load": float(load[s]), "sampled": sampled[s],
             "cycles": cycles[s], "G": G[s], "g": g[s], "yy": float(yy[s]),
             "beta_hat": beta[s], "rss_hat": float(rss[s]), "sigma2": float(sigma2[s])} for s in range(len(n))]


def speed_ranges(stats: SegmentStats) -> np.ndarray:
    """``(K, 2)``: ``[min, max]`` of the speeds of the segments where each line was measurable
    (``active``: below the position-Nyquist limit of the segment,
    :func:`gearspec.spectrum.position_nyquist`, and at least ``min_cycles`` of its cycles in the
    segment).  The amplitude law is fitted there and held at the edges elsewhere
    (``speed_range`` of a harmonic); ``[0, inf]`` for a line measured nowhere."""
    K = len(stats.frequencies)
    out = np.tile([0.0, np.inf], (K, 1))
    for k in range(K):
        m = stats.active[:, k]
        if m.any():
            out[k] = float(np.min(stats.speed[m])), float(np.max(stats.speed[m]))
        # blocks of free motion are short: each edge is the speed below (above) which the sampled
        # blocks together cover one cycle of the line (:data:`FREE_RANGE_CYCLES`)
        f = stats.free & stats.sampled[:, k] if stats.free is not None else None
        if f is not None and f.any():
            got = free_speed_range(stats.speed[f], stats.cycles[f, k])
            if got is not None:
                lo, hi = got
                out[k] = (lo, hi) if not m.any() else (min(out[k, 0], lo), max(out[k, 1], hi))
    return out


def free_speed_range(speed, cycles, need: float = FREE_RANGE_CYCLES) -> tuple[float, float] | None:
    """``(lo, hi)``: the speed below which the blocks of free motion at speeds ``speed`` (each
    holding ``cycles`` cycles of a line) together hold ``need`` cycles, and the speed above which
    they do; None when all of them together hold fewer.  The speed range of a line's amplitude law
    over free motion, in :func:`speed_ranges` and in the closed loop
    (:func:`gearspec.diagnose.coverage.line_speed_range`)."""
    sp, cyc = np.asarray(speed, float), np.asarray(cycles, float)
    if not len(sp):
        return None
    o = np.argsort(sp, kind="stable")
    up, down = np.cumsum(cyc[o]), np.cumsum(cyc[o][::-1])
    if up[-1] < need:
        return None
    return float(sp[o][np.searchsorted(up, need)]), float(sp[o][::-1][np.searchsorted(down, need)])


def pair_se(a: float, c: float, cov) -> tuple[float, float]:
    """Standard errors of the amplitude ``hypot(a, c)`` and the phase ``atan2(c, a)`` (rad) of a line
    fitted as ``a sin + c cos`` with covariance ``cov`` (2 x 2) of ``(a, c)``, by the delta method;
    NaN for a zero amplitude.  ``a``, ``c`` and the amplitude in Nm (N)."""
    A = math.hypot(a, c)
    if not A > 0:
        return float("nan"), float("nan")
    ga = np.array([a / A, c / A])
    gp = ga[::-1] * np.array([-1.0, 1.0]) / A     # (-c, a) / A^2 without A^2 (denormal A)
    return float(math.sqrt(max(ga @ cov @ ga, 0))), float(math.sqrt(max(gp @ cov @ gp, 0)))
