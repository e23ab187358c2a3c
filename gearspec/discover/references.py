"""The papers' laws (refitted by :func:`gearspec.identify.fit` on the explorer's folds) and
published models (scored as they are), beside the discovered laws."""

from __future__ import annotations

import math

import numpy as np

from ..core.crossval import n_params as _n_params
from ..errors import InputError
from ..fitdata import FitData
from ..model import FrictionModel
from .moments import Moments
from .results import Reference

__all__ = ["PAPER_LAWS"]

#: the papers' laws the explorer compares with (names of :func:`gearspec.identify.fit`)
PAPER_LAWS = ("coulomb_viscous", "stribeck", "silo4", "lola8", "lola11")


def _segment_mean(data: FitData, model: FrictionModel, M: Moments) -> np.ndarray:
    pred = model.evaluate(**data.inputs())
    pos = {int(s): i for i, s in enumerate(M.segment)}
    idx = np.array([pos[int(s)] for s in data.segment], dtype=int)
    return np.bincount(idx, weights=np.nan_to_num(pred), minlength=M.S) / M.n



def _segment_sse(data: FitData, model: FrictionModel, M: Moments, mask=None) -> np.ndarray:
    sub = data if mask is None else data.subset(mask)
    r = model.residual(sub)
    out = np.zeros(M.S)
    pos = {int(s): i for i, s in enumerate(M.segment)}
    np.add.at(out, np.array([pos[int(s)] for s in sub.segment], dtype=int), np.nan_to_num(r * r, nan=0.0))
    return out


def _paper_law(data: FitData, M: Moments, law: str, specs, fold, by) -> Reference:
    """A law of the papers, fitted by :func:`gearspec.identify.fit` (ordinary least squares,
    ``weights="uniform"``, like the candidates) on the same folds."""
    from .. import identify

    label = {"coulomb_viscous": "Coulomb + viscous (IDIM-LS structure, per direction)",
             "stribeck": "SILO4 eq. 3 (per direction)", "silo4": "SILO4 eq. 11 (per direction, declared lines)",
             "lola8": "Lola law (8)", "lola11": "Lola law (11)"}.get(law, law)
    if law in ("lola8", "lola11") and data.load is None:
        return Reference(label, "paper law", None, None, None, None, note="needs the load channel; not fitted")
    # SILO4 eq. 11 with the lines the user declared or gave (not those the spectrum found: the
    # paper's law is about the gear train's own lines)
    harmonics = ([{"frequency": s["frequency"], "label": s.get("label")} for s in specs
                  if s.get("source") != "found"] if law == "silo4" else None)
    if law == "silo4" and not harmonics:
        return Reference(label, "paper law", None, None, None, None, note="no ripple line declared; same as eq. 3")
    kw = {"harmonics": harmonics, "weights": "uniform", "holdout": None}
    try:
        model = identify.fit(data, law, **kw)
    except InputError as exc:
        return Reference(label, "paper law", None, None, None, None, note=f"not fitted: {exc}")
    except (np.linalg.LinAlgError, ValueError, FloatingPointError) as exc:   # a comparison is never worth a crash
        return Reference(label, "paper law", None, None, None, None,
                         note=f"identify.fit failed ({type(exc).__name__}: {exc})")
    seg_fold = dict(zip(M.segment.tolist(), fold.tolist()))
    sample_fold = np.array([seg_fold[int(s)] for s in data.segment])
    cv = np.zeros(M.S)
    failed = 0
    for f in np.unique(fold):
        test = sample_fold == f
        try:
            mf = identify.fit(data.subset(~test), law, **kw)
            cv += _segment_sse(data, mf, M, test)
        except (InputError, np.linalg.LinAlgError, ValueError, FloatingPointError):
            failed += 1
            cv[fold == f] = np.nan
    ok = np.isfinite(cv)
    note = ""
    if failed:
        note = f"fit failed in {failed} fold(s): held-out error over the other folds"
    n_ok = float(np.sum(M.n[ok]))
    ho = math.sqrt(float(np.sum(cv[ok])) / n_ok) if n_ok else None
    return Reference(label, "paper law", _rmse_all(data, model), ho, _n_params(model),
                     np.where(ok, cv, np.nan) if not failed else None, model, note)


def _rmse_all(data, model) -> float | None:
    try:
        r = model.residual(data)
    except InputError:
        return None
    r = r[np.isfinite(r)]
    return float(np.sqrt(np.mean(r * r))) if len(r) else None


def _published(data: FitData, M: Moments, name: str, model: FrictionModel) -> Reference:
    try:
        sse = _segment_sse(data, model, M)
    except InputError as exc:
        return Reference(name, "published", None, None, None, None, model, note=f"cannot be evaluated: {exc}")
    rm = math.sqrt(float(np.sum(sse)) / M.N)
    return Reference(name, "published", rm, rm, _n_params(model), sse, model,
                     note="parameters as published; not fitted here, so its held-out error is its error on all data")
