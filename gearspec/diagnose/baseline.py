"""The loop's entry points on their own: the model to start from (:func:`baseline_model`), the
IDIM-LS model of the EMPS procedure (:func:`idim_model`), every residual analysis of a fitted model
(:func:`residual_analysis`) and the EMPS figure of merit (:func:`relative_error`)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..errors import InputError
from ..fitdata import FitData
from ..model import FrictionModel
from ..recording import Recording
from .data import DiagnoseData
from .design import fit_state
from .frommodel import predict_model, state_from_model
from .detectors.analyses import residual_analyses

__all__ = ["baseline_model", "idim_model", "residual_analysis", "relative_error"]


def relative_error(y, prediction) -> float:
    """``100 ||y - prediction|| / ||y||`` (percent), the EMPS benchmark's figure of merit."""
    y = np.asarray(y, float)
    return float(100 * np.linalg.norm(y - np.asarray(prediction, float)) / np.linalg.norm(y))



def baseline_model(dd: DiagnoseData, law: str = "silo4", *, gear=None, harmonics=None, symmetric: bool = False,
                   terms=()) -> FrictionModel:
    """The model to start from when none is given: ``law`` fitted by :func:`gearspec.identify.fit`
    (its nonlinear parameters -- Stribeck velocity, decays -- are then kept by the loop's linear
    refits), with the declared lines of ``gear`` for ``silo4``; ``symmetric``: one parameter set
    for both directions (fitted on the friction magnitudes of both directions together).
    Whole-trajectory data take laws without nonlinear parameters (the loop fits them linearly)."""
    from .. import identify

    fd = dd.fit
    if dd.kind == "trajectory":
        if law not in ("coulomb_viscous", "none", "lola8"):
            raise InputError(f"whole-trajectory data: start from a law without nonlinear parameters "
                             f"(coulomb_viscous), not '{law}'; the loop adds a Stribeck term if the data want one")
        from ..model import LAWS
        P = {k: 0.0 for k in LAWS[law].params}
        return FrictionModel(law, P, P if symmetric else dict(P), unit=fd.unit, terms=list(terms),
                             name=f"{law} ({'symmetric' if symmetric else 'per direction'})")
    if symmetric:
        folded = replace(fd, v=np.abs(fd.v), y=fd.direction * fd.y, direction=np.ones(len(fd), np.int8),
                         segments=fd.segments.assign(direction=1), notes=list(fd.notes), cache={})
        m = identify.fit(folded, law, harmonics=harmonics, gear=gear, holdout=None)
        p = m.directions["positive"]
        ni = {k.replace("positive.", "both."): v for k, v in m.not_identified.items() if not k.startswith("negative.")}
        return FrictionModel(m.law, p, p, unit=m.unit, terms=list(terms), not_identified=ni,
                             notes=m.notes + ["symmetric: one parameter set for both directions"],
                             name=f"{law} (symmetric)", meta=m.meta)
    m = identify.fit(fd, law, harmonics=harmonics, gear=gear, holdout=None)
    if terms:
        m = m.with_terms(*terms)
    m.name = f"{law} (joint fit)"
    return m


def residual_analysis(model: FrictionModel, data, *, gear=None, fap: float = 0.01, per_segment: bool = True) -> dict:
    """Every residual analysis of :mod:`~gearspec.diagnose.residual` for a fitted model on any
    recording, as it is (nothing refitted): ``{"residual", "spectra", "speed", "load",
    "temperature", "t", "acc", "reversal"}`` (the channels the data have).  ``data``: a Recording,
    FitData or DiagnoseData."""
    dd = _as_data(data, None, gear)
    r = dd.y - predict_model(model, dd)
    return {"residual": r, **residual_analyses(dd, r, fap=fap, per_segment=per_segment)}


def idim_model(dd: DiagnoseData, *, symmetric: bool = True, offset: bool = True,
               name: str | None = None) -> FrictionModel:
    """The inverse dynamic identification model fitted by least squares (IDIM-LS), as the EMPS
    reference procedure does: ``tau = M qdd + Fv qd + Fc sign(qd) (+ offset)``, one Fv and Fc for
    both directions (``symmetric``) or per direction, on the observations of ``dd`` (use
    :func:`~gearspec.diagnose.trajectory_data`: filtered position, central differences, every
    column decimated).  A :class:`~gearspec.model.FrictionModel` of law ``coulomb_viscous`` with an
    ``inertia`` term (M) and an ``offset`` term; ``rmse`` and, in ``meta["relative_error"]``, the
    relative error ``100 ||y - yhat|| / ||y||`` in percent."""
    P = {"tau_c": 0.0, "viscous": 0.0}
    terms = [{"kind": "inertia", "inertia": 0.0}] + ([{"kind": "offset", "offset": 0.0}] if offset else [])
    tmpl = FrictionModel("coulomb_viscous", P, dict(P), unit=dd.unit, terms=terms,
                         name=name or f"IDIM-LS {'symmetric' if symmetric else 'asymmetric'}")
    st = state_from_model(tmpl, dd, symmetric=symmetric and len(dd.directions()) == 2)
    fitted = fit_state(st, dd)
    m = fitted.model(name=tmpl.name)
    m.meta = {**m.meta, "relative_error": relative_error(dd.y, fitted.prediction),
              "procedure": "IDIM-LS (ordinary least squares on the decimated observation matrix)"}
    return m


def _as_data(data, by: str | None, gear=None) -> DiagnoseData:
    if isinstance(data, DiagnoseData):
        return data
    if isinstance(data, Recording):
        return DiagnoseData.from_recording(data, by=by or "segment")
    if isinstance(data, FitData):
        return DiagnoseData.from_fitdata(data, by=by or "segment", gear=gear)
    raise InputError("diagnose takes a Recording, a FitData or a DiagnoseData")
