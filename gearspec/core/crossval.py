"""One cross-validation for the three engines: folds of whole groups, the held-out loop, the
held-out Z statistic and its critical value, and the parameter count shown beside held-out errors.

:func:`gearspec.identify.fit` (``gearspec fit``), the closed loop of :mod:`gearspec.diagnose`
(``gearspec diagnose``) and the explorer of :mod:`gearspec.discover` (``gearspec discover``) all
deal their held-out groups (segments, runs or moves) into folds with :func:`deal_folds`, from
per-group summaries computed the same way (:func:`group_summary`: the sign of the group's
directions and its mean ``|v|`` over its rows).  The same data and the same ``--holdout`` /
``folds`` therefore give the same folds everywhere, and the three report their held-out rmse on
the same splits.

The fold rule
-------------
``k = max(2, min(folds, groups))`` folds (never more folds than groups, so no fold is empty; at
least two, so that something is held out).  Within each direction the groups are sorted by speed
(ties by group id) and dealt round robin, so every fold spans the speed range of both directions.
Speeds within ``SPEED_RTOL`` (relative) of each other are ties: plateaus at one commanded speed
(e.g. one per load) have mean speeds that differ only by rounding, and the order rounding gives
them depends on how the mean was summed (over samples, over segment means), which would give each
engine its own folds.
The positive direction is dealt from fold 0 and the negative one continues where the positive
one stopped (it starts at fold ``n_positive % k``): the two directions together are one round
robin, so the folds' sizes differ by at most one group.  Without that rotation both directions
start in fold 0: one segment per direction puts both in one fold (leaving the other empty), and
2 + 2 segments in 4 folds leave two folds empty.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Iterator

import numpy as np
from scipy import stats

from ..errors import InputError

__all__ = ["SPEED_RTOL", "group_summary", "deal_folds", "row_folds", "splits", "held_out", "HeldOut", "z_statistic",
           "critical_z", "n_params"]


#: mean speeds of two groups closer than this (relative) are a tie, broken by the group id
SPEED_RTOL = 1e-9


# ---------------------------------------------------------------------- folds
def group_summary(groups, direction, speed, weight=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-group summaries that the fold rule deals by.

    Parameters
    ----------
    groups : array_like, (N,)
        Group id of every row (segment or run id; any integers).
    direction : array_like, (N,)
        Direction of every row (+1 / -1).
    speed : array_like, (N,)
        Velocity (or speed) of every row, in rad/s or m/s: its absolute value is used.
    weight : array_like, (N,), optional
        Samples each row stands for (rows that are themselves segment summaries: their sample
        counts); default one per row.

    Returns
    -------
    ids : ndarray, (G,)
        The group ids, sorted.
    sign : ndarray, (G,)
        Sign of the (weighted) sum of the group's directions; the direction of its first row on a tie.
    mean_speed : ndarray, (G,)
        (Weighted) mean of ``|speed|`` over the group's rows.
    """
    g = np.asarray(groups)
    d = np.asarray(direction, dtype=float)
    s = np.abs(np.asarray(speed, dtype=float))
    w = np.ones(len(g)) if weight is None else np.asarray(weight, dtype=float)
    if not (len(g) == len(d) == len(s) == len(w)):
        raise InputError("group summaries need one direction, speed and weight per row")
    ids, first, inv = np.unique(g, return_index=True, return_inverse=True)
    dsum = np.bincount(inv, weights=d * w, minlength=len(ids))
    sign = np.sign(dsum).astype(int)
    tie = sign == 0
    sign[tie] = np.sign(d[first[tie]]).astype(int)
    mean_speed = np.bincount(inv, weights=s * w, minlength=len(ids)) / np.bincount(inv, weights=w, minlength=len(ids))
    return ids, sign, mean_speed


def deal_folds(sign, speed, ids, folds: int) -> np.ndarray:
    """Fold of every group by THE fold rule (module docstring).

    Parameters
    ----------
    sign : array_like of int, (G,)
        Direction of each group, +1 or -1.
    speed : array_like, (G,)
        Mean ``|v|`` of each group (rad/s or m/s).
    ids : array_like, (G,)
        Group ids: they break ties of speed.
    folds : int
        Folds asked for (at least 1); at most one per group is used, and at least two.

    Returns
    -------
    ndarray of int, (G,)
        Fold (0 .. k-1) of each group, in the order given.
    """
    sign = np.asarray(sign)
    speed = np.asarray(speed, dtype=float)
    ids = np.asarray(ids)
    if int(folds) < 1:
        raise InputError(f"cross-validation needs at least one fold, got {folds}")
    if np.any((sign != 1) & (sign != -1)):
        raise InputError("every held-out group needs a direction of +1 or -1")
    k = max(2, min(int(folds), len(sign)))
    out = np.zeros(len(sign), int)
    start = 0
    for d in (1, -1):
        idx = _by_speed(np.flatnonzero(sign == d), speed, ids)
        out[idx] = (start + np.arange(len(idx))) % k
        start = len(idx) % k
    return out


def _by_speed(idx, speed, ids):
    """``idx`` sorted by speed, speeds within :data:`SPEED_RTOL` of their neighbour a tie broken by id."""
    idx = idx[np.lexsort((ids[idx], speed[idx]))]
    s = speed[idx]
    tied = np.abs(np.diff(s)) <= SPEED_RTOL * np.maximum(np.abs(s[1:]), np.abs(s[:-1]))
    level = np.cumsum(np.concatenate(([True], ~tied)))[:len(idx)]
    return idx[np.lexsort((ids[idx], level))]


def row_folds(groups, direction, v, folds: int) -> np.ndarray:
    """Fold of every row: its group's fold by :func:`deal_folds` over :func:`group_summary`."""
    ids, sign, speed = group_summary(groups, direction, v)
    fold = deal_folds(sign, speed, ids, folds)
    return fold[np.searchsorted(ids, np.asarray(groups))]


def splits(fold) -> Iterator[tuple[int, np.ndarray]]:
    """``(f, test)`` for every fold ``f`` that leaves something to train on and something to
    test: ``test`` is the boolean mask of the fold's units (rows, segments or groups)."""
    fold = np.asarray(fold)
    for f in np.unique(fold):
        test = fold == f
        if test.any() and not test.all():
            yield int(f), test


# ---------------------------------------------------------------------- the held-out loop
@dataclass
class HeldOut:
    """Held-out errors of one cross-validation.

    Attributes
    ----------
    sse : ndarray, (U,)
        Held-out sum of squared errors of every unit (torque units^2); NaN where the unit was not
        predicted (its fold's fit failed, or a non-finite prediction).
    n : ndarray, (U,)
        Samples each unit's ``sse`` covers (0 where NaN).
    fold : ndarray, (U,)
        Fold of every unit.
    failed : list of str
        Why each fold that could not be fitted failed.
    ran : int
        Folds that were tried.
    """

    sse: np.ndarray
    n: np.ndarray
    fold: np.ndarray
    failed: list = field(default_factory=list)
    ran: int = 0

    @property
    def covered(self) -> int:
        """Samples the held-out error covers."""
        return int(round(float(np.sum(self.n))))

    @property
    def rmse(self) -> float | None:
        """Held-out root-mean-square error over the predicted samples; None when none was."""
        n = float(np.sum(self.n))
        return math.sqrt(float(np.nansum(self.sse)) / n) if n > 0 else None

    def fold_sse(self) -> np.ndarray:
        """Held-out sum of squares of every fold, (k,)."""
        k = int(self.fold.max()) + 1 if len(self.fold) else 0
        return np.bincount(self.fold, weights=np.nan_to_num(self.sse, nan=0.0), minlength=k)


def held_out(fold, fit: Callable, score: Callable, *, weight=None, catch=(InputError,)) -> HeldOut:
    """Cross-validate: every fold predicted by a model fitted without it.

    Parameters
    ----------
    fold : array_like of int, (U,)
        Fold of every unit (rows of samples, or per-segment summaries).
    fit : callable
        ``fit(train)`` with ``train`` a boolean mask over the units: the model fitted to them.
    score : callable
        ``score(model, test)``: the held-out squared error of each test unit, ``(test.sum(),)``
        (a row: its squared residual, NaN when not finite; a segment: its residual sum of squares).
    weight : array_like, (U,), optional
        Samples each unit stands for (default 1: units are samples).
    catch : tuple of exception types
        Failures of a fold's fit or prediction that skip the fold (counted in ``failed``);
        others propagate.

    Returns
    -------
    HeldOut
    """
    fold = np.asarray(fold, dtype=int)
    w = np.ones(len(fold)) if weight is None else np.asarray(weight, dtype=float)
    sse = np.full(len(fold), np.nan)
    failed, ran = [], 0
    for _, test in splits(fold):
        ran += 1
        try:
            sse[test] = score(fit(~test), test)
        except catch as exc:
            failed.append(str(exc))
    n = np.where(np.isfinite(sse), w, 0.0)
    return HeldOut(sse, n, fold, failed, ran)


# ---------------------------------------------------------------------- the Z statistic
def z_statistic(r0, delta, noise, starts, stops, *, blocks: int = 8) -> float:
    """Held-out Z of a change of model: ``Z = sum_g <r0_g, Delta_g> / sqrt(sum_g V_g)``.

    Parameters
    ----------
    r0 : ndarray, (N,)
        Held-out residual without the change (torque units).
    delta : ndarray, (N,)
        The change of the held-out prediction it makes (torque units).
    noise : ndarray, (N,)
        The held-out residual the variance is estimated from (e.g. the residual with the change).
    starts, stops : sequence of int
        Rows ``starts[g]:stops[g]`` of every held-out group ``g``.
    blocks : int
        Consecutive blocks per group of the within-group variance.

    Returns
    -------
    float
        ``V_g`` is cluster-robust: the larger of ``<noise_g, Delta_g>^2`` (the group as one
        cluster) and the sum of the same over ``blocks`` consecutive blocks of the group (coloured
        noise within it).  When every ``V_g`` is 0 the ratio is taken for what it is: ``+inf``
        when the numerator is positive (the change explains the held-out data exactly: e.g.
        ``noise`` = 0), ``-inf`` when it is negative, 0 when it is 0 (no change at all).
    """
    num, var = 0.0, 0.0
    for a, z in zip(starts, stops):
        r, dl, e = r0[a:z], delta[a:z], noise[a:z]
        num += float(r @ dl)
        whole = float(e @ dl) ** 2
        split = sum(float(b1 @ b2) ** 2 for b1, b2 in zip(np.array_split(e, blocks), np.array_split(dl, blocks)))
        var += max(whole, split)
    if var > 0:
        return num / math.sqrt(var)
    return math.copysign(math.inf, num) if num != 0 else 0.0


def critical_z(alpha: float, candidates: int, groups: int) -> float:
    """The value the held-out Z must reach: the one-sided t quantile at ``alpha / candidates``
    (Bonferroni over the round's candidates, at least one) with ``groups - 1`` degrees of freedom
    (at least one)."""
    return float(stats.t.isf(alpha / max(candidates, 1), max(groups - 1, 1)))


# ---------------------------------------------------------------------- complexity
#: keys of a term that describe it rather than hold an estimated value
_TERM_SETTINGS = ("kind", "label", "direction", "law", "reference", "shape")


def n_params(model) -> int:
    """Number of parameters of a :class:`~gearspec.model.FrictionModel`, shown beside its held-out error.

    Per direction: the law's parameters that have a value, and per harmonic its amplitude and
    phase plus its decay constant unless the amplitude law is ``const`` (a decay fitted to 0 was
    still fitted); per term: its numeric values, without standard errors (``*_se``) and settings
    (kind, label, direction, law, reference temperature or time, shape).
    """
    n = 0
    for p in model.directions.values():
        n += sum(1 for k in model.law_spec.params if p.values.get(k) is not None)
        n += sum(2 if h.amplitude_law == "const" else 3 for h in p.harmonics)
    for t in model.terms:
        n += sum(1 for k, v in t.items() if k not in _TERM_SETTINGS and not k.endswith("_se")
                 and isinstance(v, (int, float)) and not isinstance(v, bool))
    return n
