"""A friction model as a linear design: blocks of columns, fitted jointly by least squares.

Base law, lines and additive terms are linear in most parameters once their few nonlinear ones
(Stribeck velocity, decays, exponents, presliding length, a frequency) are fixed.  A :class:`Block`
makes its columns from the data and writes its fitted coefficients back into a
:class:`~gearspec.model.FrictionModel`; a :class:`State` is a list of blocks, refitted jointly by
ordinary least squares (the held-out error it is judged by is an unweighted rmse).  Columns are
torques *with the sign of the motion* for friction and as they are for signed terms (inertia,
offset).
"""

from __future__ import annotations

import copy
import dataclasses
import itertools
import math
from collections import OrderedDict
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import InputError
from ..model import DIRECTIONS, LAWS, FrictionModel, Harmonic
from ..terms import LAW_LINEAR, TERM_LINEAR, TERMS, amplitude_law, clamp_speed, evaluate_term
from .coverage import line_speed_range, resolved
from .data import DiagnoseData, per_speed, speed_keys
from . import budget
from .gram import hstack, stack
from .solve import _cov, solve_normal

__all__ = ["Block", "BaseBlock", "HarmonicBlock", "TermBlock", "State", "FittedState", "fit_state",
           "state_from_model", "LINEAR", "solve_normal", "predict_model", "nonlinear_parameters"]

_TWO_PI = 2.0 * math.pi
_DNAME = {1: "positive", -1: "negative"}

#: linear and nonlinear parameters of every base law (the magnitude is linear in the first
#: given the second): the term registry's (:mod:`gearspec.terms.registry`)
LINEAR = LAW_LINEAR


# ---------------------------------------------------------------------- blocks
_UID = itertools.count(1)
_CACHE_SIZE = 96
#: ... and at most this many columns' worth of observations, within :data:`~.budget.CACHE_BYTES`
_CACHE_COLUMNS = 64


@dataclass(frozen=True, eq=False)
class Block:
    """A group of columns with the parameters they carry.  Subclasses define ``_raw(dd)`` (the
    columns over the samples of ``dd.fit``, before any reduction), ``names`` and
    ``write(model, coef, se)``.  ``uid`` identifies a block through changes of its nonlinear
    parameters (``dataclasses.replace`` keeps it)."""

    key: str = ""
    uid: int = field(default_factory=lambda: next(_UID))
    #: the block's present linear coefficients (for the Taylor columns of its nonlinear parameters)
    coef: tuple = ()

    def columns(self, dd: DiagnoseData, taylor: bool = False) -> np.ndarray:
        """Columns at the observations of ``dd`` (reduced when the data are); with ``taylor`` also
        one first-order column per nonlinear parameter (:meth:`taylor_columns`).  The last few
        computed are cached on the data."""
        cache = dd.cache.setdefault("columns", OrderedDict())
        # keyed by what the columns depend on: the block's fields (its coefficients only for the
        # Taylor columns), so that a copy carrying new coefficients reuses its plain columns
        ck = self._cache_key(taylor)
        hit = cache.get(ck)
        if hit is not None and (hit[0] is self or ck[0] == "fields"):
            cache.move_to_end(ck)
            return hit[1]
        from .rowcols import source      # long data: the columns a range of rows at a time
        lazy = source(self, dd, taylor)
        if lazy is not None:
            cols = lazy
        elif taylor:
            plain = self.columns(dd)
            T = self.taylor_columns(dd)
            cols = hstack([plain, T]) if T.shape[1] else plain
        else:
            raw = np.asarray(self._raw(dd), dtype=float).reshape(len(dd.fit), -1)
            cols = raw if dd.reduce is None else (np.column_stack([dd.R(raw[:, j]) for j in range(raw.shape[1])])
                                                  if raw.shape[1] else np.zeros((len(dd), 0)))
        cache[ck] = (self, cols)
        budget.bounded(cache, min(budget.CACHE_BYTES, 8 * _CACHE_COLUMNS * len(dd)), count=_CACHE_SIZE)
        return cols

    def _cache_key(self, taylor: bool) -> tuple:
        """The key of the block's columns in the data's cache: its type and the exact repr of every field
        but its id (floats repr round-trip); by identity when a field holds an array (repr abbreviates)."""
        vals = tuple((f.name, getattr(self, f.name)) for f in dataclasses.fields(self)
                     if f.name != "uid" and (taylor or f.name != "coef"))
        if any(isinstance(v, np.ndarray) for _, v in vals):
            return ("id", id(self), bool(taylor))
        return ("fields", type(self), repr(vals), bool(taylor))

    def taylor_columns(self, dd: DiagnoseData) -> np.ndarray:
        """First-order columns of the nonlinear parameters: the derivative of the block's present
        contribution (``columns @ coef``) with respect to each (a linear refit with them is one
        Gauss-Newton step: every fit of the held-out test refits them on its own data)."""
        out = [dd.R(self._difference(dd, up, dn, c, h)) for up, dn, c, h in self.taylor_steps(dd)]
        return np.column_stack(out) if out else np.zeros((len(dd), 0))

    def taylor_steps(self, dd: DiagnoseData) -> list:
        """``(up, dn, coef, h)`` of every nonlinear parameter: the copies of the block a step ``h``
        above and below it whose central difference (:meth:`_difference`) is its Taylor column."""
        from .nonlinear import nonlinear_parameters, with_parameter
        c = np.asarray(self.coef, dtype=float)
        out = []
        for key, val, lo, hi, log in (nonlinear_parameters(self, dd) if self.coef else ()):
            h = 1e-4 * (abs(val) if log or val != 0 else 1.0) if key[0] != "frequency" else 1e-7 * abs(val)
            if key[0] == "decay" and val == 0:
                h = 1e-4 / max(float(np.max(np.abs(dd.fit.v))), 1e-12)
            out.append((with_parameter(self, key, val + h), with_parameter(self, key, val - h), c, h))
        return out

    def _difference(self, dd: DiagnoseData, up: "Block", dn: "Block", c: np.ndarray, h: float) -> np.ndarray:
        """The central difference ``(up - dn) @ c / 2h`` of two copies of the block at the samples."""
        n = len(dd.fit)
        return (np.asarray(up._raw(dd), float).reshape(n, -1) - np.asarray(dn._raw(dd), float).reshape(n, -1)) \
            @ c / (2 * h)

    def n_taylor(self, dd: DiagnoseData) -> int:
        from .nonlinear import nonlinear_parameters
        return len(nonlinear_parameters(self, dd)) if self.coef else 0

    @property
    def names(self) -> list[str]:
        raise NotImplementedError

    def _raw(self, dd):
        raise NotImplementedError

    def write(self, model: FrictionModel, coef: np.ndarray, se: np.ndarray) -> None:
        raise NotImplementedError

    def describe(self) -> str:
        return self.key


@dataclass(frozen=True, eq=False)
class BaseBlock(Block):
    """The base law: per direction (``dirs`` = (1, -1) or the directions with data) or shared by
    both (``symmetric``).  ``nonlin[d]``: the law's nonlinear parameters of direction d (e.g.
    ``{"v_s": ...}``); ``lin[d]``: the linear parameters fitted (the law's, or its degraded
    Coulomb + viscous part when the Stribeck part is not identified)."""

    law: str = "coulomb_viscous"
    dirs: tuple = (1, -1)
    symmetric: bool = False
    lin: tuple = ()
    nonlin: tuple = ()     # ((d, {name: value}), ...)

    @property
    def names(self):
        if self.symmetric:
            return [f"{p}" for p in self._lin(0)]
        return [f"{p}[{_DNAME[d][:3]}]" for d in self.dirs for p in self._lin(d)]

    def _lin(self, d):
        return dict(self.lin)[d if not self.symmetric else 0]

    def _nonlin(self, d):
        return dict(self.nonlin).get(d if not self.symmetric else 0, {})

    def _at_keys(self, dd, keys) -> np.ndarray:
        """The columns at the distinct (speed, sign, direction) of the samples (:func:`speed_keys`)."""
        u, kidx, ksg, kdir, _ = keys
        law = LAWS[self.law]
        groups = [(0, np.ones(len(kidx), bool))] if self.symmetric else [(d, kdir == d) for d in self.dirs]
        cols = []
        for d, sel in groups:
            # the law at the distinct speeds, as :func:`per_speed` evaluates it
            X = np.asarray(law.design(self._lin(d), self._nonlin(d), u, np.zeros(len(u))))[kidx]
            cols.append(np.where(sel[:, None], ksg[:, None] * X, 0.0))
        return np.concatenate(cols, axis=1) if cols else np.zeros((len(kidx), 0))

    def _difference(self, dd, up, dn, c, h):
        keys = speed_keys(dd) if dd.fit.load is None else None
        if keys is None:
            return super()._difference(dd, up, dn, c, h)
        return np.take((up._at_keys(dd, keys) - dn._at_keys(dd, keys)) @ c / (2 * h), keys[4])

    def _raw(self, dd):
        f = dd.fit
        keys = speed_keys(dd) if f.load is None else None
        if keys is not None:
            return np.take(self._at_keys(dd, keys), keys[4], axis=0)
        speed = np.abs(f.v)
        sgn = np.sign(f.v)
        law = LAWS[self.law]
        load = f.load if f.load is not None else np.zeros(len(f))
        cols = []
        groups = [(0, np.ones(len(f), bool))] if self.symmetric else [(d, f.direction == d) for d in self.dirs]
        for d, sel in groups:
            if f.load is None:
                X = per_speed(dd, lambda sp, d=d: law.design(self._lin(d), self._nonlin(d), sp, np.zeros(len(sp))))
            else:
                X = law.design(self._lin(d), self._nonlin(d), speed, load)
            cols.append(np.where(sel[:, None], sgn[:, None] * X, 0.0))
        return np.concatenate(cols, axis=1) if cols else np.zeros((len(f), 0))

    def write(self, model, coef, se):
        i = 0
        targets = [(0, DIRECTIONS)] if self.symmetric else [(d, (_DNAME[d],)) for d in self.dirs]
        for d, names in targets:
            for p in self._lin(d):
                for nm in names:
                    model.directions[nm].set(p, float(coef[i]), float(se[i]))
                i += 1
            for nm in names:
                P = model.directions[nm]
                for k, val in self._nonlin(d).items():
                    P.set(k, val)
                law = LAWS[self.law]
                for k in law.linear:
                    if k not in self._lin(d):
                        P.set(k, None, None)
                degraded = law.degraded_for("v_s")
                if degraded is not None and tuple(self._lin(d)) == degraded.linear:
                    for k in law.nonlinear_names:
                        P.set(k, None)

    def describe(self):
        return f"{self.law} ({'symmetric' if self.symmetric else 'per direction'})"


@dataclass(frozen=True, eq=False)
class HarmonicBlock(Block):
    """A position-locked line ``g(|v|) (a sin + c cos)(2 pi f theta)`` in the friction magnitude,
    per direction (or shared), with amplitude law ``g`` (exp, const, rational, power) and decay
    per direction; with ``load_phase`` (per direction) also the SILO4 eq. 14 column
    ``load^2 g sin(2 pi f theta + phase)`` (the load coefficient)."""

    frequency: float = 1.0
    label: str | None = None
    dirs: tuple = (1, -1)
    symmetric: bool = False
    law: tuple = ()          # ((d, law), ...)
    decay: tuple = ()        # ((d, decay), ...)
    load_phase: tuple = ()   # ((d, phase), ...): eq. 14 column in these directions
    extra: tuple = ()        # ((d, {key: value}), ...) carried into the model's harmonic (e.g. evidence)
    found: bool = False      # added by the loop (else part of the model it started from)
    #: ((d, (min, max)), ...): speed ranges fixed by the model the block came from (evaluation of a
    #: fitted model on other data); directions without one take the data's (:func:`line_speed_range`)
    speed_range: tuple = ()

    def _g(self, d, speed, rng=None):
        """Amplitude factor of direction ``d`` at ``speed``, held within ``rng`` (min, max)."""
        lw = dict(self.law).get(d, "exp")
        return amplitude_law(lw, clamp_speed(speed, rng), float(dict(self.decay).get(d, 0.0)))

    def ranges(self, dd: DiagnoseData) -> dict:
        """Speed range of the amplitude law of every direction (key 0 when symmetric): the one
        the block carries, else the speeds at which ``dd`` measures the line."""
        fixed = dict(self.speed_range)
        memo = dd.cache.setdefault("line_ranges", OrderedDict())    # the data's, by frequency and direction
        for d in ((0,) if self.symmetric else self.dirs):
            if not fixed.get(d) and (self.frequency, d) not in memo:
                memo[(self.frequency, d)] = line_speed_range(dd, self.frequency, d)
                while len(memo) > 64:
                    memo.popitem(last=False)
        return {d: fixed.get(d) or memo[(self.frequency, d)] for d in ((0,) if self.symmetric else self.dirs)}

    def _trig(self, dd):
        """``sin`` and ``cos`` of ``2 pi f theta`` at the samples, 0 in the segments whose position
        sampling cannot carry the line (above 0.8 of their position Nyquist frequency: an aliased
        sinusoid would fit noise there), cached on the data."""
        trig = dd.cache.setdefault("trig", OrderedDict())
        hit = trig.get(self.frequency)
        if hit is None:
            x = _TWO_PI * self.frequency * dd.fit.theta
            sn, cs = np.sin(x), np.cos(x)
            if dd.reduce is None:
                ok = resolved(dd, self.frequency)
                if not ok.all():
                    sn, cs = np.where(ok, sn, 0.0), np.where(ok, cs, 0.0)
            hit = trig[self.frequency] = (sn, cs)
            budget.bounded(trig, budget.TRIG_BYTES, count=16)
        return hit

    def _factors(self, dd, rng: dict, keys, only=None):
        """``(d, factor)`` per direction: the amplitude factor with the sign of the motion at the
        samples of direction d, 0 elsewhere (built at the distinct speeds when :func:`speed_keys`
        has them: the same numbers); ``only``: that direction alone."""
        f = dd.fit
        if keys is None:
            sgn = np.sign(f.v)
            return [(d, np.where(sel, sgn * per_speed(dd, lambda sp, d=d: self._g(d, sp, rng.get(d))), 0.0))
                    for d, sel in self._groups(f) if only is None or d == only]
        return [(d, np.take(t, keys[4])) for d, t in self.factor_tables(rng, keys, only)]

    def factor_tables(self, rng: dict, keys, only=None) -> list:
        """``(d, factor)`` per direction at the keys of :func:`speed_keys` (:meth:`_factors` gathers them)."""
        u, kidx, ksg, kdir, _ = keys
        out = []
        for d in ((0,) if self.symmetric else self.dirs):
            if only is None or d == only:
                sel = np.ones(len(kidx), bool) if self.symmetric else kdir == d
                out.append((d, np.where(sel, ksg * np.asarray(self._g(d, u, rng.get(d)))[kidx], 0.0)))
        return out

    def _groups(self, f):
        if self.symmetric:
            return [(0, np.ones(len(f), bool))]
        return [(d, f.direction == d) for d in self.dirs]

    @property
    def names(self):
        lab = self.label or f"{self.frequency:.6g}"
        out = []
        for d in ((0,) if self.symmetric else self.dirs):
            tag = "" if d == 0 else f"[{_DNAME[d][:3]}]"
            out += [f"{lab} sin{tag}", f"{lab} cos{tag}"]
            if d in dict(self.load_phase):
                out.append(f"{lab} load^2{tag}")
        return out

    def _raw(self, dd):
        f = dd.fit
        if f.theta is None:
            raise InputError("a position-locked line needs positions (theta)")
        sn, cs = self._trig(dd)
        lp = dict(self.load_phase)
        if lp and f.load is None:
            raise InputError("a load-dependent line (SILO4 eq. 14) needs the 'load' channel")
        facs = self._factors(dd, self.ranges(dd), speed_keys(dd))
        out = np.empty((len(f), sum(2 + (d in lp) for d, _ in facs)))
        j = 0
        for d, g in facs:     # written into the columns: no list of columns stacked afterwards
            np.multiply(g, sn, out=out[:, j])
            np.multiply(g, cs, out=out[:, j + 1])
            j += 2
            if d in lp:
                out[:, j] = g * f.load ** 2 * (sn * math.cos(lp[d]) + cs * math.sin(lp[d]))
                j += 1
        return out

    def _difference(self, dd, up, dn, c, h):
        """A decay's central difference with the columns of the other directions left at exactly 0
        (as their differences are): the same matrix, and product, as :meth:`Block._difference`
        without building them twice."""
        moved = [d for d, b in dict(up.decay).items() if dict(dn.decay).get(d) != b]
        if (type(self)._raw is not HarmonicBlock._raw or len(moved) != 1 or up.frequency != dn.frequency
                or up.law != dn.law or dd.fit.theta is None):
            return super()._difference(dd, up, dn, c, h)
        f = dd.fit
        sn, cs = self._trig(dd)
        lp = dict(self.load_phase)
        rng, keys = self.ranges(dd), speed_keys(dd)
        D = np.zeros((len(f), len(c)))
        i = 0
        for d in ((0,) if self.symmetric else self.dirs):
            if d == moved[0]:
                (_, gu), = up._factors(dd, rng, keys, only=d)
                (_, gd), = dn._factors(dd, rng, keys, only=d)
                D[:, i] = gu * sn - gd * sn
                D[:, i + 1] = gu * cs - gd * cs
                if d in lp:
                    trig = sn * math.cos(lp[d]) + cs * math.sin(lp[d])
                    D[:, i + 2] = gu * f.load ** 2 * trig - gd * f.load ** 2 * trig
            i += 2 + (d in lp)
        return D @ c / (2 * h)

    def write(self, model, coef, se, ranges: dict | None = None):
        """The fitted line into ``model``'s harmonics; ``ranges`` (:meth:`ranges`): the speed range
        each direction's amplitude law was fitted on (``speed_range``)."""
        i = 0
        lp = dict(self.load_phase)
        ex = dict(self.extra)
        ranges = {**dict(self.speed_range), **(ranges or {})}
        targets = [(0, DIRECTIONS)] if self.symmetric else [(d, (_DNAME[d],)) for d in self.dirs]
        for d, names in targets:
            a, c = coef[i], coef[i + 1]
            sa, sc = se[i], se[i + 1]
            i += 2
            A = math.hypot(a, c)
            phi = math.atan2(c, a)
            # with the unit vector (a, c) / A: no A^2, which underflows to 0 for a denormal amplitude
            ua, uc = (a / A, c / A) if A > 0 else (float("nan"), float("nan"))
            A_se = math.hypot(ua * sa, uc * sc) if A > 0 else float("nan")
            p_se = math.hypot(uc * sa, ua * sc) / A if A > 0 else float("nan")
            h = {"frequency": float(self.frequency), "amplitude": float(A), "amplitude_se": float(A_se),
                 "phase": float(phi), "phase_se": float(p_se), "law": dict(self.law).get(d, "exp"),
                 "decay": float(dict(self.decay).get(d, 0.0))}
            if self.label:
                h["label"] = self.label
            if ranges.get(d) is not None:
                h["speed_range"] = [float(ranges[d][0]), float(ranges[d][1])]
            if d in lp:
                k = coef[i]
                # the load column carries its own phase; the model's term shares the line's phase
                h["load_coefficient"] = float(k * math.cos(lp[d] - phi)) if A > 0 else float(k)
                h["load_coefficient_se"] = float(se[i])
                i += 1
            h.update(ex.get(d, ex.get(0, {})))
            for nm in names:
                hs = model.directions[nm].harmonics
                hs[:] = [x for x in hs if not math.isclose(x.frequency, self.frequency, rel_tol=1e-12)]
                hs.append(Harmonic.of(h))

    def describe(self):
        laws = ", ".join(f"{_DNAME.get(d, 'both')}: {lw} (decay {dict(self.decay).get(d, 0.0):.3g})"
                         for d, lw in self.law)
        return f"line {self.label or ''} at {self.frequency:.6g} cycles/unit; {laws}"


@dataclass(frozen=True, eq=False)
class TermBlock(Block):
    """An additive term of :mod:`gearspec.terms` with its nonlinear parameters fixed (``fixed``)
    and its linear one fitted; ``direction`` 1/-1 for a term acting in one direction only.
    Presliding (``hysteresis``) and ``backlash`` use the travel since the last reversal of the
    whole recording (``DiagnoseData.travel``)."""

    kind: str = "offset"
    fixed: tuple = ()         # ((name, value), ...)
    direction: int = 0
    label: str | None = None
    effect_kind: str | None = None

    @property
    def names(self):
        tag = "" if not self.direction else f"[{_DNAME[self.direction][:3]}]"
        lin = TERM_LINEAR[self.kind]
        if lin == "trig":
            return [f"{self.kind} sin{tag}", f"{self.kind} cos{tag}"]
        return [f"{self.kind}.{lin}{tag}"]

    def matches(self, t: dict) -> bool:
        """Whether the model's term ``t`` is this block's (kind, direction and fixed parameters)."""
        return t["kind"] == self.kind and int(t.get("direction", 0) or 0) == self.direction and all(
            t.get(k) == v for k, v in self.fixed)

    def term(self, **lin) -> dict:
        t = {"kind": self.kind, **dict(self.fixed), **lin}
        if self.direction:
            t["direction"] = int(self.direction)
        if self.label:
            t["label"] = self.label
        return t

    def _raw(self, dd):
        f = dd.fit
        sgn = np.sign(f.v)
        signed = TERMS[self.kind].signed
        lin = TERM_LINEAR[self.kind]
        if self.kind in ("hysteresis", "backlash"):
            if dd.travel is None:
                raise InputError(f"a {self.kind} term needs the travel since the last reversal")
            # the kind's own profile on the travel of the whole recording; the direction is the segments'
            prof = TERMS[self.kind].func(self.term(**{lin: 1.0}), theta=f.theta, v=f.v, run=f.run, travel=dd.travel)
            col = sgn * prof
            if self.direction:
                col = np.where(f.direction == self.direction, col, 0.0)
            return col[:, None]
        inputs = dd.fit.inputs()
        if lin == "trig":
            outs = []
            for ph in (0.0, math.pi / 2):
                c, _ = evaluate_term(self.term(amplitude=1.0, phase=ph), **inputs)
                outs.append(c if signed else sgn * c)
            return np.column_stack(outs)
        c, _ = evaluate_term(self.term(**{lin: 1.0}), **inputs)
        return (c if signed else sgn * c)[:, None]

    def write(self, model, coef, se):
        lin = TERM_LINEAR[self.kind]
        if lin == "trig":
            a, c = coef[0], coef[1]
            A = math.hypot(a, c)
            t = self.term(amplitude=float(A), phase=float(math.atan2(c, a)))
            t["amplitude_se"] = float(math.sqrt((a * se[0]) ** 2 + (c * se[1]) ** 2) / A) if A > 0 else None
        else:
            t = self.term(**{lin: float(coef[0])})
            t[lin + "_se"] = float(se[0])
        if self.effect_kind:
            t["effect_kind"] = self.effect_kind
        model.terms.append(t)

    def describe(self):
        fx = ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in self.fixed)
        d = "" if not self.direction else f", {_DNAME[self.direction]} direction only"
        return f"{self.kind}({fx}){d}"


# ---------------------------------------------------------------------- state
@dataclass
class State:
    """The blocks of a model, and the model it came from (law, unit, name, notes)."""

    blocks: list
    template: FrictionModel
    symmetric: bool = False

    def design(self, dd: DiagnoseData, taylor: bool = False) -> np.ndarray:
        """The blocks' columns side by side (with ``taylor``, each block's Taylor columns after its
        own), built block by block into the result (:func:`~.gram.stack`)."""
        spans = self.spans(dd, taylor)
        return stack((b.columns(dd, taylor) for b in self.blocks), len(dd), spans[-1][1] if spans else 0)

    def spans(self, dd: DiagnoseData | None = None, taylor: bool = False) -> list[tuple[int, int]]:
        out, i = [], 0
        for b in self.blocks:
            k = len(b.names) + (b.n_taylor(dd) if taylor else 0)
            out.append((i, i + k))
            i += k
        return out

    def refreshed(self, coef: np.ndarray) -> "State":
        """The same blocks carrying the coefficients ``coef`` (of the plain design)."""
        blocks = [replace(b, coef=tuple(float(x) for x in coef[a:z])) for b, (a, z) in zip(self.blocks, self.spans())]
        return State(blocks, self.template, self.symmetric)

    @property
    def names(self) -> list[str]:
        return [n for b in self.blocks for n in b.names]

    def replaced(self, drop=(), add=()) -> "State":
        """A state without the blocks whose uid is in ``drop`` (blocks or uids), with ``add``."""
        uids = {getattr(d, "uid", d) for d in drop}
        blocks = [b for b in self.blocks if b.uid not in uids] + list(add)
        return State(blocks, self.template, self.symmetric)

    def block(self, uid: int) -> Block | None:
        return next((b for b in self.blocks if b.uid == uid), None)


@dataclass
class FittedState:
    """A state fitted to all observations: coefficients, standard errors, residual."""

    state: State
    coef: np.ndarray
    se: np.ndarray
    residual: np.ndarray
    rmse: float
    prediction: np.ndarray = field(repr=False, default=None)
    #: standard errors of the nonlinear parameters, ``{uid: {key: se}}`` (from their Taylor columns)
    nonlinear_se: dict = field(default_factory=dict)
    #: speed ranges of the lines' amplitude laws, ``{uid: {d: (min, max)}}`` (:meth:`HarmonicBlock.ranges`)
    speed_ranges: dict = field(default_factory=dict)

    def model(self, name: str | None = None, rmse_holdout: float | None = None) -> FrictionModel:
        """The fitted state as a FrictionModel (base parameters, harmonics and terms, with
        standard errors)."""
        from .nonlinear import write_nonlinear_se
        tmpl = self.state.template
        m = FrictionModel(tmpl.law, copy.deepcopy(tmpl.directions["positive"]),
                          copy.deepcopy(tmpl.directions["negative"]), unit=tmpl.unit,
                          name=name or tmpl.name, notes=list(tmpl.notes), meta=dict(tmpl.meta),
                          not_identified=dict(tmpl.not_identified))
        for p in m.directions.values():
            p.harmonics = []
        m.terms = []
        for blk, (a, z) in zip(self.state.blocks, self.state.spans()):
            n_terms = len(m.terms)
            kw = {"ranges": self.speed_ranges.get(blk.uid)} if isinstance(blk, HarmonicBlock) else {}
            blk.write(m, self.coef[a:z], self.se[a:z], **kw)
            write_nonlinear_se(m, blk, self.nonlinear_se.get(blk.uid, {}), m.terms[n_terms:])
        # through the constructor: the parameters cleaned as every model's are
        return FrictionModel(m.law, m.directions["positive"], m.directions["negative"], terms=m.terms, unit=m.unit,
                             rmse=self.rmse, rmse_holdout=rmse_holdout, not_identified=m.not_identified,
                             notes=m.notes, name=m.name, meta=m.meta)


def fit_state(state: State, dd: DiagnoseData, *, X: np.ndarray | None = None) -> FittedState:
    """Ordinary least squares of every block's linear parameters on all observations; standard
    errors as for white noise (the loop's acceptance does not rely on them)."""
    X = state.design(dd) if X is None else X
    G = X.T @ X
    beta = solve_normal(G, X.T @ dd.y)
    pred = X @ beta
    r = dd.y - pred
    n, p = X.shape
    s2 = float(r @ r) / max(n - p, 1)
    se = np.sqrt(np.clip(np.diag(_cov(G, s2)), 0, None))
    ranges = {b.uid: b.ranges(dd) for b in state.blocks if isinstance(b, HarmonicBlock)}
    return FittedState(state, beta, se, r, float(np.sqrt(np.mean(r * r))), pred, speed_ranges=ranges)


def __getattr__(name: str):
    """``state_from_model`` and ``predict_model`` live in :mod:`.frommodel`, the nonlinear parameters
    (``nonlinear_parameters``, ``with_parameter``, ``travel_range``) in :mod:`.nonlinear` (both build
    on the blocks here); still importable from this module."""
    if name in ("state_from_model", "predict_model"):
        from . import frommodel
        return getattr(frommodel, name)
    if name in ("nonlinear_parameters", "with_parameter", "travel_range"):
        from . import nonlinear
        return getattr(nonlinear, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
