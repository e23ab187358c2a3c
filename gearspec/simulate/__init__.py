"""Simulated recordings with known ground truth, knowing nothing of the analysis: synthetic test
signals (:mod:`.synthetic`), the SILO4 joint-3 twin (:mod:`.silo4`), the Lola/CROPS testbed twin
(:mod:`.lola`), effects the declared model lacks, injected into a twin's truth (:mod:`.effects`), and
the velocity profiles that drive the twins and :func:`motion_recording` through whole motions
(:mod:`.profiles`).
"""

from . import effects, profiles
from .effects import apply_effects, effects_truth, parse_effect
from .lola import MODULES, lola_twin, table3_model, table4_model
from .silo4 import PAPER_TABLE2, TwinTruth, silo4_twin, stick_slip_run, table2_model, twin_gear
from .profiles import PROFILES, velocity_profile
from .synthetic import Ripple, model_recording, motion_recording, plateau_recording

__all__ = ["Ripple", "plateau_recording", "model_recording", "effects", "apply_effects", "effects_truth",
           "parse_effect", "PAPER_TABLE2", "TwinTruth", "silo4_twin", "stick_slip_run", "table2_model", "twin_gear",
           "MODULES", "lola_twin", "table3_model", "table4_model", "profiles", "PROFILES", "velocity_profile",
           "motion_recording"]
