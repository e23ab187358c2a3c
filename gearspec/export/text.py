"""The words every exported file carries: units of the axis, each parameter with its unit and standard
error, the speed range of each amplitude law, what was not identified."""

from __future__ import annotations

from ..model import FrictionModel
from ..terms import TERMS

__all__ = ["speed_unit", "torque_unit", "axis_unit", "parameter_lines", "slowest_line_speed", "TERM_UNITS"]

#: units of the term kinds' parameters on a rotary axis (``T``: torque, Nm)
TERM_UNITS = {
    "periodic": {"frequency": "cycles/rad", "amplitude": "Nm", "decay": "s/rad", "phase": "rad",
                 "load_coefficient": "1/Nm"},
    "viscous_power": {"coefficient": "Nm (s/rad)^exponent", "exponent": "-"},
    "stribeck_extra": {"amplitude": "Nm", "v_s": "rad/s", "shape": ""},
    "load_coulomb": {"mu": "Nm per Nm of load"},
    "load_viscous": {"gamma": "s/rad"},
    "temperature": {"coefficient": "Nm/degC", "reference": "degC"},
    "drift": {"coefficient": "Nm/s", "reference": "s"},
    "inertia": {"inertia": "kg m^2"},
    "offset": {"offset": "Nm"},
    "hysteresis": {"scale": "Nm", "length": "rad"},
    "cogging": {"frequency": "cycles/rad", "amplitude": "Nm", "phase": "rad"},
    "backlash": {"scale": "Nm", "gap": "rad"},
}


def speed_unit(model: FrictionModel) -> str:
    return "rad/s" if model.unit == "rad" else "m/s"


def torque_unit(model: FrictionModel) -> str:
    return "Nm" if model.unit == "rad" else "N"


def axis_unit(unit: str, model: FrictionModel) -> str:
    """A rotary unit (Nm, rad, kg m^2) on the model's axis (N, m, kg on a linear one)."""
    if model.unit == "rad":
        return unit
    return unit.replace("kg m^2", "kg").replace("Nm", "N").replace("rad", "m")


def _num(x) -> str:
    return "n/a" if x is None else f"{x:.6g}"


def _se(se: dict, k: str) -> str:
    return f", se {_num(se[k])}" if se.get(k) is not None else ""


def parameter_lines(model: FrictionModel) -> list[str]:
    """One line per parameter: ``direction name = value unit (se ...)``, each line's amplitude law and
    the speeds it was fitted on, each term, what was not identified and the fit errors."""
    law = model.law_spec
    su = speed_unit(model)
    out = [f"law {model.law}: {law.description}", f"axis: theta in {model.unit}, velocity in {su}, "
           f"torque in {torque_unit(model)}; the friction has the sign of the velocity"]
    for dname, p in model.directions.items():
        out.append(f"{dname} direction (v > 0)" if dname == "positive" else f"{dname} direction (v < 0)")
        for k, u in zip(law.params, law.units):
            val = p.values.get(k)
            why = model.not_identified.get(f"{dname}.{k}")
            out.append(f"  {k} = {_num(val)} {axis_unit(u, model)}{_se(p.se, k)}"
                       + (" (not identified: left out)" if val is None else "") + (f"; {why}" if why else ""))
        for i, h in enumerate(p.harmonics):
            out.append(f"  line {h.label or i + 1}: " + line_text(h.to_dict(), model))
    for i, t in enumerate(model.terms):
        units = TERM_UNITS.get(t["kind"], {})
        se = {k[:-3]: v for k, v in t.items() if k.endswith("_se")}
        vals = ", ".join(f"{k} = {t[k] if isinstance(t[k], str) else _num(t[k])} "
                         f"{axis_unit(units.get(k, ''), model)}".rstrip() + _se(se, k)
                         for k in TERMS[t["kind"]].params if k in t)
        side = {1: " (v > 0 only)", -1: " (v < 0 only)"}.get(int(t.get("direction") or 0), "")
        extra = f"; {line_text(t, model)}" if t["kind"] == "periodic" else ""
        out.append(f"term {i + 1}: {t['kind']}{side}: {vals}{extra}")
    shown = {f"{d}.{k}" for d in model.directions for k in law.params}
    out += [f"not identified: {k}: {why}" for k, why in model.not_identified.items() if k not in shown]
    if model.rmse is not None or model.rmse_holdout is not None:
        out.append(f"fit error: rmse {_num(model.rmse)}, held-out rmse {_num(model.rmse_holdout)} {torque_unit(model)}")
    return out


def line_text(h: dict, model: FrictionModel) -> str:
    """A line (harmonic) in words: frequency, amplitude, law, decay, phase, speed range."""
    su = speed_unit(model)
    se = {k[:-3]: v for k, v in h.items() if k.endswith("_se")}
    law = h.get("law") or "exp"
    rng = h.get("speed_range")
    where = (f"fitted on |v| {_num(rng[0])}..{_num(rng[1])} {su}, held at the edges outside" if rng else
             "no speed range recorded: evaluated at every speed" if law != "const" else "constant")
    k = (f", load coefficient {_num(h['load_coefficient'])} 1/{torque_unit(model)}{_se(se, 'load_coefficient')}"
         if h.get("load_coefficient") else "")
    return (f"frequency {_num(h.get('frequency'))} cycles/{model.unit}{_se(se, 'frequency')}, amplitude "
            f"{_num(h.get('amplitude'))} {torque_unit(model)}{_se(se, 'amplitude')}, amplitude law {law} "
            f"(decay {_num(h.get('decay', 0.0))}{_se(se, 'decay')}), phase {_num(h.get('phase', 0.0))} rad"
            f"{_se(se, 'phase')}{k}; {where}")


def slowest_line_speed(model: FrictionModel) -> float | None:
    """The lowest speed any line's amplitude law was fitted on (rad/s or m/s), None when none says."""
    lows = [h.speed_range[0] for p in model.directions.values() for h in p.harmonics if h.speed_range]
    lows += [t["speed_range"][0] for t in model.terms if t.get("speed_range") and t["speed_range"][0] is not None]
    lows = [x for x in lows if x > 0]
    return min(lows) if lows else None
