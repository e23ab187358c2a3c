"""Constant-speed segments, direction split, derivatives and inertia removal.

Segments are found from position alone (no commanded speed is needed):

1. The recording is cut into *pieces* at run boundaries and time gaps; nothing spans a cut.
2. Each piece is averaged over short blocks of ``b`` samples (block-mean time and position).
3. Over a window of ``K = 4`` blocks (``window`` seconds) the speed is the least-squares slope of
   position against time, before, across and after every block.  A block is *steady* when the
   speed before it and after it agree within ``rel_tol`` of the speed across it, all three have
   the same sign, and the speed is above ``min_speed``.  Averaging over a window makes the test
   blind to closed-loop ripple that is faster than the window; ramps between plateaus fail it.
4. Runs of steady blocks become candidate segments.  Two candidates separated by an excursion of
   at most two windows, moving at the same speed (within ``rel_tol``), are joined: the drive left
   the plateau briefly and came back.  A candidate whose speed drifts by more than
   ``2 * rel_tol`` (a slow ramp) is split where its speed changes most (CUSUM), recursively, and
   edge blocks whose window speed is more than ``rel_tol`` off the candidate's median speed (the
   end of a gentle ramp) are dropped.
5. The ends of each candidate are trimmed where position leaves the band around the straight line
   fitted to the candidate's middle 60 % (the band is 1.5 times the largest deviation there): this
   removes a transient that a long window could not see, and nothing from a clean plateau.
   Candidates shorter than ``min_duration`` (default two windows, at least 0.1 s) are dropped.
   A candidate whose block-to-block speed follows a smooth curve (a cubic in time that stands
   out of the position noise and explains more than the ripple beside it) spanning more than a
   third of ``rel_tol`` is a ramp, a bell's top or a creeping tail: it is split, and only parts
   shown flat are kept (:func:`_split_smooth`).
6. With ``window="auto"`` steps 2-5 are repeated for windows of 0.02 ... 2 s and each piece keeps
   the shortest window whose segments cover at least 80 % of the most any window covers.
   Slow, stick-slipping plateaus thereby get long windows, brisk bang-bang profiles short ones
   (a long window would hide a short transient at the start of a plateau).

Quasi-static sweeps come first (:func:`quasi_static_sweeps`): per run, over position (time gaps do
not cut them), a monotonic sweep whose rows were stored at rest after each step of a position loop
becomes one segment of kind ``"quasi_static"`` (recognised, or every sweep with
``quasi_static=True``); the plateau search runs on the rows outside them.

Every row of the recording ends in exactly one segment or is counted under one reason:
``standstill`` (speed below ``min_speed``; a forced sweep without travel), ``transient`` (ramps,
reversals, unsteady speed and the edges of pieces), ``short_plateau`` (steady, but shorter than
``min_duration``), ``short_sweep`` (a forced quasi-static sweep of fewer than ``min_samples`` rows).

Derivatives for inertia removal use a Savitzky-Golay filter (``scipy.signal.savgol_filter``,
polynomial order 2, ``deriv_window`` samples, default about 20 ms and at least 7 samples) on each
piece, on a uniform time grid (resampled linearly when the sampling jitters by more than 1 %).
A piece too short for the filter (in samples, or in points of that grid) gets no derivative (NaN),
never an error.  Quasi-static segments use no derivative at all.
"""

from .kinematics import FrictionTorque, derivatives, friction_torque
from .plateaus import PARALLEL_MIN_SAMPLES, find_segments
from .quasistatic import quasi_static_sweeps
from .segmentation import Segment, Segmentation

__all__ = ["Segment", "Segmentation", "find_segments", "quasi_static_sweeps", "derivatives", "friction_torque",
           "FrictionTorque", "PARALLEL_MIN_SAMPLES"]
