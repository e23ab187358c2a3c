"""Identification of friction models: the papers' procedures and better estimators beside them.

- :mod:`.stats`: the lines to fit (:func:`harmonic_specs`) and the exact per-segment statistics
  of the samples (:class:`SegmentStats`) the fits start from.
- :mod:`.joint`: the joint fit of all parameters of a direction (weighted nonlinear least squares
  on the samples, standard errors from the covariance or a bootstrap), as an estimator
  (:class:`JointFit`, :func:`clone`) and as :func:`fit`; :func:`refit` rebuilds it from a model.
- :mod:`.published`: the SILO4 procedure as published (:func:`silo4_published`) and the lines'
  amplitudes per segment it reads.
- :mod:`.efficiency`: Lola/CROPS fits to efficiency (:func:`fit_efficiency`, :func:`fit_catalog`).
- :mod:`.validate`: errors per segment (:func:`segment_errors`) and held out (:func:`holdout`),
  leaving out whole segments or runs, never interleaved samples.
- :mod:`.pipeline`: models side by side (:func:`compare`) and a whole recording
  (:func:`identify_recording`, ``gearspec fit``).
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
