"""The term registry: every base law (:mod:`.registry`), additive term kind (:mod:`.kinds`) and
shared shape (:mod:`.shapes`) declared once; laws, model, identify, design and discover build on it."""

from .kinds import TERM_LINEAR, TERMS, TermKind, evaluate_term, register_term, term_names
from .registry import BASE_LAWS, LAW_LINEAR, fittable_laws, BaseLaw, Basis, Degraded, Nonlinear, basis, register_law
from .shapes import (AMPLITUDE_LAWS, STRIBECK_SHAPES, amplitude_law, clamp_speed, load_amplitude, sinusoid,
                     stribeck_shape, stribeck_term)

__all__ = ["TERMS", "TermKind", "register_term", "evaluate_term", "term_names", "amplitude_law", "AMPLITUDE_LAWS",
           "clamp_speed", "TERM_LINEAR", "BASE_LAWS", "fittable_laws", "LAW_LINEAR", "BaseLaw", "Basis", "Degraded", "Nonlinear", "basis",
           "register_law", "STRIBECK_SHAPES", "stribeck_shape", "stribeck_term", "load_amplitude", "sinusoid"]
