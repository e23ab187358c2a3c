"""The closed loop: residual -> missing effect -> new term -> error before and after.

A user fits the model they believe in; :func:`diagnose` looks for structure in its residual
(:mod:`.residual`: over position, against speed, load, temperature, time, acceleration and near
reversals), turns what it sees into candidate terms (:mod:`.candidates`, one kind per effect of
``CONTRACTS.md`` section 4), adds a term only when it lowers the error on held-out data by more
than noise would (:mod:`.loop`), and repeats until nothing more is accepted.

Modules (data flows one way):

``data``        :class:`DiagnoseData` -- samples in segments (or a whole trajectory, prepared as
                the inverse dynamic model is: :func:`trajectory_data`), the held-out groups, the
                travel since the last reversal, an optional decimation of every column
``coverage``    where the data measure a line (resolved segments, speeds)
``design``      a model as linear blocks of columns (base law, lines, terms), fitted jointly;
                to and from :class:`~gearspec.model.FrictionModel`
``nonlinear``   the nonlinear parameters: standard errors, polish and Gauss-Newton refinement
``residual``    the residual analyses
``context``     :class:`Round`, the read-only context of one round (fits per fold, held-out errors)
``candidates``  the candidate terms and how each searches its own nonlinear parameters
``detectors``   one detector per effect kind, turning the residual analyses into candidates
``baseline``    the model to start from, IDIM-LS, the residual analyses of any fitted model
``results``     :class:`Effect` and :class:`Diagnosis`
``validate``    the final judge: every accepted term checked on an independent recording
``loop``        :func:`diagnose` and the held-out acceptance test

The package exports what a user calls; the engine's parts (blocks, candidates, folds) are imported
from their modules.  ``gearspec.diagnose(data, model)`` is :func:`diagnose` (the package is callable).
"""

import sys

from .. import _CallablePackage
from .data import DiagnoseData, trajectory_data
from .design import fit_state, predict_model, state_from_model
from .loop import KINDS, Diagnosis, Effect, baseline_model, diagnose, idim_model, relative_error, residual_analysis
from .residual import position_spectra

# fit_state, state_from_model and position_spectra: the residual of a baseline as the Kinova notebook looks at it
__all__ = ["diagnose", "Diagnosis", "Effect", "KINDS", "DiagnoseData", "trajectory_data", "baseline_model",
           "idim_model", "predict_model", "relative_error", "residual_analysis", "position_spectra", "state_from_model",
           "fit_state"]

sys.modules[__name__].__class__ = _CallablePackage
