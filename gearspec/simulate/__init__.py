"""Simulated recordings with known ground truth (twins and synthetic test signals).

Simulations produce recordings and know nothing of the analysis.

* :mod:`.synthetic` -- open-loop plateau recordings with known ripple, or whose friction is any
  :class:`~gearspec.model.FrictionModel` (:func:`model_recording`).
* :mod:`.silo4` -- the SILO4 joint-3 bench (closed-loop speed control, stick-slip, encoder,
  Bessel-filtered current, ten repetitions per speed): :func:`silo4_twin`, :func:`table2_model`.
* :mod:`.lola` -- the Lola/CROPS friction testbed (quasi-static grid of speeds x brake loads):
  :func:`lola_twin`, :func:`table4_model`, :func:`table3_model`.
* :mod:`.effects` -- effects the declared model lacks (cogging, extra orders, sidebands,
  load-dependent meshing, warming, drift, other decay laws, asymmetry, hysteresis, backlash,
  inertia), injected into a twin's truth with their ground truth.
"""

from . import effects
from .effects import apply_effects, effects_truth, parse_effect
from .lola import MODULES, lola_twin, table3_model, table4_model
from .silo4 import PAPER_TABLE2, TwinTruth, silo4_twin, stick_slip_run, table2_model, twin_gear
from .synthetic import Ripple, model_recording, plateau_recording

__all__ = ["Ripple", "plateau_recording", "model_recording", "effects", "apply_effects", "effects_truth",
           "parse_effect", "PAPER_TABLE2", "TwinTruth", "silo4_twin", "stick_slip_run", "table2_model", "twin_gear",
           "MODULES", "lola_twin", "table3_model", "table4_model"]
