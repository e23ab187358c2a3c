"""Additive friction terms beyond a base law: the effects a model can be extended with.

A *term* is a plain JSON-able dict ``{"kind": KIND, ...parameters...}`` that a
:class:`~gearspec.model.FrictionModel` adds to its base law.  Each kind has one evaluation function
here, registered in :data:`TERMS`, so that a model read back from JSON evaluates identically
without knowing which module created the term.

Every function receives the model inputs as keyword arrays (``theta``, ``v``, ``load``,
``temperature``, ``t``, ``acc``, ``run``; absent ones are None) plus the term's dict, and returns
either a *magnitude* contribution (added to the friction magnitude, multiplied by sign(v) with the
rest: friction terms) or a *signed* contribution (added to the drive torque as it is: inertia,
offset).  Which one is declared with the kind.

Terms may hold per-direction parameters: a term with ``"direction": 1`` or ``-1`` acts only while
the drive moves that way; without it (or ``0``) it acts in both.

Units: SI, as everywhere (rad, rad/s, Nm, degC, s).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Mapping

import numpy as np

from ..errors import InputError
from .registry import LiveView
from .shapes import amplitude_law, clamp_speed, load_amplitude, sinusoid, stribeck_shape

__all__ = ["TERMS", "TermKind", "register_term", "evaluate_term", "term_names", "TERM_LINEAR"]


@dataclass(frozen=True)
class TermKind:
    """How one kind of term is evaluated.

    ``signed``: the contribution is added to the drive torque as is (True) or to the friction
    magnitude (False).  ``needs``: the inputs it cannot do without.  ``params``: its parameters
    (each may have ``<name>_se``).  ``describe(term)`` gives one readable line.  ``linear``: the
    parameter the term is linear in (the closed loop fits it by least squares with the others
    fixed; ``"trig"``: amplitude and phase as a sin/cos pair; None: the loop does not refit it).
    """

    kind: str
    func: Callable
    signed: bool
    needs: tuple[str, ...]
    params: tuple[str, ...]
    describe: Callable
    linear: str | None = None


#: every known kind of term, by name
TERMS: dict[str, TermKind] = {}


def register_term(kind: str, *, signed: bool = False, needs=(), params=(), describe=None, linear=None):
    """Decorator: register ``func(term, **inputs) -> array`` as the evaluation of ``kind``
    (``linear``: see :class:`TermKind`)."""

    def deco(func):
        TERMS[kind] = TermKind(kind, func, signed, tuple(needs), tuple(params),
                               describe or (lambda t: f"{kind}: " + ", ".join(f"{p}={t.get(p, 0):.4g}" for p in params)),
                               linear)
        return func

    return deco


#: linear parameter of every term kind the closed loop fits (``"trig"``: amplitude and phase)
TERM_LINEAR: Mapping[str, str] = LiveView(TERMS, lambda tk: tk.linear)


def term_names() -> list[str]:
    return sorted(TERMS)


def evaluate_term(term: dict, **inputs) -> tuple[np.ndarray, bool]:
    """Evaluate one term; returns ``(contribution, signed)``.  Raises InputError when an input
    the term needs is missing (e.g. a load term on a recording without ``load``)."""
    kind = term.get("kind")
    if kind not in TERMS:
        raise InputError(f"unknown friction term kind '{kind}' (known: {', '.join(term_names())})")
    tk = TERMS[kind]
    for name in tk.needs:
        if inputs.get(name) is None:
            raise InputError(f"the model's '{kind}' term needs the '{name}' channel, which the data does not have")
    v = np.asarray(inputs["v"], dtype=float)
    out = np.asarray(tk.func(term, **inputs), dtype=float)
    out = np.broadcast_to(out, v.shape).astype(float, copy=True)
    d = int(term.get("direction", 0) or 0)
    if d:
        out[np.sign(v) != d] = 0.0
    return out, tk.signed


# ---------------------------------------------------------------------- position-locked
@register_term("periodic", needs=("theta",), params=("frequency", "amplitude", "decay", "phase", "load_coefficient"),
               linear="trig",
               describe=lambda t: (f"periodic {t.get('label') or 'unlabelled'} at {t['frequency']:.6g} cycles/unit: "
                                   f"{t['amplitude']:.4g} x {t.get('law', 'exp')}(decay {t.get('decay', 0):.4g})"))
def _periodic(term, *, theta, v, load=None, **_):
    """``(A + k load^2) g(|v|) sin(2 pi f theta + phi)``: SILO4 eqs. 6, 8 and 14 with ``g`` the
    amplitude law (``law``: exp (default), const, rational, power).

    ``speed_range``: ``[min, max]`` of the speeds the amplitude law was fitted on; outside it the
    amplitude is held at the range's edge (``g(clip(|v|, min, max))``): a law is never
    extrapolated past the speeds that measured it.  Without ``speed_range`` (models written
    before it existed) the law is evaluated at every speed as written."""
    speed = clamp_speed(np.abs(np.asarray(v, dtype=float)), term.get("speed_range"))
    amp = term["amplitude"]
    k = term.get("load_coefficient", 0.0)
    if k:
        if load is None:
            raise InputError("a periodic term with a load coefficient (SILO4 eq. 14) needs the 'load' channel")
        amp = load_amplitude(load, amp, k)
    g = amplitude_law(term.get("law", "exp"), speed, term.get("decay", 0.0))
    return amp * g * sinusoid(theta, term["frequency"], term.get("phase", 0.0))


# ---------------------------------------------------------------------- speed laws
@register_term("viscous_power", params=("coefficient", "exponent"), linear="coefficient",
               describe=lambda t: f"nonlinear viscous {t['coefficient']:.4g} |v|^{t['exponent']:.3g}")
def _viscous_power(term, *, v, **_):
    """Nonlinear viscous friction ``c |v|^p`` (magnitude)."""
    return term["coefficient"] * np.abs(np.asarray(v, dtype=float)) ** term["exponent"]


@register_term("stribeck_extra", params=("amplitude", "v_s", "shape"), linear="amplitude",
               describe=lambda t: f"extra Stribeck dip {t['amplitude']:.4g} at v_s {t['v_s']:.4g} ({t.get('shape', 'exp')})")
def _stribeck_extra(term, *, v, **_):
    """An additional Stribeck-like term ``A g(|v|/v_s)`` with g exp (exp(-x)), gauss (exp(-x^2)) or
    rational (1/(1+x^2), Lola's law (11))."""
    speed = np.abs(np.asarray(v, dtype=float))
    return term["amplitude"] * stribeck_shape(term.get("shape", "exp"), speed, term["v_s"])


# ---------------------------------------------------------------------- load, temperature, time
@register_term("load_coulomb", needs=("load",), params=("mu",), linear="mu",
               describe=lambda t: f"load-dependent Coulomb {t['mu']:.4g} |load|")
def _load_coulomb(term, *, v, load, **_):
    """Coulomb friction growing with the output load, ``mu |T_l|`` (Lola law (8))."""
    return term["mu"] * np.abs(np.asarray(load, dtype=float))


@register_term("load_viscous", needs=("load",), params=("gamma",), linear="gamma",
               describe=lambda t: f"load-speed coupling {t['gamma']:.4g} |load| |v|")
def _load_viscous(term, *, v, load, **_):
    """Coupled load-speed friction ``gamma |T_l| |v|`` (Lola law (8))."""
    return term["gamma"] * np.abs(np.asarray(load, dtype=float)) * np.abs(np.asarray(v, dtype=float))


@register_term("temperature", needs=("temperature",), params=("coefficient", "reference"), linear="coefficient",
               describe=lambda t: f"temperature {t['coefficient']:.4g} per degC from {t.get('reference', 0):.3g} degC")
def _temperature(term, *, v, temperature, **_):
    """Friction changing linearly with temperature, ``c (T - T_ref)`` (magnitude)."""
    return term["coefficient"] * (np.asarray(temperature, dtype=float) - term.get("reference", 0.0))


@register_term("drift", needs=("t",), params=("coefficient", "reference"), linear="coefficient",
               describe=lambda t: f"slow drift {t['coefficient']:.4g} per s")
def _drift(term, *, v, t, **_):
    """Slow linear change of the friction level with time, ``c (t - t_ref)`` (magnitude)."""
    return term["coefficient"] * (np.asarray(t, dtype=float) - term.get("reference", 0.0))


# ---------------------------------------------------------------------- signed terms
@register_term("inertia", signed=True, needs=("acc",), params=("inertia",), linear="inertia",
               describe=lambda t: f"inertia {t['inertia']:.4g} x acceleration")
def _inertia(term, *, v, acc, **_):
    """Inertia torque ``J thetadd`` (signed; not friction, but part of the drive torque)."""
    return term["inertia"] * np.asarray(acc, dtype=float)


@register_term("offset", signed=True, params=("offset",), linear="offset",
               describe=lambda t: f"offset {t['offset']:.4g}")
def _offset(term, *, v, **_):
    """A constant torque independent of the motion (gravity, a sensor offset)."""
    return np.full(np.shape(v), float(term["offset"]))


# ---------------------------------------------------------------------- hysteresis
@register_term("hysteresis", needs=("theta",), params=("scale", "length"), linear="scale",
               describe=lambda t: f"presliding over {t['length']:.4g} after a reversal (depth {t['scale']:.3g})")
def _hysteresis(term, *, theta, v, run=None, travel=None, **_):
    """Presliding near reversals: just after the motion reverses, friction builds up over a
    distance ``length`` instead of jumping (a Dahl-like exponential approach).

    Contribution to the magnitude: ``-scale * exp(-|theta - theta_rev| / length)``, where
    ``theta_rev`` is the position of the last reversal in the same run (none before the first one
    in a run).  ``scale`` is in torque units (the friction level it removes at the reversal).
    Evaluated on ordered samples, with the reversal rule of :func:`_travel_since_reversal`;
    ``travel`` (unit of theta, ``inf`` before the first reversal), when given, is the travel
    since the last reversal measured elsewhere (e.g. on the whole recording), used instead.
    """
    d = _travel(theta, v, run, travel)
    out = np.zeros(len(d))
    has = np.isfinite(d)
    out[has] = -term["scale"] * np.exp(-d[has] / term["length"])
    return out


# ---------------------------------------------------------------------- kinds added for the twins' effects
# (gearspec.simulate.effects injects them into a truth model; any model may use them)
@register_term("cogging", signed=True, needs=("theta",), params=("frequency", "amplitude", "phase"), linear="trig",
               describe=lambda t: (f"cogging (same sign both ways) at {t['frequency']:.6g} cycles/unit: "
                                   f"{t['amplitude']:.4g}"))
def _cogging(term, *, theta, v, **_):
    """A conservative position-locked torque ``A sin(2 pi f theta + phi)`` (signed).

    Motor cogging (detent torque of the magnets, commutation of a brushed motor), an unbalanced
    shaft or a spring: unlike friction it does not reverse with the motion, so it is added to the
    drive torque as it is (not multiplied by sign(v)).  In the friction magnitude that the
    spectrum analyses (``direction * torque``) it shows at ``f`` with phases ``phi`` forwards and
    ``phi + pi`` backwards.
    """
    return term["amplitude"] * sinusoid(theta, term["frequency"], term.get("phase", 0.0))


def _travel_since_reversal(theta, v, run=None) -> np.ndarray:
    """Distance travelled since the last reversal of the motion, per sample (inf before the first
    reversal of a run): a reversal is a sample whose sign of v differs from the last nonzero sign
    before it in the same run, and the turning point is the sample before it (``hysteresis`` and
    ``backlash`` terms)."""
    theta = np.asarray(theta, dtype=float)
    s = np.sign(np.asarray(v, dtype=float))
    n = len(theta)
    idx = np.arange(n)
    nz = s != 0
    last = np.maximum.accumulate(np.where(nz, idx, -1))
    prev_sign = np.where(last >= 0, s[np.maximum(last, 0)], 0)
    ps = np.concatenate(([0.0], prev_sign[:-1]))
    rev = np.zeros(n, bool)
    rev[1:] = nz[1:] & (ps[1:] != 0) & (s[1:] != ps[1:])
    start = np.zeros(n, bool)
    if n:
        start[0] = True
    if run is not None:
        r = np.asarray(run)
        rev[1:] &= r[1:] == r[:-1]
        start[1:] = r[1:] != r[:-1]
    mark = np.where(rev, idx - 1, np.where(start, -1, -2))
    last_rev = np.full(n, -1)
    events = np.flatnonzero(mark != -2)
    if len(events):
        last_rev[events[0]:] = np.repeat(mark[events], np.diff(np.concatenate((events, [n]))))
    out = np.full(n, np.inf)
    has = last_rev >= 0
    out[has] = np.abs(theta[has] - theta[last_rev[has]])
    return out


def _travel(theta, v, run=None, travel=None) -> np.ndarray:
    """``travel`` as given (float array), or :func:`_travel_since_reversal` of the samples."""
    return _travel_since_reversal(theta, v, run) if travel is None else np.asarray(travel, dtype=float)


@register_term("backlash", needs=("theta",), params=("scale", "gap"), linear="scale",
               describe=lambda t: f"backlash: {t['scale']:.4g} less friction over {t['gap']:.4g} after a reversal")
def _backlash(term, *, theta, v, run=None, travel=None, **_):
    """Backlash seen from the motor: for a travel ``gap`` after every reversal of the motion the
    teeth are not in contact, so the friction of everything behind the gap (``scale``, torque
    units) is missing; then it is back at once.  Contribution to the magnitude: ``-scale`` while
    ``|theta - theta_turn| < gap``, 0 otherwise (nothing before the first reversal of a run).
    Evaluated on ordered samples, with the reversal rule of ``hysteresis`` (or on ``travel``,
    when given, as ``hysteresis``).
    """
    d = _travel(theta, v, run, travel)
    return np.where(d < term["gap"], -float(term["scale"]), 0.0)
