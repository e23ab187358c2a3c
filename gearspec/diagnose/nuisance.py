"""Declared lines the data cannot resolve, kept in the null model of the closed loop.

:func:`gearspec.identify.fit` leaves out a declared line whose segments cover less than one of its
cycles together (``not_identified``: a slow output shaft seen over a fraction of a turn).  The line
is still in the data: on each plateau it adds the part of its cycle that plateau travels over, a
level and a slow trend that differ from plateau to plateau.  Left out of the model the loop starts
from, any term that can follow those plateau levels (a second Stribeck term, a drift) would be
"discovered" in its place.  So the loop keeps every such line in its null model as a
:class:`PartialLineBlock`: two columns per direction (``sin`` and ``cos`` of ``2 pi f theta``, a
constant amplitude: a decay cannot be measured from partial cycles), fitted with the rest in every
fold and written into the model as fitted (``partial_cycles``; it stays listed in ``not_identified``),
when the held-out test wants it (:func:`admit_partial_lines`).  A candidate must then explain more
than the declared line's partial cycle to pass.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..identify.stats import harmonic_specs
from .coverage import resolved
from .data import DiagnoseData
from .design import Block, HarmonicBlock, State

__all__ = ["PartialLineBlock", "unresolved_lines", "admit_partial_lines"]

_TWO_PI = 2.0 * math.pi
_DNAME = {1: "positive", -1: "negative"}


@dataclass(frozen=True, eq=False)
class PartialLineBlock(Block):
    """A declared line seen in partial cycles only: ``(a sin + c cos)(2 pi f theta)`` with the sign
    of the motion, per direction in ``dirs`` (not a :class:`HarmonicBlock`: no candidate changes
    its law, lag or sidebands)."""

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
        """The line into ``model``'s harmonics as fitted (constant amplitude, ``partial_cycles``
        True), so that the model evaluates as the loop fitted it; its ``not_identified`` entries
        say that it was seen in partial cycles only."""
        blk = HarmonicBlock(frequency=self.frequency, label=self.label, dirs=self.dirs,
                            law=tuple((d, "const") for d in self.dirs), decay=tuple((d, 0.0) for d in self.dirs),
                            extra=tuple((d, {"partial_cycles": True}) for d in self.dirs))
        blk.write(model, coef, se)
        for d in self.dirs:
            key = f"{_DNAME[d]}.{self.label}"
            if key in model.not_identified and "partial cycle" not in model.not_identified[key]:
                model.not_identified[key] += ("; the closed loop fits it as a partial cycle (constant amplitude), "
                                              "its amplitude traded against the base law's levels")

    def describe(self) -> str:
        return (f"declared line {self.label} at {self.frequency:.6g} cycles/unit, seen in partial cycles only "
                f"(constant amplitude)")


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


def admit_partial_lines(state: State, model, dd: DiagnoseData, fold, settle, evaluate, *, alpha: float,
                        min_gain: float, harmonics=None, gear=None) -> tuple[State, list[str]]:
    """``(state, notes)``: ``state`` with the :func:`unresolved_lines` of ``model`` added when they
    pass the loop's held-out test together (``evaluate``:
    :func:`~gearspec.diagnose.loop.evaluate_candidate`, one candidate at level ``alpha``, gain
    ``min_gain``), then settled (``settle``); else ``state`` as it is.  A declared line is
    expected, but its partial-cycle columns are poorly determined: where the data do not want it,
    it would only blur the held-out test of every other term.  ``notes``: one line for the user."""
    from ..core.crossval import critical_z
    from .candidates import FixedCandidate
    from .context import Round

    extra = unresolved_lines(model, dd, harmonics=harmonics, gear=gear)
    if not extra:
        return state, []
    ev = evaluate(Round(dd, state, fold), FixedCandidate("periodic", "declared lines seen in partial cycles", extra),
                  z_crit=critical_z(alpha, 1, dd.n_groups), min_gain=min_gain, repolish=False)
    what = "; ".join(f"{b.label} at {b.frequency:.6g} cycles/{dd.unit} ({', '.join(_DNAME[d] for d in b.dirs)})"
                     for b in extra)
    numbers = f"held-out Z {ev.z:.2f} (needs {ev.z_crit:.2f}), rmse {-100 * ev.gain:+.2f} % (needs a fall of " \
              f"{100 * min_gain:.2g} %)"
    if ev.passed:
        return settle(state.replaced((), extra), dd), [
            f"declared line(s) seen in partial cycles only, not identified: {what}; kept in the model every term is "
            f"tested against ({numbers}), so no term is accepted in their place; written with a constant amplitude"]
    return state, [f"declared line(s) seen in partial cycles only, not identified: {what}; left out of the model "
                   f"the loop tests against: the data do not want them ({ev.gate}; rmse "
                   f"{-100 * ev.gain:+.2f} %)"]
