"""Per-segment moments: the exact reduction of the samples that every library column needs.

Within a constant-speed segment ``s`` the velocity is the segment's own (``FitData`` with
``velocity="segment"``), so every candidate column of the library factors into a per-segment
multiplier times one of a few *sample bases*:

    X[i, j] = a_j(speed_s, direction_s) * phi_k(j)(sample i)

with ``phi`` = 1, |load|, temperature - T_ref, acceleration, and sin / cos(2 pi f theta) for every
ripple frequency f.  So one pass over the samples that accumulates, per segment, the Gram matrix
``B_s = Phi_s^T Phi_s`` and ``c_s = Phi_s^T y_s`` of the K sample bases (K is small: 1 + 2F + up to
3) gives, for *any* library and any value of its nonlinear parameters,

    X_s^T X_s = A_s^T B_s A_s,    X_s^T y_s = A_s^T c_s

exactly.  These are stored as K "pseudo rows" per segment, ``P_s`` (K x K) and ``q_s`` (K) with
``P_s^T P_s = B_s`` and ``P_s^T q_s = c_s`` (from the eigen-decomposition of ``B_s``), so that
``||y_s - X_s w||^2 = ||q_s - (A_s-weighted P_s) w||^2 + rest_s`` for every ``w``, where
``rest_s = y_s^T y_s - ||q_s||^2`` is what no combination of the bases can explain.  Sparse
regression, cross-validation, the bootstrap and the nonlinear refinement then work on S x K rows
instead of N samples, exactly.

:mod:`gearspec.identify` keeps a similar reduction for the papers' laws (basis 1, sin, cos, one
direction at a time, segment-mean load); the explorer needs both directions at once and
per-sample load, temperature and acceleration bases, hence this one.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..core.reduction import harmonic_columns, normal_equations
from ..errors import InputError
from ..fitdata import FitData

__all__ = ["Moments", "moments"]


@dataclass
class Moments:
    """Exact per-segment sufficient statistics of a :class:`~gearspec.fitdata.FitData`.

    Attributes
    ----------
    basis : tuple of str
        Names of the K sample bases: ``"1"``, ``"load"`` (|load|), ``"temperature"`` (T - T_ref),
        ``"acc"``, ``"sin{i}"``, ``"cos{i}"`` (frequency i).
    frequencies : ndarray
        Ripple frequencies, cycles per unit of theta.
    labels : list
        Their labels (None where unlabelled).
    segment, run, direction, speed, n : ndarray, (S,)
        Segment id, run id, direction (+1/-1), speed (|mean velocity|) and sample count.
    vabs : ndarray, (S,) or None
        Mean |velocity| over the segment's samples (the speed the held-out folds are dealt by,
        :mod:`gearspec.core.crossval`); equal to ``speed`` where the velocity keeps its sign.
    B, c : ndarray, (S, K, K) and (S, K)
        Gram matrix of the bases and their products with the friction, per segment.
    yy : ndarray, (S,)
        Sum of squares of the friction samples.
    P : ndarray, (S, K, K)
        Pseudo rows of each segment (``P_s^T P_s = B_s``).
    q : ndarray, (S, K)
        Pseudo targets (``P_s^T q_s = c_s``).
    rest : ndarray, (S,)
        ``yy - ||q||^2``: what no column of any library can explain.
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
    """

    basis: tuple
    frequencies: np.ndarray
    labels: list
    segment: np.ndarray
    run: np.ndarray
    direction: np.ndarray
    speed: np.ndarray
    n: np.ndarray
    B: np.ndarray
    c: np.ndarray
    yy: np.ndarray
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
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self):
        if self.P is None:
            self.P, self.q, self.rest = _pseudo_rows(self.B, self.c, self.yy)

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
        idx = np.asarray(idx)
        t = lambda a: None if a is None else a[idx]  # noqa: E731
        return replace(self, segment=t(self.segment), run=t(self.run), direction=t(self.direction),
                       speed=t(self.speed), n=t(self.n), B=t(self.B), c=t(self.c), P=t(self.P), q=t(self.q),
                       yy=t(self.yy),
                       rest=t(self.rest), load=t(self.load), temperature=t(self.temperature),
                       cycles=t(self.cycles), noise=t(self.noise), vabs=t(self.vabs), notes=list(self.notes),
                       _cache={})

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
        B, c, yy = self.B, self.c, self.yy
        S = self.S
        B2 = np.empty((S, len(L), len(L)))
        c2 = np.empty((S, len(L)))
        yy2 = np.empty(S)
        for s in range(S):
            Rs = R
            if min_cycles is not None:
                Rs = [i for i in R if not self.basis[i].startswith(("sin", "cos"))
                      or self.cycles[s, int(self.basis[i][3:])] >= min_cycles]
            BLL = B[s][np.ix_(L, L)]
            if not Rs:
                B2[s], c2[s], yy2[s] = BLL, c[s, L], yy[s]
                continue
            BLR = B[s][np.ix_(L, Rs)]
            iRR = np.linalg.pinv(B[s][np.ix_(Rs, Rs)], rcond=1e-10, hermitian=True)
            T = BLR @ iRR
            B2[s] = BLL - T @ BLR.T
            c2[s] = c[s, L] - T @ c[s, Rs]
            yy2[s] = yy[s] - c[s, Rs] @ iRR @ c[s, Rs]
        return replace(self, basis=tuple(self.basis[i] for i in L), B=B2, c=c2, yy=np.maximum(yy2, 0.0), P=None, q=None,
                       noise=self.noise, _cache={},
                       rest=None, notes=list(self.notes) + ["bases " + ", ".join(self.basis[i] for i in R)
                                                            + " profiled out per segment"])

    def restrict(self, names) -> "Moments":
        """The moments of the bases ``names`` alone (the others ignored, not profiled out): exact
        for every law that uses only those bases, with fewer pseudo rows (cached)."""
        key = tuple(b for b in self.basis if b in set(names))
        if key == self.basis:
            return self
        if key not in self._cache:
            idx = [self.index(b) for b in key]
            self._cache[key] = replace(self, basis=key, B=self.B[:, idx][:, :, idx], c=self.c[:, idx], P=None,
                                       q=None, rest=None, _cache={})
        return self._cache[key]

    def groups(self, by: str = "segment") -> np.ndarray:
        """Group id of each segment for held-out folds: ``"segment"`` or ``"run"``."""
        if by == "segment":
            return self.segment
        if by == "run":
            return self.run
        raise InputError(f"held-out groups must be 'segment' or 'run', got '{by}'")

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
    if min_cycles is not None and len(freqs):
        freqs, labels = _lines_with_cycles(data, freqs, labels, min_cycles, notes)
    if not np.all(np.isfinite(data.y)) or not np.all(np.isfinite(data.v)):
        raise InputError("fit data: friction or velocity has NaN or infinite values")
    basis, load, temp, t_ref, acc = _sample_bases(data, inertia, notes)
    for i in range(len(freqs)):
        basis += [f"sin{i}", f"cos{i}"]
    K = len(basis)
    F = len(freqs)

    order = np.argsort(data.segment, kind="stable")
    sids, starts = np.unique(data.segment[order], return_index=True)
    bounds = np.append(starts, len(order))
    S = len(sids)
    B = np.zeros((S, K, K))
    c = np.zeros((S, K))
    yy = np.zeros(S)
    speed = np.zeros(S)
    vabs = np.zeros(S)
    direction = np.zeros(S, np.int64)
    run = np.zeros(S, np.int64)
    n = np.zeros(S, np.int64)
    seg_load = np.zeros(S) if load is not None else None
    seg_temp = np.zeros(S) if temp is not None else None
    cycles = np.zeros((S, F))
    noise = np.full(S, np.nan)
    varying = 0
    for s, (a0, b0) in enumerate(zip(bounds[:-1], bounds[1:])):
        ii = order[a0:b0]
        v = data.v[ii]
        vm = float(np.mean(v))
        if np.ptp(v) > 1e-9 * max(abs(vm), 1e-300):
            varying += 1
        dirs = data.direction[ii]
        d = int(np.sign(np.sum(dirs))) or int(dirs[0])
        speed[s] = abs(vm)
        vabs[s] = float(np.mean(np.abs(v)))
        direction[s] = d
        run[s] = int(data.run[ii[0]])
        n[s] = len(ii)
        Phi = np.empty((len(ii), K))
        Phi[:, 0] = 1.0
        col = 1
        if load is not None:
            Phi[:, col] = load[ii]
            seg_load[s] = float(np.mean(load[ii]))
            col += 1
        if temp is not None:
            Phi[:, col] = temp[ii] - t_ref
            seg_temp[s] = float(np.mean(temp[ii]))
            col += 1
        if acc is not None:
            Phi[:, col] = acc[ii]
            col += 1
        if F:
            th = np.asarray(data.theta[ii], dtype=float)
            cycles[s] = freqs * (float(np.ptp(th)) if len(th) > 1 else 0.0)
            Phi[:, col::2], Phi[:, col + 1::2] = harmonic_columns(th, freqs)   # phases about the segment's mean
        y = data.y[ii]
        B[s], c[s], yy[s] = normal_equations(Phi, y)
        noise[s] = _noise_variance(Phi, y, B[s], c[s])
    if varying:
        notes.append(f"velocity varies within {varying} of {S} segments: speed laws are evaluated at each "
                     "segment's mean velocity")
    return Moments(basis=tuple(basis), frequencies=freqs, labels=labels, segment=sids, run=run, direction=direction,
                   speed=speed, n=n, B=B, c=c, yy=yy, load=seg_load, temperature=seg_temp, cycles=cycles,
                   noise=_fill_noise(noise), t_ref=t_ref, vabs=vabs, unit=data.unit, notes=notes)



def _lines_with_cycles(data: FitData, freqs, labels, min_cycles: float, notes: list) -> tuple:
    """The frequencies (and their labels) that complete at least ``min_cycles`` cycles in some
    segment; a note for each left out."""
    order = np.argsort(data.segment, kind="stable")
    _, starts = np.unique(data.segment[order], return_index=True)
    th = np.asarray(data.theta, dtype=float)[order]
    span = np.maximum.reduceat(th, starts) - np.minimum.reduceat(th, starts)
    ok = freqs * float(np.max(span)) >= min_cycles
    for f, lab in zip(freqs[~ok], np.asarray(labels, dtype=object)[~ok]):
        notes.append(f"ripple line {f:.6g} cycles/{data.unit}" + (f" ({lab})" if lab else "")
                     + f" completes fewer than {min_cycles:g} cycle(s) in every segment: left out")
    return freqs[ok], [lab for lab, k in zip(labels, ok) if k]


def _sample_bases(data: FitData, inertia, notes: list) -> tuple:
    """The sample bases besides the ripple's (``1`` and those of the channels that vary), and the
    channels they are built from: ``(basis, |load| or None, temperature or None, t_ref, acc or None)``."""
    basis = ["1"]
    load = None
    if data.load is not None:
        load = np.abs(np.asarray(data.load, dtype=float))
        if np.ptp(load) > 0 or np.any(load > 0):
            basis.append("load")
        else:
            load = None
    temp = None
    t_ref = None
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


def _pseudo_rows(B, c, yy):
    """Pseudo rows ``P_s`` (K x K, ``P_s^T P_s = B_s``), targets ``q_s`` (``P_s^T q_s = c_s``) and
    ``rest_s = yy_s - ||q_s||^2``, from the eigen-decomposition of each B_s in a basis scaled to
    unit RMS (so that the rank test is scale-free)."""
    S, K = c.shape
    diag = np.einsum("skk->k", B) if S else np.ones(K)
    scale = np.sqrt(np.maximum(diag / max(S, 1), 0.0))
    scale[scale == 0] = 1.0
    P = np.zeros((S, K, K))
    q = np.zeros((S, K))
    for s in range(S):
        Bs = B[s] / np.outer(scale, scale)
        lam, U = np.linalg.eigh(Bs)
        keep = lam > max(lam[-1], 0.0) * 1e-12
        r = int(keep.sum())
        if r == 0:
            continue
        lam, U = lam[keep], U[:, keep]
        P[s, :r] = (np.sqrt(lam)[:, None] * U.T) * scale[None, :]
        q[s, :r] = (U.T @ (c[s] / scale)) / np.sqrt(lam)
    rest = np.maximum(yy - np.sum(q * q, axis=1), 0.0)
    return P, q, rest

