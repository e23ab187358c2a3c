"""Recordings (``CONTRACTS.md`` section 1): :mod:`.readers` read csv, parquet, .mat and .npz files,
:mod:`.bags` ROS bags (JointState per joint) and :mod:`.urdf` gear ratios from a URDF;
:mod:`.load` maps, scales and numbers runs (:func:`load_recording`); :mod:`.cleaning` keeps the ledger
of excluded rows and unwraps; :mod:`.checks` refuses implausible data (one-sentence
:class:`~gearspec.errors.InputError`) or warns; :mod:`.record` holds the :class:`Recording`.
"""

from .bags import BAG_SUFFIXES, bag_joints, is_bag, read_bag
from .checks import MAX_PLAUSIBLE_M_S, MAX_PLAUSIBLE_RAD_S, MIN_POSITION_RANGE, MIN_SIGNAL_CHANGE, MIN_TIME_STEP
from .cleaning import CLOCK_BURST_FRACTION
from .load import CANONICAL, load_recording, parse_assignments
from .record import GAP_FACTOR, GAP_QUANTILE, Recording, auto_max_gap
from .urdf import gear_from_urdf, urdf_reduction, urdf_reductions

__all__ = ["Recording", "load_recording", "CANONICAL", "parse_assignments", "auto_max_gap", "GAP_FACTOR",
           "GAP_QUANTILE", "CLOCK_BURST_FRACTION", "MIN_TIME_STEP", "MIN_POSITION_RANGE", "MIN_SIGNAL_CHANGE",
           "MAX_PLAUSIBLE_RAD_S", "MAX_PLAUSIBLE_M_S", "BAG_SUFFIXES", "bag_joints", "is_bag", "read_bag",
           "gear_from_urdf", "urdf_reduction", "urdf_reductions"]
