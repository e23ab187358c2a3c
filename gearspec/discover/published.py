"""Friction models published with the real data sets, to compare discovered laws with.

EMPS (Janot, Gautier, Brunot, "Data Set and Reference Models of EMPS"): the reference models
identified by IDIM-LS (inverse dynamic model, least squares) on the estimation set DATA_EMPS,
``tau = M qdd + Fv qd + Fc sign(qd) + offset`` (force in N on the load side, position in m),
symmetric and with separate Coulomb and viscous friction per direction (values as listed in the
data set's documentation, ``datasets/emps/SOURCE.md``).  They include the inertia term, evaluated
with the Savitzky-Golay acceleration of the fit data.
"""

from __future__ import annotations

from ..model import FrictionModel

__all__ = ["published_models", "emps_idim_ls"]


def emps_idim_ls() -> dict[str, FrictionModel]:
    """The two IDIM-LS reference models of the EMPS data set."""
    sym = FrictionModel("coulomb_viscous", {"tau_c": 20.3935, "viscous": 203.5034}, unit="m",
                        terms=[{"kind": "inertia", "inertia": 95.1089}, {"kind": "offset", "offset": -3.1648}],
                        name="EMPS IDIM-LS (published): M qdd + Fv qd + Fc sign(qd) + offset")
    asym = FrictionModel("coulomb_viscous", {"tau_c": 20.1440, "viscous": 166.7061},
                         {"tau_c": 20.6277, "viscous": 240.4236}, unit="m",
                         terms=[{"kind": "inertia", "inertia": 95.1540}],
                         name="EMPS IDIM-LS asymmetric (published): M qdd + Fv,i qd + Fc,i sign(qd)")
    return {"IDIM-LS (published)": sym, "IDIM-LS asymmetric (published)": asym}


def published_models(gear) -> dict[str, FrictionModel]:
    """Published models for the drive ``gear`` (a GearTrain or preset name), if any are known."""
    name = getattr(gear, "name", gear)
    if name in ("emps", "EMPS linear axis"):
        return emps_idim_ls()
    return {}
