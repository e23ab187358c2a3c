"""Constant-speed segments, direction split, derivatives and inertia removal.

Segments are found from position alone (:func:`find_segments`): each piece (a run, split at time
gaps) is averaged over blocks; a block is *steady* when the least-squares speeds over a window of
``K = 4`` blocks before, across and after it agree within ``rel_tol``, share a sign and exceed
``min_speed`` (blind to ripple faster than the window).  Runs of steady blocks are joined across
short excursions (:func:`.ramps._merge_fragments`), split where they drift (CUSUM) or follow a
smooth speed curve (:func:`.ramps._split_smooth`), trimmed by speed and to the straight-line band
of their middle (:func:`.ramps._trim_to_line`), and dropped below ``min_duration``.  With
``window="auto"`` each piece keeps the shortest window of 0.02 ... 2 s whose segments cover at
least 80 % of the most any window covers.  Quasi-static sweeps (:func:`quasi_static_sweeps`) are
taken out first.

Every row ends in one segment or is counted under one reason: ``standstill``, ``transient``,
``short_plateau`` or ``short_sweep``.  Derivatives for inertia removal use a Savitzky-Golay filter
(order 2, about 20 ms, at least 7 samples) per piece on a uniform time grid; a piece too short for
it gets NaN, never an error.
"""

from .kinematics import FrictionTorque, derivatives, friction_torque
from .plateaus import PARALLEL_MIN_SAMPLES, find_segments
from .quasistatic import quasi_static_sweeps
from .segmentation import Segment, Segmentation

__all__ = ["Segment", "Segmentation", "find_segments", "quasi_static_sweeps", "derivatives", "friction_torque",
           "FrictionTorque", "PARALLEL_MIN_SAMPLES"]
