"""Recordings: load, map, scale and validate measured data (``CONTRACTS.md`` section 1).

A :class:`Recording` holds the rows that can be analysed, in canonical columns and SI units, plus a
ledger of every row that was excluded and why (``excluded``), and notes of everything that was done
to the data on the way in (unwrapping, current-to-torque conversion, ...).  Nothing is dropped
silently: ``n_read == len(data) + sum(excluded.values())``.

Bad input raises :class:`~gearspec.errors.InputError` with one sentence naming the file, the column
and the reason.  Doubtful input gives a :class:`~gearspec.errors.GearspecWarning`.

One module per job:

* :mod:`.record`: the :class:`Recording` and its time gaps (pieces, :func:`auto_max_gap`);
* :mod:`.readers`: csv, parquet, .mat and .npz files into tables;
* :mod:`.load`: :func:`load_recording`: columns mapped and scaled, runs numbered, then cleaned and checked;
* :mod:`.cleaning`: the exclusion ledger (NaN or inf, backward and repeated times, saturation) and unwrapping;
* :mod:`.checks`: plausibility (time unit, motion, a changing signal, speeds of a robot drive).
"""

from .checks import MAX_PLAUSIBLE_M_S, MAX_PLAUSIBLE_RAD_S, MIN_POSITION_RANGE, MIN_SIGNAL_CHANGE, MIN_TIME_STEP
from .cleaning import CLOCK_BURST_FRACTION
from .load import CANONICAL, load_recording, parse_assignments
from .record import GAP_FACTOR, GAP_QUANTILE, Recording, auto_max_gap

__all__ = ["Recording", "load_recording", "CANONICAL", "parse_assignments", "auto_max_gap", "GAP_FACTOR",
           "GAP_QUANTILE", "CLOCK_BURST_FRACTION", "MIN_TIME_STEP", "MIN_POSITION_RANGE", "MIN_SIGNAL_CHANGE",
           "MAX_PLAUSIBLE_RAD_S", "MAX_PLAUSIBLE_M_S"]
