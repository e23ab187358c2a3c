"""A block's columns computed a range of rows at a time (:class:`Columns`): on a long recording a
block whose columns would hold more than :data:`~.budget.LAZY_BYTES` keeps only what its rows are
computed from -- facts of the whole data, small or one per row at most (the law at the distinct
speed keys, a line's amplitude factor at them, its speed range, the segments that resolve it; an
elementwise term's inputs, :data:`ELEMENTWISE_TERMS`) --
and every product of the closed loop (:mod:`.gram`, :mod:`.chunked`) asks for the rows of the
chunk it works on (issue 13: memory bounded on long recordings, no rows x terms array).

The rows are those of the whole array bit for bit: they are computed elementwise, gathered from
the same tables, and a Taylor column's ``(up - dn) @ coef`` is a product per row (BLAS gives the
same row in a product of two rows or more; one row alone is computed within two).  Blocks whose
rows depend on other rows (a lagged line's shifted view), reduced data and kinds not listed here
keep whole arrays (:func:`source` returns None)."""

from __future__ import annotations

import math

import numpy as np

from ..terms import TERM_LINEAR, TERMS, evaluate_term
from . import budget, gram
from .coverage import resolved
from .data import DiagnoseData, speed_keys
from .design import BaseBlock, Block, HarmonicBlock, TermBlock

__all__ = ["ELEMENTWISE_TERMS", "Columns", "chunk_ranges", "side_by_side", "source"]

_TWO_PI = 2.0 * math.pi
#: additive terms whose value at a sample depends on that sample's inputs alone (elementwise)
ELEMENTWISE_TERMS = frozenset({"viscous_power", "stribeck_extra", "load_coulomb", "load_viscous", "temperature",
                               "drift", "inertia", "offset", "cogging"})


class Columns:
    """``k`` columns over ``n`` rows given by ``make(a, z)`` (the (z - a, k) array of rows ``[a, z)``),
    holding no rows: ``C[a:z]`` computes them, ``C @ beta`` a chunk of rows at a time; any other
    index of rows, and ``np.asarray(C)``, gathers them (for checks, not for the loop)."""

    ndim = 2
    dtype = np.dtype(float)
    nbytes = 0

    def __init__(self, n: int, k: int, make):
        self.n, self.k, self._make = int(n), int(k), make

    @property
    def shape(self) -> tuple[int, int]:
        return self.n, self.k

    def __len__(self) -> int:
        return self.n

    def reshape(self, *shape):
        shape = shape[0] if len(shape) == 1 and isinstance(shape[0], tuple) else shape
        if tuple(shape) not in ((self.n, -1), (self.n, self.k)):
            raise ValueError(f"lazy columns of shape {self.shape} cannot take the shape {shape}")
        return self

    def rows(self, a: int, z: int) -> np.ndarray:
        """The rows ``[a, z)`` (a new array)."""
        if z - a == 1 and self.n > 1:
            # BLAS computes a product of one row unlike the same row in a product of many: within two
            b = min(a, self.n - 2)
            return self._make(b, b + 2)[a - b:a - b + 1]
        return self._make(a, z) if z > a else np.zeros((0, self.k))

    def __getitem__(self, key):
        if isinstance(key, tuple):
            return self[key[0]][(slice(None),) + key[1:]]
        if isinstance(key, slice) and key.step in (None, 1):
            a, z, _ = key.indices(self.n)
            return self.rows(a, max(a, z))
        key = np.asarray(key)
        idx = np.flatnonzero(key) if key.dtype == bool else np.arange(self.n)[key]
        if idx.ndim == 0:
            return self.rows(int(idx), int(idx) + 1)[0]
        out = np.empty((len(idx), self.k))
        if len(idx):
            for a, z in chunk_ranges(int(idx.max()) + 1 - int(idx.min()), int(idx.min())):
                sel = (idx >= a) & (idx < z)
                if sel.any():
                    out[sel] = self.rows(a, z)[idx[sel] - a]
        return out

    def __matmul__(self, other):
        other = np.asarray(other, dtype=float)
        out = np.empty((self.n,) + other.shape[1:])
        for a, z in chunk_ranges(self.n):
            out[a:z] = self.rows(a, z) @ other
        return out

    def __array__(self, dtype=None, copy=None):
        out = np.empty((self.n, self.k))
        for a, z in chunk_ranges(self.n):
            out[a:z] = self.rows(a, z)
        return out if dtype is None else out.astype(dtype)

    def sum_of_squares(self) -> float:
        """``sum(C ** 2)`` a chunk of rows at a time (its Frobenius norm squared)."""
        return float(sum(np.sum(self.rows(a, z) ** 2) for a, z in chunk_ranges(self.n)))


def chunk_ranges(n: int, start: int = 0) -> list[tuple[int, int]]:
    """Ranges of :data:`~.gram.CHUNK_ROWS` rows covering ``[start, start + n)``, none of one row
    alone (a last row joins the chunk before it)."""
    out = [(start + a, start + z) for a, z in gram.every_row(n)]
    if len(out) > 1 and out[-1][1] - out[-1][0] == 1:
        out[-2:] = [(out[-2][0], out[-1][1])]
    return out


def side_by_side(parts: list) -> Columns:
    """The columns of ``parts`` (arrays or :class:`Columns` over the same rows) side by side, lazily."""
    n = len(parts[0])
    ks = [p.shape[1] for p in parts]
    return Columns(n, sum(ks), lambda a, z: np.concatenate([p[a:z].reshape(z - a, k) for p, k in zip(parts, ks)],
                                                           axis=1))


# ---------------------------------------------------------------------- rows of the blocks
#: sines and cosines of the lines at the rows of the chunk asked for last (every block of a chunk
#: reads the same lines): ``{"key": (theta, a, z), frequency: (sin, cos)}``
_CHUNK: dict = {}


def _trig(dd: DiagnoseData, frequency: float, ok, a: int, z: int):
    """``sin`` and ``cos`` of ``2 pi f theta`` at rows ``[a, z)``, 0 where ``ok`` (the rows that
    resolve the line, None: all) is false: :meth:`~.design.HarmonicBlock._trig`'s rows."""
    theta = dd.fit.theta
    key = _CHUNK.get("key")
    if key is None or key[0] is not theta or key[1:] != (a, z):
        _CHUNK.clear()
        _CHUNK["key"] = (theta, a, z)
    hit = _CHUNK.get(frequency)
    if hit is None:
        x = _TWO_PI * frequency * theta[a:z]
        sn, cs = np.sin(x), np.cos(x)
        if ok is not None:
            sn, cs = np.where(ok[a:z], sn, 0.0), np.where(ok[a:z], cs, 0.0)
        hit = _CHUNK[frequency] = (sn, cs)
    return hit


def _lazy_kind(blk: Block) -> str | None:
    """Which rows the block's kind computes (its ``_raw`` one of these), or None."""
    from .candidates import SidebandBlock
    raw = type(blk)._raw
    if raw is BaseBlock._raw:
        return "base"
    if raw is HarmonicBlock._raw or raw is SidebandBlock._raw and getattr(blk, "lag", 0.0) == 0.0:
        return "line"
    if raw is TermBlock._raw and blk.kind in ELEMENTWISE_TERMS:
        return "term"
    return None


def _plain(blk: Block, dd: DiagnoseData):
    """``(k, make)``: the block's columns, ``make(a, z)`` their rows; None when they are not computed by rows."""
    kind = _lazy_kind(blk)
    if kind == "term":
        return _term(blk, dd)
    keys = speed_keys(dd)
    f = dd.fit
    if kind is None or keys is None or f.load is not None and kind == "base":
        return None
    kinv = keys[4]
    if kind == "base":
        table = blk._at_keys(dd, keys)
        return table.shape[1], lambda a, z: np.take(table, kinv[a:z], axis=0)
    if f.theta is None or (blk.load_phase and f.load is None):
        return None
    ok = resolved(dd, blk.frequency)
    ok = None if ok.all() else ok
    tables = blk.factor_tables(blk.ranges(dd), keys)
    lp = dict(blk.load_phase)
    travel = None
    if getattr(blk, "min_travel", 0.0) > 0:
        from .candidates import travel_ok
        travel = travel_ok(dd, blk.min_travel)
    k = sum(2 + (d in lp) for d, _ in tables)

    def make(a, z):
        sn, cs = _trig(dd, blk.frequency, ok, a, z)
        out = np.empty((z - a, k))
        j = 0
        for d, t in tables:     # as :meth:`HarmonicBlock._raw` writes them
            g = np.take(t, kinv[a:z])
            np.multiply(g, sn, out=out[:, j])
            np.multiply(g, cs, out=out[:, j + 1])
            j += 2
            if d in lp:
                out[:, j] = g * f.load[a:z] ** 2 * (sn * math.cos(lp[d]) + cs * math.sin(lp[d]))
                j += 1
        return out if travel is None else np.where(travel[a:z, None], out, 0.0)   # SidebandBlock._raw
    return k, make


def _term(blk: TermBlock, dd: DiagnoseData):
    """An elementwise additive term's rows, as :meth:`TermBlock._raw` computes them on the samples."""
    f = dd.fit
    n = len(f)
    inputs = f.inputs()
    signed = TERMS[blk.kind].signed
    lin = TERM_LINEAR[blk.kind]
    terms = ([blk.term(amplitude=1.0, phase=ph) for ph in (0.0, math.pi / 2)] if lin == "trig"
             else [blk.term(**{lin: 1.0})])

    def make(a, z):
        sub = {k: (x[a:z] if isinstance(x, np.ndarray) and x.ndim == 1 and len(x) == n else x) for k, x in inputs.items()}
        sgn = np.sign(f.v[a:z])
        out = np.empty((z - a, len(terms)))
        for j, t in enumerate(terms):
            c, _ = evaluate_term(t, **sub)
            out[:, j] = c if signed else sgn * c
        return out
    return len(terms), make


def _step(blk: Block, dd: DiagnoseData, up: Block, dn: Block, c: np.ndarray, h: float):
    """``make(a, z)``: the rows of the Taylor column ``(up - dn) @ c / 2h`` (:meth:`Block._difference`
    of the block's kind), or None."""
    keys = speed_keys(dd)
    if isinstance(blk, BaseBlock) and type(blk)._difference is BaseBlock._difference and dd.fit.load is None \
            and keys is not None:
        t = (up._at_keys(dd, keys) - dn._at_keys(dd, keys)) @ c / (2 * h)
        return lambda a, z: np.take(t, keys[4][a:z])
    if isinstance(blk, HarmonicBlock) and type(blk)._difference is HarmonicBlock._difference:
        moved = [d for d, b in dict(up.decay).items() if dict(dn.decay).get(d) != b]
        if (type(blk)._raw is HarmonicBlock._raw and len(moved) == 1 and up.frequency == dn.frequency
                and up.law == dn.law and dd.fit.theta is not None and keys is not None):
            return _decay_step(blk, dd, up, dn, c, h, moved[0], keys)
    pu, pd = _plain(up, dd), _plain(dn, dd)
    if pu is None or pd is None:
        return None
    return lambda a, z: (pu[1](a, z) - pd[1](a, z)) @ c / (2 * h)


def _decay_step(blk, dd, up, dn, c, h, moved, keys):
    """A decay's Taylor rows, as :meth:`HarmonicBlock._difference` computes them."""
    f = dd.fit
    ok = resolved(dd, blk.frequency)
    ok = None if ok.all() else ok
    lp = dict(blk.load_phase)
    rng, kinv = blk.ranges(dd), keys[4]
    (_, tu), = up.factor_tables(rng, keys, only=moved)
    (_, td), = dn.factor_tables(rng, keys, only=moved)
    i = 0
    for d in ((0,) if blk.symmetric else blk.dirs):
        if d == moved:
            break
        i += 2 + (d in lp)

    def make(a, z):
        sn, cs = _trig(dd, blk.frequency, ok, a, z)
        gu, gd = np.take(tu, kinv[a:z]), np.take(td, kinv[a:z])
        D = np.zeros((z - a, len(c)))
        D[:, i] = gu * sn - gd * sn
        D[:, i + 1] = gu * cs - gd * cs
        if moved in lp:
            trig = sn * math.cos(lp[moved]) + cs * math.sin(lp[moved])
            D[:, i + 2] = gu * f.load[a:z] ** 2 * trig - gd * f.load[a:z] ** 2 * trig
        return D @ c / (2 * h)
    return make


def source(blk: Block, dd: DiagnoseData, taylor: bool = False) -> Columns | None:
    """The block's columns (with ``taylor``, its Taylor columns after them: :meth:`Block.columns`)
    as :class:`Columns` when they would hold more than :data:`~.budget.LAZY_BYTES` and its kind
    computes them by rows; else None (the block builds the array)."""
    if dd.reduce is not None or _lazy_kind(blk) is None:
        return None
    k = len(blk.names) + (blk.n_taylor(dd) if taylor else 0)
    if 8 * len(dd) * k <= budget.LAZY_BYTES:
        return None
    plain = _plain(blk, dd)
    if plain is None:
        return None
    kp, make = plain
    steps = [_step(blk, dd, *s) for s in blk.taylor_steps(dd)] if taylor else []
    if any(s is None for s in steps):
        return None
    if not steps:
        return Columns(len(dd), kp, make)

    def rows(a, z):
        out = np.empty((z - a, kp + len(steps)))
        out[:, :kp] = make(a, z)
        for j, s in enumerate(steps):
            out[:, kp + j] = s(a, z)
        return out
    return Columns(len(dd), kp + len(steps), rows)
