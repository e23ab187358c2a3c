"""One cross-validation for the three engines (identify, diagnose, discover): folds of whole groups,
the held-out loop, the held-out Z statistic and its critical value, and the parameter count shown
beside held-out errors.  All three deal their groups (segments, runs or moves) with
:func:`deal_folds` from the same per-group summaries (:func:`group_summary`), so the same data and
``folds`` give the same splits everywhere.

The fold rule: ``k = max(2, min(folds, groups))`` folds (no empty fold; something held out).
Within each direction the groups are sorted by speed (ties by group id) and dealt round robin, so
every fold spans the speed range of both directions.  Speeds within ``SPEED_RTOL`` (relative) are
ties: plateaus at one commanded speed differ only by rounding, whose order depends on how the mean
was summed and would give each engine its own folds.  The negative direction continues the deal
where the positive one stopped (fold ``n_positive % k``), so fold sizes differ by at most one
group (starting both in fold 0 would leave folds empty, e.g. 2 + 2 segments in 4 folds).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Iterator

import numpy as np
from scipy import stats

from ..errors import InputError
from .reduction import unique_ids

__all__ = ["SPEED_RTOL", "group_summary", "deal_folds", "row_folds", "splits", "held_out", "HeldOut", "z_statistic",
           "ROUNDOFF_SHARE",
           "critical_z", "n_params"]


#: mean speeds of two groups closer than this (relative) are a tie, broken by the group id
SPEED_RTOL = 1e-9


# ---------------------------------------------------------------------- folds
def group_summary(groups, direction, speed, weight=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-group summaries the fold rule deals by: ``(ids, sign, mean_speed)``, each (G,).

    Per row (N,): ``groups`` its group id (any integers), ``direction`` +1 / -1, ``speed`` its
    velocity (rad/s or m/s; the absolute value is used), ``weight`` the samples it stands for
    (rows that are segment summaries: their counts; default 1).  ``ids``: the sorted group ids;
    ``sign``: sign of the weighted sum of the group's directions (its first row's on a tie);
    ``mean_speed``: weighted mean of ``|speed|`` over its rows.
    """
    g = np.asarray(groups)
    d = np.asarray(direction, dtype=float)
    s = np.abs(np.asarray(speed, dtype=float))
    w = np.ones(len(g)) if weight is None else np.asarray(weight, dtype=float)
    if not (len(g) == len(d) == len(s) == len(w)):
        raise InputError("group summaries need one direction, speed and weight per row")
    ids, first, inv = unique_ids(g, return_index=True, return_inverse=True)
    sign = np.sign(np.bincount(inv, weights=d * w, minlength=len(ids))).astype(int)
    sign = np.where(sign == 0, np.sign(d[first]), sign).astype(int)
    mean_speed = np.bincount(inv, weights=s * w, minlength=len(ids)) / np.bincount(inv, weights=w, minlength=len(ids))
    return ids, sign, mean_speed


def deal_folds(sign, speed, ids, folds: int) -> np.ndarray:
    """Fold (0 .. k-1) of every group, in the order given, by THE fold rule (module docstring).

    Per group (G,): ``sign`` its direction (+1 / -1), ``speed`` its mean ``|v|`` (rad/s or m/s),
    ``ids`` its id (breaks ties of speed).  ``folds``: folds asked for (at least 1); at most one
    per group is used, and at least two.
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
    small = fold.dtype.kind in "iu" and len(fold) and 0 <= fold.min() and fold.max() < 2 ** 20
    for f in (np.flatnonzero(np.bincount(fold)) if small else np.unique(fold)):   # the same folds, no sort
        test = fold == f
        if test.any() and not test.all():
            yield int(f), test


# ---------------------------------------------------------------------- the held-out loop
@dataclass
class HeldOut:
    """Held-out errors of one cross-validation, per unit (U,): ``sse`` its held-out sum of squared
    errors (torque units^2; NaN where not predicted: its fold's fit failed, or a non-finite
    prediction), ``n`` the samples it covers (0 where NaN), ``fold`` its fold; ``failed``: why each
    fold that could not be fitted failed; ``ran``: folds tried."""

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
    """Cross-validate: every fold predicted by a model fitted without it (a :class:`HeldOut`).

    ``fold`` (U,): fold of every unit (rows of samples, or per-segment summaries).  ``fit(train)``,
    ``train`` a boolean mask over the units: the model fitted to them.  ``score(model, test)``: the
    held-out squared error of each test unit, ``(test.sum(),)`` (a row: its squared residual, NaN
    when not finite; a segment: its residual sum of squares).  ``weight`` (U,): samples each unit
    stands for (default 1).  ``catch``: exceptions of a fold's fit or prediction that skip the fold
    (counted in ``failed``); others propagate.
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
#: a change of model whose held-out effect is below this share of the held-out sum of squares is
#: round-off (a column the model already has, refitted): no evidence either way.  An effect of
#: relative size e gives Z ~ sqrt(N) e, so one this small (e ~ 3e-5) cannot reach a critical Z of 2-4
#: below 10^9 rows; round-off of sums over 10^6-10^7 rows in double precision is ~1e-13 of them.
ROUNDOFF_SHARE = 1e-9


def z_statistic(r0, delta, noise, starts, stops, *, blocks: int = 8) -> float:
    """Held-out Z of a change of model: ``Z = sum_g <r0_g, Delta_g> / sqrt(sum_g V_g)``.

    Per row (N,, torque units): ``r0`` the held-out residual without the change, ``delta`` the
    change of the held-out prediction it makes, ``noise`` the held-out residual the variance is
    estimated from (e.g. the residual with the change).  Rows ``starts[g]:stops[g]`` are held-out
    group ``g``.  ``V_g`` is cluster-robust: the larger of ``<noise_g, Delta_g>^2`` (the group as one
    cluster) and the sum of the same over ``blocks`` consecutive blocks of it (coloured noise within
    it).  When every ``V_g`` is 0: ``+inf`` for a positive numerator (the change explains the
    held-out data exactly, e.g. ``noise`` = 0), ``-inf`` for a negative one, 0 for none.  0 as well
    when ``delta`` is round-off: ``sum delta^2 <= ROUNDOFF_SHARE * sum r0^2`` (its sign and size are
    then those of the floating-point sums).
    """
    delta = np.asarray(delta, dtype=float)
    r0 = np.asarray(r0, dtype=float)
    if np.vdot(delta, delta) <= ROUNDOFF_SHARE * np.vdot(r0, r0) and r0.any():
        return 0.0
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
