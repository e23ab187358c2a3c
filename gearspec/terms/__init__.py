"""The term registry: every base law and every additive term kind declared once.

* :mod:`.shapes` -- the nonlinear shapes laws and terms share (Stribeck exp/gauss/rational,
  amplitude laws exp/const/rational/power, the position-locked sinusoid, SILO4 eq. 14's load
  amplitude);
* :mod:`.registry` -- the base laws (:class:`BaseLaw`: parameters, units, papers' names,
  magnitude, linear columns, nonlinear parameters with bounds and start grid, degraded forms);
* :mod:`.kinds` -- the additive term kinds a model can be extended with (:data:`TERMS`).

:mod:`gearspec.laws`, :mod:`gearspec.model`, :mod:`gearspec.identify`, the closed loop's design
(:mod:`gearspec.diagnose.design`) and the explorer's library (:mod:`gearspec.discover.library`)
build from these; none keeps its own copy of a law.
"""

from .kinds import TERM_LINEAR, TERMS, TermKind, evaluate_term, register_term, term_names
from .registry import BASE_LAWS, LAW_LINEAR, fittable_laws, BaseLaw, Basis, Degraded, Nonlinear, basis, register_law
from .shapes import (AMPLITUDE_LAWS, STRIBECK_SHAPES, amplitude_law, clamp_speed, load_amplitude, sinusoid,
                     stribeck_shape, stribeck_term)

__all__ = ["TERMS", "TermKind", "register_term", "evaluate_term", "term_names", "amplitude_law", "AMPLITUDE_LAWS",
           "clamp_speed", "TERM_LINEAR", "BASE_LAWS", "fittable_laws", "LAW_LINEAR", "BaseLaw", "Basis", "Degraded", "Nonlinear", "basis",
           "register_law", "STRIBECK_SHAPES", "stribeck_shape", "stribeck_term", "load_amplitude", "sinusoid"]
