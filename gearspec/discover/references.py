"""The papers' laws (refitted by :func:`gearspec.identify.fit` on the explorer's folds) and
published models (scored as they are), beside the discovered laws."""

from __future__ import annotations

import math

import numpy as np

from ..core.crossval import held_out, n_params as _n_params, splits
from ..errors import InputError
from ..fitdata import FitData
from ..identify.joint import fold_fit
from ..model import FrictionModel
from ..terms import BASE_LAWS, fittable_laws
from .forked import fits_map
from .moments import Moments
from .results import Reference

__all__ = ["PAPER_LAWS"]

#: the papers' laws the explorer compares with: every base law of :mod:`gearspec.terms` with
#: parameters (names of :func:`gearspec.identify.fit`)
PAPER_LAWS = fittable_laws()
#: a paper law's held-out folds run in forked workers for data of at most this many rows, in turn
#: above: a fold's refit gathers its training samples and, with the inertia held, reduces them again
#: (about 0.5 GB a worker on the 10^7-row benchmark recording, whose peak it set: 2.4 -> 2.9 GB)
FORK_MAX_ROWS = 3_000_000
#: what a fold's fit or prediction may raise: the fold is skipped (counted), not the comparison
_FOLD_ERRORS = (InputError, np.linalg.LinAlgError, ValueError, FloatingPointError)

#: how the comparison names them (a law not listed: by its name)
_LABELS = {"coulomb_viscous": "Coulomb + viscous (IDIM-LS structure, per direction)",
           "stribeck": "SILO4 eq. 3 (per direction)", "silo4": "SILO4 eq. 11 (per direction, declared lines)",
           "lola8": "Lola law (8)", "lola11": "Lola law (11)"}


def _segment_mean(data: FitData, model: FrictionModel, M: Moments) -> np.ndarray:
    pred = model.evaluate(**data.inputs())
    return np.bincount(M.rows(data.segment), weights=np.nan_to_num(pred), minlength=M.S) / M.n


def _segment_sse(data: FitData, model: FrictionModel, M: Moments, mask=None) -> np.ndarray:
    """Residual sum of squares of ``model`` in every segment of ``M`` over the samples ``mask``."""
    sub = data if mask is None else data.subset(mask)
    r = model.residual(sub)
    out = np.zeros(M.S)
    np.add.at(out, M.rows(sub.segment), np.nan_to_num(r * r, nan=0.0))
    return out


def _paper_law(data: FitData, M: Moments, law: str, specs, fold) -> Reference:
    """A law of the papers, fitted by :func:`gearspec.identify.fit` (ordinary least squares,
    ``weights="uniform"``, like the candidates) on all data and on the same folds (``fold``: of
    every segment of ``M``)."""
    from .. import identify

    label = _LABELS.get(law, law)
    if law in BASE_LAWS and BASE_LAWS[law].needs_load and data.load is None:
        return Reference(label, "paper law", None, None, None, None, note="needs the load channel; not fitted")
    # SILO4 eq. 11 with the lines the user declared or gave (not those the spectrum found: the
    # paper's law is about the gear train's own lines)
    harmonics = ([{"frequency": s["frequency"], "label": s.get("label")} for s in specs
                  if s.get("source") != "found"] if law == "silo4" else None)
    if law == "silo4" and not harmonics:
        return Reference(label, "paper law", None, None, None, None, note="no ripple line declared; same as eq. 3")
    # the same columns as the candidates: the inertia identified with the friction wherever the
    # data carry an acceleration the explorer's laws may use (an IDIM-LS structure without its
    # inertia is not IDIM-LS)
    kw = {"harmonics": harmonics, "weights": "uniform", "holdout": None,
          "inertia": "fit" if M.has("acc") else "none"}
    try:
        model = identify.fit(data, law, **kw)
    except InputError as exc:
        return Reference(label, "paper law", None, None, None, None, note=f"not fitted: {exc}")
    except (np.linalg.LinAlgError, ValueError, FloatingPointError) as exc:   # a comparison is never worth a crash
        return Reference(label, "paper law", None, None, None, None,
                         note=f"identify.fit failed ({type(exc).__name__}: {exc})")
    seg = M.rows(data.segment)

    def one(test):
        # a fold refitted with the settings of the fit on all data, only for its predictions (no
        # in-sample rmse of its training data, no warning repeated once per fold), and scored
        try:
            return _segment_sse(data, fold_fit(model, data.subset((~test)[seg])), M, test[seg])[test]
        except _FOLD_ERRORS as exc:
            return exc

    # the folds at once in forked workers (the fit on all data above, here, left the samples'
    # per-segment statistics on ``data`` for them to read), on long recordings in turn (memory);
    # held_out takes their results in turn
    tests = [test for _, test in splits(fold)]
    done = iter(fits_map(one, tests) if len(data) <= FORK_MAX_ROWS else [one(t) for t in tests])

    def score(_, test):
        got = next(done)
        if isinstance(got, Exception):
            raise got
        return got

    ho = held_out(fold, lambda train: None, score, weight=M.n, catch=_FOLD_ERRORS)
    failed = len(ho.failed)
    note = f"fit failed in {failed} fold(s): held-out error over the other folds" if failed else ""
    return Reference(label, "paper law", _rmse_all(data, model), ho.rmse, _n_params(model),
                     None if failed else ho.sse, model, note)


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
