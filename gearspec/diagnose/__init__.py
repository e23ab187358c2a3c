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
``design``      a model as linear blocks of columns (base law, lines, terms), fitted jointly;
                to and from :class:`~gearspec.model.FrictionModel`
``residual``    the residual analyses
``candidates``  the candidate terms and how each searches its own nonlinear parameters (a channel
                lag and declared sidebands included)
``loop``        :func:`diagnose`, the held-out acceptance test, :class:`Diagnosis`
"""

from .candidates import (Candidate, GridCandidate, LagCandidate, PeriodicCandidate, SidebandCandidate,
                         choose_amplitude_law)
from .data import (DiagnoseData, butter_filtfilt, central_difference, decimate, decimation_index, moves,
                   reversal_travel, trajectory_data, travel_since_reversal)
from .design import BaseBlock, FittedState, HarmonicBlock, State, TermBlock, fit_state, predict_model, state_from_model
from .loop import (KINDS, Diagnosis, Effect, baseline_model, diagnose, evaluate_candidate, folds_of, idim_model,
                   relative_error, residual_analysis)
from .residual import (ResidualSpectrum, acceleration_analysis, channel_analysis, position_spectra,
                       reversal_analysis, speed_analysis, speed_groups)

__all__ = ["diagnose", "Diagnosis", "Effect", "KINDS", "baseline_model", "idim_model", "residual_analysis",
           "evaluate_candidate", "folds_of",
           "relative_error", "DiagnoseData", "trajectory_data", "travel_since_reversal", "reversal_travel", "moves",
           "butter_filtfilt", "central_difference", "decimate", "decimation_index", "State", "BaseBlock",
           "HarmonicBlock", "TermBlock", "FittedState", "fit_state", "state_from_model", "predict_model",
           "Candidate", "GridCandidate", "PeriodicCandidate", "LagCandidate", "SidebandCandidate", "choose_amplitude_law", "ResidualSpectrum",
           "position_spectra", "speed_analysis", "speed_groups", "channel_analysis", "acceleration_analysis",
           "reversal_analysis"]
