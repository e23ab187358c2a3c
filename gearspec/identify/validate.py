"""Errors of a fitted model: in-sample over the directions it can predict, per segment (SILO4
eqs. 12-13), and held out -- ``folds``-fold cross-validation over whole segments or runs, never
interleaved samples, by THE fold rule and held-out loop of :mod:`gearspec.core.crossval`."""

from __future__ import annotations

from typing import Callable

import numpy as np
import pandas as pd

from ..core.crossval import deal_folds, group_summary, held_out, row_folds
from ..core.reduction import unique_ids
from ..errors import InputError
from ..fitdata import FitData
from ..model import FrictionModel
from . import scores

__all__ = ["holdout", "holdout_rmse", "segment_errors", "segment_row", "segment_rows", "inverted_sign", "negative_viscous"]


def _folds(data: FitData, by: str, folds: int) -> np.ndarray:
    """Fold of every sample: its segment's (or run's) fold by THE rule of :mod:`gearspec.core.crossval`;
    computed once per data (every model's held-out error on them deals the same folds)."""
    cache = data.__dict__.setdefault("_row_folds", {})
    if (by, int(folds)) not in cache:
        cache[by, int(folds)] = row_folds(data.groups(by), data.direction, data.v, folds)
    return cache[by, int(folds)]


def holdout_rmse(fit_fn: Callable[[FitData], FrictionModel], data: FitData, *, by: str = "segment",
                 folds: int = 5, residual: Callable | None = None) -> float | None:
    """The held-out rmse of :func:`holdout`, without the reason."""
    return holdout(fit_fn, data, by=by, folds=folds, residual=residual)[0]


def holdout(fit_fn: Callable[[FitData], FrictionModel], data: FitData, *, by: str = "segment",
            folds: int = 5, residual: Callable | None = None) -> tuple[float | None, str | None]:
    """Root-mean-square error on held-out data and why it is missing or partial: ``(rmse, reason)``.

    ``folds``-fold cross-validation over whole segments (or runs, ``by``), folds by THE rule of
    :mod:`gearspec.core.crossval`; each fold is predicted by a model ``fit_fn(train_data)`` fitted to
    the others, its error ``residual(model, test_data)`` (default: ``model.residual``, friction
    torque).  ``rmse`` is None when cross-validation cannot run -- fewer than two held-out groups, or no
    fold whose model can be fitted without it and predict it (each direction needs its own
    groups, and enough speeds left for the law) -- and ``reason`` says which, in one sentence;
    never the in-sample error in its place.  When some folds fail, ``rmse`` comes from the others
    and ``reason`` says how many held-out samples it covers."""
    ng = len(unique_ids(data.groups(by)))
    if ng < 2:
        return None, (f"cross-validation needs two held-out {by}s or more; the data have {ng}")

    def score(m, test):
        t = data.subset(test)
        r = np.asarray(m.residual(t) if residual is None else residual(m, t), dtype=float)
        return np.where(np.isfinite(r), r * r, np.nan)

    h = _by_segment(fit_fn, data, by, folds) if residual is None else None
    if h is None:
        h = held_out(_folds(data, by, folds), lambda train: fit_fn(data.subset(train)), score)
    n, failed = h.covered, h.failed
    if not n:
        why = failed[0] if failed else f"every {by} falls into one fold"
        return None, (f"cross-validation over {ng} {by}s could not run: no fold could be fitted without its "
                      f"{by}s and predict them ({why})")
    if n < len(data):
        return h.rmse, (f"from {n} of {len(data)} samples: {len(failed)} of {h.ran} folds could not be "
                        f"fitted without their {by}s ({failed[0] if failed else 'no test data'})")
    return h.rmse, None


def _segment_folds(data: FitData, lay, by: str, folds: int) -> np.ndarray | None:
    """Fold of every segment of plateau data (:func:`.scores.layout`) by THE rule of
    :mod:`gearspec.core.crossval`, dealt from per-segment summaries (each segment's direction, speed
    and rows as its weight: :func:`~gearspec.core.crossval.group_summary`), the folds :func:`_folds`
    gives its rows; None when a held-out group is not made of whole segments."""
    groups = data.groups(by)
    first = groups[lay.starts]
    if not np.array_equal(np.minimum.reduceat(groups, lay.starts), np.maximum.reduceat(groups, lay.starts)):
        return None
    ids, sign, speed = group_summary(first, lay.direction, lay.v, weight=lay.n)
    return deal_folds(sign, speed, ids, folds)[np.searchsorted(ids, first)]


def _by_segment(fit_fn, data: FitData, by: str, folds: int):
    """:func:`holdout`'s cross-validation with whole segments as the units (plateau data,
    :func:`.scores.layout`): the same folds, fits and training data, each held-out segment's sum of
    squared errors from its normal equations (:func:`.scores.segment_sums`) instead of the model's
    predictions at its samples.  None when the data (or a fold's model) cannot be scored so: then
    by samples."""
    lay = scores.layout(data)
    if lay is None:
        return None
    fold = _segment_folds(data, lay, by, folds)
    if fold is None:
        return None

    def score(m, test):
        out = scores.segment_sums(m, data, test)
        if out is None:
            raise scores.Fallback
        return scores.check_finite(out.sse)

    try:
        return held_out(fold, lambda train: fit_fn(data.segment_subset(train)), score, weight=lay.n)
    except scores.Fallback:
        return None


def _safe_rmse(model: FrictionModel, data: FitData) -> float | None:
    """In-sample rmse (Nm) on the samples of the directions ``model`` has parameters for; None if none.
    On plateau data from the segments' normal equations (:func:`.scores.segment_sums`)."""
    dirs = [d for d, dname in ((1, "positive"), (-1, "negative"))
            if all(model.params(dname).get(k) is not None for k in model.law_spec.params
                   if k not in model.law_spec.optional)]
    lay = scores.layout(data)
    if lay is not None:
        sel = np.flatnonzero(np.isin(lay.direction, dirs))
        out = scores.segment_sums(model, data, sel) if len(sel) else None
        if out is not None and np.all(np.isfinite(out.sse)):
            return float(np.sqrt(np.sum(out.sse) / np.sum(lay.n[sel])))
    ok = np.zeros(len(data), bool)
    for d in dirs:
        ok |= data.direction == d
    if ok.all():        # every sample: the data as they are (the same rows, no copy)
        return model.rmse_on(data)
    return model.rmse_on(data.subset(ok)) if ok.any() else None


def segment_errors(model: FrictionModel, data: FitData) -> pd.DataFrame:
    """Model error per segment, as SILO4 validates its model (eqs. 12-13, Table 3): the mean
    error ``e`` and its standard deviation ``s_e`` of ``model - data`` (friction magnitudes, so that
    a model above the data is positive in both directions), the rmse, the mean friction and ``e``
    in percent of it.  Segments of a direction the model cannot predict are left out.  Blocks of
    free motion count by their stretch of motion (its first block's id in ``segment``)."""
    rows = []
    group = data.groups("segment")
    for sid in np.unique(group):
        ii = np.flatnonzero(group == sid)
        try:
            pred = model.evaluate(**data.subset(ii).inputs())
        except InputError:
            continue
        rows.append(segment_row(data, ii, pred, sid))
    return pd.DataFrame(rows)


def segment_row(data: FitData, ii: np.ndarray, pred: np.ndarray, sid) -> dict:
    """One row of :func:`segment_errors`: segment (or stretch) ``sid`` of ``data``, its rows ``ii`` in
    time order, and the model's prediction ``pred`` there (torque, Nm or N)."""
    d = int(data.direction[ii[0]])
    y = data.y[ii]
    err = d * (pred - y)
    return _row(sid, data.run[ii[0]], d, float(np.mean(np.abs(data.v[ii]))), len(ii), float(np.mean(d * y)),
                float(np.mean(err)), float(np.std(err, ddof=1)) if len(err) > 1 else float("nan"),
                float(np.sqrt(np.mean(err ** 2))))


def _row(sid, run, d, speed, n, level, e, s_e, rmse) -> dict:
    """:func:`segment_errors`' row from its numbers."""
    return {"segment": int(sid), "run": int(run), "direction": d, "speed": speed, "n": n, "level": level,
            "e": e, "s_e": s_e, "rmse": rmse,
            # in percent of the mean friction; undefined (NaN) where that mean is 0
            "e_percent": 100 * e / level if level != 0 else float("nan")}


def segment_rows(models: dict, data: FitData) -> dict | None:
    """:func:`segment_errors`' rows of every model in ``models`` (name -> model) on plateau data
    (:func:`.scores.layout`), from the segments' normal equations (:func:`.scores.segment_sums`): the
    mean error ``(sum of predictions - sum of data) / n``, its standard deviation from the residual
    sum of squares less ``n e^2``; the level, speed and run from the samples as
    :func:`segment_row` takes them.  A segment whose deviations about its mean error would lose
    digits to cancellation (their sum of squares below :data:`.scores.CANCEL` of the torque's, or
    the sum of errors below it of the sum of the torque) is computed from the model's predictions
    at its samples.  None
    (name -> None for one model) where the data (the model) cannot be scored so."""
    lay = scores.layout(data)
    if lay is None:
        return None
    S = len(lay.ids)
    group = data.groups("segment")
    common = []     # model-independent: (id, run, level, speed) per segment, as segment_row has them
    for j in range(S):
        a, b = int(lay.starts[j]), int(lay.stops[j])
        d = int(lay.direction[j])
        common.append((group[a], data.run[a], float(np.mean(d * data.y[a:b])), float(np.mean(np.abs(data.v[a:b])))))
    out = {}
    for name, m in models.items():
        sums = scores.segment_sums(m, data, check=False)
        if sums is None or not np.all(np.isfinite(sums.sse[sums.ok])):
            out[name] = None
            continue
        recs = []
        for j in np.flatnonzero(sums.ok):
            n, d = int(lay.n[j]), int(lay.direction[j])
            sid, run, level, speed = common[j]
            diff = sums.pred[j] - sums.y[j]
            e = float(diff / n)
            dev = sums.sse[j] - n * e * e
            if n < 2 or not (abs(diff) > scores.CANCEL * abs(sums.y[j]) and dev > scores.CANCEL * sums.yy[j]):
                a, b = int(lay.starts[j]), int(lay.stops[j])
                recs.append(segment_row(data, np.arange(a, b), scores.predict_rows(m, data, a, b), sid))
                continue
            recs.append(_row(sid, run, d, speed, n, level, e, float(np.sqrt(dev / (n - 1))),
                             float(np.sqrt(sums.sse[j] / n))))
        out[name] = pd.DataFrame(recs) if recs else pd.DataFrame([])
    return out


# ---------------------------------------------------------------------- checks of a fitted model
def _flag(model: FrictionModel, key: str, msg: str) -> None:
    """One sentence into ``model.meta["flags"][key]`` and ``model.notes`` (``warning: ...``)."""
    model.meta.setdefault("flags", {})[key] = msg
    if "warning: " + msg not in model.notes:
        model.notes.append("warning: " + msg)


def inverted_sign(model: FrictionModel, data: FitData) -> list[str]:
    """Flag friction opposite to the velocity in most segments: a segment whose mean friction
    magnitude (``level`` of :meth:`FitData.plateaus`) lies more than two standard errors below 0
    counts, and more than half of the segments counting is no friction a drive can have (it
    dissipates: the torque it needs has the sign of the motion) but a torque channel logged with
    the opposite sign convention.  One sentence with the fix, flagged as :func:`negative_viscous`
    does (``"sign"``); returns it in a list (empty when the data look right)."""
    pl = data.plateaus()
    if pl.empty:
        return []
    wrong = int(np.sum(pl["level"] + 2 * pl["level_se"].fillna(np.inf) < 0))
    if not wrong > len(pl) / 2:
        return []
    tu = "Nm" if data.unit == "rad" else "N"
    msg = (f"friction opposes the velocity in {wrong} of {len(pl)} segments (median level "
           f"{float(np.median(pl['level'])):.3g} {tu}): the torque's sign is likely inverted relative to the "
           f"velocity; rerun with --scale torque=-1 (or, if the column is an output-side torque sensor, it holds "
           f"the load the gear drives, not the gear's friction: use the drive's torque minus it)")
    _flag(model, "sign", msg)
    return [msg]


def negative_viscous(model: FrictionModel, data: FitData | None = None) -> list[str]:
    """Flag a negative viscous coefficient (``viscous``, Lola's ``b``; more than two standard errors
    below 0) of each direction: friction that falls with speed over the whole measured range is
    rarely physical, more often an inertia, a channel lag or aliasing the model does not hold, or
    plateau speeds too close together to tell viscous from Stribeck friction.  Each flag is one
    sentence, added to ``model.notes`` (``warning: ...``) and to ``model.meta["flags"]``
    (``"direction.parameter" -> sentence``); returns the sentences."""
    out = []
    model.meta.setdefault("flags", {})
    su = "rad/s" if model.unit == "rad" else "m/s"
    for dname, p in model.directions.items():
        for k in ("viscous", "b"):
            val = p.values.get(k)
            if k not in model.law_spec.params or val is None or not val < 0:
                continue
            se = p.se.get(k)
            # a value within two standard errors of 0 is no finding (and none without an error)
            if se is None or not np.isfinite(se) or not val < -2 * se:
                continue
            sig = f" ({abs(val) / se:.1f} standard errors below 0)" if se > 0 else ""
            rng = ""
            if data is not None:
                sp = np.abs(data.v[data.direction == (1 if dname == "positive" else -1)])
                if len(sp):
                    rng = f" over {float(np.min(sp)):.3g}..{float(np.max(sp)):.3g} {su}"
            msg = (f"{model.name}: the {dname} viscous coefficient ({k}) {val:.3g}{sig} is negative{rng}: likely an "
                   f"inertia, a channel lag or aliasing the model does not hold, or a speed range too narrow to "
                   f"tell viscous from Stribeck friction")
            _flag(model, f"{dname}.{k}", msg)
            out.append(msg)
    return out
