"""Digital twin of the Lola/CROPS friction testbed (section IV of the testbed paper).

A speed-controlled drive module (BLDC motor, HarmonicDrive gear) is loaded by a current-controlled
hysteresis brake behind a torque sensor; the automatic mode sets a speed, raises the load step by
step to its maximum, holding each operating point several seconds, then moves to the next speed.
Current and load are low-pass filtered and averaged per point; friction and efficiency follow from
eqs. (12) and (13).  The twin's friction is law (11) with Table IV's values (:func:`table4_model`)
or any ``truth`` model, plus the effects of :mod:`gearspec.simulate.effects`.  SI at the motor
(wave-generator) side: theta in motor rad, speeds in rad/s of the motor, load in Nm at the output,
friction in Nm at the motor with the sign of the velocity.

The unknowns, chosen (the paper does not give them; values in :data:`TESTBED`, :data:`MODULES`)
-------------------------------------------------------------------------------------------------
* Grid ("points equally spaced between maximum and minimum speeds and torques"): 8 speeds per
  direction, 25-400 rad/s for A and C (0.25-4 times their Stribeck velocity of 100 rad/s) and
  10-290 rad/s for B (Stribeck velocity 31.5 rad/s); 8 loads from 5 % to 80 % of the nominal output
  torque ``k_m I_nom N`` (the paper's loads reach "the nominal torque"); 5 s per point.
* Brake: torque ``K_b U`` through a 50 ms coil lag, 0-24 V, 0.092-17 Nm; loads above 17 Nm use the
  brake behind the 5:1 testbed gear (0.46-85 Nm), a second campaign over all speeds as on the real
  bench.  PI control with anti-windup, its zero on the coil pole, closed-loop time constant 0.25 s:
  settled in about 1 s, as in the paper's Fig. 4.
* Ideal motor speed control (its loops are far faster than a 5 s point), 1 s linear ramps between
  speeds; current ``(friction + load / N + J thetadd) / k_m``.  Motor + wave-generator inertia
  A 3e-5, B 8e-5, C 1.2e-5 kg m^2 (they matter only on the ramps).
* Per point: current and load filtered (Butterworth, 2 Hz) and averaged over the last 3 s.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Iterable, Sequence

import numpy as np
import pandas as pd
from scipy import signal

from .. import laws
from ..errors import InputError
from ..gears import GearTrain, load_gear
from ..model import FrictionModel
from ..recording import Recording
from .effects import Effect, apply_effects, effect_channels, effects_truth
from ..jsonsafe import plain
from .profiles import Reference, reference
from .silo4 import TwinTruth

__all__ = ["MODULES", "PAPER_TABLE3", "PAPER_TABLE4", "TESTBED", "table3_model", "table4_model", "lola_twin",
           "default_speeds", "default_loads", "module_gear", "PROFILE_DURATION"]

#: Table II, with the ratio from the gear's name and the choices of the twin (see the docstring)
MODULES = {
    "A": {"name": "Lola adduction", "torque_constant": 0.13, "nominal_current": 7.0, "gear_model": "HFUC-25-100",
          "gear": "lola-a", "inertia": 3e-5, "speed_range": (25.0, 400.0)},
    "B": {"name": "Lola flexion", "torque_constant": 0.097, "nominal_current": 15.0, "gear_model": "CSG-32-50",
          "gear": "lola-b", "inertia": 8e-5, "speed_range": (10.0, 290.0)},
    "C": {"name": "Crops test", "torque_constant": 0.075, "nominal_current": 3.5, "gear_model": "CSD-20-100",
          "gear": "lola-c", "inertia": 1.2e-5, "speed_range": (25.0, 400.0)},
}
for _m in MODULES.values():
    _m["ratio"] = float(_m["gear_model"].rsplit("-", 1)[1])
    _m["nominal_output_torque"] = _m["torque_constant"] * _m["nominal_current"] * _m["ratio"]

#: Table III (law (8) fitted to measured efficiency), SI
PAPER_TABLE3 = {
    "A": {"t_f0": 0.098, "mu": 3.10e-3, "b": 2.73e-4, "gamma": 0.0, "rms": 1.11e-2},
    "B": {"t_f0": 0.456, "mu": 8.60e-3, "b": 7.36e-4, "gamma": 0.0, "rms": 4.99e-2},
    "C": {"t_f0": 0.067, "mu": 4.4e-3, "b": 2.26e-4, "gamma": 0.0, "rms": 6.4e-3},
}
#: Table IV (law (11) fitted to measured efficiency), SI (v_s in rad/s of the motor)
PAPER_TABLE4 = {
    "A": {"t_f0": 0.174, "mu": 3.10e-3, "b": 4.41e-5, "t_fs": 0.079, "v_s": 99.98, "rms": 4.6e-3},
    "B": {"t_f0": 0.479, "mu": 1.20e-2, "b": 4.275e-4, "t_fs": 0.078, "v_s": 31.525, "rms": 1.20e-2},
    "C": {"t_f0": 0.112, "mu": 4.4e-3, "b": 9.06e-5, "t_fs": 0.057, "v_s": 99.985, "rms": 3.0e-3},
}

#: seconds of a motion profile per load (eight loads: 160 s, against 656 s of the default grid)
PROFILE_DURATION = 20.0

#: the testbed's settings, as chosen (see the module docstring)
TESTBED = {
    "fs": 1000.0,                  # Hz, recording and simulation
    "hold": 5.0,                   # s per operating point
    "average": 3.0,                # s averaged at the end of each point
    "ramp": 1.0,                   # s between speeds
    "brake_max": 17.0,             # Nm, configuration 1
    "brake_min": 0.092,            # Nm
    "brake_voltage": 24.0,         # V
    "brake_time_constant": 0.05,   # s, coil
    "brake_closed_loop": 0.25,     # s, PI closed-loop time constant (settles in ~1 s)
    "testbed_gear": 5.0,           # configuration 2
    "sensor_ranges": (20.0, 200.0),
    "sensor_noise": 5e-4,          # of the range
    "current_noise": 5e-3,         # of the nominal current
    "counts_per_rev": 8192,
    "filter_cutoff": 2.0,          # Hz, per-point low-pass
    "filter_order": 2,
    "n_speeds": 8,
    "n_loads": 8,
    "load_range": (0.05, 0.80),    # of the nominal output torque
}


def _key(module: str) -> str:
    key = str(module).upper().replace("LOLA-", "")
    if key not in MODULES:
        raise InputError(f"unknown Lola/CROPS module '{module}' (A, B or C)")
    return key


def _module(module: str) -> dict:
    return MODULES[_key(module)]


def table4_model(module: str) -> FrictionModel:
    """Law (11) with Table IV's values for module A, B or C (symmetric; SI at the motor)."""
    key = _key(module)
    return FrictionModel("lola11", {k: v for k, v in PAPER_TABLE4[key].items() if k != "rms"},
                         name=f"Lola/CROPS {key} Table IV",
                         notes=["law (11) made odd in velocity (gearspec.laws.lola11)"])


def table3_model(module: str) -> FrictionModel:
    """Law (8) with Table III's values for module A, B or C (symmetric; SI at the motor)."""
    key = _key(module)
    return FrictionModel("lola8", {k: v for k, v in PAPER_TABLE3[key].items() if k != "rms"},
                         name=f"Lola/CROPS {key} Table III")


def module_gear(module: str) -> GearTrain:
    """The module's gear preset (lola-a/-b/-c, with its torque constant) and the twin's inertia."""
    m = _module(module)
    g = load_gear(m["gear"])
    if not math.isclose(g.total_ratio, m["ratio"]):
        raise InputError(f"preset {m['gear']} has ratio {g.total_ratio}, the gear {m['gear_model']} {m['ratio']}")
    return dataclasses.replace(g, inertia=m["inertia"], source="gearspec.simulate.lola")


def default_speeds(module: str) -> list[float]:
    """The twin's motor speeds (rad/s): ``n_speeds`` equally spaced over the module's range, each
    forwards then backwards."""
    lo, hi = _module(module)["speed_range"]
    return [float(s) * d for s in np.linspace(lo, hi, TESTBED["n_speeds"]) for d in (1, -1)]


def default_loads(module: str) -> list[float]:
    """The twin's load torques (Nm at the output): ``n_loads`` equally spaced from 5 % to 80 % of
    the nominal output torque."""
    lo, hi = TESTBED["load_range"]
    t = _module(module)["nominal_output_torque"]
    return [float(x) for x in np.linspace(lo * t, hi * t, TESTBED["n_loads"])]


# ---------------------------------------------------------------------- brake loop
def _brake(commands: np.ndarray, n_hold: int, n_ramp: int, T_init: np.ndarray, kb: float, P: dict,
           rng: np.random.Generator, sensor_sd: float, t_min: float) -> tuple[np.ndarray, np.ndarray]:
    """PI-controlled hysteresis brake for a batch of blocks (same load schedule, one per speed):
    ``n_ramp`` samples at the first of ``commands`` (Nm; the speed ramp), then ``n_hold`` per level.
    Returns the actual and the measured (sensor noise) brake torque magnitude, (n_samples, n_blocks)."""
    cmd = np.concatenate([np.full(n_ramp, commands[0])] + [np.full(n_hold, c) for c in commands])
    return _brake_loop(cmd, T_init, kb, P, rng, sensor_sd, t_min)


def _brake_loop(cmd: np.ndarray, T_init: np.ndarray, kb: float, P: dict, rng: np.random.Generator, sensor_sd: float,
                t_min: float) -> tuple[np.ndarray, np.ndarray]:
    """The brake's PI loop from torques ``T_init`` (Nm, settled) following the load command ``cmd``
    (Nm, one per sample, or (n_samples, n_blocks)): actual and measured torque, (n_samples, n_blocks)."""
    dt = 1.0 / P["fs"]
    tau_c = P["brake_time_constant"]
    ki = 1.0 / (kb * P["brake_closed_loop"])
    kp = tau_c * ki
    alpha = math.exp(-dt / tau_c)
    n, B = len(cmd), len(T_init)
    T = np.asarray(T_init, dtype=float).copy()
    integ = T / (kb * ki)  # steady state at the initial torque
    Umax = P["brake_voltage"]
    act = np.empty((n, B))
    noise = sensor_sd * rng.standard_normal((n, B))
    for k in range(n):
        act[k] = np.maximum(T, t_min)
        e = cmd[k] - (act[k] + noise[k])
        u = kp * e + ki * integ
        U = np.clip(u, 0.0, Umax)
        integ += np.where((U != u) & ((u > Umax) == (e > 0)), 0.0, e * dt)
        T = alpha * T + (1 - alpha) * kb * U
    return act, act + noise


# ---------------------------------------------------------------------- the twin
#: the columns of the points a grid twin's truth keeps
_TRUTH_COLUMNS = ["point", "campaign", "speed_cmd", "load_cmd", "t0", "t1", "friction_true", "load_true",
                  "efficiency_true", "level_true"]


def lola_twin(module: str = "A", speeds: Sequence[float] | None = None, loads: Sequence[float] | None = None, *,
              hold: float | None = None, truth: FrictionModel | None = None, effects: Iterable[Effect] = (),
              seed: int | None = 0, fs: float | None = None, testbed: dict | None = None, profile: str = "plateaus",
              profile_options: dict | None = None, top_speed: float | None = None, duration: float | None = None
              ) -> tuple[Recording, pd.DataFrame]:
    """Simulate the testbed's automatic mode for module A, B or C, or a motion ``profile`` per load.

    Parameters
    ----------
    module : {"A", "B", "C"}
    speeds : sequence of float, optional
        Signed motor speeds (rad/s), visited in order (default :func:`default_speeds`).
    loads : sequence of float, optional
        Load torque magnitudes (Nm at the output), in increasing order at every speed (default
        :func:`default_loads`); those above 17 Nm in a second campaign with the testbed gear.
    hold : float, optional
        Seconds per operating point (default 5; the last 3 s, or the last 60 %, are averaged).
    truth : FrictionModel, optional
        The friction (default :func:`table4_model`); needs the load as law (11) does.
    effects : sequence of Effect
        Injected into ``truth``; their channels (temperature) are fed to the model and recorded;
        ``load_meshing`` uses the brake's load (leave its ``loads`` empty).
    seed, fs, testbed
        Seed of the noise; sample rate (default 1 kHz); overrides of :data:`TESTBED`.
    profile, profile_options, top_speed, duration : str, dict, float, float, optional
        ``"plateaus"`` (the grid) or a :mod:`~gearspec.simulate.profiles` profile with its options (``seed``:
        the sine's phases) up to ``top_speed`` rad/s (default: the module's top) over ``duration`` s
        (default 20), followed from rest to rest once per load (one run each), the brake settled at it.

    Returns
    -------
    recording : Recording
        ``t`` (s, experiment clock), ``theta`` (motor rad, 8192 counts/rev), ``current`` (A, raw),
        ``load`` (Nm at the output, the torque sensor, signed like the velocity), ``run`` (one per
        operating point), ``temperature`` where an effect supplies it; read it with :func:`module_gear`.
    points : DataFrame
        One row per operating point: ``point`` (= run), ``campaign`` (1 or 2), ``speed_cmd``,
        ``load_cmd``, ``speed`` (mean motor speed from the encoder, rad/s), ``load`` (Nm, signed),
        ``current`` (A), ``friction`` (eq. 12 at the motor, ``k_m I - T_l / N``, sign of the
        velocity), ``efficiency`` (eq. 13), ``t0, t1`` (the averaged window), ``n``; the truth over
        the window: ``friction_true``, ``load_true``, ``efficiency_true``, and ``level_true``
        (``truth`` without effects, position-averaged, at the commanded speed and load).
        ``points.attrs["truth"]`` is the :class:`~gearspec.simulate.silo4.TwinTruth`.  A profile:
        one row per run (:func:`_profile_rows`); ``settings["profile"]`` records the profile.
    """
    P = {**TESTBED, **(testbed or {})}
    for k, v in (("fs", fs), ("hold", hold)):
        if v is not None:
            P[k] = float(v)
    key = _key(module)
    mod = MODULES[key]
    N, km = mod["ratio"], mod["torque_constant"]
    rng = np.random.default_rng(seed)
    prof = _profile(key, profile, speeds, hold, top_speed, duration, profile_options, P)
    speeds, loads = _grid(key, speeds, loads, P)
    effects = list(effects or ())
    base = truth if truth is not None else table4_model(key)
    model = apply_effects(base, effects)
    gear = module_gear(key)
    J = mod["inertia"] + float(sum(t["inertia"] for t in model.terms if t["kind"] == "inertia"))
    model_eval = model.copy()
    model_eval.terms = [t for t in model.terms if t["kind"] != "inertia"]
    dt = 1.0 / P["fs"]
    pieces, point_rows, n_avg = _schedule(speeds, loads, prof, P, rng)
    v, T_act, T_meas, run = (np.concatenate(c) for c in zip(*pieces))
    run = run.astype(np.int64)
    n = len(v)
    t = np.arange(n) * dt
    theta = np.concatenate(([0.0], np.cumsum(0.5 * (v[1:] + v[:-1])) * dt))
    acc = np.gradient(v, dt)
    load_true = np.sign(v) * T_act  # the brake opposes the motion
    load_meas = np.sign(v) * T_meas
    ch, recorded = effect_channels(effects, t, run)
    if "load" in ch:
        raise InputError("lola_twin: the brake is the load here; give load_meshing no loads")
    missing = {nm for e in effects for nm in e.needs} - set(ch) - {"load"}
    if missing:
        raise InputError(f"lola_twin: an effect needs the {', '.join(sorted(missing))} channel, which no effect supplies")
    friction = model_eval.evaluate(theta, v, load=load_true, temperature=ch.get("temperature"), t=t, acc=acc, run=run)
    torque = friction + load_true / N + J * acc
    noise_i = P["current_noise"] * mod["nominal_current"]
    current = torque / km + noise_i * rng.standard_normal(n)
    q = 2 * math.pi / P["counts_per_rev"]
    theta_meas = np.floor(theta / q) * q
    starts = np.concatenate(([0], np.cumsum([len(p[0]) for p in pieces])))
    sim = {"t": t, "theta_meas": theta_meas, "current": current, "load_meas": load_meas, "load_true": load_true,
           "friction": friction, "run": run, "temperature": ch.get("temperature"), "v": v, "brake": T_act}
    points = pd.DataFrame(_point_rows(point_rows, sim, starts, base, P, n_avg, N, km) if prof is None else
                          _profile_rows(point_rows, sim, starts, prof))
    data = {"t": t, "theta": theta_meas, "current": current, "load": load_meas, "run": run,
            **{k: ch[k] for k in recorded}}
    rec = Recording.from_arrays(gear=gear, source=f"lola twin {key}", **data)
    settings = {**P, "module": key, **{f"module_{k}": v for k, v in mod.items()}, "seed": seed,
                "speeds": None if prof else speeds, "loads": loads, "inertia_total": J,
                "profile": prof.record() if prof else {"kind": "plateaus"}}
    truth_info = TwinTruth(f"lola-{key}", model, gear, effects_truth(effects, gear),
                           points[list(points.columns) if prof else _TRUTH_COLUMNS].copy(), plain(settings))
    points.attrs["truth"] = truth_info
    return rec, points


def _schedule(speeds, loads, prof: Reference | None, P: dict, rng: np.random.Generator):
    """The pieces and point rows of :func:`_operating_points` (the grid) or :func:`_profile_runs`,
    and the samples averaged per point."""
    n_hold = int(round(P["hold"] * P["fs"]))
    n_ramp = int(round(P["ramp"] * P["fs"]))
    n_avg = min(int(round(P["average"] * P["fs"])), int(0.6 * n_hold))
    if n_hold < 10:
        raise InputError("lola_twin: hold must be at least 10 samples")
    if prof is not None:
        return (*_profile_runs(prof, loads, P, rng), n_avg)
    return (*_operating_points(speeds, loads, P, n_hold, n_ramp, rng), n_avg)


def _profile_rows(point_rows: list[dict], sim: dict, starts: np.ndarray, prof: Reference) -> list[dict]:
    """One row per run of a profile: ``point`` (= ``run``), ``campaign``, ``load_cmd``, ``t0, t1``
    (the run), ``n``, ``top_speed`` and ``speed_max`` (true, rad/s), ``load_true`` (mean brake torque, Nm)."""
    t, v = sim["t"], sim["v"]
    return [{"point": i, "run": i, **r, "t0": float(t[a]), "t1": float(t[b - 1]), "n": int(b - a),
             "top_speed": prof.top_speed, "speed_max": float(np.abs(v[a:b]).max()),
             "load_true": float(sim["brake"][a:b].mean())}
            for i, (r, a, b) in enumerate(zip(point_rows, starts[:-1], starts[1:]))]


def _profile(key: str, profile: str, speeds, hold, top_speed, duration, options, P: dict) -> Reference | None:
    """The motion profile of a profile twin at the testbed's rate (None: the plateau grid)."""
    if profile == "plateaus":
        if options or top_speed is not None or duration is not None:
            raise InputError("lola_twin: top_speed, duration and profile_options are for a motion profile, "
                             "not the grid")
        return None
    if speeds is not None or hold is not None:
        raise InputError(f"lola_twin: speeds and hold are for the plateau grid; the {profile} profile takes top_speed "
                         "and duration")
    return reference(profile, top_speed=MODULES[key]["speed_range"][1] if top_speed is None else top_speed,
                     duration=PROFILE_DURATION if duration is None else duration, fs=P["fs"], options=options,
                     who="lola_twin")


def _profile_runs(prof: Reference, loads, P: dict, rng: np.random.Generator):
    """One run of the profile per load (increasing), the brake of each campaign's runs at once,
    settled at its load from the start: ``pieces`` and rows as :func:`_operating_points`'."""
    pieces, rows, n = [], [], len(prof.v)
    for camp, levels, gear_ratio, rng_sensor in _campaigns(loads, P):
        act, meas = _brake_loop(np.broadcast_to(np.asarray(levels), (n, len(levels))), np.asarray(levels),
                                P["brake_max"] * gear_ratio / P["brake_voltage"], P, rng,
                                P["sensor_noise"] * rng_sensor, P["brake_min"] * gear_ratio)
        for b, lv in enumerate(levels):
            pieces.append((prof.v, act[:, b], meas[:, b], np.full(n, len(rows))))
            rows.append({"campaign": camp, "load_cmd": lv})
    return pieces, rows


def _campaigns(loads, P: dict) -> list[tuple]:
    """The brake's campaigns: (1, loads up to 17 Nm, gear 1, small sensor range), then (2, those
    above, the testbed gear, the large range); only those with loads."""
    campaigns = [(1, [x for x in loads if x <= P["brake_max"]], 1.0, P["sensor_ranges"][0]),
                 (2, [x for x in loads if x > P["brake_max"]], P["testbed_gear"], P["sensor_ranges"][1])]
    return [c for c in campaigns if c[1]]


def _grid(key: str, speeds, loads, P: dict) -> tuple[list[float], list[float]]:
    """The speeds (rad/s, in order) and loads (Nm at the output, increasing) of the operating
    points, given or the defaults, checked against the testbed's brake."""
    speeds = default_speeds(key) if speeds is None else [float(s) for s in np.atleast_1d(speeds)]
    loads = default_loads(key) if loads is None else sorted(float(x) for x in np.atleast_1d(loads))
    if not speeds or any(s == 0 or not math.isfinite(s) for s in speeds):
        raise InputError("lola_twin: speeds must be nonzero finite motor speeds in rad/s")
    if not loads or any(x < 0 or not math.isfinite(x) for x in loads):
        raise InputError("lola_twin: loads must be finite torques >= 0 Nm at the output")
    gmax = P["brake_max"] * P["testbed_gear"]
    if max(loads) > gmax:
        raise InputError(f"lola_twin: loads above {gmax:g} Nm are beyond the testbed's brake (17 Nm x gear 5)")
    return speeds, loads


def _operating_points(speeds, loads, P: dict, n_hold: int, n_ramp: int, rng: np.random.Generator):
    """The automatic mode's schedule: per campaign (loads up to the brake's 17 Nm, then those above
    with the testbed gear) the brake of every speed block at once, then the blocks one after
    another.  Returns ``pieces`` (per block: velocity, actual and measured brake torque, point
    index per sample) and one row per point (``campaign, speed_cmd, load_cmd``)."""
    campaigns = _campaigns(loads, P)
    pieces = []  # (v, T_actual, T_meas, point index per sample)
    point_rows = []
    v_prev = 0.0
    for camp, levels, gear_ratio, rng_sensor in campaigns:
        kb = P["brake_max"] * gear_ratio / P["brake_voltage"]
        t_min = P["brake_min"] * gear_ratio
        T_init = np.full(len(speeds), max(levels))
        T_init[0] = 0.0
        act, meas = _brake(np.asarray(levels), n_hold, n_ramp, T_init, kb, P, rng, P["sensor_noise"] * rng_sensor,
                           t_min)
        for b, sp in enumerate(speeds):
            v = np.concatenate((np.linspace(v_prev, sp, n_ramp, endpoint=False), np.full(n_hold * len(levels), sp)))
            pt = np.concatenate((np.zeros(n_ramp, int), np.repeat(np.arange(len(levels)), n_hold)))
            pieces.append((v, act[:, b], meas[:, b], pt + len(point_rows)))
            point_rows += [{"campaign": camp, "speed_cmd": sp, "load_cmd": lv} for lv in levels]
            v_prev = sp
    return pieces, point_rows


def _point_rows(point_rows: list[dict], sim: dict, starts: np.ndarray, base: FrictionModel, P: dict, n_avg: int,
                N: float, km: float) -> list[dict]:
    """Per operating point: current and load low-pass filtered (forwards and backwards, per speed
    block) and averaged over the settled end of the point; friction (eq. 12) and efficiency
    (eq. 13) from them, and the truth over the same samples."""
    dt = 1.0 / P["fs"]
    t, theta_meas, run, temperature = sim["t"], sim["theta_meas"], sim["run"], sim["temperature"]
    bq = signal.butter(P["filter_order"], P["filter_cutoff"], fs=P["fs"], output="sos")
    cur_f, load_f = (np.concatenate([signal.sosfiltfilt(bq, sim[k][a:b]) for a, b in zip(starts[:-1], starts[1:])])
                     for k in ("current", "load_meas"))
    rows = []
    ends = np.flatnonzero(np.diff(np.concatenate((run, [-1]))) != 0)  # last sample of each run
    for pi, row in enumerate(point_rows):
        e_ = ends[pi] + 1
        s_ = e_ - n_avg
        sl = slice(s_, e_)
        I_m, L_m = float(cur_f[sl].mean()), float(load_f[sl].mean())
        spd = float((theta_meas[e_ - 1] - theta_meas[s_]) / ((e_ - 1 - s_) * dt))
        f_true = float(sim["friction"][sl].mean())
        lt = float(sim["load_true"][sl].mean())
        d = 1.0 if row["speed_cmd"] > 0 else -1.0
        lvl = d * float(base.mean_level(abs(row["speed_cmd"]), d, load=np.array([row["load_cmd"]]))[0])
        rows.append({"point": pi, "run": pi, **row, "speed": spd, "load": L_m, "current": I_m,
                     "friction": float(laws.friction_from_load_current(L_m, I_m, N, km)),
                     "efficiency": float(laws.efficiency(L_m, I_m, N, km)),
                     "t0": float(t[s_]), "t1": float(t[e_ - 1]), "n": int(e_ - s_),
                     "friction_true": f_true, "load_true": lt,
                     "efficiency_true": float(lt / (N * (f_true + lt / N))), "level_true": lvl,
                     **({"temperature": float(temperature[sl].mean())} if temperature is not None else {})})
    return rows
