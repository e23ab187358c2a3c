"""Identification of friction models: the papers' procedures and better estimators beside them.

:mod:`.stats` (lines to fit, per-segment statistics), :mod:`.joint` (the joint fit, :class:`JointFit`),
:mod:`.published` (SILO4 as published), :mod:`.efficiency` (Lola/CROPS efficiency fits),
:mod:`.validate` (per-segment and held-out errors), :mod:`.pipeline` (:func:`compare`, ``gearspec fit``).
"""

from .efficiency import efficiency_model, fit_catalog, fit_efficiency
from .joint import JointFit, clone, fit, negative_viscous, refit
from .pipeline import FitResult, compare, identify_recording
from .published import amplitudes_from_spectrum, line_amplitudes, silo4_published
from .stats import MIN_CYCLES, ConvergenceError, SegmentStats, harmonic_specs, segment_stats
from .validate import holdout, holdout_rmse, segment_errors

__all__ = ["fit", "JointFit", "clone", "refit", "silo4_published", "holdout_rmse", "holdout", "compare",
           "harmonic_specs", "fit_efficiency", "fit_catalog", "efficiency_model", "SegmentStats", "segment_stats",
           "ConvergenceError", "segment_errors", "identify_recording", "FitResult", "line_amplitudes",
           "amplitudes_from_spectrum", "negative_viscous", "MIN_CYCLES"]
