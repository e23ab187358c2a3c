"""Per-segment moments: the exact reduction of the samples that every library column needs.

Within a constant-speed segment ``s`` (``FitData(velocity="segment")``) every library column is a
per-segment multiplier times one of a few *sample bases* ``phi`` (1, |load|, temperature - T_ref,
acceleration, sin / cos(2 pi f theta) per ripple line): ``X[i, j] = a_j(speed_s, direction_s)
phi_k(j)(i)``.  So the per-segment normal equations of the bases (``G_s = Phi_s^T Phi_s``,
``b_s = Phi_s^T y_s``, :class:`~gearspec.core.reduction.GroupNormals`) give those of any library and
any value of its nonlinear parameters exactly: ``X_s^T X_s = A_s^T G_s A_s``, ``X_s^T y_s =
A_s^T b_s``.  They are held as K pseudo rows per segment
(:meth:`~gearspec.core.reduction.GroupNormals.pseudo_rows`), on which sparse regression,
cross-validation, the bootstrap and the refinement work exactly, on S x K rows instead of N samples.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..core.reduction import GroupNormals, group_normal_equations, harmonic_columns, partial_out_last
from ..errors import InputError
from ..fitdata import FitData
from .forked import chunk_count, fits_map

__all__ = ["Moments", "moments"]


@dataclass
class Moments(GroupNormals):
    """Exact per-segment sufficient statistics of a :class:`~gearspec.fitdata.FitData`: the normal
    equations ``G``, ``b``, ``yy``, ``n`` of the sample bases per segment, and

    Attributes
    ----------
    basis : tuple of str
        Names of the K sample bases: ``"1"``, ``"load"`` (|load|), ``"temperature"`` (T - T_ref),
        ``"acc"``, ``"sin{i}"``, ``"cos{i}"`` (frequency i).
    frequencies : ndarray
        Ripple frequencies, cycles per unit of theta.
    labels : list
        Their labels (None where unlabelled).
    segment, run, direction, speed : ndarray, (S,)
        Segment id, run id, direction (+1/-1) and speed (|mean velocity|).
    vabs : ndarray, (S,) or None
        Mean |velocity| over the segment's samples (the speed the held-out folds are dealt by,
        :mod:`gearspec.core.crossval`); equal to ``speed`` where the velocity keeps its sign.
    P, q, rest : ndarray, (S, K, K), (S, K), (S,)
        The pseudo rows, targets and unexplained rest (:meth:`GroupNormals.pseudo_rows`).
    load, temperature : ndarray (S,) or None
        Mean |load| and mean temperature of each segment (for tables and plots).
    cycles : ndarray, (S, F)
        Cycles of each frequency completed in each segment.
    noise : ndarray, (S,)
        Noise variance of each segment: the variance of the residual of the segment's own fit of
        the bases, or -- larger when the noise is coloured -- what the scatter of its block means
        implies (10 blocks).  The yardstick of held-out comparisons.
    t_ref : float or None
        Reference temperature (mean over the samples) of the temperature basis.
    unit : str
    notes : list of str
    group : ndarray, (S,) or None
        The held-out unit of each segment where it is not the segment itself: a block of free
        motion's whole stretch of motion (:attr:`gearspec.fitdata.FitData.group`); None when every
        segment is its own unit (plateaus, sweeps).  Folds, paired comparisons and the held-out
        Z's clusters follow it (:meth:`groups`).
    Gb, bb, yyb : ndarray, (S, B, K, K), (S, B, K), (S, B), or None
        The same normal equations in ``B`` consecutive blocks of every segment's samples
        (``np.array_split`` of them, as :func:`gearspec.core.crossval.z_statistic` splits a
        held-out group): what the held-out Z's cluster-robust variance needs (:mod:`.accept`).
        None in free motion (there the whole segment is one cluster).
    """

    basis: tuple = ()
    frequencies: np.ndarray | None = None
    labels: list | None = None
    segment: np.ndarray | None = None
    run: np.ndarray | None = None
    direction: np.ndarray | None = None
    speed: np.ndarray | None = None
    P: np.ndarray | None = None
    q: np.ndarray | None = None
    rest: np.ndarray | None = None
    load: np.ndarray | None = None
    temperature: np.ndarray | None = None
    cycles: np.ndarray | None = None
    noise: np.ndarray | None = None
    t_ref: float | None = None
    vabs: np.ndarray | None = None
    unit: str = "rad"
    notes: list = field(default_factory=list)
    group: np.ndarray | None = None
    Gb: np.ndarray | None = None
    bb: np.ndarray | None = None
    yyb: np.ndarray | None = None
    _cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    per_group = GroupNormals.per_group + ("segment", "run", "direction", "speed", "P", "q", "rest", "load",
                                          "temperature", "cycles", "noise", "vabs", "group", "Gb", "bb", "yyb")

    def __post_init__(self):
        if self.P is None:
            self.P, self.q, self.rest = self.pseudo_rows()

    @property
    def S(self) -> int:
        return len(self.speed)

    @property
    def K(self) -> int:
        return len(self.basis)

    @property
    def N(self) -> int:
        return int(np.sum(self.n))

    @property
    def directions(self) -> tuple[int, ...]:
        return tuple(int(d) for d in (1, -1) if np.any(self.direction == d))

    def has(self, name: str) -> bool:
        return name in self.basis

    def index(self, name: str) -> int:
        return self.basis.index(name)

    def take(self, idx) -> "Moments":
        """The moments of segments ``idx`` (repeats allowed, as in a bootstrap)."""
        return replace(super().take(idx), notes=list(self.notes))

    def profile(self, keep, min_cycles: float | None = None) -> "Moments":
        """The moments of the bases ``keep`` with the others profiled out *per segment* (each
        segment's own free coefficients for them, Frisch-Waugh): e.g. the friction level with every
        segment's ripple removed by its own sin/cos fit, whatever law the ripple follows.  Where a
        ripple line does not complete a cycle, it absorbs part of the level, and the segment says
        correspondingly less about the level.  With ``min_cycles``, a ripple basis is profiled
        out only in the segments where its line completes that many cycles (elsewhere it stays in
        the level as noise, as it is not identifiable there anyway)."""
        L = [i for i, b in enumerate(self.basis) if b in keep]
        R = [i for i, b in enumerate(self.basis) if b not in keep]
        if not R:
            return self
        G, b, yy = self.G, self.b, self.yy
        G2, b2, yy2 = G[:, L][:, :, L].copy(), b[:, L].copy(), yy.copy()
        for s in range(self.S):
            Rs = [i for i in R if min_cycles is None or not self.basis[i].startswith(("sin", "cos"))
                  or self.cycles[s, int(self.basis[i][3:])] >= min_cycles]
            if not Rs:
                continue
            GLR = G[s][np.ix_(L, Rs)]
            iRR = np.linalg.pinv(G[s][np.ix_(Rs, Rs)], rcond=1e-10, hermitian=True)
            T = GLR @ iRR
            G2[s] -= T @ GLR.T
            b2[s] -= T @ b[s, Rs]
            yy2[s] -= b[s, Rs] @ iRR @ b[s, Rs]
        return replace(self, basis=tuple(self.basis[i] for i in L), G=G2, b=b2, yy=np.maximum(yy2, 0.0), P=None,
                       q=None, rest=None, Gb=None, bb=None, yyb=None,
                       notes=list(self.notes) + ["bases " + ", ".join(self.basis[i] for i in R)
                                                                    + " profiled out per segment"])

    def restrict(self, names) -> "Moments":
        """The moments of the bases ``names`` alone (the others ignored, not profiled out): exact
        for every law that uses only those bases, with fewer pseudo rows (cached)."""
        key = tuple(b for b in self.basis if b in set(names))
        if key == self.basis:
            return self
        if key not in self._cache:
            cols = np.array([self.index(b) for b in key], dtype=int)
            G, b = self.columns(cols)
            blocks = {} if self.Gb is None else {"Gb": self.Gb[:, :, cols][:, :, :, cols], "bb": self.bb[:, :, cols]}
            self._cache[key] = replace(self, basis=key, G=G, b=b, P=None, q=None, rest=None, **blocks)
        return self._cache[key]

    def rows(self, segment) -> np.ndarray:
        """Position in these moments of each of the segment ids ``segment`` (e.g. every sample's)."""
        seg = np.asarray(self.segment)
        order = np.argsort(seg, kind="stable")
        k = np.searchsorted(seg[order], np.asarray(segment))
        return order[np.minimum(k, len(seg) - 1)].astype(int)

    #: group id of each segment for held-out folds: ``"segment"`` or ``"run"`` (FitData's rule)
    groups = FitData.groups

    def rss_of(self, beta: np.ndarray) -> np.ndarray:
        """Residual sum of squares of every segment for per-segment coefficients ``beta`` (S, K) of
        the sample bases (a prediction as :meth:`~.law.LawFit.basis_coefficients` gives it)."""
        return (self.yy - 2.0 * np.einsum("sk,sk->s", self.b, beta)
                + np.einsum("sk,skl,sl->s", beta, self.G, beta))

    def sse(self, X: np.ndarray, w: np.ndarray) -> np.ndarray:
        """Residual sum of squares of each segment for the pseudo-row design ``X`` (S*K, p) and
        coefficients ``w``: exactly ``sum_i (y_i - x_i w)^2`` over the segment's samples."""
        r = self.q.reshape(-1) - X @ w
        return np.sum(r.reshape(self.S, self.K) ** 2, axis=1) + self.rest


def moments(data: FitData, frequencies=(), labels=None, *, inertia: bool | str = "auto",
            min_cycles: float | None = None) -> Moments:
    """One pass over the samples of ``data``: see :class:`Moments`.

    Parameters
    ----------
    data : FitData
        Samples in constant-speed segments.  The speed laws are evaluated at each segment's mean
        velocity; when ``data.v`` varies within a segment (``velocity="measured"``) the reduction
        uses the mean and says so in ``notes``.
    frequencies : sequence of float
        Ripple frequencies (cycles per unit of theta); needs ``data.theta``.
    labels : sequence, optional
        A label per frequency.
    inertia : bool or "auto"
        Add the acceleration as a basis (a signed inertia column, for residual inertia that the
        gear spec's J did not remove).  "auto": when ``data.acc`` is present and not zero.
    min_cycles : float, optional
        Leave out frequencies that complete fewer cycles than this in every segment (they cannot
        be told from the friction level); ``notes`` lists them.
    """
    freqs = np.asarray([float(f) for f in frequencies], dtype=float)
    if len(freqs) and data.theta is None:
        raise InputError("ripple frequencies need positions (theta) in the fit data")
    if np.any(~np.isfinite(freqs)) or np.any(freqs <= 0):
        raise InputError(f"ripple frequencies must be positive numbers, got {freqs.tolist()}")
    labels = list(labels) if labels is not None else [None] * len(freqs)
    if len(labels) != len(freqs):
        raise InputError(f"{len(labels)} labels for {len(freqs)} frequencies")
    if len(data) == 0:
        raise InputError("fit data: no samples")
    notes: list[str] = []
    order = np.argsort(data.segment, kind="stable")
    sids, starts = np.unique(data.segment[order], return_index=True)
    segs = [slice(a, z) for a, z in zip(starts, np.append(starts[1:], len(order)))]
    th = np.asarray(data.theta, dtype=float)[order] if len(freqs) else None
    span = np.maximum.reduceat(th, starts) - np.minimum.reduceat(th, starts) if len(freqs) else None
    if min_cycles is not None and len(freqs):
        ok = freqs * float(np.max(span)) >= min_cycles
        for f, lab in zip(freqs[~ok], np.asarray(labels, dtype=object)[~ok]):
            notes.append(f"ripple line {f:.6g} cycles/{data.unit}" + (f" ({lab})" if lab else "")
                         + f" completes fewer than {min_cycles:g} cycle(s) in every segment: left out")
        freqs, labels = freqs[ok], [lab for lab, k in zip(labels, ok) if k]
    if not np.all(np.isfinite(data.y)) or not np.all(np.isfinite(data.v)):
        raise InputError("fit data: friction or velocity has NaN or infinite values")
    basis, load, temp, t_ref, acc = _sample_bases(data, inertia, notes)
    K0, F = len(basis), len(freqs)
    basis += [f"{sc}{i}" for i in range(F) for sc in ("sin", "cos")]
    chans = [np.ones(len(data))] + [x for x in (load, None if temp is None else temp - t_ref, acc) if x is not None]
    cycles = np.outer(span, freqs) if F else np.zeros((len(segs), 0))
    y, v, dirs = data.y[order], data.v[order], data.direction[order]
    change = data.speed_change()
    # chunks of whole segments reduced at once in forked workers (a segment's sums do not depend on
    # its chunk): a few per worker, each within the memory bound
    sizes = np.array([sl.stop - sl.start for sl in segs])
    parts = fits_map(lambda az: _reduce_chunk(chans, change, th, y, order, segs[az[0]:az[1]], K0, freqs),
                     list(_chunks(sizes, len(basis), chunk_count(float(np.sum(sizes)) * len(basis)))))
    gn = GroupNormals(*(np.concatenate([c[0][k] for c in parts]) for k in range(4)))
    blocks = {} if change is not None else {k: np.concatenate([c[1][k] for c in parts]) for k in ("Gb", "bb", "yyb")}
    noise = np.concatenate([c[2] for c in parts])
    group = None
    if data.group is not None and change is not None:
        group = np.asarray(data.group)[order][starts].astype(np.int64)
        block = group != sids
        if block.any():
            # a block of free motion (a few samples over which the speed changes) cannot tell its
            # noise from the friction's change within it (its own estimate was about 100 times the
            # noise variance on bell moves): blocks take the other segments' median, or -- with
            # none -- held-out comparisons use the spread over stretches of motion (pool._excess)
            noise = np.where(block, np.nan, noise)
        else:
            group = None
    vm = np.array([np.mean(v[sl]) for sl in segs])
    varying = sum(np.ptp(v[sl]) > 1e-9 * max(abs(m), 1e-300) for sl, m in zip(segs, vm))
    if varying:
        notes.append(f"velocity varies within {varying} of {len(segs)} segments: speed laws are evaluated at each "
                     "segment's mean velocity")

    def seg_mean(x):
        if x is None:
            return None
        x = x[order]
        return np.array([np.mean(x[sl]) for sl in segs])

    return Moments(gn.G, gn.b, gn.yy, gn.n, basis=tuple(basis), frequencies=freqs, labels=labels, segment=sids,
                   run=data.run[order][starts].astype(np.int64), speed=np.abs(vm), vabs=seg_mean(np.abs(data.v)),
                   direction=np.array([int(np.sign(np.sum(dirs[sl]))) or int(dirs[sl][0]) for sl in segs], np.int64),
                   load=seg_mean(load), temperature=seg_mean(temp), cycles=cycles, noise=_fill_noise(noise),
                   t_ref=t_ref, unit=data.unit, notes=notes, group=group, **blocks)


#: samples x sample bases held at once while reducing (a chunk of whole segments; at least one)
_CHUNK_CELLS = 4_000_000


def _chunks(sizes: np.ndarray, K: int, parts: int = 1):
    """``(first, stop)`` indices of consecutive segments holding about :data:`_CHUNK_CELLS` / ``K``
    samples together, or fewer so as to make at least about ``parts`` chunks (at least one segment
    each)."""
    per = max(min(_CHUNK_CELLS // max(K, 1), -(-int(np.sum(sizes)) // max(parts, 1))), 1)
    a, S = 0, len(sizes)
    cum = np.cumsum(sizes)
    while a < S:
        before = cum[a - 1] if a else 0
        z = max(int(np.searchsorted(cum, before + per, side="right")), a + 1)
        yield a, min(z, S)
        a = min(z, S)


def _reduce_chunk(chans, change, th, y, order, segs, K0: int, freqs) -> tuple:
    """The normal equations (``G, b, yy, n``), block normal equations and noise variances of the
    segments ``segs`` (slices of the sorted samples, consecutive): the sample bases of these
    samples alone are built, never those of the whole recording."""
    a0, z0 = segs[0].start, segs[-1].stop
    local = [slice(sl.start - a0, sl.stop - a0) for sl in segs]
    idx = order[a0:z0]
    F = len(freqs)
    Phi = np.empty((z0 - a0, K0 + 2 * F))
    Phi[:, :K0] = np.column_stack([c[idx] for c in chans])
    for sl in local if F else ():
        Phi[sl, K0::2], Phi[sl, K0 + 1::2] = harmonic_columns(th[a0:z0][sl], freqs)   # phases about the segment's mean
    yc = y[a0:z0]
    starts, stops = [sl.start for sl in local], [sl.stop for sl in local]
    blocks = {}
    if change is None:
        gn = GroupNormals.of(Phi, yc, starts, stops)
        blocks = _block_normals(Phi, yc, local)
    else:  # free motion: the first-order effect of the change of speed within each segment taken out
        ext = GroupNormals.of(np.column_stack([Phi, change[idx]]), yc, starts, stops)
        gn = GroupNormals(*partial_out_last(ext.G, ext.b, ext.yy), ext.n)
    noise = np.array([_noise_variance(Phi[sl], yc[sl], gn.G[s], gn.b[s]) for s, sl in enumerate(local)])
    return (gn.G, gn.b, gn.yy, gn.n), blocks, noise


#: blocks per segment of :attr:`Moments.Gb` (the ``blocks`` of :func:`gearspec.core.crossval.z_statistic`)
BLOCKS = 8


def _block_normals(Phi, y, segs) -> dict:
    """:attr:`Moments.Gb`, ``bb``, ``yyb``: normal equations of :data:`BLOCKS` consecutive blocks of
    every segment (``np.array_split`` of its rows; empty blocks of short segments are zeros)."""
    a, z = [], []
    for sl in segs:
        edges = np.cumsum([0] + [len(x) for x in np.array_split(np.arange(sl.stop - sl.start), BLOCKS)]) + sl.start
        a += list(edges[:-1])
        z += list(edges[1:])
    G, b, yy = group_normal_equations(Phi, y, a, z)
    S, K = len(segs), Phi.shape[1]
    return {"Gb": G.reshape(S, BLOCKS, K, K), "bb": b.reshape(S, BLOCKS, K), "yyb": yy.reshape(S, BLOCKS)}


def _sample_bases(data: FitData, inertia, notes: list) -> tuple:
    """The sample bases besides the ripple's (``1`` and those of the channels that vary), and the
    channels they are built from: ``(basis, |load| or None, temperature or None, t_ref, acc or None)``."""
    basis, load, temp, t_ref = ["1"], None, None, None
    if data.load is not None and np.any(np.abs(data.load) > 0):
        load = np.abs(np.asarray(data.load, dtype=float))
        basis.append("load")
    if data.temperature is not None:
        temp = np.asarray(data.temperature, dtype=float)
        if np.ptp(temp) > 0:
            t_ref = float(np.round(np.mean(temp), 1))
            basis.append("temperature")
        else:
            notes.append(f"temperature constant ({temp[0]:.3g} degC): no temperature term")
            temp = None
    acc = None
    if inertia and data.acc is not None:
        a = np.asarray(data.acc, dtype=float)
        scale = np.max(np.abs(data.v)) if len(data.v) else 0.0
        if inertia is True or (np.sqrt(np.mean(a * a)) > 1e-9 * max(scale, 1e-300)):
            acc = a
            basis.append("acc")
    return basis, load, temp, t_ref, acc


def _noise_variance(Phi, y, B, c, blocks: int = 10) -> float:
    """Noise variance of one segment (see :attr:`Moments.noise`); NaN for segments too short."""
    n, K = Phi.shape
    if n <= K + 2:
        return float("nan")
    beta = np.linalg.lstsq(B, c, rcond=1e-10)[0]
    e = y - Phi @ beta
    white = float(e @ e) / (n - K)
    if n < 4 * blocks:
        return white
    m = n // blocks
    bm = e[: m * blocks].reshape(blocks, m).mean(axis=1)
    return max(white, m * float(np.var(bm, ddof=1)))


def _fill_noise(noise):
    """Segments too short for their own estimate (quasi-static points) take the median of the
    others, or -- when none has one -- stay NaN (held-out comparisons then use the spread of the
    held-out errors instead)."""
    ok = np.isfinite(noise)
    if ok.any() and not ok.all():
        noise = noise.copy()
        noise[~ok] = np.median(noise[ok])
    return noise
