"""Edge rows of constant-speed segments whose time derivatives see the transient next to them.

The velocity and acceleration of a row (:func:`~gearspec.segment.derivatives`) come from a
Savitzky-Golay filter over a window of samples centred on it.  In the first and last half window
of a plateau that window reaches into the ramp (or the step to the next plateau) beside it, so the
acceleration there -- and with it ``J thetadd``, the inertia torque removed from the drive torque --
belongs to the ramp, not to the plateau.  :func:`trim_edges` takes those rows out of every plateau
(one rule, from the filter's own window, :func:`edge_rows`): they are counted under ``edge`` in the
ledger.  The closed loop applies the same rule to its data
(:meth:`gearspec.diagnose.DiagnoseData.without_edges`).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import replace

import numpy as np

from ..recording import Recording
from .kinematics import _filter_params
from .segmentation import Segmentation

__all__ = ["trim_edges", "edge_rows"]


def edge_rows(t, deriv_window: int | None = None) -> int:
    """Rows at each end of a stretch of samples at times ``t`` (s) whose derivative filter window
    (:func:`~gearspec.segment.derivatives`, ``deriv_window`` samples, default about 20 ms) reaches
    outside it: half the window, rounded down (0 when the stretch is too short for the filter)."""
    params = _filter_params(np.asarray(t, dtype=float), deriv_window)
    return 0 if params is None else params[1] // 2


def trim_edges(rec: Recording, seg: Segmentation, deriv_window: int | None = None) -> Segmentation:
    """``seg`` with :func:`edge_rows` rows cut from both ends of every plateau (segments of kind
    ``"plateau"``; quasi-static sweeps use no derivative, free-motion blocks are transients by
    design) that keeps at least half of its rows; the rows cut are counted under ``edge``.
    A plateau's speed (travel over duration) is kept: the segmenter measured it on its rows."""
    segments = []
    cut = 0
    for s in seg.segments:
        h = edge_rows(rec.t[s.start:s.stop], deriv_window) if s.kind == "plateau" else 0
        if h and s.n - 2 * h >= s.n / 2:
            segments.append(replace(s, start=s.start + h, stop=s.stop - h))
            cut += 2 * h
        else:
            segments.append(s)
    if not cut:
        return seg
    excluded = Counter(seg.excluded)
    excluded["edge"] += cut
    out = Segmentation(segments, excluded, seg.n_rows, {**seg.settings, "edge_rows_trimmed": cut})
    out.check_ledger()
    return out
