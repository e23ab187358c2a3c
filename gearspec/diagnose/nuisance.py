"""Declared lines the data cannot resolve, kept in the null model of the closed loop.

:func:`gearspec.identify.fit` leaves out a declared line whose segments cover less than one of its
cycles together (``not_identified``: a slow output shaft seen over a fraction of a turn).  The line
is still in the data: on each plateau it adds the part of its cycle that plateau travels over, a
level and a slow trend that differ from plateau to plateau.  Left out of the model the loop starts
from, any term that can follow those plateau levels (a second Stribeck term, a drift) would be
"discovered" in its place.  So the loop keeps every such line in its null model as a
:class:`PartialLineBlock`: two columns per direction (``sin`` and ``cos`` of ``2 pi f theta``, a
constant amplitude: a decay cannot be measured from partial cycles), fitted with the rest in every
fold, never written into the model (it stays ``not_identified``).  A candidate must then explain
more than the declared line's partial cycle to pass.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..identify.stats import harmonic_specs
from .coverage import resolved
from .data import DiagnoseData
from .design import Block, State

__all__ = ["PartialLineBlock", "unresolved_lines", "with_unresolved_lines", "partial_line_notes"]

_TWO_PI = 2.0 * math.pi
_DNAME = {1: "positive", -1: "negative"}


@dataclass(frozen=True, eq=False)
class PartialLineBlock(Block):
    """A declared line seen in partial cycles only: ``(a sin + c cos)(2 pi f theta)`` with the sign
    of the motion, per direction in ``dirs``; part of the null model, not of the fitted model
    (:meth:`write` writes nothing)."""

    frequency: float = 1.0
    label: str = ""
    dirs: tuple = (1, -1)

    @property
    def names(self):
        return [f"{self.label} {fn}[{_DNAME[d][:3]}] (partial cycle)" for d in self.dirs for fn in ("sin", "cos")]

    def _raw(self, dd: DiagnoseData):
        f = dd.fit
        if f.theta is None:
            raise InputError("a position-locked line needs positions (theta)")
        x = _TWO_PI * self.frequency * f.theta
        sn, cs = np.sin(x), np.cos(x)
        if dd.reduce is None:
            ok = resolved(dd, self.frequency)
            if not ok.all():
                sn, cs = np.where(ok, sn, 0.0), np.where(ok, cs, 0.0)
        sgn = np.sign(f.v)
        cols = []
        for d in self.dirs:
            g = np.where(f.direction == d, sgn, 0.0)
            cols += [g * sn, g * cs]
        return np.column_stack(cols)

    def write(self, model, coef, se) -> None:
        """Nothing: the line is not identified by these data (the model says so in ``not_identified``)."""

    def describe(self) -> str:
        return (f"declared line {self.label} at {self.frequency:.6g} cycles/unit, seen in partial cycles only: "
                f"in the null model, not identified")


def unresolved_lines(model, dd: DiagnoseData, *, harmonics=None, gear=None) -> list[PartialLineBlock]:
    """One :class:`PartialLineBlock` per declared line (``harmonics`` / ``gear`` as
    :func:`gearspec.identify.fit` takes them) that ``model`` lists as not identified in a direction
    where ``dd`` has data (there: its segments cover less than one cycle of it together); lines
    the model has (at 1e-9 relative) are skipped."""
    if dd.fit.theta is None or not model.not_identified:
        return []
    specs = harmonic_specs(harmonics, gear) if (harmonics is not None or gear is not None) else []
    have = [h.frequency for d in dd.directions() for h in model.harmonics(d)]
    out = []
    for h in specs:
        f = float(h["frequency"])
        lab = h.get("label") or f"{f:.6g}"
        if any(math.isclose(f, x, rel_tol=1e-9) for x in have):
            continue
        # identify.fit leaves a declared line out of a direction with data for one reason: its
        # segments there cover less than one cycle of it together
        dirs = tuple(d for d in dd.directions() if f"{_DNAME[d]}.{lab}" in model.not_identified)
        if dirs:
            out.append(PartialLineBlock(key=f"partial line {f:.6g}", frequency=f, label=lab, dirs=dirs))
    return out


def with_unresolved_lines(state: State, model, dd: DiagnoseData, *, harmonics=None, gear=None) -> State:
    """``state`` with :func:`unresolved_lines` added (the loop's null model)."""
    extra = unresolved_lines(model, dd, harmonics=harmonics, gear=gear)
    return state.replaced((), extra) if extra else state


def partial_line_notes(state: State) -> list[str]:
    """One note per :class:`PartialLineBlock` of ``state``, for the console and the report."""
    return [f"{b.describe()} ({', '.join(_DNAME[d] for d in b.dirs)}): its partial cycle is fitted with every "
            f"model the loop tests, so no term is accepted in its place"
            for b in state.blocks if isinstance(b, PartialLineBlock)]
