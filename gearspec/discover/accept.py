"""The acceptance rule of the closed loop, applied to the explorer's law: every term of the selected
law must pass the held-out test of :mod:`gearspec.diagnose.loop` against the law without it, and,
when an independent recording is given, the check of :mod:`gearspec.diagnose.validate` on it.

The test of a term (the law with it against the law with its simpler form: a direction-dependent
term against the same term for both directions, a decaying ripple amplitude against a constant one,
any other term against the law without it): on the same folds, both laws refitted on the training
folds predict the held-out segments (``p0`` without, ``p1`` with); with ``r0 = y - p0`` and
``Delta = p1 - p0`` the held-out Z of :func:`gearspec.core.crossval.z_statistic` (cluster-robust:
every held-out group one cluster or its :data:`~.moments.BLOCKS` blocks, the larger) must reach
:func:`~gearspec.core.crossval.critical_z` at ``alpha`` over the candidates a forward round of the
search tries (Bonferroni), the folds that improve must carry :data:`CONSISTENCY` of the change, and
-- for a whole term -- the held-out rmse must fall by ``min_gain``.  Where a term fails, the weakest (smallest Z) is
simplified first and every term is tested again (backward elimination, as the loop does).

Everything is computed on the pseudo rows of the segments' (and their blocks') normal equations:
``<r0, Delta>`` over a block's samples equals the same product over its pseudo rows exactly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.crossval import critical_z, z_statistic
from ..core.reduction import GroupNormals
from .law import Part, canonical, cross_validate, fit_law
from .moments import Moments
from .pool import _signature

__all__ = ["CONSISTENCY", "TERM", "Verdict", "held_out_z", "simpler", "judge", "backward", "validate_law"]

#: share of the absolute held-out change the improving folds must carry (the closed loop's value)
CONSISTENCY = 0.9
#: the move that removes a whole term (the minimum gain applies to it: a term must be worth its
#: place); a term's form (direction dependence, decaying amplitude) needs the held-out Z and the
#: fold consistency only -- the search already holds the term, and a form the data resolve at the
#: test's level is kept even when it moves the rmse by less than the minimum gain
TERM = "the term"


@dataclass
class Verdict:
    """One held-out test of a term: ``term`` (its label), ``move`` (what the alternative does to it),
    Z and its critical value, relative held-out rmse gain, fold consistency, and the decision."""

    term: str
    move: str
    z: float
    z_crit: float
    gain: float
    consistency: float
    passed: bool
    data: str = "estimation"

    def reason(self) -> str:
        why = []
        if not self.z >= self.z_crit:
            why.append(f"held-out Z {self.z:.2f} below {self.z_crit:.2f}")
        if not self.consistency >= CONSISTENCY:
            why.append(f"improves in folds carrying only {100 * self.consistency:.0f} % of the change")
        if not self.passed and self.z >= self.z_crit and self.consistency >= CONSISTENCY and self.move == TERM:
            why.append(f"held-out rmse falls by {100 * self.gain:.2f} % only")
        head = f"{self.term} ({self.move}, {self.data} data): "
        if self.passed:
            return head + f"accepted: held-out Z {self.z:.1f} >= {self.z_crit:.2f}, rmse -{100 * self.gain:.2f} %"
        return head + "rejected: " + "; ".join(why)

    def to_dict(self) -> dict:
        return {"term": self.term, "move": self.move, "z": self.z, "z_crit": self.z_crit, "gain": self.gain,
                "consistency": self.consistency, "passed": self.passed, "data": self.data, "reason": self.reason()}


def _block_rows(M: Moments):
    """Pseudo rows of every segment's blocks ``(P (S, B, K, K), q (S, B, K), B)``, or of the whole
    segments (B = 1) when the moments hold no blocks (cached on ``M``)."""
    key = ("block rows", M.basis)
    if key not in M._cache:
        if M.Gb is None:
            M._cache[key] = (M.P[:, None], M.q[:, None], 1)
        else:
            S, B, K = M.bb.shape
            gn = GroupNormals(M.Gb.reshape(S * B, K, K), M.bb.reshape(S * B, K), M.yyb.reshape(-1),
                              np.zeros(S * B))
            P, q, _ = gn.pseudo_rows()
            M._cache[key] = (P.reshape(S, B, K, K), q.reshape(S, B, K), B)
    return M._cache[key]


def held_out_z(M: Moments, p0: np.ndarray, p1: np.ndarray, groups: np.ndarray) -> float:
    """Z of :func:`gearspec.core.crossval.z_statistic` for the held-out predictions ``p0`` (without)
    and ``p1`` (with), each (S, K) coefficients of ``M``'s sample bases per segment; ``groups``:
    held-out group of every segment (one cluster each, split into its blocks)."""
    P, q, B = _block_rows(M)
    fit0 = np.einsum("sbkl,sl->sbk", P, p0)
    fit1 = np.einsum("sbkl,sl->sbk", P, p1)
    order = np.argsort(groups, kind="stable")
    _, first = np.unique(groups[order], return_index=True)
    per = B * M.K                                            # pseudo rows per segment
    starts, stops = first * per, np.append(first[1:], len(order)) * per
    r0, delta = (q - fit0)[order].ravel(), (fit1 - fit0)[order].ravel()
    # every group's rows are B blocks of its segments in turn: z_statistic's B-way split of a group
    # takes whole blocks (a group of m segments: m blocks per part)
    return z_statistic(r0, delta, (q - fit1)[order].ravel(), starts, stops, blocks=B)


def _cv(M: Moments, parts, fold, holdout=None):
    """Held-out sse per segment and held-out predictions (S, K) of a law (the empty law: zeros):
    ``holdout(parts)``'s (the search pool's, :meth:`.pool._Pool.holdout`) where it gives them,
    else :func:`~.law.cross_validate`'s (its folds converged from the all-data optimum)."""
    if not parts:
        return M.yy.copy(), np.zeros((M.S, M.K))
    got = holdout(parts) if holdout is not None else None
    return got if got is not None else cross_validate(M, canonical(parts), fold)


def simpler(p: Part, families=()) -> tuple[Part | None, str]:
    """The simpler form a term is tested against: ``(part or None for none, what the move is)``."""
    if p.split:
        return Part(p.family, p.freq, False, p.param0), "direction dependence"
    if p.fam.basis == "ripple" and p.family != "ripple_const" and "ripple_const" in families:
        return Part("ripple_const", p.freq, False, None), "amplitude decaying with speed"
    return None, TERM


def judge(M: Moments, fold, groups, with_parts, without_parts, *, z_crit: float, min_gain: float, term: str,
          move: str, cache: dict | None = None, holdout=None) -> Verdict:
    """The held-out test of the module docstring for one term (``cache``: held-out results by the
    laws' signatures; ``holdout``: see :func:`_cv`)."""
    cache = {} if cache is None else cache
    res = []
    for parts in (without_parts, with_parts):
        key = _signature(parts)
        if key not in cache:
            cache[key] = _cv(M, parts, fold, holdout)
        res.append(cache[key])
    (sse0, p0), (sse1, p1) = res
    z = held_out_z(M, p0, p1, groups)
    k = int(fold.max()) + 1
    fold_d = np.bincount(fold, weights=sse0 - sse1, minlength=k)
    tot = float(np.abs(fold_d).sum())
    cons = float(np.clip(fold_d, 0, None).sum() / tot) if tot > 0 else 0.0
    hb, ha = math.sqrt(float(sse0.sum()) / M.N), math.sqrt(float(sse1.sum()) / M.N)
    gain = (hb - ha) / hb if hb > 0 else 0.0
    ok = bool(z >= z_crit and cons >= CONSISTENCY and (gain >= min_gain or move != TERM))
    return Verdict(term, move, float(z), z_crit, gain, cons, ok)


def _alternatives(parts, families):
    """Per term of the law: (index, the law with its simpler form, what the move is)."""
    out = []
    for i, p in enumerate(parts):
        alt, move = simpler(p, families)
        rest = list(parts[:i]) + list(parts[i + 1:])
        out.append((i, tuple(rest + ([alt] if alt is not None else [])), move))
    return out


def backward(M: Moments, fold, groups, parts, *, alpha: float, min_gain: float, n_candidates: int,
             families=(), label=None, progress=None, holdout=None, prefetch=None) -> tuple[tuple, list[Verdict]]:
    """Backward elimination of the module docstring: the law with every term passing, and the
    verdicts of the last round (every term) plus those of the simplifications made.  ``progress``:
    called with one line of text after every round (each refits every term's alternative on the
    held-out folds: on a long recording a round takes seconds).  ``holdout``: where a law's held-out
    error comes from (:func:`_cv`; the search's pool: the laws it scored keep their error);
    ``prefetch``: called with the laws a round will ask ``holdout`` for, in the order it will ask,
    before it asks (the pool computes the new ones at once: :meth:`.pool._Pool.holdout_all`)."""
    parts = canonical(_start_values(M, parts))
    z_crit = critical_z(alpha, n_candidates, len(np.unique(groups)))
    label = label or (lambda p: p.label(M.frequencies))
    cache: dict = {}
    made = []
    while True:
        alts = _alternatives(parts, families)
        if prefetch is not None and holdout is not None:
            # judge's order: each alternative, then the law itself (once: then cached)
            prefetch([ps for _, alt, _ in alts for ps in (alt, parts) if ps and _signature(ps) not in cache])
        verdicts = [(judge(M, fold, groups, parts, alt, z_crit=z_crit, min_gain=min_gain, term=label(parts[i]),
                           move=move, cache=cache, holdout=holdout), alt)
                    for i, alt, move in alts]
        failing = [(v, alt) for v, alt in verdicts if not v.passed and alt]
        if not failing:
            if progress is not None:
                progress(f"acceptance round {len(made) + 1}: all {len(parts)} terms pass")
            return parts, made + [v for v, _ in verdicts]
        v, alt = min(failing, key=lambda x: x[0].z)
        made.append(v)
        if progress is not None:
            progress(f"acceptance round {len(made)}: {v.reason()}; simplified")
        parts = canonical(_start_values(M, alt))


def _start_values(M: Moments, parts) -> tuple:
    """The parts with their nonlinear parameters started where a fit on all data puts them."""
    parts = tuple(parts)
    if not any(p.free for p in parts):
        return parts
    fit = fit_law(M, parts)
    vals: dict = {}
    for (i, _), zv in zip(fit.layout.nl, fit.z):
        vals.setdefault(i, []).append(zv)
    return tuple(Part(p.family, p.freq, p.split, math.exp(float(np.mean(vals[i]))) if i in vals else p.param0)
                 for i, p in enumerate(fit.parts))


def validate_law(M: Moments, Mv: Moments, parts, *, alpha: float, min_gain: float, families=(),
                 label=None) -> tuple[tuple, list[Verdict]]:
    """The independent-recording check: every term of the law (fitted on all of ``M``) must lower
    the error on the validation moments ``Mv`` (same bases) by the held-out Z over ``Mv``'s segments
    at ``alpha`` over the law's terms and by ``min_gain``; the weakest failing term is simplified and
    the check repeats (:func:`gearspec.diagnose.validate.validate`'s rule)."""
    parts = canonical(parts)
    label = label or (lambda p: p.label(M.frequencies))
    groups = Mv.segment
    made = []

    fitted: dict = {}      # the law kept after a round is one of that round's alternatives: fitted once

    def pred(ps):
        if not ps:
            return np.zeros((Mv.S, Mv.K))
        key = canonical(ps)
        if key not in fitted:
            fitted[key] = fit_law(M, key).basis_coefficients(Mv)
        return fitted[key]

    while True:
        p1 = pred(parts)
        sse1 = Mv.rss_of(p1)
        z_crit = critical_z(alpha, len(parts), Mv.S)
        verdicts = []
        for i, alt, move in _alternatives(parts, families):
            p0 = pred(alt)
            sse0 = Mv.rss_of(p0)
            z = held_out_z(Mv, p0, p1, groups)
            hb, ha = math.sqrt(float(sse0.sum()) / Mv.N), math.sqrt(float(sse1.sum()) / Mv.N)
            gain = (hb - ha) / hb if hb > 0 else 0.0
            ok = bool(z >= z_crit and gain >= min_gain)
            verdicts.append((Verdict(label(parts[i]), move, float(z), z_crit, gain, 1.0, ok, "validation"), alt))
        failing = [(v, alt) for v, alt in verdicts if not v.passed and alt]
        if not failing:
            return parts, made + [v for v, _ in verdicts]
        v, alt = min(failing, key=lambda x: x[0].z)
        made.append(v)
        parts = canonical(alt)
