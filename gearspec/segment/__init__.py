"""Constant-speed segments, direction split, derivatives and inertia removal.

Segments are found from position alone (:func:`find_segments`): each piece (a run, split at time
gaps) is averaged over blocks; a block is *steady* when the least-squares speeds over a window of
``K = 4`` blocks before, across and after it agree within ``rel_tol``, share a sign and exceed
``min_speed`` (blind to ripple faster than the window).  Runs of steady blocks are refined in
:mod:`.ramps`.  With ``window="auto"`` each piece keeps the shortest window of 0.02 ... 2 s whose
segments cover at least 80 % of the most any window covers.  Quasi-static sweeps
(:func:`quasi_static_sweeps`) are taken out first.  Free motion (ramps, moves, chirps) is cut into
blocks of nearly constant speed by :func:`free_motion`.  Every row ends in one segment or is counted
under one reason: ``standstill``, ``transient``, ``short_plateau`` or ``short_sweep``.
"""

from .freemotion import FREE_BAND, FREE_SHARE, MOTIONS, free_motion
from .kinematics import FrictionTorque, derivatives, friction_torque
from .plateaus import PARALLEL_MIN_SAMPLES, find_segments
from .quasistatic import quasi_static_sweeps
from .segmentation import Segment, Segmentation

__all__ = ["Segment", "Segmentation", "find_segments", "quasi_static_sweeps", "derivatives", "friction_torque",
           "FrictionTorque", "PARALLEL_MIN_SAMPLES", "free_motion", "MOTIONS", "FREE_BAND", "FREE_SHARE"]
