"""Models side by side on the same data (:func:`compare`), and a whole recording identified
(:func:`identify_recording`, ``gearspec fit``): the joint fit beside the published procedure and
simpler laws, with in-sample, held-out and per-segment errors.

Units: friction and errors Nm (N), speeds rad/s (m/s).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np
import pandas as pd

from ..core.crossval import n_params as _n_params
from ..core.reduction import group_rows, on_one_blas_thread
from ..errors import InputError
from ..fitdata import FitData
from ..gears import load_gear
from ..jsonsafe import plain
from ..model import FrictionModel
from ..segment import find_segments, free_motion
from .joint import fit, refit
from .published import line_amplitudes, silo4_published
from .stats import harmonic_specs
from .validate import _safe_rmse, holdout, segment_errors, segment_row, segment_rows

__all__ = ["compare", "FitResult", "identify_recording"]


def compare(data: FitData, candidates: Mapping[str, FrictionModel | Mapping], *, by: str = "segment",
            folds: int = 5) -> pd.DataFrame:
    """Models side by side on the same data: rmse (in-sample) and held-out rmse.

    ``candidates`` maps a name to a fitted model (refitted per fold with its own settings for the
    held-out error; a model without fit settings cannot be refitted: ``rmse_holdout`` None, never
    its in-sample rmse) or to keyword arguments of :func:`fit` (``{"law": "stribeck"}``).
    ``rmse_holdout_reason`` says why a held-out rmse is missing or partial (:func:`holdout`).
    """
    rows = []
    for name, c in candidates.items():
        if isinstance(c, FrictionModel):
            m = c
            if m.meta.get("fit"):
                ho, why = holdout(lambda tr, m=m: refit(m, tr, holdout=None), data, by=by, folds=folds)
            else:
                ho, why = None, "the model carries no fit settings to refit it without the held-out data"
        else:
            kw = {"holdout": None, **c}
            m = fit(data, **kw)
            ho, why = holdout(lambda tr, kw=kw: fit(tr, **{**kw, "check": False}), data, by=by, folds=folds)
        rows.append({"model": name, "law": m.law, "parameters": _n_params(m), "rmse": _safe_rmse(m, data),
                     "rmse_holdout": ho, "rmse_holdout_reason": why})
    return pd.DataFrame(rows)


@dataclass
class FitResult:
    """What :func:`identify_recording` (``gearspec fit``) produces.

    ``model``: the requested law, fitted jointly; ``models``: it and the models it is compared
    with (the published procedure for ``silo4``, simpler laws), by name; ``comparison``: rmse and
    held-out rmse of each on the same data; ``errors``: per-segment errors of each (SILO4 eqs.
    12-13); ``data``: what they were fitted to; ``amplitudes``: the lines' amplitude, phase and
    standard error in every segment (:func:`line_amplitudes`).
    """

    model: FrictionModel
    models: dict
    comparison: pd.DataFrame
    errors: dict
    data: FitData
    amplitudes: pd.DataFrame | None = None
    notes: list = None

    def to_dict(self) -> dict:
        """The ``gearspec fit --json`` form (CONTRACTS.md section 4) plus the comparison."""
        d = self.model.to_dict()
        d["comparison"] = plain(self.comparison.to_dict("records"))
        d["models"] = {name: m.to_dict() for name, m in self.models.items() if m is not self.model}
        return d


#: laws compared with each law by default, and whether they get the same lines
_COMPARE_WITH = {"silo4": (("stribeck", False), ("coulomb_viscous", True)), "stribeck": (("coulomb_viscous", False),),
                 "lola11": (("lola8", False),), "lola8": (("lola11", False),), "coulomb_viscous": (), "none": ()}


def _motion_note(seg) -> str:
    """What each kind of segment contributes, in one sentence."""
    names = {"plateau": "plateaus", "quasi_static": "quasi-static sweeps", "free": "free-motion blocks"}
    parts = []
    for kind, label in names.items():
        segs = [s for s in seg.segments if s.kind == kind]
        if segs:
            parts.append(f"{len(segs)} {label} ({sum(s.n for s in segs):,} rows)")
    share = seg.settings.get("free_share")
    how = (f"free motion is {100 * share:.0f} % of the moving rows" if share is not None
           else "free motion forced (--motion free)")
    return (f"fitted from {', '.join(parts)}: {how}; each block's law at its mean speed, positions and accelerations "
            f"sample by sample; held out by whole stretches of motion")


def identify_recording(rec, law: str = "silo4", *, segmentation=None, gear=None, harmonics=None,
                       published: bool | None = None, holdout: str = "segment", folds: int = 5,
                       se: str = "covariance", load_ratio: float | None = None,
                       compare_with=None, motion: str = "auto", inertia: bool = True) -> FitResult:
    """Identify ``law`` (a key of :data:`gearspec.model.LAWS`) from a recording ``rec``, beside the
    published procedure and simpler laws.

    ``segmentation``, ``gear``: default found segments and the recording's gear spec; ``harmonics``:
    lines to fit (:func:`harmonic_specs`; default for ``silo4``: every declared line); ``published``:
    also run :func:`silo4_published` (default: for ``silo4`` and ``stribeck``); ``holdout``,
    ``folds``, ``se``: as in :func:`fit`; ``load_ratio``: subtract ``|load| / load_ratio`` (the load
    seen at the motor, eq. 12) from the torque (default for the Lola laws: the gear's total ratio
    when the recording has a load); ``compare_with``: other laws fitted to the same data (default:
    the simpler ones); ``motion``: what the fit uses (:func:`~gearspec.segment.free_motion`:
    "auto" adds free motion -- ramps, moves, chirps -- where it is a large part of the recording,
    and then identifies the inertia with the friction unless the gear spec gives it); ``inertia``:
    False leaves the torque as measured (no ``J thetadd`` subtracted even when the spec gives J).
    """
    return _identify(rec, law, segmentation, gear, harmonics, published, holdout, folds, se, load_ratio,
                     compare_with, motion, inertia)


# BLAS on one thread: every product here is of few columns (X^T y over a segment's rows, the small
# least-squares problems of the fits), where OpenBLAS's threads only contend for the cores (10^7
# rows: 74 -> 42 s of CPU).  With two threads the sums of X^T y split by core count; on one thread
# the numbers no longer depend on the machine (0.9 with two threads: 10^7-row SEs differ in their 5th digit)
@on_one_blas_thread
def _identify(rec, law, segmentation, gear, harmonics, published, holdout, folds, se, load_ratio, compare_with,
              motion, inertia) -> FitResult:
    """:func:`identify_recording`'s work (its arguments, in its order)."""
    gear = load_gear(gear) if gear is not None else rec.gear
    seg = free_motion(rec, segmentation if segmentation is not None else find_segments(rec), motion=motion)
    notes = [_motion_note(seg)] if any(s.kind == "free" for s in seg.segments) else []
    if law in ("lola8", "lola11") and load_ratio is None and "load" in rec.data and gear is not None and gear.stages:
        load_ratio = gear.total_ratio
        notes.append(f"friction = drive torque - |load| / {load_ratio:g} (Lola eq. 12; the load opposes the motion)")
    lines = harmonic_specs(harmonics, gear) if law == "silo4" else (harmonic_specs(harmonics) if harmonics else [])
    data = FitData.from_recording(rec, seg, load_ratio=load_ratio, inertia=inertia,
                                  lines=[h["frequency"] for h in lines])
    if published is None:
        published = law in ("silo4", "stribeck")
    amplitudes = line_amplitudes(data, lines) if lines and not data.free_motion else None
    model = fit(data, law, harmonics=harmonics, gear=gear, holdout=holdout, folds=folds, se=se,
                name=f"{law} (joint fit)")
    models = {model.name: model}
    if published and data.free_motion:
        published = False
        notes.append("published procedure (SILO4 sections 3-4) not run: it reads plateaus, and this recording is "
                     "fitted from free motion")
    if published:
        pm = silo4_published(data, amplitudes, harmonics=lines, holdout=holdout, folds=folds)
        if law == "stribeck":
            for p in pm.directions.values():
                p.harmonics = []
            pm.law = "stribeck"
            pm.rmse = _safe_rmse(pm, data)
        models[pm.name] = pm
    others = _COMPARE_WITH.get(law, ()) if compare_with is None else [(o, True) for o in compare_with]
    for other, with_lines in others:
        h = lines if with_lines else []
        try:
            m = fit(data, other, harmonics=h, gear=gear, holdout=holdout, folds=folds,
                    name=other + (" + lines" if h else ""))
            models[m.name] = m
        except InputError as exc:
            notes.append(f"{other} not fitted: {exc}")
    rows = [{"model": name, "law": m.law, "parameters": _n_params(m), "rmse": m.rmse,
             "rmse_holdout": m.rmse_holdout, "rmse_holdout_reason": m.rmse_holdout_reason}
            for name, m in models.items()]
    errors = _segment_errors(models, data)
    return FitResult(model, models, pd.DataFrame(rows), errors, data, amplitudes, notes)


def _segment_errors(models: dict, data: FitData) -> dict:
    """:func:`segment_errors` of every model.  On plateau data from the segments' normal equations
    (:func:`.validate.segment_rows`, the same numbers to rounding); a model that cannot be scored so:
    the data cut into one piece per segment once (a
    segment's rows are found by one sort, not by a mask over all rows per segment and model: the
    cost grows with rows, not rows x segments); the same rows, in the same order, as on the whole
    data.  Each model is evaluated once on all rows, or (a model that cannot predict one direction)
    once per direction on that direction's rows, never once per segment: the predictions are the
    same sample by sample.  Data that hold free motion (blocks
    grouped by stretch) go through :func:`segment_errors` as they are."""
    if data.free_motion or len(data) == 0:
        return {name: segment_errors(m, data) for name, m in models.items()}
    names = list(models)
    fast = segment_rows(models, data) or {}
    out = {name: fast[name] for name in names if fast.get(name) is not None}
    models = {name: m for name, m in models.items() if name not in out}
    if not models:
        return {name: out[name] for name in names}
    group = data.groups("segment")
    order, _, bounds = group_rows(group)
    starts = bounds[:-1]
    pieces = [order[a:b] for a, b in zip(bounds[:-1], bounds[1:])]
    first_dir = data.direction[order[starts]]
    inputs = data.inputs()
    for name, m in models.items():
        try:    # every row at once (no gathered copies of the inputs); per direction if one fails
            whole = m.evaluate(**inputs)
        except InputError:
            whole = None
        preds = {} if whole is None else {j: whole[p] for j, p in enumerate(pieces)}
        for d in (np.unique(first_dir) if whole is None else ()):
            rows = np.concatenate([p for p, fd in zip(pieces, first_dir) if fd == d])
            try:
                pred = m.evaluate(**{k: (None if x is None else x[rows]) for k, x in inputs.items()})
            except InputError:      # a direction the model cannot predict: its segments left out
                continue
            at = 0
            for j in np.flatnonzero(first_dir == d):
                preds[j] = pred[at:at + len(pieces[j])]
                at += len(pieces[j])
        recs = [segment_row(data, pieces[j], preds[j], group[pieces[j][0]]) for j in range(len(pieces)) if j in preds]
        out[name] = pd.DataFrame(recs) if recs else pd.DataFrame([])
    return {name: out[name] for name in names}
