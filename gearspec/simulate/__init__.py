"""Simulated recordings with known ground truth (twins and synthetic test signals).

Simulations produce recordings and know nothing of the analysis.
"""

from .synthetic import Ripple, model_recording, plateau_recording

__all__ = ["Ripple", "plateau_recording", "model_recording"]
