"""The base friction laws, each declared once as a :class:`BaseLaw` in :data:`BASE_LAWS`.

:mod:`gearspec.laws`, ``gearspec.model.LAWS``, the joint fit (:func:`basis`) and the closed loop's
design are built from it.  Units are for a rotary axis (Nm, rad/s, Nm s/rad, s/rad, ``-``
dimensionless; N, m/s, ... on a linear one).  A magnitude takes ``speed = |v| >= 0``; the friction
torque is ``sign(v) * magnitude``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Mapping

import numpy as np

from ..errors import InputError
from .shapes import stribeck_shape, stribeck_term

__all__ = ["BaseLaw", "Nonlinear", "Degraded", "Basis", "BASE_LAWS", "fittable_laws", "LAW_LINEAR", "LiveView", "basis",
           "register_law"]


@dataclass(frozen=True)
class Nonlinear:
    """A nonlinear parameter of a law: ``bounds(lo, hi)`` and ``grid(lo, hi)`` are the range and
    start grid of the joint fit's search, given the lowest and highest plateau speeds (rad/s)."""

    name: str
    unit: str
    bounds: Callable
    grid: Callable


@dataclass(frozen=True)
class Degraded:
    """The form a law falls back to when some parameters are not identified: ``columns(speed,
    load) -> (n, len(linear))``; ``dropped``: parameters left out (None in a model); ``when``:
    ``"v_s"`` (Stribeck velocity not identified) or ``"speed"`` (quasi-static: no speed dependence)."""

    name: str
    linear: tuple[str, ...]
    columns: Callable
    dropped: tuple[str, ...]
    when: str


@dataclass(frozen=True)
class Basis:
    """A law (or degraded form) as ``columns(speed, load, *nonlin) @ lin``; ``nonneg``: linear
    parameters constrained to >= 0; ``search``: the :class:`Nonlinear` of each ``nonlin``."""

    lin: tuple[str, ...]
    nonlin: tuple[str, ...]
    columns: Callable
    nonneg: tuple[str, ...] = ()
    search: tuple[Nonlinear, ...] = ()


@dataclass(frozen=True)
class BaseLaw:
    """One base friction law: ``params`` in the model's order with their ``units``;
    ``magnitude(speed, load, *params)`` (an ``optional`` parameter given as None drops its part);
    ``magnitude == columns(speed, load, *nonlinear) @ linear``; ``nonneg``: linear parameters the
    papers constrain to >= 0 (Lola/CROPS eq. 10); ``paper``: its name in the papers."""

    name: str
    params: tuple[str, ...]
    units: tuple[str, ...]
    magnitude: Callable
    needs_load: bool = False
    description: str = ""
    paper: str = ""
    linear: tuple[str, ...] = ()
    nonlinear: tuple[Nonlinear, ...] = ()
    columns: Callable | None = None
    nonneg: tuple[str, ...] = ()
    degraded: tuple[Degraded, ...] = field(default=())

    @property
    def nonlinear_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.nonlinear)

    @property
    def optional(self) -> tuple[str, ...]:
        """Parameters that may be missing (not identified): those some degraded form drops."""
        dropped = {k for d in self.degraded for k in d.dropped}
        return tuple(k for k in self.params if k in dropped)

    def degraded_for(self, when: str) -> Degraded | None:
        """The degraded form used when ``when`` (``"v_s"`` or ``"speed"``) is not identified."""
        return next((d for d in self.degraded if d.when == when), None)

    def design(self, lin, nonlin: dict, speed, load) -> np.ndarray:
        """``(n, len(lin))`` columns of the linear parameters ``lin`` (the law's, a subset, or a
        degraded form's) at the nonlinear values ``nonlin`` (name -> value)."""
        lin = tuple(lin)
        nl = [nonlin.get(k) for k in self.nonlinear_names]
        full = all(x is not None for x in nl)
        if full and lin == self.linear:
            return self.columns(speed, load, *nl)
        for d in self.degraded:
            if d.linear == lin:
                return d.columns(speed, load)
        if full and set(lin) <= set(self.linear):
            return self.columns(speed, load, *nl)[:, [self.linear.index(k) for k in lin]]
        raise InputError(f"law {self.name} has no form linear in {', '.join(lin) or 'nothing'}")


# ---------------------------------------------------------------------- columns and magnitudes
def _none_cols(s, load):
    return np.zeros((len(s), 0))


def _level_cols(s, load):
    return np.ones((len(s), 1))


def _cv_cols(s, load):
    return np.column_stack([np.ones_like(s), s])


def _cv_mag(speed, load, tau_c, viscous):
    return tau_c + (0.0 if viscous is None else viscous) * speed


def _stribeck_cols(s, load, v_s):
    e = stribeck_shape("exp", s, v_s)
    return np.column_stack([1.0 - e, e, s])


def _stribeck_mag(speed, load, tau_c, tau_s, v_s, viscous):
    speed = np.asarray(speed, dtype=float)
    if viscous is None:  # not identified (a quasi-static map): the viscous part is left out
        viscous = 0.0
    if tau_s is None or v_s is None:  # Stribeck part not identified: Coulomb + viscous
        return tau_c + viscous * speed
    return tau_c + stribeck_term("exp", tau_s - tau_c, speed, v_s) + viscous * speed


def _lola8_cols(s, load):
    tl = np.abs(load)
    return np.column_stack([np.ones_like(s), tl, s, tl * s])


def _lola8_nogamma_cols(s, load):
    return np.column_stack([np.ones_like(s), np.abs(load), s])


def _lola8_mag(speed, load, t_f0, mu, b, gamma):
    tl = np.abs(np.asarray(load, dtype=float))
    return (t_f0 + mu * tl) + (b + gamma * tl) * np.asarray(speed, dtype=float)


def _lola11_cols(s, load, v_s):
    r = stribeck_shape("rational", s, v_s)
    return np.column_stack([1.0 - r, np.abs(load), s, r])


def _lola11_mag(speed, load, t_f0, mu, b, t_fs, v_s):
    if t_fs is None or v_s is None:  # Stribeck part not identified
        return _lola8_mag(speed, load, t_f0, mu, b, 0.0)
    speed = np.asarray(speed, dtype=float)
    tl = np.abs(np.asarray(load, dtype=float))
    return t_f0 + mu * tl + stribeck_term("rational", t_fs - t_f0, speed, v_s) + b * speed


def _vs_bounds(lo, hi):
    """A Stribeck velocity far outside the plateau speeds is not identifiable (the term is then a
    constant or a straight line; below lo/10 it has fallen by e^10 before the slowest plateau and
    its height is pure extrapolation)."""
    return lo / 10, 2 * hi


_V_S = Nonlinear("v_s", "rad/s", _vs_bounds, lambda lo, hi: np.geomspace(lo / 10, hi * 2, 25))
_LEVEL = Degraded("level", ("tau_c",), _level_cols, ("tau_s", "v_s", "viscous"), "speed")
_CV = Degraded("coulomb_viscous", ("tau_c", "viscous"), _cv_cols, ("tau_s", "v_s"), "v_s")
_STRIBECK = dict(params=("tau_c", "tau_s", "v_s", "viscous"), units=("Nm", "Nm", "rad/s", "Nm s/rad"),
                 magnitude=_stribeck_mag, linear=("tau_c", "tau_s", "viscous"), nonlinear=(_V_S,),
                 columns=_stribeck_cols, degraded=(_CV, _LEVEL))

#: every base law by name; ``silo4`` is eq. 3 plus the harmonics of eq. 11
BASE_LAWS: dict[str, BaseLaw] = {}


def register_law(law: BaseLaw) -> BaseLaw:
    """Add ``law`` to :data:`BASE_LAWS` (``tests/test_registry.py`` checks magnitude == columns @ linear)."""
    BASE_LAWS[law.name] = law
    return law


for _law in (
    BaseLaw("none", (), (), lambda speed, load: np.zeros_like(speed), description="no base friction",
            columns=_none_cols, degraded=(Degraded("none", (), _none_cols, (), "speed"),)),
    BaseLaw("coulomb_viscous", ("tau_c", "viscous"), ("Nm", "Nm s/rad"), _cv_mag,
            description="Coulomb + viscous: tau_c + B|v|", paper="SILO4 eq. 3 without its Stribeck term",
            linear=("tau_c", "viscous"), columns=_cv_cols,
            degraded=(Degraded("level", ("tau_c",), _level_cols, ("viscous",), "speed"),)),
    BaseLaw("stribeck", description="SILO4 eq. 3: tau_c + (tau_s - tau_c) exp(-|v|/v_s) + B|v|",
            paper="SILO4 eq. 3 (tau_E static, tau_C Coulomb, v_s, B)", **_STRIBECK),
    BaseLaw("silo4", description="SILO4 eq. 11: eq. 3 + position ripple + meshing ripple decaying as exp(-b|v|)",
            paper="SILO4 eq. 11 (its base part: eq. 3)", **_STRIBECK),
    BaseLaw("lola8", ("t_f0", "mu", "b", "gamma"), ("Nm", "-", "Nm s/rad", "s/rad"), _lola8_mag, True,
            "Lola/CROPS law (8): T_f0 + mu|T_l| + (b + gamma|T_l|)|v|", paper="Lola/CROPS eq. (8)",
            linear=("t_f0", "mu", "b", "gamma"), columns=_lola8_cols, nonneg=("t_f0", "mu", "b")),
    BaseLaw("lola11", ("t_f0", "mu", "b", "t_fs", "v_s"), ("Nm", "-", "Nm s/rad", "Nm", "rad/s"), _lola11_mag, True,
            "Lola/CROPS law (11), Stribeck term made odd: T_f0 + mu|T_l| + (T_fS - T_f0)/(1+(v/v_S)^2) + b|v|",
            paper="Lola/CROPS eq. (11) (barred T_f0, mu, b; T_fS, v_S)", linear=("t_f0", "mu", "b", "t_fs"),
            nonlinear=(_V_S,), columns=_lola11_cols, nonneg=("t_f0", "mu", "b", "t_fs"),
            degraded=(Degraded("lola8_nogamma", ("t_f0", "mu", "b"), _lola8_nogamma_cols, ("t_fs", "v_s"), "v_s"),)),
):
    register_law(_law)


def fittable_laws() -> tuple[str, ...]:
    """The laws a fit can identify: every registered base law with parameters, in registry order."""
    return tuple(name for name, law in BASE_LAWS.items() if law.params)


def basis(name: str) -> Basis:
    """The linear basis of a law or of a degraded form (``level``, ``lola8_nogamma``, ...) by name."""
    if name in BASE_LAWS:
        law = BASE_LAWS[name]
        return Basis(law.linear, law.nonlinear_names, law.columns, search=law.nonlinear)
    for law in BASE_LAWS.values():
        for d in law.degraded:
            if d.name == name:
                return Basis(d.linear, (), d.columns)
    raise InputError(f"unknown friction law '{name}' (known: {', '.join(BASE_LAWS)})")


class LiveView(Mapping):
    """Read-only ``key -> value(source[key])`` computed at each access (later registrations show);
    keys whose value is None are left out."""

    def __init__(self, source: Mapping, value: Callable):
        self._source, self._value = source, value

    def __getitem__(self, key):
        out = self._value(self._source[key])
        if out is None:
            raise KeyError(key)
        return out

    def __iter__(self):
        return (k for k, x in list(self._source.items()) if self._value(x) is not None)

    def __len__(self):
        return sum(1 for _ in self)


#: ``(linear, nonlinear)`` parameters of every base law
LAW_LINEAR: Mapping[str, tuple] = LiveView(BASE_LAWS, lambda law: (law.linear, law.nonlinear_names))
