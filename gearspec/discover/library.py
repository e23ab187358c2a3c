"""The candidate library: physically meaningful friction terms, each printed as its equation.

A library is a list of :class:`Term` (as in pysindy, library and optimiser are separate objects):
a *family* (:data:`FAMILIES`), the value of its nonlinear parameter on a grid, a ripple frequency
where it has one, and a *variant*: ``sym``, the friction form ``sign(v) m(|v|)``; ``asym``, the
even form ``m(|v|)``, which added to ``sym`` makes the magnitude direction-dependent (``m_i =
(c_sym + i c_asym) m`` in direction ``i`` = +1/-1, so sparsity in the asym columns *is* the
question "does this term depend on the direction?"; the asym Coulomb column is also an offset
such as gravity); ``signed``, a torque that does not reverse with the motion (inertia).  Ripple
terms have a sin and a cos column.  Every column is ``multiplier(speed_s, direction_s) *
basis_k(sample)`` (:mod:`.moments`).  Units SI; names print the numbers in them, e.g.
``sign(v)*exp(-|v|/2.95)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import Callable

import numpy as np

from ..core.reduction import harmonic_columns
from ..errors import InputError
from ..terms.shapes import amplitude_law, stribeck_shape
from .moments import Moments

__all__ = ["Family", "FAMILIES", "Term", "Library", "default_library"]


def _g(x: float, digits: int = 4) -> str:
    return f"{x:.{digits}g}"


@dataclass(frozen=True)
class Family:
    """A family of terms: magnitude ``m(speed, p)``, the sample basis it multiplies, how it prints
    and what it becomes in a :class:`~gearspec.model.FrictionModel`.

    ``factor``: the readable factor, ``{p}`` standing for the nonlinear parameter (a ripple
    family's: the amplitude law's, the sinusoid follows), printed with ``digits`` significant
    digits in column names; ``param``: name of the nonlinear parameter (None: none), with
    ``bounds(lo_speed, hi_speed)`` for its refinement; ``group``: the slot of mutually exclusive
    shapes it belongs to (default: its own).  ``term``: what a fitted term becomes in a model --
    ``"base"`` (the parameter ``coef`` of the base law coulomb_viscous), ``"harmonic"`` (a harmonic
    with amplitude law ``shape``) or a term kind of :mod:`gearspec.terms` (its coefficient ``coef``,
    its parameter under the name ``param``, its Stribeck ``shape`` if it has one).
    """

    name: str
    basis: str                         # "1", "load", "temperature", "acc" or "ripple"
    magnitude: Callable
    factor: str
    param: str | None = None
    bounds: Callable | None = None
    group: str = ""
    description: str = ""
    refine: bool = True                # the parameter is refined by nonlinear least squares
    term: str = ""
    coef: str = ""
    shape: str | None = None
    digits: int = 4

    @property
    def slot(self) -> str:
        """The slot of equivalent shapes (one of them is enough in a law)."""
        return self.group or self.name


def _VS_BOUNDS(lo, hi):
    """Stribeck velocities the plateaus can identify: below lo/5 the term has vanished at every
    plateau, above hi/2 it is a straight line over the measured speeds (and the refinement would
    trade it against Coulomb and viscous friction with huge cancelling coefficients)."""
    return (lo / 5, hi / 2)


def _DECAY_BOUNDS(lo, hi):
    """Decay constants from a 5 % fall over the speed range to a fall by e^-20."""
    return (0.05 / hi, 20.0 / hi)


def _ones(u, p):
    return np.ones_like(u)


def _linear(u, p):
    return u


def _stribeck(shape: str, factor: str, description: str) -> Family:
    return Family(f"stribeck_{shape}", "1", partial(stribeck_shape, shape), factor, "v_s", _VS_BOUNDS, "stribeck",
                  description, term="stribeck_extra", coef="amplitude", shape=shape)


def _ripple(law: str, factor: str, description: str) -> Family:
    decays = law != "const"
    return Family(f"ripple_{law}", "ripple", partial(amplitude_law, law), factor, "decay" if decays else None,
                  _DECAY_BOUNDS if decays else None, "ripple", description, term="harmonic", shape=law)


FAMILIES: dict[str, Family] = {f.name: f for f in [
    Family("coulomb", "1", _ones, "1", description="Coulomb friction", term="base", coef="tau_c"),
    Family("viscous", "1", _linear, "|v|", description="viscous friction", term="base", coef="viscous"),
    # exponents stay at their grid values: a free exponent mimics Coulomb (p -> 0) or viscous (p -> 1)
    # friction and turns every law into a power law
    Family("power", "1", lambda u, p: u ** p, "|v|^{p}", "exponent", lambda lo, hi: (0.05, 4.0),
           description="power law |v|^p (sqrt: p = 0.5, |v|v: p = 2)", refine=False, term="viscous_power",
           coef="coefficient", digits=3),
    _stribeck("exp", "exp(-|v|/{p})", "Stribeck, exponential (SILO4 eq. 3)"),
    _stribeck("gauss", "exp(-(|v|/{p})^2)", "Stribeck, Gaussian"),
    _stribeck("rational", "1/(1+(|v|/{p})^2)", "Stribeck, rational (Lola law (11))"),
    Family("load_coulomb", "load", _ones, "|T_l|", description="load-dependent Coulomb (Lola law (8))",
           term="load_coulomb", coef="mu"),
    Family("load_viscous", "load", _linear, "|T_l|*|v|", description="load-speed coupling (Lola law (8))",
           term="load_viscous", coef="gamma"),
    Family("temperature", "temperature", _ones, "(T-T_ref)", description="friction level changing with temperature",
           term="temperature", coef="coefficient"),
    Family("inertia", "acc", _ones, "a", description="residual inertia (acceleration; not friction)", term="inertia",
           coef="inertia"),
    _ripple("const", "", "position ripple of constant amplitude (SILO4 eq. 6)"),
    _ripple("exp", "exp(-{p}*|v|)", "meshing ripple decaying exponentially with speed (SILO4 eq. 8)"),
    _ripple("rational", "1/(1+({p}*|v|)^2)", "ripple decaying as a Lorentzian of speed"),
]}


@dataclass(frozen=True)
class Term:
    """One entry of the library: family, nonlinear parameter (grid value), ripple frequency index,
    variant (``sym``, ``asym`` or ``signed``)."""

    family: str
    param: float | None = None
    freq: int | None = None
    variant: str = "sym"

    @property
    def fam(self) -> Family:
        return FAMILIES[self.family]

    @property
    def key(self) -> tuple:
        """The term without its variant (what direction dependence is a property of)."""
        return (self.family, self.param, self.freq)

    def parts(self) -> tuple[str, ...]:
        return ("sin", "cos") if self.fam.basis == "ripple" else ("",)

    def basis_names(self) -> list[str]:
        if self.fam.basis == "ripple":
            return [f"sin{self.freq}", f"cos{self.freq}"]
        return [self.fam.basis]

    def names(self, frequencies, t_ref=None) -> list[str]:
        """The columns' equations."""
        fac = self.fam.factor.format(p=None if self.param is None else _g(self.param, self.fam.digits))
        if self.fam.basis == "ripple":
            s = f"sin(2pi*{_g(float(frequencies[self.freq]), 6)}*theta)"
            fac = f"{fac}*{s}" if fac else s
        if t_ref is not None:
            fac = fac.replace("T_ref", _g(t_ref))
        out = []
        for part in self.parts():
            x = fac.replace("sin(", "cos(") if part == "cos" else fac
            if self.variant == "sym":
                out.append("sign(v)" if x == "1" else f"sign(v)*{x}")
            else:
                out.append(x)
        return out

    def multiplier(self, speed, direction, param=None) -> np.ndarray:
        """Per-segment multiplier of the term's basis column(s)."""
        p = self.param if param is None else param
        m = self.fam.magnitude(np.asarray(speed, dtype=float), p)
        if self.variant == "sym":
            return direction * m
        return np.asarray(m, dtype=float)


class Library:
    """An ordered set of candidate terms; its columns are what sparse regression selects from.

    Parameters
    ----------
    terms : sequence of Term
    frequencies : sequence of float
        Ripple frequencies the terms' ``freq`` indices refer to (cycles per unit of theta).
    t_ref : float, optional
        Reference temperature printed in temperature terms.
    """

    def __init__(self, terms, frequencies=(), t_ref=None):
        self.terms = list(dict.fromkeys(terms))
        self.frequencies = np.asarray(frequencies, dtype=float)
        self.t_ref = t_ref
        for t in self.terms:
            if t.family not in FAMILIES:
                raise InputError(f"unknown library family '{t.family}' (known: {', '.join(FAMILIES)})")
            if (t.fam.param is None) != (t.param is None):
                raise InputError(f"library term {t.family} needs {'a ' + t.fam.param if t.fam.param else 'no'} "
                                 "parameter")
            if t.fam.basis == "ripple" and (t.freq is None or not 0 <= t.freq < len(self.frequencies)):
                raise InputError(f"ripple term {t.family} refers to frequency {t.freq}, the library has "
                                 f"{len(self.frequencies)}")
        #: (term index, part, basis name) of every column
        self.columns = [(i, part, b) for i, t in enumerate(self.terms) for part, b in zip(t.parts(), t.basis_names())]

    def __len__(self) -> int:
        return len(self.columns)

    @property
    def names(self) -> list[str]:
        return [name for t in self.terms for name in t.names(self.frequencies, self.t_ref)]

    def column_terms(self) -> np.ndarray:
        return np.array([c[0] for c in self.columns], dtype=int)

    def multipliers(self, m: Moments) -> np.ndarray:
        """(S, p): the per-segment multiplier of every column."""
        A = np.empty((m.S, len(self.columns)))
        cache = {}
        for j, (i, part, b) in enumerate(self.columns):
            if i not in cache:
                cache[i] = self.terms[i].multiplier(m.speed, m.direction)
            A[:, j] = cache[i]
        return A

    def basis_index(self, m: Moments) -> np.ndarray:
        missing = sorted({b for _, _, b in self.columns if b not in m.basis})
        if missing:
            raise InputError(f"the library needs sample bases {missing} that the data does not have "
                             f"(it has {list(m.basis)})")
        return np.array([m.index(b) for _, _, b in self.columns], dtype=int)

    def design(self, m: Moments) -> np.ndarray:
        """(S*K, p): the library's columns on the pseudo rows of ``m`` (exact normal equations)."""
        A = self.multipliers(m)
        return (A[:, None, :] * m.P[:, :, self.basis_index(m)]).reshape(m.S * m.K, len(self.columns))

    def evaluate(self, data, m: Moments) -> np.ndarray:
        """(N, p): the columns at every sample of ``data`` (dense; for checks and baselines -- the
        search itself never builds this).  Rows in the order of ``data``."""
        A = self.multipliers(m)[m.rows(data.segment)]
        X = np.empty((len(data), len(self.columns)))
        bases = {"1": np.ones(len(data))}
        if "load" in m.basis:
            bases["load"] = np.abs(np.asarray(data.load, dtype=float))
        if "temperature" in m.basis:
            bases["temperature"] = np.asarray(data.temperature, dtype=float) - m.t_ref
        if "acc" in m.basis:
            bases["acc"] = np.asarray(data.acc, dtype=float)
        if len(m.frequencies):
            sn, cs = harmonic_columns(data.theta, m.frequencies)
            for i in range(len(m.frequencies)):
                bases[f"sin{i}"], bases[f"cos{i}"] = sn[:, i], cs[:, i]
        for j, (_, _, b) in enumerate(self.columns):
            X[:, j] = A[:, j] * bases[b]
        return X

    def describe(self) -> str:
        fams: dict[str, int] = {}
        for t in self.terms:
            fams[t.family] = fams.get(t.family, 0) + len(t.parts())
        return (f"{len(self.columns)} columns from {len(self.terms)} terms: "
                + ", ".join(f"{k} {v}" for k, v in fams.items()))


def default_library(m: Moments, *, families=None, n_stribeck: int = 5, n_decay: int = 3,
                    exponents=(0.5, 2.0), directions: str = "auto", ripple_laws=("const", "exp", "rational"),
                    min_cycles: float = 1.0, min_segments: int = 3) -> Library:
    """The standard library for the data summarised in ``m``.

    Parameters
    ----------
    m : Moments
    families : sequence of str, optional
        Families to include (default: every family the data's bases allow).
    n_stribeck : int
        Stribeck velocities on a log grid from half the lowest to half the highest plateau speed,
        for each of the three shapes.
    n_decay : int
        Decay constants of the ripple amplitude laws on a log grid, ``b * v_max`` from 0.5 to 4.5.
    exponents : sequence of float
        Power-law exponents (0.5: sqrt-type, 2: |v|v).
    directions : {"auto", "sym"}
        "auto": a direction-dependent (asym) version of every friction term when the data has both
        directions; "sym": symmetric terms only.
    ripple_laws : sequence of {"const", "exp", "rational"}
        Amplitude laws of the ripple terms.
    min_cycles : float
        A ripple frequency enters the library only if it completes at least this many cycles in
        ``min_segments`` segments or more (otherwise it cannot be told from the friction level,
        nor its amplitude law from its amplitude).
    min_segments : int
    """
    speeds = m.speed[m.speed > 0]
    if len(speeds) == 0:
        raise InputError("fit data: every segment is at standstill; nothing to explore")
    lo, hi = float(np.min(speeds)), float(np.max(speeds))
    distinct = len(np.unique(np.round(speeds / hi, 6)))
    ripple = {f"ripple_{law}" for law in ripple_laws}
    unknown = ripple - set(FAMILIES)
    if unknown:
        raise InputError(f"unknown ripple amplitude law(s) {sorted(unknown)} (const, exp, rational)")
    # the speed laws, the families of the channels the data has, and the ripple laws asked for
    allowed = {name for name, fam in FAMILIES.items() if fam.basis == "1" or m.has(fam.basis)} | ripple
    fams = [f for f in (families or FAMILIES) if f in allowed]
    bad = [f for f in (families or ()) if f not in FAMILIES]
    if bad:
        raise InputError(f"unknown library families {bad} (known: {', '.join(FAMILIES)})")
    if distinct < 2:
        fams = [f for f in fams if f in ("coulomb", "load_coulomb", "temperature", "inertia", "ripple_const")]
    both = len(m.directions) == 2 and directions == "auto"
    variants = ("sym", "asym") if both else ("sym",)
    # grid values rounded to 3 significant digits, so that the names print them exactly
    vs_grid = _round3(np.geomspace(lo / 2, hi / 2, n_stribeck)) if n_stribeck > 0 and hi > lo else np.array([])
    decay_grid = _round3(np.geomspace(0.5, 4.5, n_decay) / hi) if n_decay > 0 else np.array([])
    grids = {"v_s": vs_grid, "decay": decay_grid, "exponent": np.asarray(exponents, dtype=float)}
    # frequencies that complete enough cycles somewhere
    need = min(min_segments, m.S)
    freqs = [i for i in range(len(m.frequencies)) if np.sum(m.cycles[:, i] >= min_cycles) >= need]
    terms: list[Term] = []
    for f in fams:
        fam = FAMILIES[f]
        if fam.basis == "acc":
            terms.append(Term(f, None, None, "signed"))
            continue
        lines = freqs if fam.basis == "ripple" else [None]
        terms += [Term(f, None if p is None else float(p), fi, var) for fi in lines
                  for p in grids.get(fam.param, [None]) for var in variants]
    return Library(terms, m.frequencies, m.t_ref)


def _round3(x):
    return np.array([float(f"{v:.3g}") for v in np.asarray(x, dtype=float)])
