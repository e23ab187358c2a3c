"""Candidate terms: how each one is fitted (what proposes them: :mod:`.detectors`).

A candidate is a *procedure*, not a fixed term: given the groups it may use (the training groups
of a fold, or all of them) it searches its own nonlinear parameters there and returns the blocks
to add to the model (and those they replace), so that the data a fold is judged on never chose the
term that predicts it.  It reads the round through its context (:class:`~.context.Round`) only.
"""

from __future__ import annotations

import math
import types
import weakref
from dataclasses import dataclass, field, fields, replace

import numpy as np

from ..core.reduction import group_cross, normal_equations
from ..gears import integer_hint
from ..spectrum import LombScargle
from .amplitude import EXP_GRID, POW_GRID, RAT_GRID, choose_amplitude_law, segment_index  # noqa: F401 (re-exported)
from .context import BLAS_GROUP_ROWS, Round, group_normals
from .coverage import measurable, segment_span
from .design import HarmonicBlock, TermBlock, solve_normal
from . import rowcols
from .rowcols import Columns

__all__ = ["Candidate", "Proposal", "PeriodicCandidate", "GridCandidate", "FixedCandidate",
           "LagCandidate", "LaggedHarmonicBlock", "SidebandCandidate", "SidebandBlock", "choose_amplitude_law",
           "cross_grams", "train_fit", "per_direction", "travel_ok", "lagged", "DIRECTION_NAMES"]

_TWO_PI = 2.0 * math.pi
#: the name of a direction (0: both, in a symmetric model)
DIRECTION_NAMES = {1: "positive", -1: "negative", 0: "both"}


@dataclass
class Proposal:
    """Blocks to add (and to drop) with their per-group cross products (for the fits)."""

    add: list
    drop: list = field(default_factory=list)
    xtc: np.ndarray | None = None
    ctc: np.ndarray | None = None
    cty: np.ndarray | None = None
    describe: str = ""
    #: :func:`train_fit`'s answers, by round, training groups and kept columns (a grid candidate's
    #: fold asks for its best value's fit again)
    fits: dict = field(default_factory=dict, repr=False)

    def columns(self, dd) -> np.ndarray:
        return side_by_side(self.column_blocks(dd))

    def column_blocks(self, dd) -> list:
        """The added blocks' columns, each as it is (:meth:`columns` puts them side by side)."""
        return [b.columns(dd) for b in self.add]

    def __getstate__(self):
        # pickled (a forked round's result) without :attr:`fits`: a memo, holding weak references
        return {**self.__dict__, "fits": {}}

    def n_params(self, rnd: Round) -> int:
        return sum(len(b.names) for b in self.add) - sum(len(b.names) for b in self.drop)

    @classmethod
    def of(cls, rnd: Round, add: list, drop=(), describe: str = "", C: np.ndarray | None = None) -> "Proposal":
        """The proposal of blocks ``add`` (columns ``C``, default theirs) with their cross products."""
        prop = cls(add, list(drop), describe=describe)
        prop.xtc, prop.ctc, prop.cty = cross_grams(rnd, prop.column_blocks(rnd.dd) if C is None else C)
        return prop


def side_by_side(cols: list) -> np.ndarray:
    """``np.column_stack(cols)``; one block's columns as they are (cached on the data: read-only
    for the caller) when they are what the copy would be (float, 2-D, C-ordered): no copy."""
    if len(cols) == 1:
        c = cols[0]
        if isinstance(c, Columns) or (isinstance(c, np.ndarray) and c.ndim == 2 and c.dtype == np.float64
                                      and c.flags.c_contiguous):
            return c
    if any(isinstance(c, Columns) for c in cols):     # a long recording's: side by side a range of rows at a time
        return rowcols.side_by_side(cols)
    return np.column_stack(cols)


def cross_grams(rnd: Round, C):
    """Per-group X^T C, C^T C and C^T y of new columns ``C`` (an array, or a list of blocks of
    columns: their side-by-side columns) against the round's design.  Blocks over groups that
    :func:`~.context.group_normals` reduces one by one are put side by side a group's rows at a
    time, never all rows at once: the same group arrays, the same products, bit for bit."""
    dd = rnd.dd
    if isinstance(C, list):
        n = dd.stops - dd.starts
        if len(C) > 1 and len(n) and float(np.mean(n)) >= BLAS_GROUP_ROWS:
            return _cross_grams_by_group(rnd, C)
        C = side_by_side(C)
    c = group_normals(C, dd.y, dd.starts, dd.stops)
    return group_cross(rnd.X, C, dd.starts, dd.stops), c.G, c.b


def _cross_grams_by_group(rnd: Round, blocks: list):
    """:func:`cross_grams` of the blocks' columns side by side, one group's rows stacked at a time
    (what :func:`~gearspec.core.reduction.group_cross` and :func:`~.context.group_normals` compute
    from the group's rows of the stacked columns)."""
    dd = rnd.dd
    X = rnd.X
    q = sum(b.shape[1] for b in blocks)
    ng = len(dd.starts)
    xtc, ctc, cty = np.empty((ng, X.shape[1], q)), np.empty((ng, q, q)), np.empty((ng, q))
    for g, (a, z) in enumerate(zip(dd.starts, dd.stops)):
        Cg = np.concatenate([b[a:z] for b in blocks], axis=1)
        xtc[g] = X[a:z].T @ Cg
        ctc[g], cty[g], _ = normal_equations(Cg, dd.y[a:z])
    return xtc, ctc, cty


def train_fit(rnd: Round, keep: np.ndarray, prop: Proposal, train: np.ndarray):
    """Coefficients (kept columns, then new ones) fitted on the training groups, and the
    training residual sum of squares."""
    key = (id(rnd), rnd.key(train), np.packbits(keep).tobytes())
    hit = prop.fits.get(key)
    if hit is not None and hit[0]() is rnd:
        return hit[1], hit[2]
    Gx, bx, yy = rnd.train_sums(train)
    k = np.flatnonzero(keep)
    xtc = prop.xtc[train].sum(0)[k]
    ctc = prop.ctc[train].sum(0)
    cty = prop.cty[train].sum(0)
    G = np.block([[Gx[np.ix_(k, k)], xtc], [xtc.T, ctc]])
    b = np.concatenate([bx[k], cty])
    ref = np.concatenate([rnd.ref_diag[k], np.einsum("gii->i", prop.ctc)])
    beta = solve_normal(G, b, reference=ref)
    rss = float(yy - 2 * beta @ b + beta @ G @ beta)
    if len(prop.fits) >= 16:
        prop.fits.clear()
    prop.fits[key] = (weakref.ref(rnd), beta, rss)     # never keeps an extended round's design alive
    return beta, rss


class Candidate:
    """Base class: ``kind``, ``name`` (unique within a round), ``evidence`` (one readable
    sentence), ``detail`` (what the figure of the report shows) and :meth:`propose`."""

    kind = "other"

    def __init__(self, name: str, evidence: str = "", detail: dict | None = None, gate_p: float | None = None):
        self.name = name
        self.evidence = evidence
        self.detail = detail or {}
        self.gate_p = gate_p
        self.frequency = None
        self.label = None
        self.hint = None
        self._cache = {}

    def _round_cache(self, rnd: Round) -> dict:
        """The cache of what the candidate computed for round ``rnd`` (emptied for a new round)."""
        if self._cache.get("round") is not rnd:
            self._cache = {"round": rnd}
        return self._cache

    def propose(self, rnd: Round, train: np.ndarray) -> Proposal | None:
        """The blocks to add (and drop), their nonlinear parameters searched on the groups where
        ``train`` (a boolean mask over the round's groups) is true; None when the data there
        cannot show the term."""
        raise NotImplementedError


class FixedCandidate(Candidate):
    """Blocks as they are (nonlinear parameters fixed): to check that a term accepted earlier
    still earns its place once later terms are in (backward elimination)."""

    def __init__(self, kind: str, name: str, blocks, drop=()):
        super().__init__(name)
        self.kind = kind
        self.blocks = list(blocks)
        self.drop = list(drop)

    def propose(self, rnd: Round, train: np.ndarray) -> Proposal | None:
        cache = self._round_cache(rnd)
        if "prop" not in cache:
            cache["prop"] = Proposal.of(rnd, self.blocks, self.drop)
        return cache["prop"]


# ---------------------------------------------------------------------- grid candidates
class GridCandidate(Candidate):
    """A term family with a grid of nonlinear values; ``make(value) -> (add blocks, drop blocks)``.
    In each fold the grid value with the smallest training error is used."""

    def __init__(self, kind: str, name: str, make, grid, *, evidence: str = "", detail=None, gate_p=None,
                 describe_value=None):
        super().__init__(name, evidence, detail, gate_p)
        self.kind = kind
        self.make = make
        self.grid = list(grid)
        self.describe_value = describe_value or (lambda v: "" if v is None else f"{v:.4g}")

    def _prop(self, rnd: Round, i: int) -> Proposal | None:
        cache = self._round_cache(rnd)
        if i not in cache:
            made = self.make(self.grid[i])
            cache[i] = None
            if made is not None:
                add, drop = made
                C = side_by_side([b.columns(rnd.dd) for b in add])
                norm = math.sqrt(C.sum_of_squares()) if isinstance(C, Columns) else np.linalg.norm(C)
                if norm > 1e-6 * np.linalg.norm(rnd.dd.y):  # else nothing the data can see
                    cache[i] = Proposal.of(rnd, add, drop, self.describe_value(self.grid[i]), C)
        return cache[i]

    def propose(self, rnd: Round, train: np.ndarray) -> Proposal | None:
        best = None
        keeps: dict = {}     # the grid's values mostly drop the same blocks (none, or one line)
        for i in range(len(self.grid)):
            p = self._prop(rnd, i)
            if p is None:
                continue
            uids = tuple(getattr(d, "uid", d) for d in p.drop)
            if uids not in keeps:
                keeps[uids] = rnd.keep_mask(p.drop)
            _, rss = train_fit(rnd, keeps[uids], p, train)
            if best is None or rss < best[0]:
                best = (rss, p)
        return None if best is None else best[1]


def per_direction(rnd: Round, kind: str, fixed=(), key: str | None = None, effect_kind: str = "other",
                  label: str | None = None) -> list[TermBlock]:
    """One term block of ``kind`` (terms registry) per direction of the data (one for both in a
    symmetric model), keyed ``key+`` / ``key-`` (``key`` when symmetric); ``fixed``: its
    nonlinear parameters, ``((name, value), ...)``."""
    key = kind if key is None else key
    dirs = [0] if rnd.state.symmetric else rnd.dd.directions()
    return [TermBlock(key=f"{key}{'' if x == 0 else ('+' if x > 0 else '-')}", kind=kind, fixed=tuple(fixed),
                      direction=x, label=label, effect_kind=effect_kind) for x in dirs]


# ---------------------------------------------------------------------- periodic
class PeriodicCandidate(Candidate):
    """A line at a frequency near ``f0`` found in the residual spectrum.  In each fold: the
    frequency is searched again on the training residual (Lomb-Scargle over +-2 resolution steps,
    the directions' powers added in units of their residual variance, parabolic refinement), the
    amplitude law chosen per direction (:func:`choose_amplitude_law`), and the line fitted jointly
    with the model."""

    kind = "periodic"

    def __init__(self, f0: float, resolution: float, *, gear=None, evidence: str = "", detail=None, gate_p=None,
                 unit: str = "rad"):
        super().__init__(f"line at {f0:.6g} cycles/{unit}", evidence, detail, gate_p)
        self.f0 = float(f0)
        self.resolution = float(resolution)
        self.gear = gear
        self.unit = unit
        self.frequency = self.f0
        self.relabel(self.f0)

    def relabel(self, f: float, se: float | None = None) -> None:
        """Label (or integer hint) of frequency ``f``: within three standard errors of it (or a
        tenth of a resolution step before it is fitted), and at least 0.2 % of it (0.5 % for an
        integer hint)."""
        self.frequency = float(f)
        tol = max(3 * se if se is not None and np.isfinite(se) else 0.1 * self.resolution, 2e-3 * f)
        ln = self.gear.label(f, tol) if self.gear is not None else None
        self.label = None if ln is None else ln.label
        # an integer relation to a shaft is looser (a filtered or delayed signal shifts a fitted
        # frequency by a few tenths of a percent); a high multiple (72x) needs the line's own precision
        self.hint = None
        if self.gear is not None and ln is None:
            self.hint = integer_hint(self.gear, f, max(tol, 5e-3 * f))
            if self.hint is None and se is not None and np.isfinite(se) and se > 0:
                self.hint = integer_hint(self.gear, f, 3 * se)

    def propose(self, rnd: Round, train: np.ndarray) -> Proposal | None:
        # the all-data proposal is asked for again when the loop accepts the candidate: the same
        # search on the same residual, kept for the round
        if train.all():
            cache = self._round_cache(rnd)
            if "all" not in cache:
                cache["all"] = self._propose(rnd, train)
            return cache["all"]
        return self._propose(rnd, train)

    def _propose(self, rnd: Round, train: np.ndarray) -> Proposal | None:
        dd = rnd.dd
        rows = rnd.rows(train)
        r0 = rnd.train_residual(train)
        theta = rnd.channel("theta")[rows]
        d = rnd.channel("direction")[rows]
        speed = rnd.channel("speed")[rows]
        seg = rnd.channel("segment")[rows]
        top = float(np.max(rnd.channel("speed"))) if len(dd) else 0.0
        moving = speed > (0.05 * top if dd.kind == "trajectory" else 0.0)
        dirs = [x for x in (1, -1) if np.sum((d == x) & moving) >= 16]
        if not dirs:
            return None
        f = self._search(theta, d, seg, r0, moving, dirs)
        symmetric = rnd.state.symmetric
        laws, decays = [], []
        # the amplitude law from the segments that measure the line only (below their position
        # Nyquist limit, a whole cycle): aliased segments would pass for a decay
        meas = measurable(dd, f)[dd.index][rows] if dd.reduce is None else np.ones(len(d), bool)
        groups = [(0, moving & meas)] if symmetric else [(x, (d == x) & moving & meas) for x in dirs]
        for x, sel in groups:
            law, dec = "const", 0.0
            if sel.any():
                yv = (d[sel] if x == 0 else x) * r0[sel]
                law, dec, _ = choose_amplitude_law(theta[sel], speed[sel], seg[sel], yv, f)
            laws.append((x, law))
            decays.append((x, dec))
        blk = HarmonicBlock(key=f"found {f:.6g}", frequency=f, label=self.label, dirs=tuple(dirs),
                            symmetric=symmetric, law=tuple(laws), decay=tuple(decays), found=True)
        laws_text = ", ".join(f"{DIRECTION_NAMES[x]}: {lw}" + (f" (decay {dc:.3g})" if lw != "const" else "")
                              for (x, lw), (_, dc) in zip(laws, decays))
        return Proposal.of(rnd, [blk], (), f"{f:.6g} cycles/{self.unit}; {laws_text}")

    def _search(self, theta, d, seg, r0, moving, dirs) -> float:
        """The frequency (cycles per unit of ``theta``) of the strongest line within two
        resolution steps of ``f0`` in the residual ``r0`` (Nm): Lomb-Scargle powers of the moving
        samples of every direction in ``dirs`` (each segment's mean removed), in units of their
        variance, added; parabolic refinement of the peak."""
        w = 2.0 * self.resolution
        freqs = np.linspace(max(self.f0 - w, 0.5 * self.f0), self.f0 + w, 81)
        total = np.zeros(len(freqs))
        for x in dirs:
            sel = (d == x) & moving
            y = x * r0[sel]
            sids, inv = segment_index(seg[sel])
            y = y - (np.bincount(inv, weights=y) / np.bincount(inv))[inv]
            var = float(np.var(y))
            if var <= 0:
                continue
            # a uniform grid: the non-uniform FFT (nifty-ls), O(N) where the exact sums are O(N x 81)
            total += LombScargle(theta[sel], y, method="nifty").power_grid(freqs[0], freqs[1] - freqs[0],
                                                                          len(freqs)) / var
        i = int(np.argmax(total))
        f = float(freqs[i])
        if 0 < i < len(freqs) - 1:
            a, b, c = total[i - 1:i + 2]
            den = a - 2 * b + c
            if den < 0:
                f += float(np.clip(0.5 * (a - c) / den, -0.5, 0.5) * (freqs[1] - freqs[0]))
        return f


# ---------------------------------------------------------------------- lag
@dataclass(frozen=True, eq=False)
class LaggedHarmonicBlock(HarmonicBlock):
    """A line of the model seen through a torque channel logged ``lag`` seconds behind position
    (:mod:`gearspec.lag`): its columns at ``theta - v lag`` (exact on a plateau, where the
    velocity is constant).  The harmonic it writes is the friction's own (phase at the true
    position); the model records the lag in ``meta["lag"]``."""

    lag: float = 0.0

    def _raw(self, dd):
        if self.lag == 0.0:
            return super()._raw(dd)
        store = dd.cache.setdefault("lagged", {})
        view = store.get(self.lag)
        if view is None:
            f = dd.fit
            view = types.SimpleNamespace(fit=replace(f, theta=f.theta - f.v * self.lag, cache={}),
                                         cache={}, reduce=dd.reduce)
            while len(store) >= 8:
                store.pop(next(iter(store)))
            store[self.lag] = view
        return super()._raw(view)

    def write(self, model, coef, se, ranges: dict | None = None):
        super().write(model, coef, se, ranges=ranges)
        model.meta = {**model.meta, "lag": float(self.lag)}
        note = f"lag: torque channel {1e3 * self.lag:.4g} ms behind position (lines fitted at theta - v lag)"
        if note not in model.notes:
            model.notes.append(note)

    def describe(self):
        return super().describe() + f"; torque lag {1e3 * self.lag:.4g} ms"


def lagged(blk: HarmonicBlock, lag: float) -> LaggedHarmonicBlock:
    """The lagged form of a line of the model (a sideband stays a sideband: same columns rule)."""
    cls = LaggedSidebandBlock if isinstance(blk, SidebandBlock) else LaggedHarmonicBlock
    kw = {f.name: getattr(blk, f.name) for f in fields(blk) if f.name not in ("uid", "coef", "lag")}
    return cls(**kw, coef=blk.coef, lag=float(lag))


class LagCandidate(Candidate):
    """The torque channel behind position by a lag (kind ``lag``): in every fold the lag estimated
    from the training plateaus' line phases (:func:`gearspec.lag.lag_from_phases`), every line of
    the model replaced by its lagged form.  ``value``: the lag estimated on all data (s)."""

    kind = "lag"

    def __init__(self, table: dict, estimate, max_lag: float, evidence: str = ""):
        super().__init__("torque channel lag", evidence, {"analysis": "lag", "estimate": estimate.to_dict()},
                         gate_p=estimate.p)
        self.table = table
        self.max_lag = float(max_lag)
        self.value = float(estimate.lag)
        self.value_se = float(estimate.se)

    def estimate(self, train: np.ndarray):
        from ..lag import lag_from_phases
        t = self.table
        sel = train[t["group"].astype(int)]
        return lag_from_phases(t["frequency"][sel], t["velocity"][sel], t["phase"][sel], t["phase_se"][sel],
                               t["series"][sel], max_lag=self.max_lag)

    def propose(self, rnd: Round, train: np.ndarray) -> Proposal | None:
        est = self.estimate(train)
        if est is None:
            return None
        lines = [b for b in rnd.state.blocks if isinstance(b, HarmonicBlock)]
        if not lines:
            return None
        ck = (id(rnd), round(est.lag, 15))
        cache = self._round_cache(rnd)
        if ck not in cache:
            cache[ck] = _TaylorProposal.of(rnd, [lagged(b, est.lag) for b in lines], lines,
                                           f"lag {1e3 * est.lag:.4g} ms")
        return cache[ck]


class _TaylorProposal(Proposal):
    """Blocks replacing blocks of the model with the same nonlinear parameters (the lines, lagged)
    keep their Taylor columns, so that the held-out comparison differs by the candidate alone."""

    def column_blocks(self, dd) -> list:
        return [b.columns(dd, taylor=True) for b in self.add]


# ---------------------------------------------------------------------- sidebands
@dataclass(frozen=True, eq=False)
class SidebandBlock(HarmonicBlock):
    """A sideband line (declared by the gear: carrier +- modulating shaft), pooled per direction
    over the plateaus whose travel is at least ``min_travel`` (its columns are zero on the others);
    the model it writes carries it at every speed (README, "Declared sidebands")."""

    min_travel: float = 0.0

    def _raw(self, dd):
        cols = super()._raw(dd)
        if self.min_travel > 0:
            ok = travel_ok(dd, self.min_travel)
            cols = np.where(ok[:, None], cols, 0.0)
        return cols


@dataclass(frozen=True, eq=False)
class LaggedSidebandBlock(SidebandBlock, LaggedHarmonicBlock):
    """A sideband line seen through a lagged torque channel."""


def travel_ok(dd, min_travel: float) -> np.ndarray:
    """Samples (of ``dd.fit``) in a segment whose travel is at least ``min_travel``."""
    return segment_span(dd) >= min_travel


class SidebandCandidate(Candidate):
    """Both sidebands ``f_c +- f_m`` of a line of the model (the carrier) modulated by a slower
    shaft, at the frequencies the gear declares (:meth:`GearTrain.candidate_lines`), pooled per
    direction over the plateaus that resolve them, with the carrier's amplitude law."""

    kind = "periodic"

    def __init__(self, carrier: HarmonicBlock, lines: list, min_travel: float, *, evidence: str = "", gate_p=None,
                 unit: str = "rad", detail=None):
        lab = " and ".join(ln.label for ln in lines)
        super().__init__(f"sidebands {lab}", evidence, detail, gate_p)
        self.carrier = carrier
        self.lines = lines
        self.min_travel = float(min_travel)
        self.frequency = float(lines[0].frequency)
        self.label = lines[0].label
        self.f0 = self.frequency
        self.resolution = 0.0

    def propose(self, rnd: Round, train: np.ndarray) -> Proposal | None:
        cache = self._round_cache(rnd)
        if "prop" not in cache:
            c = next((b for b in rnd.state.blocks if isinstance(b, HarmonicBlock)
                      and math.isclose(b.frequency, self.carrier.frequency, rel_tol=1e-9)), self.carrier)
            add = [SidebandBlock(key=f"sideband {ln.frequency:.6g}", frequency=float(ln.frequency), label=ln.label,
                                 dirs=c.dirs, symmetric=c.symmetric, law=c.law, decay=c.decay, found=False,
                                 min_travel=self.min_travel) for ln in self.lines]
            if isinstance(c, LaggedHarmonicBlock):   # a lag accepted before: the sidebands see it too
                add = [lagged(b, c.lag) for b in add]
            cache["prop"] = Proposal.of(rnd, add, (), self.name)
        return cache["prop"]
