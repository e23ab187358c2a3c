"""Synthetic recordings with known truth: constant-speed plateaus with position-locked ripple of
known amplitude and phase (:func:`plateau_recording`, SILO4 eq. 11's shape), plateaus whose friction
is any :class:`~gearspec.model.FrictionModel` (:func:`model_recording`), quasi-static stepped maps,
excitation trajectories, and any model driven open loop by a velocity profile (:func:`motion_recording`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import laws
from ..errors import InputError
from ..model import FrictionModel
from ..recording import Recording
from .profiles import position, velocity_profile
from .scatter import run_scatter

__all__ = ["Ripple", "plateau_recording", "model_recording", "quasi_static_recording", "excitation_recording",
           "motion_recording"]


@dataclass(frozen=True)
class Ripple:
    """A position-locked component: ``amplitude * exp(-decay |v|) * sin(2 pi frequency theta + phase)``.

    ``amplitude``, ``decay`` and ``phase`` may be pairs ``(positive, negative)`` for direction-
    dependent values.
    """

    frequency: float
    amplitude: float | tuple[float, float]
    phase: float | tuple[float, float] = 0.0
    decay: float | tuple[float, float] = 0.0

    def value(self, name: str, direction: int) -> float:
        v = getattr(self, name)
        if isinstance(v, (tuple, list)):
            return float(v[0] if direction > 0 else v[1])
        return float(v)

    def amplitude_at(self, speed: float, direction: int) -> float:
        return self.value("amplitude", direction) * np.exp(-self.value("decay", direction) * abs(speed))


def plateau_recording(speeds, *, ripples=(), level=0.01, duration=2.0, fs=1000.0, ramp=0.2,
                      speed_ripple=0.0, speed_ripple_frequency=None, noise=0.0, theta0=0.0,
                      one_run_per_plateau=False, quantum=0.0, gear=None, unit="rad", seed=None):
    """A recording that visits constant-velocity plateaus, with known ripple.

    The drive torque is ``sign(v) * (level(|v|, dir) + sum_k A_k(|v|, dir) sin(2 pi f_k theta +
    phi_k)) + noise`` (SILO4 eq. 11's shape), ``A_k = amplitude_k exp(-decay_k |v|)`` from ``ripples``.

    Parameters
    ----------
    speeds : sequence of float
        Signed plateau velocities (unit/s), visited in order, starting from standstill.
    ripples : sequence of Ripple
    level : float or callable
        Friction magnitude without ripple: a number, or ``level(speed, direction)`` (vectorised).
    duration : float or sequence
        Seconds held on each plateau.
    fs, ramp : float
        Sample rate (Hz); seconds of each linear velocity ramp between plateaus and from/to rest.
    speed_ripple, speed_ripple_frequency : float
        Relative speed ripple on plateaus, ``v (1 + r sin(2 pi f_r theta))``, and its frequency over
        position (default: that of the first ripple, as a friction-driven closed loop would show).
    noise : float
        Standard deviation of white torque noise.
    one_run_per_plateau : bool
        Give every plateau (with its ramps) its own ``run`` id and restart time at 0.
    quantum : float
        Encoder resolution: theta is rounded to multiples of it (0: exact).
    gear, unit, seed
        Passed to the recording; the noise's seed.

    Returns
    -------
    recording : Recording
    truth : list of dict
        Per plateau: ``direction``, ``speed``, ``level``, ``t0``, ``t1`` (the held part), ``run``
        and ``ripples`` (list of ``frequency``, ``amplitude``, ``phase``).
    """
    rng = np.random.default_rng(seed)
    speeds = list(speeds)
    lvl = level if callable(level) else (lambda s, d, _c=float(level): _c)
    f_r = speed_ripple_frequency if speed_ripple_frequency is not None else (ripples[0].frequency if ripples else 1.0)
    t, theta, v_actual, hold, idx, run = _profile(speeds, duration, fs, ramp, speed_ripple, f_r, theta0,
                                                  one_run_per_plateau)
    n = len(t)
    direction = np.sign(v_actual)
    torque = np.zeros(n)
    truth = []
    for j, v in enumerate(speeds):
        d = 1 if v > 0 else -1
        sel = idx == j
        spd = np.abs(v_actual[sel])
        y = np.broadcast_to(np.asarray(lvl(spd, d), dtype=float), spd.shape).copy()
        rip = []
        for r in ripples:
            y = y + laws.meshing_ripple(theta[sel], spd, r.value("amplitude", d), r.value("decay", d), r.frequency,
                                        r.value("phase", d))
            rip.append({"frequency": r.frequency, "amplitude": r.amplitude_at(abs(v), d), "phase": r.value("phase", d)})
        torque[sel] = np.where(direction[sel] != 0, direction[sel], d) * y
        held = sel & hold
        truth.append({"direction": d, "speed": abs(v), "level": float(lvl(np.float64(abs(v)), d)), "t0": float(t[held][0]),
                      "t1": float(t[held][-1]), "run": int(run[held][0]), "ripples": rip})
    if noise:
        torque = torque + rng.normal(0.0, noise, n)
    meas_theta = np.round(theta / quantum) * quantum if quantum else theta
    rec = Recording.from_arrays(t=t, theta=meas_theta, torque=torque, run=run, gear=gear, unit=unit,
                                source="synthetic")
    return rec, truth


def _profile(speeds, duration, fs, ramp, speed_ripple, f_r, theta0, one_run_per_plateau):
    """Velocity profile of plateaus joined by linear ramps, with a position-locked speed ripple on
    the plateaus; returns ``t, theta, v, hold, plateau_index, run``."""
    durations = list(duration) if np.ndim(duration) else [float(duration)] * len(speeds)
    if len(durations) != len(speeds):
        raise ValueError(f"{len(durations)} durations for {len(speeds)} plateaus")
    dt = 1.0 / fs
    # velocity command profile: ramp -> hold -> (next) ..., back to 0 at the end; pieces (command, held)
    pieces = []
    prev = 0.0
    n_r = max(1, int(round(ramp * fs)))
    for v, dur in zip(speeds, durations):
        pieces.append((np.linspace(0.0 if one_run_per_plateau else prev, v, n_r, endpoint=False), False))
        pieces.append((np.full(int(round(dur * fs)), float(v)), True))
        if one_run_per_plateau:
            pieces.append((np.linspace(v, 0.0, n_r), False))
        prev = v
    if not one_run_per_plateau:
        pieces.append((np.linspace(prev, 0.0, n_r), False))
    vcmd = np.concatenate([p for p, _ in pieces])
    hold = np.concatenate([np.full(len(p), h) for p, h in pieces])
    # plateau index per sample (which plateau's hold/ramp-in it belongs to)
    per = 3 if one_run_per_plateau else 2
    idx = np.concatenate([np.full(len(p), min(j // per, len(speeds) - 1)) for j, (p, _) in enumerate(pieces)])
    n = len(vcmd)
    theta = float(theta0) + np.concatenate(([0.0], np.cumsum(vcmd[:-1]) * dt))
    v_actual = vcmd
    if speed_ripple:
        # theta' = v_cmd (1 + r sin(2 pi f theta)) on the plateaus, stepped exactly as sampled
        # (theta[i+1] = theta[i] + v[i] dt), so that position, velocity and acceleration agree
        k = 2 * np.pi * f_r
        gain = vcmd * speed_ripple * hold
        th = np.empty(n)
        v_actual = np.empty(n)
        x = float(theta0)
        for i, (vc, g) in enumerate(zip(vcmd.tolist(), gain.tolist())):
            th[i] = x
            vi = vc + g * math.sin(k * x)
            v_actual[i] = vi
            x += vi * dt
        theta = th
    if one_run_per_plateau:
        run = idx.astype(np.int64)
        t = np.concatenate([np.arange(np.sum(run == r)) * dt for r in range(len(speeds))])
    else:
        run = np.zeros(n, np.int64)
        t = np.arange(n) * dt
    return t, theta, v_actual, hold, idx, run


def _per_plateau(value, idx, t, name, n_plateaus):
    """A channel from a scalar, a per-plateau sequence or a callable of time."""
    if value is None:
        return None
    if callable(value):
        return np.asarray(value(t), dtype=float) * np.ones(len(t))
    if np.ndim(value) == 0:
        return np.full(len(t), float(value))
    value = np.asarray(value, dtype=float)
    if len(value) != n_plateaus:
        raise ValueError(f"{name}: {len(value)} values for {n_plateaus} plateaus")
    return value[idx]


def model_recording(model, speeds, *, duration=2.0, fs=1000.0, ramp=0.2, speed_ripple=0.0,
                    speed_ripple_frequency=1.0, noise=0.0, load=None, temperature=None, inertia=0.0,
                    one_run_per_plateau=True, quantum=0.0, gear=None, unit="rad", theta0=0.0, seed=None,
                    scatter=0.0, noise_correlation=0.0):
    """A recording of plateaus whose friction is ``model`` (a FrictionModel, evaluated at every
    sample), with known truth.

    ``speeds, duration, fs, ramp, speed_ripple, one_run_per_plateau, quantum, gear, unit, theta0,
    seed`` as in :func:`plateau_recording`; ``speed_ripple_frequency`` in cycles per unit; ``noise``:
    sd of white torque noise (Nm); ``load`` (Nm), ``temperature`` (degC): a number, one per plateau
    or a callable of the time of each sample (restarting at 0 in each run when
    ``one_run_per_plateau``), recorded and passed to the model; ``inertia``: rotor inertia J, the
    drive torque is ``friction + J thetadd``; ``scatter``: repetition scatter (relative sd): the
    base law's linear parameters and the line amplitudes of each plateau (run) have their own factors
    ``1 + scatter N(0, 1)`` (:func:`~.scatter.run_scatter`); ``noise_correlation``: the noise is
    AR(1) with this coefficient between consecutive samples (0: white; its sd stays ``noise``).

    Returns the recording and, per plateau, ``direction``, ``speed``, ``run``, ``t0``, ``t1`` and
    ``level`` (the model's position-averaged friction magnitude at the plateau speed; with scatter,
    also ``factors``: the plateau's factor of each parameter of ``scatter["parameters"]``).  With
    ``scatter`` > 0 the truth is ``(plateaus, scatter)``: :meth:`~.scatter.RunScatter.truth`.
    """
    rng = np.random.default_rng(seed)
    speeds = list(speeds)
    t, theta, v, hold, idx, run = _profile(speeds, duration, fs, ramp, speed_ripple, speed_ripple_frequency, theta0,
                                           one_run_per_plateau)
    ld = _per_plateau(load, idx, t, "load", len(speeds))
    temp = _per_plateau(temperature, idx, t, "temperature", len(speeds))
    acc = np.gradient(v, 1.0 / fs)
    torque = model.evaluate(theta, v, load=ld, temperature=temp, t=t, acc=acc, run=run) + inertia * acc
    scat = run_scatter(model, scatter, len(speeds), rng, np.sign(speeds))
    if scat is not None:
        torque = torque + scat.extra(theta, v, idx, load=ld, temperature=temp, t=t)
    if noise:
        torque = torque + _ar1(rng, noise, len(t), noise_correlation)
    truth = []
    for j, sp in enumerate(speeds):
        held = (idx == j) & hold
        d = 1 if sp > 0 else -1
        lvl = model.mean_level(abs(sp), d, load=None if ld is None else ld[held][:1])
        truth.append({"direction": d, "speed": abs(sp), "run": int(run[held][0]), "t0": float(t[held][0]),
                      "t1": float(t[held][-1]), "level": float(lvl[0])})
        if scat is not None:
            truth[-1]["factors"] = scat.factors[j].tolist()
    meas_theta = np.round(theta / quantum) * quantum if quantum else theta
    rec = Recording.from_arrays(t=t, theta=meas_theta, torque=torque, run=run, load=ld, temperature=temp, gear=gear,
                                unit=unit, source="synthetic")
    return rec, (truth if scat is None else (truth, scat.truth(model)))


def _ar1(rng: np.random.Generator, sd: float, n: int, rho: float) -> np.ndarray:
    """``n`` samples of AR(1) noise with marginal standard deviation ``sd`` and lag-1 correlation
    ``rho`` (0: white)."""
    if not -1.0 < float(rho) < 1.0:
        raise InputError(f"noise_correlation must lie between -1 and 1, got {rho}")
    e = rng.normal(0.0, sd, n)
    if rho == 0.0:
        return e
    from scipy.signal import lfilter

    e[1:] *= math.sqrt(1.0 - rho * rho)
    return lfilter([1.0], [1.0, -rho], e)


# ---------------------------------------------------------------------- quasi-static maps
def quasi_static_recording(*, step=0.002, revolutions=1.0, levels=(0.05, 0.04), ripples=(), noise=0.0,
                           median_dt=0.013, dt_spread=0.35, gap_probability=0.01, max_gap=1.0,
                           repeat_probability=0.05, position_noise=0.0, theta0=0.0, velocity=False,
                           gear=None, unit="rad", seed=None):
    """A quasi-static stepped map: a row stored only when the shaft is at rest after each step.

    A position loop steps the shaft by ``step`` over ``revolutions`` turns forward, then back over
    the same travel.  Rows come at irregular times: log-normal steps of median ``median_dt``
    (log-sd ``dt_spread``), now and then (``gap_probability``) a pause uniform up to ``max_gap`` s,
    and with ``repeat_probability`` a further row at the same position (the loop stored twice).

    The friction magnitude at rest is that of the direction d of the last step: torque = d * y + noise,
    ``y = level_d + sum_k A_k,d sin(2 pi f_k theta + phi_k,d)`` (``level = (forward, backward)``;
    ``ripples``: :class:`Ripple` with per-direction amplitude and phase, decay ignored).

    Returns the recording and the truth: ``directions`` (for +1 and -1, ``level`` and ``ripples``:
    ``frequency``, ``amplitude``, ``phase`` in the friction-magnitude frame), ``sweeps`` ((start,
    stop, direction) rows) and ``n`` (rows).
    """
    rng = np.random.default_rng(seed)
    n_steps = int(round(revolutions * 2 * np.pi / step))
    fwd = theta0 + step * np.arange(n_steps + 1)
    pos = np.concatenate([fwd, fwd[::-1][1:]])
    dirs = np.concatenate([np.ones(n_steps + 1, int), -np.ones(n_steps, int)])
    # repeated rows at the same position
    reps = 1 + (rng.random(len(pos)) < repeat_probability).astype(int)
    pos = np.repeat(pos, reps)
    dirs = np.repeat(dirs, reps)
    n = len(pos)
    dt = median_dt * np.exp(dt_spread * rng.standard_normal(n - 1))
    gaps = rng.random(n - 1) < gap_probability
    dt[gaps] = rng.uniform(5 * median_dt, max_gap, int(gaps.sum()))
    t = np.concatenate(([0.0], np.cumsum(dt)))
    lvl = {1: float(levels[0]), -1: float(levels[1])}
    y = np.where(dirs > 0, lvl[1], lvl[-1])
    truth = {"directions": {}, "n": n}
    for d in (1, -1):
        sel = dirs == d
        rip = []
        for r in ripples:
            a, ph = r.value("amplitude", d), r.value("phase", d)
            y[sel] += laws.position_ripple(pos[sel], a, r.frequency, ph)
            rip.append({"frequency": r.frequency, "amplitude": a, "phase": ph})
        truth["directions"][d] = {"level": lvl[d], "ripples": rip}
    torque = dirs * y + (rng.normal(0.0, noise, n) if noise else 0.0)
    meas = pos + (rng.normal(0.0, position_noise, n) if position_noise else 0.0)
    turn = int(np.flatnonzero(dirs < 0)[0])
    truth["sweeps"] = [(0, turn, 1), (turn, n, -1)]
    cols = {"velocity": rng.normal(0.0, 1e-4, n)} if velocity else {}
    rec = Recording.from_arrays(t=t, theta=meas, torque=torque, gear=gear, unit=unit, source="synthetic-quasi-static",
                                **cols)
    return rec, truth


# ---------------------------------------------------------------------- excitation trajectories
def excitation_recording(*, fs=250.0, move=10.0, amplitude=2.0, cruise_speed=1.5, creep=0.2, creep_time=2.0,
                         sines=((0.2, 1.0), (0.5, 0.4), (1.1, 0.15)), position_noise=2e-5, noise=0.02,
                         level=0.3, viscous=0.05, inertia=0.01, gear=None, unit="rad", seed=None):
    """An industrial axis moved by excitation trajectories: no plateau except where stated.

    Three moves of ``move`` seconds each, sampled at ``fs`` (4 ms), one run, one after the other:

    1. a bell-shaped point-to-point move of ``amplitude`` rad (minimum-jerk velocity profile),
       there and back;
    2. a smooth point-to-point move with a genuine constant-speed cruise at ``cruise_speed``
       (velocity ramps shaped as half-cosines), there and back;
    3. a sum of sines (``sines``: (frequency Hz, velocity amplitude rad/s) pairs), a Fourier
       excitation trajectory with speeds sweeping through zero.

    Every move ends in a creeping tail: the axis keeps creeping at ``creep`` rad/s, decaying to
    rest over ``creep_time`` s (a position loop settling against friction), in the direction of the
    last motion.  Torque: ``sign(v) (level + viscous |v|) + inertia * acc`` plus white noise.

    Returns the recording and the truth: ``velocity`` (true, every row), ``acceleration``,
    ``cruise`` ((t0, t1, speed) of the genuine constant-speed stretches), ``tails`` ((t0, t1)).
    """
    rng = np.random.default_rng(seed)
    dt = 1.0 / fs
    vs, cruise, tails = [], [], []
    t_now = 0.0

    def add(v, kind=None, speed=None):
        nonlocal t_now
        if kind == "cruise":
            cruise.append((t_now, t_now + (len(v) - 1) * dt, speed))
        if kind == "tail":
            tails.append((t_now, t_now + (len(v) - 1) * dt))
        vs.append(v)
        t_now += len(v) * dt

    def tail(sign):
        tt = np.arange(int(round(creep_time * fs))) * dt
        add(sign * creep * (1 - tt / creep_time) ** 2 * (1 + 0.3 * np.sin(2 * np.pi * 1.3 * tt)), "tail")

    half = 0.5 * (move - 2 * creep_time)
    # 1. minimum-jerk there and back: v = A/T * 30 s^2 (1-s)^2
    for sign in (1, -1):
        s = np.arange(int(round(half * fs))) * dt / half
        add(sign * amplitude / half * 30 * s ** 2 * (1 - s) ** 2)
        tail(sign)
    # 2. cruise between half-cosine ramps, there and back
    for sign in (1, -1):
        ramp = 0.8
        r = np.arange(int(round(ramp * fs))) * dt / ramp
        up = cruise_speed * 0.5 * (1 - np.cos(np.pi * r))
        add(sign * up)
        add(np.full(int(round((half - 2 * ramp) * fs)), sign * cruise_speed), "cruise", cruise_speed)
        add(sign * up[::-1])
        tail(sign)
    # 3. sum of sines with a window that starts and ends at rest
    T = move - creep_time
    tt = np.arange(int(round(T * fs))) * dt
    w = np.sin(np.pi * tt / T) ** 2
    v3 = w * sum(a * np.sin(2 * np.pi * f * tt) for f, a in sines)
    add(v3)
    tail(np.sign(v3[np.flatnonzero(np.abs(v3) > 1e-3)[-1]]) or 1.0)
    v = np.concatenate(vs)
    n = len(v)
    t = np.arange(n) * dt
    theta = np.concatenate(([0.0], np.cumsum(0.5 * (v[1:] + v[:-1])) * dt))
    acc = np.gradient(v, dt)
    friction = FrictionModel("coulomb_viscous", {"tau_c": level, "viscous": viscous}).evaluate(theta, v)
    torque = friction + inertia * acc + rng.normal(0.0, noise, n)
    meas = theta + rng.normal(0.0, position_noise, n)
    rec = Recording.from_arrays(t=t, theta=meas, torque=torque, gear=gear, unit=unit, source="synthetic-excitation")
    return rec, {"velocity": v, "acceleration": acc, "cruise": cruise, "tails": tails}


# ---------------------------------------------------------------------- any motion, open loop
def motion_recording(model: FrictionModel, profile: str = "bell", *, top_speed: float, duration: float,
                     fs: float = 1000.0, inertia: float = 0.0, noise: float = 0.0, position_noise: float = 0.0,
                     gear=None, load=None, seed=None, **profile_options):
    """A shaft moved open loop along a velocity profile, its torque from ``model``: exact and fast.

    ``theta`` is the trapezoid integral of the profile's velocity ``v``
    (:func:`~gearspec.simulate.profiles.velocity_profile`; ``profile_options`` its keywords, ``seed``
    also the sine's phases), ``acc = np.gradient(v, 1 / fs)``, and the torque
    ``model.evaluate(theta, v, load=..., t=..., acc=acc, run=0) + inertia * acc`` plus white noise.

    Parameters
    ----------
    model : FrictionModel
        The friction (SI, at the shaft ``theta`` measures).
    profile : str
        ``plateaus``, ``ramp``, ``chirp``, ``bell`` or ``sine``.
    top_speed, duration, fs : float
        rad/s (both directions), s, Hz.
    inertia : float
        kg m^2 at the shaft; its torque ``inertia * acc`` is added (undeclared unless ``gear`` says it).
    noise, position_noise : float
        Standard deviations of white noise on the torque (Nm) and on the recorded position (rad).
    gear, load, seed
        The recording's gear spec; the load (Nm: a number, one per sample or ``load(t)``), recorded
        and passed to the model; the noise's seed.

    Returns
    -------
    recording : Recording
        ``t, theta, torque, run`` (0) and ``load`` when given.
    truth : dict
        ``profile`` (kind, top_speed, duration, fs, options, seed), ``theta`` (true), ``velocity``,
        ``acceleration``, ``friction`` (the model's part of the torque), ``inertia``, ``noise``,
        ``position_noise``.
    """
    t, v = velocity_profile(profile, top_speed=top_speed, duration=duration, fs=fs, seed=seed, **profile_options)
    n = len(t)
    theta = position(v, fs)
    acc = np.gradient(v, 1.0 / fs)
    if load is not None:
        load = np.asarray(load(t) if callable(load) else load, dtype=float)
        load = np.full(n, float(load)) if load.ndim == 0 else load
        if load.shape != (n,):
            raise InputError(f"motion_recording: load must be a number, {n} values (one per sample) or load(t)")
    run = np.zeros(n, np.int64)
    friction = model.evaluate(theta, v, load=load, t=t, acc=acc, run=run)
    rng = np.random.default_rng(seed)
    torque = friction + inertia * acc + (rng.normal(0.0, noise, n) if noise else 0.0)
    meas = theta + (rng.normal(0.0, position_noise, n) if position_noise else 0.0)
    rec = Recording.from_arrays(t=t, theta=meas, torque=torque, run=run, load=load, gear=gear,
                                source=f"synthetic-{profile}")
    record = {"kind": profile, "top_speed": float(top_speed), "duration": float(duration), "fs": float(fs),
              "options": dict(profile_options), "seed": seed}
    return rec, {"profile": record, "theta": theta, "velocity": v, "acceleration": acc, "friction": friction,
                 "inertia": float(inertia), "noise": float(noise), "position_noise": float(position_noise)}
