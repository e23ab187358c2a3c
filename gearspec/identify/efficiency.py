"""Lola/CROPS: fits to efficiency.  :func:`fit_efficiency` fits law (8) or (11) to the efficiency
(eq. 13) of quasi-static points as the paper does (eq. 9) under the constraints of eq. 10;
:func:`fit_catalog` fits law (8) to a catalog table of efficiency (Table V);
:func:`efficiency_model` is the efficiency a friction model predicts.

Units: motor speeds rad/s, output loads Nm, efficiency dimensionless, N the gear ratio.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
from scipy import optimize

from .. import laws
from ..errors import InputError
from ..fitdata import FitData
from ..model import LAWS, RPM, FrictionModel
from . import validate
from .joint import fit
from .stats import ConvergenceError

__all__ = ["efficiency_model", "fit_efficiency", "fit_catalog"]


def efficiency_model(model: FrictionModel, v, load, ratio: float) -> np.ndarray:
    """Efficiency a friction model predicts when the motor drives the load (Lola eq. 13 with
    eq. 12): ``eta = (|T_l|/N) / (|T_l|/N + |tau_f(v, T_l)|)``."""
    tau = model.friction(None, v, load=load)
    return laws.efficiency_from_friction(tau, load, ratio)


def fit_efficiency(data: FitData, law: str = "lola8", *, ratio: float, init: FrictionModel | None = None,
                   holdout: str | None = None, folds: int = 5, name: str | None = None,
                   gamma_free: bool = True) -> FrictionModel:
    """Fit law (8) or (11) to the *efficiency* of quasi-static points (Lola eq. 9) under the
    constraints of eq. 10 (``T_f0, mu, b >= 0``; law (11) also ``T_fS >= 0``, ``v_S > 0``).

    ``data`` carries the measured efficiency as ``y`` (dimensionless) with ``v`` the motor speed
    and ``load`` the output torque (e.g. ``FitData.from_points(v, eta, load=T_l)``).  The RMS of the
    efficiency residual is ``rmse`` (what the paper's Tables III-V call RMS).  Symmetric model.
    """
    if law not in ("lola8", "lola11"):
        raise InputError(f"efficiency fits take law lola8 or lola11, got '{law}'")
    if data.load is None:
        raise InputError("an efficiency fit needs the output load torque ('load')")
    if not ratio or ratio <= 0:
        raise InputError("an efficiency fit needs the gear ratio N")
    eta = np.asarray(data.y, dtype=float)
    v = np.abs(data.v)
    tl = np.abs(data.load)
    if np.any(tl <= 0):
        raise InputError("efficiency points need a nonzero load (eta = 0 at no load carries no information)")
    all_names = list(LAWS[law].params)
    fixed = {"gamma": 0.0} if (not gamma_free and "gamma" in all_names) else {}
    names = [k for k in all_names if k not in fixed]
    # start: friction implied by the efficiency, fitted linearly
    tau_implied = (tl / ratio) * (1.0 / np.clip(eta, 1e-3, None) - 1.0)
    pts = FitData.from_points(v, tau_implied, load=tl, unit=data.unit)
    src = init
    if src is None:
        try:
            src = fit(pts, law, holdout=None, weights="uniform", check=False)
        except InputError:
            src = None
    if src is not None:
        x0 = np.array([src.params("positive").values[k] for k in names], float)
    else:
        guess = {"t_f0": float(np.median(tau_implied)), "mu": 1e-3, "b": 1e-4, "gamma": 0.0,
                 "t_fs": float(np.median(tau_implied)), "v_s": float(np.median(v))}
        x0 = np.array([guess[k] for k in names])
    lo = np.array([1e-9 if k == "v_s" else 0.0 if k in LAWS[law].nonneg else -np.inf for k in names])
    x0 = np.where(np.isfinite(lo), np.maximum(x0, lo + 1e-12), x0)

    def params_of(x):
        p = dict(zip(names, x))
        p.update(fixed)
        return [p[k] for k in all_names]

    def resid(x):
        tau = LAWS[law].magnitude(v, tl, *params_of(x))
        return laws.efficiency_from_friction(tau, tl, ratio) - eta

    scale = np.where(np.abs(x0) > 0, np.abs(x0), 1.0)
    res = optimize.least_squares(resid, x0, bounds=(lo, np.inf), x_scale=scale, method="trf", max_nfev=2000)
    if res.status <= 0:
        raise ConvergenceError(f"the efficiency fit of law {law} did not converge ({res.message})")
    r = res.fun
    dof = max(len(r) - len(names), 1)
    s2 = float(r @ r) / dof
    cov = np.linalg.pinv(res.jac.T @ res.jac) * s2
    se = np.sqrt(np.clip(np.diag(cov), 0, None))
    P = {k: float(x) for k, x in zip(names, res.x)}
    P.update({k + "_se": float(e) for k, e in zip(names, se)})
    for k, val in fixed.items():
        P[k], P[k + "_se"] = val, 0.0
    at_bound = [k for k, x, lb in zip(names, res.x, lo) if np.isfinite(lb) and x <= lb + 1e-12 and k != "gamma"]
    notes = [f"fitted to efficiency (eq. 9) of {len(r)} points, ratio N = {ratio:g}; constraints of eq. 10"]
    if at_bound:
        notes.append("at the eq. 10 bound (0): " + ", ".join(at_bound))
    m = FrictionModel(law, P, None, unit=data.unit, notes=notes, name=name or f"{law} (efficiency fit)",
                      meta={"fit": {"law": law, "method": "efficiency", "ratio": ratio}})
    m.rmse = float(math.sqrt(np.mean(r * r)))
    if holdout:
        m.rmse_holdout, m.rmse_holdout_reason = validate.holdout(
            lambda tr: fit_efficiency(tr, law, ratio=ratio), data, by=holdout, folds=folds,
            residual=lambda mf, t: efficiency_model(mf, t.v, t.load, ratio) - t.y)
    return m


def fit_catalog(table: pd.DataFrame, *, ratio: float, law: str = "lola8", drop_extrapolated: bool = True
                ) -> tuple[FrictionModel, pd.DataFrame]:
    """Fit law (8) (or (11)) to a catalog efficiency table (Lola Table V), as the paper does.

    ``table`` has columns ``input_speed_rpm``, ``load`` (output torque, Nm) and ``efficiency``
    -- e.g. the product form ``eta_R(speed) * K(load)`` of ``gearspec.datasets.load
    ("harmonic_drive_catalog")``.  Rows at zero speed (an extrapolation in that source) and zero
    load (zero output power, where efficiency carries no information) are left out when
    ``drop_extrapolated``.  Returns the model (``rmse``: RMS of the efficiency residual) and the
    table with the model's efficiency beside the catalog's.
    """
    need = {"input_speed_rpm", "load", "efficiency"}
    if not need <= set(table.columns):
        raise InputError(f"a catalog table needs columns {sorted(need)}, has {list(table.columns)}")
    t = table.copy()
    if drop_extrapolated:
        t = t[(t["input_speed_rpm"] > 0) & (t["load"] > 0)]
    data = FitData.from_points(t["input_speed_rpm"].to_numpy() * RPM, t["efficiency"].to_numpy(),
                               load=t["load"].to_numpy())
    m = fit_efficiency(data, law, ratio=ratio, name=f"law ({law[4:]}) fitted to catalog efficiency")
    out = table.copy()
    ok = (out["load"] > 0)
    out["model"] = np.nan
    out.loc[ok, "model"] = efficiency_model(m, out.loc[ok, "input_speed_rpm"].to_numpy() * RPM,
                                            out.loc[ok, "load"].to_numpy(), ratio)
    out["used"] = out.index.isin(t.index)
    return m, out
