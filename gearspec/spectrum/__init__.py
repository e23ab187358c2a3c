"""Spectra of friction over position: ``analyze`` runs the per-segment analysis of a recording;
its building blocks (resampling, order spectrum, Lomb-Scargle, harmonic fit) work on any signal;
``order_map`` and ``order_track`` analyse motion at varying speed."""

from .analysis import Peak, SegmentSpectrum, SpectrumResult, analyze, analyze_segment, position_nyquist, MEASURABLE_FRACTION
from .analysis import QUANTISATION_FRACTION, quantisation_limit, quantisation_lines, quantisation_step
from .fft import order_spectrum
from .ordermap import Motion, OrderMap, motion, order_map
from .ordertrack import OrderAnalysis, OrderTrack, order_analysis, order_track
from .harmonic import HarmonicFit, harmonic_fit, min_degree_for_cycles
from .periodogram import LombScargle, false_alarm_probability, local_noise
from .resample import resample_over_position

__all__ = ["analyze", "analyze_segment", "position_nyquist", "MEASURABLE_FRACTION", "QUANTISATION_FRACTION",
           "quantisation_limit", "quantisation_lines", "quantisation_step", "Peak", "SegmentSpectrum", "SpectrumResult", "order_spectrum",
           "HarmonicFit", "harmonic_fit", "min_degree_for_cycles", "LombScargle", "false_alarm_probability",
           "local_noise", "resample_over_position", "Motion", "motion", "OrderMap", "order_map",
           "OrderTrack", "order_track", "OrderAnalysis", "order_analysis"]
