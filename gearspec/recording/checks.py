"""Plausibility of a loaded recording: the time column is in seconds, the drive moved, the analysed
signal changes, speeds are those of a robot drive.  A refusal is an InputError of one sentence; a
doubt is a warning."""

from __future__ import annotations

import math

import numpy as np

from ..errors import InputError, warn
from .record import Recording

__all__ = ["MIN_TIME_STEP", "MIN_POSITION_RANGE", "MIN_SIGNAL_CHANGE", "MAX_PLAUSIBLE_RAD_S", "MAX_PLAUSIBLE_M_S"]

#: largest plausible speed of a rotary reference shaft, rad/s (about 19 000 rpm)
MAX_PLAUSIBLE_RAD_S = 2000.0
#: largest plausible speed of a linear axis, m/s
MAX_PLAUSIBLE_M_S = 10.0
#: shortest plausible sample period, s (a 1 GHz logger): below it the time column is not in seconds
MIN_TIME_STEP = 1e-9
#: smallest change of position any encoder resolves (rad or m): a 32-bit encoder's count is 1.5e-9 rad,
#: an interferometer's 1e-12 m; a theta whose whole range is below this is in the wrong unit or noise
MIN_POSITION_RANGE = 1e-12
#: a signal whose range is below this fraction of its magnitude (or below 1e-15 absolute) never changes
MIN_SIGNAL_CHANGE = 1e-12


def _check_time_unit(rec: Recording) -> None:
    t = rec.t
    if len(t) < 2:
        raise InputError(f"{', '.join(rec.sources)}: fewer than two usable rows")
    dts = [np.median(np.diff(t[s:e])) for _, s, e in rec.pieces() if e - s > 1]
    med = float(np.median(dts)) if dts else 0.0
    if dts and med < MIN_TIME_STEP:
        raise InputError(f"{', '.join(rec.sources)}: column 't' steps by {med:.3g} s (median), faster than any logger "
                         "samples; the time column is in the wrong unit (--scale t=...) or is not a time")
    if med >= 1.0:
        warn(f"{', '.join(rec.sources)}: the median time step is {med:g} s; if 't' is in ms or sample numbers, "
             "use --scale t=0.001 or --fs HZ")


def _check_signal(rec: Recording) -> None:
    """The analysed channel must change: a constant (or denormal) torque holds no friction to fit."""
    col = rec.signal
    v = rec.data[col].to_numpy(dtype=float)
    src = ", ".join(rec.sources)
    rng = float(np.ptp(v))
    if rng == 0:
        raise InputError(f"{src}: column '{col}' never changes (always {v[0]:g}); it holds no friction to analyse: "
                         "check which column is mapped to it")
    if rng < max(1e-15, MIN_SIGNAL_CHANGE * float(np.max(np.abs(v)))):
        raise InputError(f"{src}: column '{col}' changes only by {rng:.3g} in all (below any sensor's resolution); "
                         "check the column and its unit (--scale)")


def _check_motion(rec: Recording) -> None:
    theta = rec.theta
    src = ", ".join(rec.sources)
    if np.ptp(theta) == 0:
        raise InputError(f"{src}: column 'theta' never changes (always {theta[0]:g}): the drive did not move, "
                         "or the wrong column is mapped to theta")
    if np.ptp(theta) < MIN_POSITION_RANGE:
        raise InputError(f"{src}: column 'theta' moves by only {np.ptp(theta):.3g} {rec.unit} in all, less than any "
                         "encoder step: the drive did not move, or theta is in the wrong unit (--scale)")
    pieces = rec.pieces()
    longest = max(e - s for _, s, e in pieces)
    if longest < 20:
        lost = ", ".join(f"{k} {v}" for k, v in sorted(rec.excluded.items())) or "none"
        raise InputError(f"{src}: no stretch of at least 20 contiguous usable rows (longest {longest}, "
                         f"{len(rec)} usable of {rec.n_read}; excluded: {lost}); nothing can be analysed")
    if not any(_moves(theta[s:e]) for _, s, e in pieces if e - s >= 20):
        raise InputError(f"{src}: no motion: 'theta' only jitters (range {np.ptp(theta):.3g} {rec.unit}) without "
                         "moving; friction needs the drive to turn")


def _moves(th: np.ndarray) -> bool:
    """Whether one piece of positions moves beyond its jitter and its encoder step."""
    d = np.diff(th)
    nz = np.abs(d[d != 0])
    quantum = nz.min() if len(nz) else 0.0
    noise = 1.4826 * np.median(np.abs(np.diff(d) - np.median(np.diff(d)))) / math.sqrt(6) if len(d) > 2 else 0.0
    # two block lengths (not multiples of each other): a back-and-forth motion whose period is the
    # block length returns to the same place every block and would look like no motion at one
    for block in {max(10, len(th) // 200), max(10, len(th) // 1409)}:
        disp = np.abs(th[block::block] - th[:-block:block]) if len(th) > block else np.array([abs(th[-1] - th[0])])
        # slow motion seen by a coarse encoder moves less than a few counts per block: compare block
        # means too (averaging takes jitter down, a steady drift stays)
        nb = len(th) // block
        means = th[:nb * block].reshape(nb, block).mean(axis=1) if nb > 1 else th[:1]
        if max(disp.max(initial=0.0), np.ptp(means)) > 5 * max(noise * math.sqrt(2), quantum):
            return True
    return False


def _check_units(rec: Recording) -> None:
    theta, t = rec.theta, rec.t
    speeds = []
    for _, s, e in rec.pieces():
        if e - s < 20:
            continue
        step = max(1, (e - s) // 500)
        th, tt = theta[s:e:step], t[s:e:step]
        speeds.append(np.abs(np.diff(th) / np.diff(tt)))
    if not speeds:
        return
    v99 = float(np.percentile(np.concatenate(speeds), 99))
    src = ", ".join(rec.sources)
    if rec.unit == "rad" and v99 > MAX_PLAUSIBLE_RAD_S:
        warn(f"{src}: theta moves at up to {v99:.3g} rad/s ({v99 * 60 / (2 * math.pi):.3g} rpm), faster than any robot "
             "drive; if it is in degrees use --scale theta=0.0174533, if in encoder counts scale by 2*pi/counts")
    if rec.unit == "m" and v99 > MAX_PLAUSIBLE_M_S:
        warn(f"{src}: theta moves at up to {v99:.3g} m/s; if it is in mm use --scale theta=0.001")
