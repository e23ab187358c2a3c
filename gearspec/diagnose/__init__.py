"""The closed loop: residual -> missing effect -> new term -> error before and after.

:func:`diagnose` looks for structure in a fitted model's residual, turns it into candidate terms
and adds one only when it lowers the error on held-out data by more than noise would; the README
("The closed loop") lists the modules and the rules.  The package exports what a user calls; the
engine's parts are imported from their modules.  ``gearspec.diagnose(data, model)`` is
:func:`diagnose` (the package is callable).
"""

import sys

from .. import _CallablePackage
from .data import DiagnoseData, trajectory_data
from .design import fit_state
from .frommodel import predict_model, state_from_model
from .loop import KINDS, Diagnosis, Effect, baseline_model, diagnose, idim_model, relative_error, residual_analysis
from .residual import position_spectra

# fit_state, state_from_model and position_spectra: the residual of a baseline as the Kinova notebook looks at it
__all__ = ["diagnose", "Diagnosis", "Effect", "KINDS", "DiagnoseData", "trajectory_data", "baseline_model",
           "idim_model", "predict_model", "relative_error", "residual_analysis", "position_spectra", "state_from_model",
           "fit_state"]

sys.modules[__name__].__class__ = _CallablePackage
