"""Additive friction terms beyond a base law, each kind declared once in :data:`TERMS`.

A term is a JSON-able dict ``{"kind": KIND, ...parameters...}`` that a
:class:`~gearspec.model.FrictionModel` adds to its base law; its kind's function gets the model
inputs as keyword arrays (``theta``, ``v``, ``load``, ``temperature``, ``t``, ``acc``, ``run``;
absent ones None) and returns a friction *magnitude* contribution (times sign(v) with the rest) or
a *signed* one (inertia, offset).  ``"direction": 1`` or ``-1`` limits a term to that direction of
motion.  Units: SI (rad, rad/s, Nm, degC, s).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Mapping

import numpy as np

from ..errors import InputError
from .registry import LiveView
from .lines import Lines
from .shapes import sinusoid, stribeck_shape

__all__ = ["TERMS", "TermKind", "register_term", "evaluate_term", "term_names", "TERM_LINEAR"]


@dataclass(frozen=True)
class TermKind:
    """How one kind of term is evaluated: ``signed`` (added to the drive torque as is, else to the
    friction magnitude); ``needs``: inputs it cannot do without; ``params`` (each may have
    ``<name>_se``); ``describe(term)``: one readable line; ``linear``: the parameter the closed loop
    refits by least squares (``"trig"``: amplitude and phase as a sin/cos pair; None: not refitted).
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
    """``(contribution, signed)`` of one term; InputError when an input it needs is missing."""
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
    """``(A + k load^2) g(|v|) sin(2 pi f theta + phi)``: SILO4 eqs. 6, 8 and 14, ``g`` the amplitude
    law ``law`` (exp by default).  With ``speed_range`` ``[min, max]`` (the speeds the law was
    fitted on) ``g`` is held at the range's edges: never extrapolated (older models lack it).
    Evaluated as one :class:`.lines.Lines`, as the model evaluates its harmonics."""
    theta, v = np.broadcast_arrays(np.asarray(theta, dtype=float), np.asarray(v, dtype=float))
    flat = None if load is None else np.broadcast_to(np.asarray(load, dtype=float), v.shape).reshape(-1)
    return Lines([term])(theta.reshape(-1), np.abs(v).reshape(-1), flat)[0].reshape(v.shape)


# ---------------------------------------------------------------------- speed laws
@register_term("viscous_power", params=("coefficient", "exponent"), linear="coefficient",
               describe=lambda t: f"nonlinear viscous {t['coefficient']:.4g} |v|^{t['exponent']:.3g}")
def _viscous_power(term, *, v, **_):
    """Nonlinear viscous friction ``c |v|^p`` (magnitude)."""
    return term["coefficient"] * np.abs(np.asarray(v, dtype=float)) ** term["exponent"]


@register_term("stribeck_extra", params=("amplitude", "v_s", "shape"), linear="amplitude",
               describe=lambda t: f"extra Stribeck dip {t['amplitude']:.4g} at v_s {t['v_s']:.4g} ({t.get('shape', 'exp')})")
def _stribeck_extra(term, *, v, **_):
    """An additional Stribeck-like term ``A g(|v|/v_s)``, ``shape`` as :func:`.shapes.stribeck_term`."""
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
    """Presliding: after a reversal friction builds up over a distance ``length`` (Dahl-like):
    ``-scale * exp(-d / length)`` with ``d`` the travel since the last reversal in the run
    (:func:`_travel_since_reversal`; nothing before the first), ``scale`` in torque units.
    ``travel``, when given, is that travel measured elsewhere (e.g. on the whole recording)."""
    d = _travel(theta, v, run, travel)
    out = np.zeros(len(d))
    has = np.isfinite(d)
    out[has] = -term["scale"] * np.exp(-d[has] / term["length"])
    return out


# ---------------------------------------------------------------------- added for the twins' effects
@register_term("cogging", signed=True, needs=("theta",), params=("frequency", "amplitude", "phase"), linear="trig",
               describe=lambda t: (f"cogging (same sign both ways) at {t['frequency']:.6g} cycles/unit: "
                                   f"{t['amplitude']:.4g}"))
def _cogging(term, *, theta, v, **_):
    """A conservative position-locked torque ``A sin(2 pi f theta + phi)``, signed: cogging, an
    unbalanced shaft or a spring does not reverse with the motion (in the friction magnitude it
    shows with phase ``phi`` forwards and ``phi + pi`` backwards)."""
    return term["amplitude"] * sinusoid(theta, term["frequency"], term.get("phase", 0.0))


def _travel_since_reversal(theta, v, run=None) -> np.ndarray:
    """Travel since the last reversal per sample (inf before a run's first): a reversal is a sample
    whose sign of v differs from the last nonzero sign before it in the run; the turning point is
    the sample before it."""
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
    return _travel_since_reversal(theta, v, run) if travel is None else np.asarray(travel, dtype=float)


@register_term("backlash", needs=("theta",), params=("scale", "gap"), linear="scale",
               describe=lambda t: f"backlash: {t['scale']:.4g} less friction over {t['gap']:.4g} after a reversal")
def _backlash(term, *, theta, v, run=None, travel=None, **_):
    """Backlash seen from the motor: for a travel ``gap`` after each reversal the teeth are apart
    and the friction behind them (``scale``, torque units) is missing: ``-scale`` while the travel
    (as for ``hysteresis``) is below ``gap``, else 0."""
    d = _travel(theta, v, run, travel)
    return np.where(d < term["gap"], -float(term["scale"]), 0.0)
