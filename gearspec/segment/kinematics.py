"""Kinematics of a recording: velocity and acceleration by a Savitzky-Golay filter, piece by piece
(on plateaus with a line of the fit, the acceleration of the position-locked motion instead:
:func:`fit_derivatives`, :mod:`gearspec.segment.poslock`), and the friction torque ``tau - J thetadd``
(SILO4 eq. 2), whole or one segment at a time (:class:`FrictionTorque`)."""

from __future__ import annotations

import math
from functools import cached_property

import numpy as np
from ..recording import Recording

__all__ = ["derivatives", "fit_derivatives", "friction_torque", "FrictionTorque"]


def derivatives(rec: Recording, deriv_window: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Velocity and acceleration (unit/s, unit/s^2, one per row) of ``theta`` by a Savitzky-Golay
    filter of ``deriv_window`` samples (odd, >= 5; default about 20 ms, at least 7), piece by
    piece; pieces shorter than the window (in samples, or on the uniform grid a jittered piece is
    resampled to) get NaN."""
    t, theta = rec.t, rec.theta
    vel = np.full(len(t), np.nan)
    acc = np.full(len(t), np.nan)
    alike = {}  # uniform pieces of one length, step and window: filtered together (_savgol_rows)
    for _, a, b in rec.pieces():
        tt, th = t[a:b], theta[a:b]
        params = _filter_params(tt, deriv_window)
        if params is None:
            continue
        dt, w, uniform = params
        if uniform:
            alike.setdefault((b - a, dt, w), []).append(a)
            continue
        vel[a:b] = _savgol(tt, th, dt, w, uniform, 1)
        acc[a:b] = _savgol(tt, th, dt, w, uniform, 2)
    for (n, dt, w), starts in alike.items():
        _savgol_rows(theta, n, dt, w, starts, vel, acc)
    return vel, acc


#: most samples filtered in one call of :func:`_savgol_rows` (bounds its temporary arrays: 8 MB each)
_ROWS_SAMPLES = 1_000_000


def _savgol_rows(theta, n, dt, w, starts, vel, acc) -> None:
    """Velocity and acceleration of the uniform pieces ``theta[a:a + n]`` (``a`` in ``starts``), all of
    one step ``dt`` and window ``w``, written into ``vel`` and ``acc``: one ``savgol_filter`` call
    per derivative on the pieces stacked as rows (of at most :data:`_ROWS_SAMPLES` samples) instead of
    one per piece.  The same numbers as :func:`_savgol` piece by piece: the filter works row by row
    (the convolution per row, the edge fits as one least-squares problem with a right-hand side per
    row; ``tests/test_segment_speed.py`` checks equality bit for bit)."""
    from scipy.signal import savgol_filter

    per = max(1, _ROWS_SAMPLES // n)
    for k in range(0, len(starts), per):
        group = starts[k:k + per]
        rows = np.stack([theta[a:a + n] for a in group])
        for deriv, out in ((1, vel), (2, acc)):
            filtered = savgol_filter(rows, w, 2, deriv=deriv, delta=dt, axis=-1)
            for a, row in zip(group, filtered):
                out[a:a + n] = row


def fit_derivatives(rec: Recording, segments, lines=None, deriv_window: int | None = None):
    """Velocity and acceleration (unit/s, unit/s^2, one per row) for a fit on ``segments``.

    The velocity is :func:`derivatives`'; so is the acceleration, except on plateau segments where a
    line of ``lines`` (cycles per unit of theta: the lines the fit models) or one of its multiples
    makes a full cycle below the position Nyquist: there it is the acceleration of the
    position-locked motion (:func:`gearspec.segment.poslock.plateau_acceleration`), which a
    derivative filter attenuates at high frequency.  ``lines`` None or empty: :func:`derivatives`.

    Returns
    -------
    (velocity, acceleration, plateaus, rows)
        The two arrays and how many plateaus and rows have the position-locked acceleration.
    """
    from .poslock import plateau_acceleration

    vel, acc = derivatives(rec, deriv_window)
    if lines is None or not len(lines):
        return vel, acc, 0, 0
    acc, n_seg, n_rows = plateau_acceleration(rec, segments, lines, acc, in_place=True)  # acc is ours
    return vel, acc, n_seg, n_rows


def _savgol(tt, th, dt, w, uniform, deriv):
    """The Savitzky-Golay derivative of one piece; a jittered one on a uniform grid of ``dt``."""
    from scipy.signal import savgol_filter

    if uniform:
        return savgol_filter(th, w, 2, deriv=deriv, delta=dt)
    grid = np.arange(tt[0], tt[-1] + dt / 2, dt)
    return np.interp(tt, grid, savgol_filter(np.interp(grid, tt, th), w, 2, deriv=deriv, delta=dt))


def _filter_params(tt: np.ndarray, deriv_window: int | None):
    """``(dt, window, uniform)`` of the Savitzky-Golay filter on one piece with sample times ``tt``,
    or None when it has fewer samples (or, jittered, fewer grid points) than the window."""
    n = len(tt)
    if n < 5:
        return None
    d = np.diff(tt)
    dt = float(np.median(d))
    if not dt > 0:
        return None
    w = int(deriv_window or max(7, int(round(0.02 / dt)) | 1)) | 1
    if w > n:
        return None
    np.subtract(d, dt, out=d)
    uniform = bool(np.max(np.abs(d)) <= 0.01 * dt)
    if not uniform and math.ceil((tt[-1] + dt / 2 - tt[0]) / dt) < w:  # len(np.arange(...)) of the grid
        return None
    return dt, w, uniform


def friction_torque(rec: Recording, inertia: float | None = None, deriv_window: int | None = None) -> np.ndarray:
    """Drive torque minus inertia torque, ``tau - J * thetadd`` (SILO4 eq. 2).

    ``inertia`` defaults to the gear spec's; without one the drive torque is returned unchanged.
    """
    J = _inertia(rec, inertia)
    if not J:
        return rec.tau
    _, acc = derivatives(rec, deriv_window)
    return rec.tau - J * np.nan_to_num(acc)


def _inertia(rec: Recording, inertia: float | None):
    return inertia if inertia is not None else (rec.gear.inertia if rec.gear is not None else None)


class FrictionTorque:
    """``friction_torque(rec, inertia, deriv_window)[rows]`` on demand, one segment at a time, bit
    for bit, without the whole-recording arrays: the acceleration is computed over the rows asked
    for plus one filter length each side (or to the piece's edge).  Jittered pieces are computed
    whole, once.  Without an inertia the rows of the drive torque are returned (a view).
    """

    def __init__(self, rec: Recording, inertia: float | None = None, deriv_window: int | None = None):
        self.rec = rec
        self.J = _inertia(rec, inertia)
        self.deriv_window = deriv_window
        self.tau = rec.tau
        self._whole = {}

    @cached_property
    def _piece_params(self):
        """``(a, b, dt, window, uniform)`` of every piece (None for the last three when too short)."""
        t, w = self.rec.t, self.deriv_window
        return [(a, b, *(_filter_params(t[a:b], w) or (None, None, None))) for _, a, b in self.rec.pieces()]

    def __getitem__(self, rows: slice) -> np.ndarray:
        start, stop, _ = rows.indices(len(self.tau))
        tau = self.tau[start:stop]
        if not self.J:
            return tau
        piece = next((p for p in self._piece_params if p[0] <= start and stop <= p[1]), None)
        if piece is None:  # rows across pieces: the whole-recording computation
            return friction_torque(self.rec, self.J, self.deriv_window)[start:stop]
        a, b, dt, w, uniform = piece
        if dt is None:  # too short for the filter: no acceleration (as friction_torque)
            return tau.copy()
        if not uniform:
            if a not in self._whole:
                self._whole[a] = _savgol(self.rec.t[a:b], self.rec.theta[a:b], dt, w, False, 2)
            acc = self._whole[a][start - a:stop - a]
        else:
            from scipy.signal import savgol_filter

            lo, hi = max(a, start - w), min(b, stop + w)
            acc = savgol_filter(self.rec.theta[lo:hi], w, 2, deriv=2, delta=dt)[start - lo:stop - lo]
        return tau - self.J * np.nan_to_num(acc)
