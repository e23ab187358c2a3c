"""Plausibility of a loaded recording: the time column is in seconds, the drive moved, the analysed
signal changes, speeds are those of a robot drive.  A refusal is an InputError of one sentence; a
doubt is a warning."""

from __future__ import annotations

import math

import numpy as np

from ..errors import InputError, warn
from .record import Recording

__all__ = ["MIN_TIME_STEP", "MIN_POSITION_RANGE", "MIN_SIGNAL_CHANGE", "MAX_PLAUSIBLE_RAD_S", "MAX_PLAUSIBLE_M_S",
           "MAX_TORQUE_TO_CURRENT", "MAX_MOTOR_TORQUE", "VELOCITY_TOLERANCE", "plausible_speed"]

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
    """Doubts about the units of theta, torque and velocity, each one warning (and a note) with the fix."""
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
    if rec.unit == "rad":
        _check_angle_unit(rec, v99, src)
    if rec.unit == "m" and v99 > MAX_PLAUSIBLE_M_S:
        warn(f"{src}: theta moves at up to {v99:.3g} m/s; if it is in mm use --scale theta=0.001")
    _check_torque_unit(rec, src)
    _check_velocity_column(rec, src)


def _doubt(rec: Recording, msg: str) -> None:
    """A doubt about the data: a warning, and a note so that reports show it (nothing is changed)."""
    rec.notes.append("warning: " + msg)
    warn(msg)


def plausible_speed(gear) -> float:
    """The largest plausible speed of the shaft ``theta`` measures, rad/s: :data:`MAX_PLAUSIBLE_RAD_S`
    at a motor, that divided by the gear's total ratio at the output of a gear (an output turns no
    faster than the fastest motor through the reduction)."""
    if gear is not None and gear.reference == "output" and gear.stages and gear.total_ratio > 1:
        return MAX_PLAUSIBLE_RAD_S / gear.total_ratio
    return MAX_PLAUSIBLE_RAD_S


def _check_angle_unit(rec: Recording, v99: float, src: str) -> None:
    """theta in degrees (too fast for the reference shaft, plausible once scaled by pi/180) or in
    encoder counts (whole numbers only: no encoder resolves as coarsely as 1 rad)."""
    limit = plausible_speed(rec.gear)
    th = rec.theta
    counts = bool(np.all(th == np.round(th))) and np.ptp(th) >= 2
    counts_fix = "scale by 2*pi/counts per turn (--scale theta=0.00153398 for 4096 counts)"
    rpm = v99 * 60 / (2 * math.pi)
    if v99 > limit:
        shaft = ("any robot drive" if limit == MAX_PLAUSIBLE_RAD_S else
                 f"the output of a gear of ratio {rec.gear.total_ratio:g} turns (at most {limit:.3g} rad/s)")
        if counts:
            fix = f"theta holds whole numbers only, likely encoder counts: {counts_fix}"
        elif v99 * math.pi / 180 <= limit:
            fix = f"if it is in degrees use --scale theta=0.0174533, if in encoder counts {counts_fix}"
        else:
            fix = f"if it is in encoder counts {counts_fix}"
        _doubt(rec, f"{src}: theta moves at up to {v99:.3g} rad/s ({rpm:.3g} rpm), faster than {shaft}; {fix}")
    elif counts:
        steps = np.abs(np.diff(th))
        _doubt(rec, f"{src}: theta holds whole numbers only (steps of {np.min(steps[steps > 0]):g}), "
                    f"and no encoder is as coarse as 1 rad: it is likely in encoder counts; {counts_fix}")


#: a torque column this many times the torque the motor current gives (gear spec's torque constant,
#: ideal gear) is not in Nm: efficiency, offsets and inertia keep the ratio of a torque in Nm within
#: about 0.1 to 10, a torque in mNm gives about 1000
MAX_TORQUE_TO_CURRENT = 100.0
#: largest plausible torque level at a motor shaft, Nm (the median |torque| while moving, divided
#: by the total ratio at the output of a gear): servo motors for robot joints are rated below about
#: 50 Nm; a level above this is a torque in mNm (or a wrong ratio)
MAX_MOTOR_TORQUE = 100.0


def _check_torque_unit(rec: Recording, src: str) -> None:
    """A torque whose level only makes sense in mNm (:data:`MAX_TORQUE_TO_CURRENT`, :data:`MAX_MOTOR_TORQUE`)."""
    if rec.unit != "rad" or rec.signal != "torque" or "torque" not in rec.data:
        return
    tau = np.abs(rec.data["torque"].to_numpy(dtype=float))
    gear = rec.gear
    fix = "if the torque is in mNm use --scale torque=0.001"
    if gear is not None and gear.torque_constant is not None and "current" in rec.data:
        cur = np.abs(gear.torque_from_current(rec.data["current"].to_numpy(dtype=float)))
        ok = np.isfinite(cur) & np.isfinite(tau)
        if ok.any() and np.median(cur[ok]) > 0:
            ratio = float(np.median(tau[ok]) / np.median(cur[ok]))
            if ratio > MAX_TORQUE_TO_CURRENT:
                _doubt(rec, f"{src}: column 'torque' is {ratio:.3g} times the torque the current gives (torque "
                            f"constant {gear.torque_constant:g} Nm/A of gear spec '{gear.name}'); {fix}")
            return
    ratio = gear.total_ratio if (gear is not None and gear.reference == "output" and gear.stages) else 1.0
    fin = np.isfinite(tau)
    # tau is this function's own array (np.abs made it): the median may reorder it in place
    level = float(np.median(tau if fin.all() else tau[fin], overwrite_input=True)) / ratio
    if level > MAX_MOTOR_TORQUE:
        at = "at the motor" + (f" (the output's divided by the ratio {ratio:g})" if ratio != 1 else "")
        _doubt(rec, f"{src}: the median torque is {level:.3g} Nm {at}, more than any robot servo motor gives "
                    f"(about {MAX_MOTOR_TORQUE:g} Nm); {fix}")


#: a velocity column within this factor of d(theta)/dt is taken as consistent (lags, filters, a
#: different derivative scheme move the ratio by a few %: Kinova's is 0.97 to 0.99)
VELOCITY_TOLERANCE = 1.25
#: clean factors a velocity column may be off by: name of the unit it then is in
_VELOCITY_FACTORS = {60 / (2 * math.pi): "as if in rpm", 180 / math.pi: "as if in deg/s",
                     1 / (2 * math.pi): "as if in rev/s", 1000.0: "as if in thousandths, mrad/s or mm/s",
                     -1.0: "the opposite sign"}


def _check_velocity_column(rec: Recording, src: str) -> None:
    """A ``velocity`` column a constant factor away from d(theta)/dt: the factor, the unit it suggests, the fix."""
    if "velocity" not in rec.data:
        return
    vel = rec.data["velocity"].to_numpy(dtype=float)
    d_all, v_all = [], []
    for _, s, e in rec.pieces():
        if e - s >= 20:
            d_all.append(np.gradient(rec.theta[s:e], rec.t[s:e]))
            v_all.append(vel[s:e])
    if not d_all:
        return
    d, v = np.concatenate(d_all), np.concatenate(v_all)
    ok = np.isfinite(d) & np.isfinite(v)
    # rows well in motion: the ratio of two small numbers is noise
    moving = ok & (np.abs(d) > 0.2 * np.percentile(np.abs(d[ok]), 90)) if ok.any() else ok
    if moving.sum() < 20:
        return
    k = float(np.median(v[moving] / d[moving]))
    if k > 0 and abs(math.log(k)) < math.log(VELOCITY_TOLERANCE):
        return
    if not (math.isfinite(k) and k != 0):
        # the column is 0 where the position moves (stick-slip: an encoder's steps while the true
        # velocity rests): not a unit, nothing to suggest
        return
    unit = rec.unit + "/s"
    factors = dict(_VELOCITY_FACTORS)
    if rec.gear is not None and rec.gear.stages and rec.gear.total_ratio > 1:
        other = "motor" if rec.gear.reference == "output" else "output"
        r = rec.gear.total_ratio
        factors[r if other == "motor" else 1 / r] = f"as if the {other}'s speed, gear ratio {r:g}"
    # a clean factor within 5 %: the ratio's scatter on a noisy or lagging column is a few %
    found = next((f for f in factors if abs(k / f - 1) < 0.05), None)
    if found is None and rec.unit == "rad" and abs(k * 180 / math.pi - 1) < 0.05:
        # the velocity in rad/s, theta in degrees: theta is what to scale
        _doubt(rec, f"{src}: column 'velocity' is {k:.4g} x d(theta)/dt, as if theta were in degrees and "
                    "the velocity in rad/s: use --scale theta=0.0174533")
        return
    what = factors[found] if found is not None else "no usual unit"
    fix = 1 / (found if found is not None else k)
    _doubt(rec, f"{src}: column 'velocity' is {k:.4g} x d(theta)/dt ({what}); it is used as {unit}: "
                f"use --scale velocity={fix:.6g}")
