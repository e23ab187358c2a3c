"""A friction model as a per-joint parameter file (YAML) for a ros2_control hardware interface or a
drive's parameter list: ``joints: {NAME: {friction: {law, unit, positive: {...}, negative: {...},
terms: [...]}}}``, SI values, units and standard errors in comments.

Written by hand (PyYAML writes no comments); every number is written so that ``yaml.safe_load``
reads back the same float (``repr`` digits, with a ``.`` in the mantissa as YAML 1.1 wants).
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

from .. import __version__
from ..model import FrictionModel
from ..terms import TERMS
from .text import TERM_UNITS, axis_unit, speed_unit, torque_unit

__all__ = ["write_yaml", "yaml_number"]

_JOINT = re.compile(r"^[A-Za-z_][A-Za-z0-9_./-]*$")


def yaml_number(x) -> str:
    """A number as a YAML 1.1 scalar ``yaml.safe_load`` reads back as the same value (``null`` for None)."""
    if x is None:
        return "null"
    if isinstance(x, bool):
        return "true" if x else "false"
    if isinstance(x, int):
        return str(x)
    x = float(x)
    if math.isnan(x):
        return ".nan"
    if math.isinf(x):
        return ".inf" if x > 0 else "-.inf"
    text = repr(x)
    if "e" in text:
        mant, exp = text.split("e")
        if "." not in mant:
            mant += ".0"
        if exp[0] not in "+-":
            exp = "+" + exp
        text = f"{mant}e{exp}"
    return text


def _scalar(x) -> str:
    return json.dumps(x) if isinstance(x, str) else yaml_number(x)


def _item(indent: str, key: str, value, comment: str = "") -> str:
    return f"{indent}{key}: {_scalar(value)}" + (f"  # {comment}" if comment else "")


def _se(se: dict, k: str) -> str:
    return f", se {se[k]:.3g}" if se.get(k) is not None else ""


def _line(model: FrictionModel, h: dict, indent: str) -> list[str]:
    """One line (harmonic) as a YAML mapping in a list."""
    tu, su = torque_unit(model), speed_unit(model)
    se = {k[:-3]: v for k, v in h.items() if k.endswith("_se")}
    units = {"frequency": f"cycles/{model.unit}", "amplitude": tu, "decay": "s/" + model.unit, "phase": "rad",
             "load_coefficient": f"1/{tu}"}
    out = []
    for k in ("label", "frequency", "amplitude", "law", "decay", "phase", "load_coefficient", "speed_range"):
        if k not in h and k not in ("law",):
            continue
        val = h.get(k, "exp") if k == "law" else h[k]
        if k == "decay" and (h.get("law") or "exp") == "power":
            units["decay"] = "- (exponent)"
        if k == "speed_range":
            out.append(f"{indent}speed_range: [{yaml_number(val[0])}, {yaml_number(val[1])}]  # |v| in {su} the "
                       f"amplitude law was fitted on; held at the edges outside")
        else:
            out.append(_item(indent, k, val, (units.get(k, "") + _se(se, k)).lstrip(", ")))
    return [indent[:-2] + "- " + out[0].lstrip()] + out[1:]


def write_yaml(model: FrictionModel, out: Path, *, source: str = "a FrictionModel", joint: str = "joint",
               **_) -> list[Path]:
    """Write ``out/friction_params.yaml``.

    Parameters
    ----------
    model : the (checked) model.
    out : folder, created when missing.
    source : the model file's name, quoted in the file.
    joint : the joint's name in the file (letters, digits, ``_ . / -``).

    Returns
    -------
    The path written.
    """
    from ..errors import InputError

    if not _JOINT.match(joint or ""):
        raise InputError(f"--joint '{joint}': a joint name is letters, digits and _ . / - (starting with a letter)")
    law = model.law_spec
    lines = [f"# friction model \"{model.name}\" exported by gearspec {__version__} from {source}",
             f"# law {model.law}: {law.description}",
             f"# SI: theta in {model.unit}, velocity in {speed_unit(model)}, torque in {torque_unit(model)}; the "
             f"friction has the sign of the velocity (the torque the drive must supply)",
             "joints:", f"  {joint}:", "    friction:",
             _item("      ", "law", model.law), _item("      ", "unit", model.unit),
             _item("      ", "model", model.name)]
    for dname, p in model.directions.items():
        lines.append(f"      {dname}:  # parameters for v {'>' if dname == 'positive' else '<'} 0")
        for k, u in zip(law.params, law.units):
            why = model.not_identified.get(f"{dname}.{k}")
            note = " (not identified)" if p.values[k] is None else ""
            lines.append(_item("        ", k, p.values[k], f"{axis_unit(u, model)}{_se(p.se, k)}{note}"
                               + (f"; {why}" if why and note else "")))
        hs = [h.to_dict() for h in p.harmonics if h.amplitude is not None]
        lines.append("        harmonics:" + ("" if hs else " []  # no position-locked line"))
        for h in hs:
            lines += _line(model, h, "            ")
    lines.append("      terms:" + ("" if model.terms else " []"))
    for t in model.terms:
        units = TERM_UNITS.get(t["kind"], {})
        items = [_item("          ", "kind", t["kind"], "signed: added as it is" if TERMS[t["kind"]].signed
                       else "added to the friction magnitude")]
        if t.get("direction"):
            items.append(_item("          ", "direction", int(t["direction"]), "only while moving this way"))
        se = {k[:-3]: v for k, v in t.items() if k.endswith("_se")}
        for k, val in t.items():
            if k in ("kind", "direction") or k.endswith("_se"):
                continue
            if k == "speed_range":
                items.append(f"          speed_range: [{_scalar(val[0])}, {_scalar(val[1])}]  # |v| the law was "
                             f"fitted on")
            else:
                unit = axis_unit(units.get(k, ""), model)
                items.append(_item("          ", k, val, (unit + _se(se, k)).lstrip(", ")))
        lines += ["        - " + items[0].lstrip()] + items[1:]
    out.mkdir(parents=True, exist_ok=True)
    path = out / "friction_params.yaml"
    path.write_text("\n".join(lines) + "\n")
    return [path]
