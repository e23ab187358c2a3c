"""A friction model as C99 (``gearspec_model.h``, ``gearspec_model.c``): ``<math.h>`` only, no
allocation, no global mutable state; the parameters are literals in the code, with units and standard
errors in comments.

Each contribution is the expression :meth:`FrictionModel.evaluate` computes, in the same order of
operations, so the double functions agree with Python to rounding.  The float functions compute in
float; a line's ``sin(2 pi f theta + phi)`` reduces ``f theta`` to a fraction of a cycle with the exact
rounding error of the product (``fmaf``), so a float angle far from 0 keeps its ripple's phase.
Laws and term kinds have one C form each here (:data:`C_LAWS`, :data:`C_TERMS`); one without refuses
the export (the tests compare every one with :meth:`FrictionModel.evaluate`).
"""

from __future__ import annotations

import math
import textwrap
from pathlib import Path

import numpy as np

from .. import __version__
from ..errors import InputError
from ..model import FrictionModel
from ..terms import AMPLITUDE_LAWS, TERMS
from .text import parameter_lines, slowest_line_speed, speed_unit

__all__ = ["write_c", "C_LAWS", "C_TERMS", "SMOOTHING"]

#: the smoothing of sign(v) below GEARSPEC_SMOOTH_VELOCITY, as the generated header states it
SMOOTHING = ("below |v| = GEARSPEC_SMOOTH_VELOCITY (> 0) the sign of the velocity is replaced by the ramp "
             "v / GEARSPEC_SMOOTH_VELOCITY: the friction falls linearly to 0 at v = 0, where "
             "FrictionModel.evaluate also gives 0 (sign(0) = 0); at and above it the functions are exact. "
             "0 (the default) keeps the exact sign")


class _Real:
    """How one C floating type is written: literals, functions (``exp`` or ``expf``)."""

    def __init__(self, double: bool):
        self.double = double
        self.t = "double" if double else "float"
        self.s = "" if double else "f"

    def lit(self, x) -> str:
        x = float(x)
        if not self.double:
            if abs(x) > float(np.finfo(np.float32).max):
                raise InputError(f"a parameter of the model, {x:g}, does not fit a float (the _f functions); "
                                 f"check the model's units")
            x = float(np.float32(x))
        text = repr(x) + self.s
        return f"({text})" if x < 0 else text

    def fn(self, name: str) -> str:
        return name + self.s


def _req(t: dict, key: str, where: str):
    if t.get(key) is None:
        raise InputError(f"{where} has no '{key}'; the export needs it")
    return t[key]


# ------------------------------------------------------------------ base laws: C expressions of the magnitude
def _law_none(r, p):
    return None


def _law_cv(r, p):
    if p["viscous"] is None:
        return r.lit(p["tau_c"])
    return f"{r.lit(p['tau_c'])} + {r.lit(p['viscous'])} * speed"


def _law_stribeck(r, p):
    visc = 0.0 if p["viscous"] is None else p["viscous"]
    if p["tau_s"] is None or p["v_s"] is None:     # Stribeck part not identified: Coulomb + viscous
        return f"{r.lit(p['tau_c'])} + {r.lit(visc)} * speed"
    return (f"{r.lit(p['tau_c'])} + {r.lit(p['tau_s'] - p['tau_c'])} * {r.fn('exp')}(-(speed / {r.lit(p['v_s'])}))"
            f" + {r.lit(visc)} * speed")


def _law_lola8(r, p):
    return (f"({r.lit(p['t_f0'])} + {r.lit(p['mu'])} * {r.fn('fabs')}(load)) + "
            f"({r.lit(p['b'])} + {r.lit(p['gamma'])} * {r.fn('fabs')}(load)) * speed")


def _law_lola11(r, p):
    base = f"{r.lit(p['t_f0'])} + {r.lit(p['mu'])} * {r.fn('fabs')}(load)"
    if p["t_fs"] is None or p["v_s"] is None:        # Stribeck part not identified: law (8) without gamma
        return f"({base}) + {r.lit(p['b'])} * speed"
    x = f"(speed / {r.lit(p['v_s'])})"
    return f"{base} + {r.lit(p['t_fs'] - p['t_f0'])} / ({r.lit(1.0)} + {x} * {x}) + {r.lit(p['b'])} * speed"


#: the C form of each base law's magnitude (``speed = |v|``, ``load``)
C_LAWS = {"none": _law_none, "coulomb_viscous": _law_cv, "stribeck": _law_stribeck, "silo4": _law_stribeck,
          "lola8": _law_lola8, "lola11": _law_lola11}


# ------------------------------------------------------------------ terms
def _sin(r, theta_var, f, phase):
    """``sin(2 pi f theta + phase)``: in double as Python computes it, in float reduced per cycle."""
    if r.double:
        return f"sin({r.lit(2.0 * math.pi * f)} * {theta_var} + {r.lit(phase)})"
    hi = np.float32(f)
    lo = np.float32(f - float(hi))
    return f"gs_sin_cycles_f({theta_var}, {r.lit(hi)}, {r.lit(lo)}, {r.lit(phase)})"


def _periodic(r, t, where):
    """``(A + k load^2) g(clamp(|v|)) sin(2 pi f theta + phi)``: a line of a direction or a periodic term."""
    law = t.get("law") or "exp"
    if law not in AMPLITUDE_LAWS:
        raise InputError(f"{where}: unknown amplitude law '{law}'")
    f, amp = _req(t, "frequency", where), _req(t, "amplitude", where)
    decay, phase, k = t.get("decay", 0.0) or 0.0, t.get("phase", 0.0) or 0.0, t.get("load_coefficient") or 0.0
    a = f"({r.lit(amp)} + {r.lit(k)} * load * load)" if k else r.lit(amp)
    rng = t.get("speed_range")
    sp = "speed"
    if rng:
        lo = 0.0 if rng[0] is None else float(rng[0])
        hi = "HUGE_VAL" + ("" if r.double else "F") if rng[1] is None else r.lit(rng[1])
        sp = f"{r.fn('gs_clamp')}(speed, {r.lit(lo)}, {hi})"
    if law == "const":
        g = ""
    elif law == "exp":
        g = f" * {r.fn('exp')}({r.lit(-decay)} * {sp})"
    elif law == "rational":
        g = f" * ({r.lit(1.0)} / ({r.lit(1.0)} + ({r.lit(decay)} * {sp}) * ({r.lit(decay)} * {sp})))"
    else:   # power
        g = f" * {r.fn('pow')}({r.lit(1.0)} + {sp}, {r.lit(-decay)})"
    return f"{a}{g} * {_sin(r, 'theta', f, phase)}"


def _stribeck_extra(r, t, where):
    shape = t.get("shape", "exp")
    x = f"(speed / {r.lit(_req(t, 'v_s', where))})"
    g = {"exp": f"{r.fn('exp')}(-{x})", "gauss": f"{r.fn('exp')}(-{x} * {x})",
         "rational": f"({r.lit(1.0)} / ({r.lit(1.0)} + {x} * {x}))"}.get(shape)
    if g is None:
        raise InputError(f"{where}: unknown Stribeck shape '{shape}' (exp, gauss, rational)")
    return f"{r.lit(_req(t, 'amplitude', where))} * {g}"


#: the C form of each term kind: ``(inputs it reads, expression)``; signed kinds are added as they are
C_TERMS = {
    "periodic": _periodic,
    "viscous_power": lambda r, t, w: f"{r.lit(_req(t, 'coefficient', w))} * {r.fn('pow')}(speed, "
                                     f"{r.lit(_req(t, 'exponent', w))})",
    "stribeck_extra": _stribeck_extra,
    "load_coulomb": lambda r, t, w: f"{r.lit(_req(t, 'mu', w))} * {r.fn('fabs')}(load)",
    "load_viscous": lambda r, t, w: f"{r.lit(_req(t, 'gamma', w))} * {r.fn('fabs')}(load) * speed",
    "temperature": lambda r, t, w: (f"{r.lit(_req(t, 'coefficient', w))} * (temperature - "
                                    f"{r.lit(t.get('reference', 0.0))})"),
    "inertia": lambda r, t, w: f"{r.lit(_req(t, 'inertia', w))} * acceleration",
    "offset": lambda r, t, w: r.lit(_req(t, "offset", w)),
    "cogging": lambda r, t, w: f"{r.lit(_req(t, 'amplitude', w))} * "
                               f"{_sin(r, 'theta', _req(t, 'frequency', w), t.get('phase', 0.0))}",
}


def _term_expr(r, t, i):
    kind = t["kind"]
    where = f"term {i + 1} ({kind})"
    if kind not in C_TERMS:
        raise InputError(f"{where}: the C exporter has no C form of the term kind '{kind}'")
    return C_TERMS[kind](r, t, where)


# ------------------------------------------------------------------ the file
def _magnitude(r, model, dname, d):
    """The C function of one direction's friction magnitude: base law, lines, magnitude terms."""
    law = model.law
    if law not in C_LAWS:
        raise InputError(f"law '{law}': the C exporter has no C form of it")
    p = model.directions[dname]
    lines = [f"static {r.t} gs_magnitude_{dname[:3]}{r.s}({r.t} theta, {r.t} speed, {r.t} load, {r.t} temperature)",
             "{", f"    {r.t} m = {r.lit(0.0)};", "    (void)theta; (void)speed; (void)load; (void)temperature;"]
    base = C_LAWS[law](r, p.values)
    if base is not None:
        lines += [f"    m += {base};   /* base law {law} */"]
    for i, h in enumerate(p.harmonics):
        if h.amplitude is None:
            continue
        lines += [f"    m += {_periodic(r, h.term(), f'line {i + 1}')};   /* line {h.label or i + 1} */"]
    for i, t in enumerate(model.terms):
        if not TERMS[t["kind"]].signed and int(t.get("direction") or 0) in (0, d):
            lines += [f"    m += {_term_expr(r, t, i)};   /* term {i + 1}: {t['kind']} */"]
    return lines + ["    return m;", "}", ""]


def _functions(r, model):
    """gearspec_friction(_f) and gearspec_torque(_f) in type ``r``."""
    s = r.s
    out = _magnitude(r, model, "positive", 1) + _magnitude(r, model, "negative", -1)
    f = "_f" if s else ""
    args = f"{r.t} theta, {r.t} velocity, {r.t} load, {r.t} temperature"
    out += [f"static {r.t} gs_friction{s}({args})",
            "{", f"    const {r.t} speed = {r.fn('fabs')}(velocity);",
            f"    if (velocity > {r.lit(0.0)})",
            f"        return gs_sign{s}(velocity) * gs_magnitude_pos{s}(theta, speed, load, temperature);",
            f"    if (velocity < {r.lit(0.0)})",
            f"        return gs_sign{s}(velocity) * gs_magnitude_neg{s}(theta, speed, load, temperature);",
            f"    return velocity == velocity ? {r.lit(0.0)} : velocity;   /* 0 at standstill, NaN stays NaN */",
            "}", "", f"{r.t} gearspec_friction{f}({args})", "{",
            f"    return gs_friction{s}(theta, velocity, load, temperature);", "}", ""]
    out += [f"{r.t} gearspec_torque{f}({r.t} theta, {r.t} velocity, {r.t} acceleration, "
            f"{r.t} load, {r.t} temperature)", "{",
            f"    {r.t} tau = gs_friction{s}(theta, velocity, load, temperature);",
            "    (void)acceleration;"]
    for i, t in enumerate(model.terms):
        if TERMS[t["kind"]].signed:
            d = int(t.get("direction") or 0)
            cond = "" if not d else f"if (velocity {'>' if d > 0 else '<'} {r.lit(0.0)}) "
            out += [f"    {cond}tau += {_term_expr(r, t, i)};   /* term {i + 1}: {t['kind']} */"]
    return out + ["    return tau;", "}", ""]


#: static helpers, each written only when the functions call it (no unused function under -Werror)
_HELPERS = {
    "gs_clamp(": """static double gs_clamp(double x, double lo, double hi)
{
    return x < lo ? lo : (x > hi ? hi : x);
}
""",
    "gs_clampf(": """static float gs_clampf(float x, float lo, float hi)
{
    return x < lo ? lo : (x > hi ? hi : x);
}
""",
    "gs_sin_cycles_f(": """/* sin(2 pi f theta + phase) in float, f = f_hi + f_lo: f theta reduced to a fraction of a
   cycle with the exact rounding error of the product (fmaf): a line keeps its phase far from 0 */
static float gs_sin_cycles_f(float theta, float f_hi, float f_lo, float phase)
{
    const float p = f_hi * theta;
    const float e = fmaf(f_hi, theta, -p);
    const float c = (p - floorf(p)) + (e + f_lo * theta);
    return sinf(6.28318530717958647692f * c + phase);
}
""",
    "gs_sign(": """/* sign(v) for v != 0, smoothed below GEARSPEC_SMOOTH_VELOCITY (see gearspec_model.h) */
static double gs_sign(double v)
{
    const double vs = GEARSPEC_SMOOTH_VELOCITY;
    if (vs > 0.0 && fabs(v) < vs)
        return v / vs;
    return v > 0.0 ? 1.0 : -1.0;
}
""",
    "gs_signf(": """static float gs_signf(float v)
{
    const float vs = (float)(GEARSPEC_SMOOTH_VELOCITY);
    if (vs > 0.0f && fabsf(v) < vs)
        return v / vs;
    return v > 0.0f ? 1.0f : -1.0f;
}
""",
}


def _header(model: FrictionModel, source: str, smooth: float) -> str:
    su = speed_unit(model)
    tu = "Nm" if model.unit == "rad" else "N"
    slow = slowest_line_speed(model)
    hint = (f" The slowest speed a line of this model was measured at is {slow:.4g} {su}; below it the model is "
            f"not backed by data." if slow is not None else "")
    params = "\n".join(" * " + y for x in parameter_lines(model) for y in _wrap(x, "   "))
    smoothing = "\n".join(" * " + y for y in _wrap(f"GEARSPEC_SMOOTH_VELOCITY ({su}; override with "
                                                   f"-DGEARSPEC_SMOOTH_VELOCITY=...): {SMOOTHING}.{hint}", ""))
    return f"""/* gearspec_model.h: friction model "{model.name}" (law {model.law}) exported by gearspec {__version__}
 * from {source}.
 *
 * gearspec_friction(theta, velocity, load, temperature): the friction torque the drive must supply, with
 * the sign of the velocity, {tu} (gearspec's FrictionModel.friction); theta in {model.unit}, velocity in {su},
 * load in Nm at the output, temperature in degC (inputs a model does not use are ignored).
 * gearspec_torque(theta, velocity, acceleration, load, temperature): the same plus the model's signed terms
 * (inertia x acceleration in {su}/s, offset, cogging): FrictionModel.evaluate.
 * The _f variants compute in float.  C99, <math.h> only (link with -lm), no allocation, no state.
 *
{smoothing}
 *
{params}
 */
#ifndef GEARSPEC_MODEL_H
#define GEARSPEC_MODEL_H

#ifndef GEARSPEC_SMOOTH_VELOCITY
#define GEARSPEC_SMOOTH_VELOCITY {float(smooth)!r}
#endif

#ifdef __cplusplus
extern "C" {{
#endif

double gearspec_friction(double theta, double velocity, double load, double temperature);
float gearspec_friction_f(float theta, float velocity, float load, float temperature);
double gearspec_torque(double theta, double velocity, double acceleration, double load, double temperature);
float gearspec_torque_f(float theta, float velocity, float acceleration, float load, float temperature);

#ifdef __cplusplus
}}
#endif

#endif /* GEARSPEC_MODEL_H */
"""


def _wrap(text: str, indent: str) -> list[str]:
    return textwrap.wrap(text, 100, subsequent_indent=indent, break_on_hyphens=False) or [""]


def write_c(model: FrictionModel, out: Path, *, source: str = "a FrictionModel", smooth_velocity: float = 0.0,
            **_) -> list[Path]:
    """Write ``out/gearspec_model.h`` and ``out/gearspec_model.c``.

    Parameters
    ----------
    model : the (checked) model.
    out : folder, created when missing.
    source : the model file's name, quoted in the files.
    smooth_velocity : default of ``GEARSPEC_SMOOTH_VELOCITY`` (rad/s or m/s, >= 0; 0: the exact sign).

    Returns
    -------
    The two paths.
    """
    if not (math.isfinite(smooth_velocity) and smooth_velocity >= 0):
        raise InputError(f"the smoothing velocity must be a number >= 0 (rad/s or m/s), got {smooth_velocity!r}")
    funcs = "\n".join(_functions(_Real(True), model) + _functions(_Real(False), model))
    helpers = [text for name, text in _HELPERS.items() if name in funcs]
    body = [f"/* gearspec_model.c: friction model \"{model.name}\" exported by gearspec {__version__} from "
            f"{source}; see gearspec_model.h */", "#include <math.h>", '#include "gearspec_model.h"', "",
            *helpers, funcs]
    out.mkdir(parents=True, exist_ok=True)
    h, c = out / "gearspec_model.h", out / "gearspec_model.c"
    h.write_text(_header(model, source, smooth_velocity))
    c.write_text("\n".join(body))
    return [h, c]
