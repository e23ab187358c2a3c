"""The acceleration of position-locked motion on constant-speed plateaus, without a derivative filter.

On a plateau the speed ripple that matters for the inertia torque ``J thetadd`` is locked to the
position: the gear's lines (cogging, shafts, meshes) make it.  A Savitzky-Golay second derivative
over a fixed number of samples passes only part of that acceleration at high frequency (its gain
at 48 Hz over 7 samples at 4 ms is 0.25), and the part left in the torque is in quadrature with the
line, so it turns the fitted line's phase.  Here time is fitted over position on each plateau,

    t(theta) = c0 + c1 u + c2 u^2 + sum_j (a_j sin + b_j cos)(2 pi f_j theta),

``u`` the position scaled to [-1, 1] over the plateau, ``f_j`` the lines (cycles per unit of theta)
and their multiples up to :data:`ORDERS`; then ``v = 1 / t'(theta)`` and ``thetadd = -v^3 t''(theta)``,
exact for a locked ripple at any speed (least squares, linear in the rows).

The rule (:func:`locked_frequencies`): a frequency is used on a plateau when it makes at least
:data:`MIN_CYCLES` full cycle there and lies below ``MEASURABLE_FRACTION`` of the plateau's position
Nyquist frequency (the rule of :func:`gearspec.spectrum.position_nyquist`, the fit's own); a plateau
with no such frequency, free motion, ramps and quasi-static sweeps keep the Savitzky-Golay derivative.
"""

from __future__ import annotations

import numpy as np

__all__ = ["ORDERS", "MIN_CYCLES", "locked_frequencies", "locked_acceleration", "plateau_acceleration"]

#: multiples of each line in the time-over-position fit (a linear loop's response to a line is at the
#: line; its multiples carry what the line's own shape and 1/v add)
ORDERS = 3
#: full cycles of a frequency on a plateau before it enters the fit
MIN_CYCLES = 1.0


def locked_frequencies(theta: np.ndarray, frequencies, nyquist: float | None = None) -> np.ndarray:
    """The frequencies (cycles per unit of theta) of the time-over-position fit on one plateau.

    Parameters
    ----------
    theta : array
        The plateau's positions (rad or m), in time order.
    frequencies : sequence of float
        The lines the fit models (cycles per unit of theta); each with its multiples up to :data:`ORDERS`.
    nyquist : float, optional
        The plateau's position Nyquist frequency (cycles per unit of theta); default
        :func:`gearspec.spectrum.position_nyquist` of ``theta``.

    Returns
    -------
    array
        The distinct frequencies with at least :data:`MIN_CYCLES` cycles on the plateau and below
        ``MEASURABLE_FRACTION`` x ``nyquist``, ascending (empty: keep the Savitzky-Golay derivative).
    """
    from ..spectrum.analysis import MEASURABLE_FRACTION, position_nyquist

    f = np.asarray(frequencies, dtype=float).ravel()
    if len(theta) < 2 or not len(f):
        return np.empty(0)
    f = np.unique(np.round((f[:, None] * np.arange(1, ORDERS + 1)).ravel(), 12))
    travel = abs(float(theta[-1]) - float(theta[0]))
    ny = position_nyquist(np.asarray(theta, dtype=float)) if nyquist is None else float(nyquist)
    return f[(f * travel >= MIN_CYCLES) & (f < MEASURABLE_FRACTION * ny)]


def locked_acceleration(t: np.ndarray, theta: np.ndarray, frequencies) -> np.ndarray:
    """The acceleration (unit/s^2) of one plateau's motion from its sample times and positions.

    Parameters
    ----------
    t : array
        Sample times (s); any spacing.
    theta : array
        Positions (rad or m), monotonic over the plateau up to encoder steps.
    frequencies : sequence of float
        The frequencies of the fit (cycles per unit of theta), e.g. from :func:`locked_frequencies`.

    Returns
    -------
    array
        ``-v^3 t''(theta)`` per sample, ``v = 1 / t'(theta)``, of the least-squares fit of
        ``t(theta)`` (module docstring).
    """
    return _time_fit(t, theta, frequencies, residual=False)[0]


def _time_fit(t, theta, frequencies, residual: bool = True):
    """``(acc, v, r)``: the locked acceleration and velocity at each sample and the residual time
    ``t - t(theta)`` (s) of the fit of :func:`locked_acceleration` (``residual`` False: None, not
    computed)."""
    from ..core.reduction import gram

    t = np.asarray(t, dtype=float)
    th = np.asarray(theta, dtype=float)
    lo, hi = float(th.min()), float(th.max())
    mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo) or 1.0
    u = (th - mid) / half
    w = 2 * np.pi * np.asarray(frequencies, dtype=float)
    ph = th[:, None] * w[None, :]
    s, c = np.sin(ph), np.cos(ph)
    X = np.column_stack([np.ones_like(u), u, u * u, s, c])
    # the straight line first (t spans seconds, the lines' part microseconds), then the normal
    # equations of the rest (p x p, p = 3 + 2 lines: no LAPACK call on the N rows)
    tc = t - t.mean()
    slope = float(np.dot(u - u.mean(), tc) / np.dot(u - u.mean(), u - u.mean()))
    rest = tc - slope * u
    coef = np.linalg.lstsq(gram(X), X.T @ rest, rcond=None)[0]
    coef[1] += slope
    m = len(w)
    a, b = coef[3:3 + m], coef[3 + m:]
    d1 = (coef[1] + 2 * coef[2] * u) / half + c @ (w * a) - s @ (w * b)
    d2 = 2 * coef[2] / half ** 2 - s @ (w * w * a) - c @ (w * w * b)
    v = 1.0 / d1
    return -v ** 3 * d2, v, (tc - X @ coef) if residual else None


def plateau_acceleration(rec, segments, frequencies, acc: np.ndarray,
                         in_place: bool = False) -> tuple[np.ndarray, int, int]:
    """``acc`` (one per row of ``rec``, e.g. the Savitzky-Golay one) with the rows of each plateau
    segment that qualifies (:func:`locked_frequencies`) replaced by :func:`locked_acceleration`.

    Parameters
    ----------
    rec : Recording
        The recording (its ``t`` s and ``theta``).
    segments : iterable of Segment
        The fit's segments; only ``kind == "plateau"`` ones are considered.
    frequencies : sequence of float
        The lines the fit models (cycles per unit of theta).
    acc : array
        The acceleration elsewhere (unit/s^2); not modified unless ``in_place``.
    in_place : bool
        Write the plateaus' accelerations into ``acc`` (a float64 array) and return it, instead of
        into a copy (a caller that owns ``acc``: one full-length array less).

    Returns
    -------
    (array, int, int)
        The acceleration, and how many plateaus and rows got the position-locked one.
    """
    out = acc if (in_place and acc.dtype == np.float64) else np.array(acc, dtype=float, copy=True)
    n_seg = n_rows = 0
    if frequencies is None or not len(frequencies):
        return out, 0, 0
    t, theta = rec.t, rec.theta
    plateaus = [s for s in segments if s.kind == "plateau"]

    def one(s):
        th = theta[s.start:s.stop]
        f = locked_frequencies(th, frequencies)
        if not len(f) or s.n < 2 * (3 + 2 * len(f)):   # at least two rows per coefficient
            return None
        return locked_acceleration(t[s.start:s.stop], th, f)

    for s, a in zip(plateaus, _map_plateaus(one, plateaus)):
        if a is None:
            continue
        out[s.start:s.stop] = a
        n_seg += 1
        n_rows += s.n
    return out, n_seg, n_rows


#: plateaus of at least this many rows between them (and ``FORK_MIN_PLATEAUS`` or more) get their
#: accelerations in forked worker processes (:func:`~gearspec.core.parallel.forked_map`) when BLAS
#: runs on one thread here (as ``fit`` holds it, and as in the workers): the same numbers
FORK_MIN_ROWS = 500_000
FORK_MIN_PLATEAUS = 8
#: plateaus per task: a few tasks per worker
_TASKS_PER_WORKER = 4


def _map_plateaus(one, plateaus: list) -> list:
    """``[one(s) for s in plateaus]``, in contiguous chunks by a forked map when the rule above allows."""
    from ..core.parallel import forked_map_chunked, worker_count
    from ..core.reduction import blas_on_one_thread

    rows = sum(s.n for s in plateaus)
    n = (worker_count() if len(plateaus) >= FORK_MIN_PLATEAUS and rows >= FORK_MIN_ROWS
         and blas_on_one_thread() else 1)
    return forked_map_chunked(one, plateaus, workers=n, tasks_per_worker=_TASKS_PER_WORKER)
