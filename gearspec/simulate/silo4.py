"""Digital twin of the SILO4 leg's joint 3 (Garcia, Gonzalez de Santos, Canudas de Wit, IJRR 2002).

The paper's bench (section 2) with a known friction: a PID on a quantised encoder drives a DC motor
(back-EMF, R) through a PWM voltage; rotor inertia J; friction of motor + planetary 14 + worm 20.5
(eq. 11, Table 2's values, :func:`table2_model`, or any ``truth`` model, plus the effects of
:mod:`gearspec.simulate.effects`); the armature current goes through a 1 kHz 4th-order Bessel filter
and is sampled every 4 ms with noise.  One *run* is one experiment: from standstill an
acceleration-limited ramp, a held speed, a ramp back to rest; ten repetitions per speed.

SI throughout, at the MOTOR: theta and speeds in rad, rad/s; torques in Nm; current in A.  Table
2's omegas are per motor rad: output, worm (= planetary output) and motor shaft.

The unknowns, chosen (the paper does not give them; values in :data:`PLANT`)
-----------------------------------------------------------------------------
* Motor, 24 V graphite-brush DC, ``k_M = 0.0231 Nm/A``, ``R = 1.6 ohm``: 6500 rpm is reachable
  against Table 2's friction there (94 mNm, 4.1 A: ``k_M w + R I = 15.7 V + 6.5 V < 24 V``), and the
  electrical damping ``k_M^2 / R = 3.3e-4 Nm s/rad`` is *below* the Stribeck law's velocity-weakening
  slope at standstill (5.0e-4 positive, 5.4e-4 negative): near standstill the drive is negatively
  damped unless the derivative acts -- which a 2000-count encoder cannot below a count per
  derivative interval.  That is the stick-slip of Fig. 3.
* ``J = 2.0e-6 kg m^2`` at the motor (rotor about 1.5e-6 plus the reflected gears); encoder 500
  lines in quadrature (2000 counts/rev).
* PID on the encoder position error for a triple closed-loop pole at 2 pi 15 Hz:
  ``Kd + k_M^2/R = 3 J w``, ``Kp = 3 J w^2``, ``Ki = J w^3`` (torque units; times ``R / k_M`` in
  volts); derivative over 5 ms, anti-windup while the voltage saturates, trajectory limited to
  2000 rad/s^2.  A stiffer loop (30 Hz, 2 ms) made the encoder's quantisation sawtooth, folded by
  the 4 ms sampling into lines at fixed *time* frequencies, 0.2-0.8 mNm (above the motor-shaft
  ripple); at 15 Hz and 5 ms they are 0.05-0.13 mNm, about the noise per sample.  They are physical
  and not locked to position, so an analysis can tell them from the gear lines.
* Control and integration at 4 kHz, not the paper's 16 kHz: the crossover (~15 Hz) and the fastest
  ripple (108 Hz) are 40-270 times below it.  The Bessel filter is discretised exactly for a
  current held over each control period (zero-order hold), which a PWM-averaged current is.
* Current noise 4 mA (0.09 mNm, about 1 % of the friction) per sample and a repetition-to-repetition
  friction variation of 1 %, inside the paper's "< 3 %".  Every repetition starts from the same
  position (the bench returns home), so the position ripple does not add to the scatter.
* Stick-slip: a motor at rest stays at rest while the net drive torque is below the static friction
  at its position (the model at zero speed, ripple included); a velocity that would change sign
  within a step stops instead.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import Callable, Iterable, Sequence

import numpy as np
import pandas as pd
from scipy import signal

from ..errors import InputError
from ..jsonsafe import plain
from ..gears import GearTrain, load_gear
from ..model import RPM, FrictionModel
from ..recording import Recording
from ..terms import TERMS
from .effects import Effect, apply_effects, effect_channels, effects_truth
from .friction import _LoopFriction
from .profiles import Reference, reference, tracking
from .scatter import run_scatter

__all__ = ["PAPER_TABLE2", "table2_model", "twin_gear", "silo4_twin", "stick_slip_run", "TwinTruth",
           "DEFAULT_SPEEDS_RPM", "RATIO", "PLANT", "FIG3_JOINT_SPEED", "default_hold", "PROFILE_DURATION"]

#: planetary and worm ratios, and the total (Table 1)
RATIO_PLANETARY = 14.0
RATIO_WORM = 20.5
RATIO = RATIO_PLANETARY * RATIO_WORM

#: joint speed of the paper's Fig. 3 (stick-slip), rad/s
FIG3_JOINT_SPEED = 1e-4

#: the bench's unknowns, as chosen (see the module docstring)
PLANT = {
    "torque_constant": 0.0231,     # Nm/A
    "resistance": 1.6,             # ohm
    "inertia": 2.0e-6,             # kg m^2 at the motor
    "supply_voltage": 24.0,        # V
    "counts_per_rev": 2000,        # 500 lines, quadrature
    "control_rate": 4000.0,        # Hz (the paper: 16 kHz)
    "bandwidth_hz": 15.0,          # closed-loop triple pole
    "derivative_interval": 5e-3,   # s
    "acceleration": 2000.0,        # rad/s^2, trajectory limit
    "filter_cutoff": 1000.0,       # Hz, 4th-order Bessel (-3 dB)
    "filter_order": 4,
    "sample_interval": 4e-3,       # s
    "current_noise": 4e-3,         # A, standard deviation per sample
    "repeatability": 0.01,         # relative sd of the friction between repetitions
    "settle": 0.3,                 # s recorded at rest after each run's ramp down
    "pause": 1.0,                  # s between runs on the experiment clock
}

#: motor speeds (rpm) of the default twin, each in both directions: the Stribeck region of
#: Fig. 4, Table 3's 280 / 560 / 3000 rpm and Fig. 5's 2000 / 4500 / 6500 rpm
DEFAULT_SPEEDS_RPM = (2, 5, 10, 20, 30, 50, 75, 100, 150, 200, 280, 400, 560, 800, 1000, 1500, 2000, 3000, 4500, 6500)

#: seconds of a motion profile per run (ten runs: 400 s, against 3790 s of the default plateaus)
PROFILE_DURATION = 40.0

_PI = math.pi

#: Table 2 as published (paper units: mNm, motor rpm, mNm/rpm, 1/rpm, rad; omega per motor rad)
PAPER_TABLE2 = {
    "tau_E": {"unit": "mNm", "positive": 8.58, "negative": 9.41},
    "tau_C": {"unit": "mNm", "positive": 7.106, "negative": 7.909},
    "theta_s": {"unit": "rpm", "positive": 28.18, "negative": 26.58},
    "B": {"unit": "mNm/rpm", "positive": 0.0134, "negative": 0.0138},
    "A1": {"unit": "mNm", "positive": 0.3, "negative": 0.3},
    "omega1": {"unit": "per motor rad", "positive": 3.5e-3, "negative": 3.5e-3},
    "phi1": {"unit": "rad", "positive": _PI / 2, "negative": _PI / 2},
    "A2": {"unit": "mNm", "positive": 0.576, "negative": 0.526},
    "b2": {"unit": "1/rpm", "positive": 1.27e-4, "negative": 1.12e-4},
    "omega2": {"unit": "per motor rad", "positive": 0.071, "negative": 0.071},
    "phi2": {"unit": "rad", "positive": _PI / 2, "negative": _PI / 2},
    "A3": {"unit": "mNm", "positive": 0.133, "negative": 0.152},
    "b3": {"unit": "1/rpm", "positive": 5.28e-5, "negative": 7.49e-6},
    "omega3": {"unit": "per motor rad", "positive": 1.0, "negative": 1.0},
    "phi3": {"unit": "rad", "positive": _PI, "negative": _PI},
}

#: labels of the three harmonics, as the silo4-joint3 preset declares its lines
_LABELS = {1: "output shaft", 2: "planetary output shaft", 3: "motor shaft"}
#: exact shaft frequencies per motor rad (the table's rounded omegas are 1/287, 1/14, 1)
_FREQS = {1: 1.0 / (2 * _PI * RATIO), 2: 1.0 / (2 * _PI * RATIO_PLANETARY), 3: 1.0 / (2 * _PI)}


def table2_model() -> FrictionModel:
    """The full SILO4 model (eq. 11) with Table 2's values, in SI units at the motor: torques in Nm,
    ``v_s`` in rad/s, viscous in Nm s/rad, decays in s/rad, the harmonics at the exact shaft
    frequencies (cycles per motor rad) labelled as the ``silo4-joint3`` preset labels its lines.
    The paper uses one Stribeck velocity per direction (28.18 / 26.58 rpm)."""
    dirs = {}
    for d in ("positive", "negative"):
        P = {k: v[d] for k, v in PAPER_TABLE2.items()}
        harmonics = [{"frequency": _FREQS[k], "amplitude": P[f"A{k}"] * 1e-3, "decay": P.get(f"b{k}", 0.0) / RPM,
                      "phase": P[f"phi{k}"], "label": _LABELS[k]} for k in (1, 2, 3)]
        dirs[d] = {"tau_c": P["tau_C"] * 1e-3, "tau_s": P["tau_E"] * 1e-3, "v_s": P["theta_s"] * RPM,
                   "viscous": P["B"] * 1e-3 / RPM, "harmonics": harmonics}
    return FrictionModel("silo4", dirs["positive"], dirs["negative"], name="SILO4 Table 2",
                         notes=["Garcia et al. 2002, Table 2, converted to SI at the motor"])


def twin_gear(torque_constant: float | None = None, inertia: float | None = None) -> GearTrain:
    """The ``silo4-joint3`` gear train with the twin's torque constant and inertia (what is needed
    to read its recordings: ``current`` -> torque, and ``J thetadd`` removed as in SILO4 eq. 2)."""
    g = load_gear("silo4-joint3")
    return dataclasses.replace(
        g, name="SILO4 leg, joint 3 (twin)",
        torque_constant=float(torque_constant if torque_constant is not None else PLANT["torque_constant"]),
        inertia=float(inertia if inertia is not None else PLANT["inertia"]),
        description=g.description + " Twin: torque constant and inertia as chosen in gearspec.simulate.silo4.",
        source="gearspec.simulate.silo4")


def default_hold(speed: float) -> float:
    """Held seconds at a motor speed (rad/s): one output revolution (2 pi 287 rad of travel, so
    that the joint line completes a cycle) where that takes 3-10 s; 3 s above, 10 s below."""
    return float(np.clip(2 * _PI * RATIO / max(abs(speed), 1e-9), 3.0, 10.0))


# ---------------------------------------------------------------------- truth record
@dataclass
class TwinTruth:
    """What a twin knows and a recording does not: the twin's name, the friction ``model`` simulated
    (effects applied), the ``gear`` spec to read the recording with (the twin's torque constant and
    inertia), the ground truth of the injected ``effects`` (:func:`~.effects.effects_truth`), one row
    per run (``runs``, see the twin's docstring), every setting of the bench (plant, controller,
    sensors, seed), the operating ``points`` (or None) and the repetition ``scatter`` (None: none;
    else :meth:`~.scatter.RunScatter.truth`: its fraction, factors and the run-mean model)."""

    twin: str
    model: FrictionModel
    gear: GearTrain
    effects: list
    runs: pd.DataFrame
    settings: dict
    points: pd.DataFrame | None = None
    scatter: dict | None = None

    def to_dict(self) -> dict:
        def table(df):
            return None if df is None else json.loads(df.to_json(orient="records"))

        return {"twin": self.twin, "model": self.model.to_dict(), "gear": self.gear.to_dict(),
                "effects": self.effects, "settings": plain(self.settings), "runs": table(self.runs),
                "points": table(self.points), **({} if self.scatter is None else {"scatter": self.scatter})}

    def to_json(self, path) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(self.to_dict(), indent=1))
        return path


def _bessel_zoh(order: int, cutoff_hz: float, dt: float):
    """The analog Bessel low-pass (-3 dB at ``cutoff_hz``) discretised exactly for an input held
    over each step (zero-order hold): state-space (A, B, C, D) of the discrete filter."""
    b, a = signal.bessel(order, 2 * _PI * cutoff_hz, btype="low", analog=True, norm="mag")
    A, B, C, D = signal.tf2ss(b, a)
    Ad, Bd, Cd, Dd, _ = signal.cont2discrete((A, B, C, D), dt, method="zoh")
    return Ad, Bd[:, 0], Cd[0], float(Dd[0, 0])


def _starts(theta0, base: FrictionModel, runs: SimpleNamespace) -> np.ndarray:
    """Start position of every run (rad): ``theta0``, or "auto" (:func:`_auto_starts`; 0 for a profile)."""
    if not isinstance(theta0, str):
        return np.full(runs.n, float(theta0))
    if theta0 != "auto":
        raise InputError(f"silo4_twin: theta0 must be a number or 'auto', got '{theta0}'")
    return _auto_starts(base, runs.w_cmd, runs.holds, runs.acc) if runs.prof is None else np.zeros(runs.n)


def _auto_starts(model: FrictionModel, w_cmd, holds, acc, step: float = 0.05) -> np.ndarray:
    """Start positions that centre each run's held travel where the model's position ripple
    (friction minus its position average, at the run's speed) averages to about zero over the
    travel; searched over one output revolution, the nearest to 0 among the best."""
    out = np.zeros(len(w_cmd))
    period = 2 * _PI * RATIO
    for w, hold in dict.fromkeys(zip(w_cmd.tolist(), holds.tolist())):  # each (speed, hold) once, in order
        d = 1.0 if w > 0 else -1.0
        travel = abs(w) * hold
        if travel >= period:
            continue
        n_w = max(1, int(round(travel / step)))
        grid = np.arange(-n_w, int(period / step) + n_w + 1) * step
        ripple = d * model.friction(grid, np.full(len(grid), w)) - model.mean_level(abs(w), d)[0]
        c = np.concatenate(([0.0], np.cumsum(ripple)))
        avg = (c[n_w:] - c[:-n_w]) / n_w  # mean over windows of n_w samples
        centres = grid[:len(avg)] + 0.5 * n_w * step
        ok = (centres >= 0) & (centres < period)
        best = np.min(np.abs(avg[ok]))
        cand = centres[ok][np.abs(avg[ok]) <= best + 1e-3 * np.std(ripple) + 1e-15]
        centre = float(cand[np.argmin(np.abs(cand))])
        out[(w_cmd == w) & (holds == hold)] = centre - d * (w * w / (2 * acc) + 0.5 * travel)
    return out


# ---------------------------------------------------------------------- the twin
def silo4_twin(speeds_rpm: Sequence[float] | None = None, repetitions: int = 10, *, truth: FrictionModel | None = None,
               effects: Iterable[Effect] = (), duration: float | Sequence[float] | Callable | None = None,
               seed: int | None = 0, load=None, theta0: float | str = "auto", record_velocity: bool = False,
               sample_interval: float | None = None, current_noise: float | None = None,
               repeatability: float | None = None, plant: dict | None = None, profile: str = "plateaus",
               profile_options: dict | None = None, top_speed_rpm: float | None = None,
               feedforward: Callable | None = None, scatter: float = 0.0) -> tuple[Recording, TwinTruth]:
    """Simulate the SILO4 joint-3 bench: one closed-loop run per (speed, repetition) or of a ``profile``.

    Parameters
    ----------
    speeds_rpm : sequence of float, optional
        Signed motor speeds in rpm, visited in this order, each ``repetitions`` times in a row.
        Default: :data:`DEFAULT_SPEEDS_RPM`, each forwards then backwards.
    repetitions : int
        Runs per speed (the paper: ten).
    truth : FrictionModel, optional
        The friction (default :func:`table2_model`); theta at the motor, SI.
    effects : sequence of Effect
        Injected into ``truth``; the channels they supply (temperature, load) are fed to the model
        and recorded.
    duration : float, sequence (one per speed) or callable(speed rad/s) -> s, optional
        Seconds held at speed (default :func:`default_hold`); with a ``profile``: seconds of the
        profile (default :data:`PROFILE_DURATION`).
    seed : int or None
        Noise and repetition-to-repetition variation.
    load : float, sequence (per repetition, cycled) or callable(t, run), optional
        Output load torque (Nm); the drive supplies ``load / 287`` more at the motor.  SILO4 was
        measured without load; an effect may supply one (``load_meshing(loads=...)``).
    theta0 : float or "auto"
        Motor position at the start of every run (rad), the same for every repetition.  "auto"
        (default): per speed, the start that centres the held travel where the position ripple of
        ``truth`` (without effects) averages out -- at low speed a 10 s plateau covers a fraction of
        a worm-shaft cycle (88 rad) and would otherwise carry the ripple at one position (up to
        +-0.9 mNm, 10 %), which the Stribeck curve of Fig. 4 does not.
    record_velocity : bool
        Add a ``velocity`` column: the true motor velocity (the bench did not measure it).
    sample_interval, current_noise, repeatability : float, optional
        Override :data:`PLANT`'s 4 ms, 4 mA and 1 %.
    plant : dict, optional
        Override any other entry of :data:`PLANT`.
    profile, profile_options, top_speed_rpm : str, dict, float, optional
        ``"plateaus"`` (the above) or a :mod:`~gearspec.simulate.profiles` profile (``ramp, chirp,
        bell, sine``; its ``profile_options``, ``seed`` the sine's phases) up to ``top_speed_rpm``
        (default 6500): followed from rest to rest in every run (from ``theta0``, "auto": 0).
    feedforward : callable(theta, velocity) -> torque, optional
        A friction compensation: at every control step, the torque (Nm at the motor) it returns for
        the encoder position (rad) and the reference velocity (rad/s), arrays over the runs, is added
        to the PID's command (times ``R / k_M`` in volts, before the saturation).  None: the loop as is.
    scatter : float
        Repetition scatter (relative sd, e.g. 0.03): every linear parameter of the base law (Coulomb,
        static / Stribeck, viscous) and every line amplitude of each direction varies from run to run
        by its own factor ``1 + scatter N(0, 1)`` (:func:`~.scatter.run_scatter`), on top of the
        common ``repeatability`` factor.  ``truth.scatter`` then holds the factors and the run-mean
        model (what a fit of all runs estimates).  Default 0: none (the random stream unchanged).

    Returns
    -------
    recording : Recording
        ``t`` (s on the experiment clock, a pause between runs), ``theta`` (motor rad, encoder-
        quantised), ``current`` (A, filtered, sampled, noisy), ``run``, and ``load`` /
        ``temperature`` / ``velocity`` where present; read it with :func:`twin_gear`.
    truth : TwinTruth
        ``runs``: one row per run with ``run, speed_rpm, velocity`` (commanded, rad/s),
        ``direction, repetition, t_start, t_stop, t0, t1`` (the settled held part, on the clock),
        ``scale`` (the repetition's friction factor), ``level`` (``scale`` times the truth's
        :meth:`~FrictionModel.mean_level` at the speed), ``friction_mean`` (mean true friction
        magnitude over the held samples, ripple included), ``velocity_mean``, ``stuck_fraction``.
        A profile's ``runs``: ``run, repetition, profile, theta_start, t_start, t_stop, t0, t1`` (the
        motion), ``scale, top_speed`` and :func:`~.profiles.tracking`'s; ``settings["profile"]`` its record.
    """
    P = {**PLANT, **(plant or {})}
    for k, v in (("sample_interval", sample_interval), ("current_noise", current_noise),
                 ("repeatability", repeatability)):
        if v is not None:
            P[k] = float(v)
    rng = np.random.default_rng(seed)
    if int(repetitions) < 1:
        raise InputError("silo4_twin: repetitions must be at least 1")
    repetitions = int(repetitions)
    runs, speeds_rpm, prof = _runs(speeds_rpm, repetitions, duration, profile, profile_options, top_speed_rpm, P, rng)
    effects = list(effects or ())
    base = truth if truth is not None else table2_model()
    model = apply_effects(base, effects)
    lf = _LoopFriction(model)
    lf.scatter = run_scatter(model, scatter, runs.n, rng, np.sign(runs.w_cmd))
    bench = _Bench(P, lf.extra_inertia, runs.dt)
    channels = _Channels(effects, load, runs.t_start, runs.rep)
    ch0, recorded = channels.at(np.zeros(runs.n), np.arange(runs.n))
    missing = {n for e in effects for n in e.needs} - set(ch0)
    if missing:
        raise InputError(f"silo4_twin: an effect needs the {', '.join(sorted(missing))} channel, which this twin "
                         "does not have (SILO4 was measured without load): give load=... or the effect's loads=...")
    if model.law_spec.needs_load and "load" not in ch0:
        raise InputError(f"silo4_twin: law {model.law} needs a load; give load=...")
    starts = _starts(theta0, base, runs)
    out = _closed_loop(runs, bench, lf, channels, ch0, starts, feedforward)
    cols, rows = _twin_columns(runs, out, model, P, rng, speeds_rpm, repetitions, starts)
    data = {k: cols[k] for k in ("t", "theta", "current", "run")}
    data.update({k: cols[k] for k in out.out_ch if k in recorded})
    if record_velocity:
        data["velocity"] = cols["velocity"]
    gear = twin_gear(bench.kM, float(P["inertia"]))
    rec = Recording.from_arrays(gear=gear, source="silo4 twin", **data)
    settings = {**P, "Kp": bench.Kp, "Ki": bench.Ki, "Kd": bench.Kd, "electrical_damping": bench.b_emf,
                "inertia_total": bench.J, "seed": seed, "repetitions": repetitions,
                "speeds_rpm": speeds_rpm if prof is None else None,
                "theta0": theta0 if not isinstance(theta0, str) else "auto",
                "load": None if load is None or callable(load) else plain(np.asarray(load).tolist()),
                "profile": {"kind": "plateaus"} if prof is None else prof.record()}
    settings["scatter"] = float(scatter)
    truth_info = TwinTruth("silo4", model, gear, effects_truth(effects, gear), pd.DataFrame(rows), settings,
                           scatter=None if lf.scatter is None else lf.scatter.truth(model))
    return rec, truth_info


def _schedule(speeds_rpm, repetitions: int, duration, P: dict, rng: np.random.Generator) -> SimpleNamespace:
    """The runs of a twin, one per (speed, repetition), in order: commanded velocity ``w_cmd``
    (rad/s), ``rep``, held seconds ``holds``, the profile's times (s from the run's start: end of the
    ramp up ``t_acc``, of the hold, of the ramp down, of the record ``t_stop``), ``n_samp`` samples,
    ``t_start`` on the experiment clock, the friction factor ``scale`` of the repetition; and the
    clock: control step ``dt``, ``n_sub`` of them per sample interval ``dt_s``."""
    n_sp = len(speeds_rpm)
    w_cmd = np.repeat(np.asarray(speeds_rpm) * RPM, repetitions)
    rep = np.tile(np.arange(repetitions), n_sp)
    if duration is None:
        holds = np.array([default_hold(w) for w in w_cmd])
    elif callable(duration):
        holds = np.array([float(duration(abs(w))) for w in w_cmd])
    elif np.ndim(duration) == 0:
        holds = np.full(len(w_cmd), float(duration))
    else:
        d = np.asarray(duration, dtype=float)
        if len(d) != n_sp:
            raise InputError(f"silo4_twin: {len(d)} durations for {n_sp} speeds")
        holds = np.repeat(d, repetitions)
    if np.any(holds <= 0):
        raise InputError("silo4_twin: durations must be positive")
    acc = float(P["acceleration"])
    t_acc = np.abs(w_cmd) / acc
    t_hold_end = t_acc + holds
    t_end = t_hold_end + t_acc
    t_stop = t_end + float(P["settle"])
    dt_s = float(P["sample_interval"])
    rate = float(P["control_rate"])
    dt = 1.0 / rate
    n_sub = max(1, int(round(dt_s * rate)))
    dt_s = n_sub * dt
    n_samp = np.floor(t_stop / dt_s).astype(int) + 1
    t_start = np.concatenate(([0.0], np.cumsum(n_samp * dt_s + float(P["pause"]))[:-1]))
    scale = 1.0 + float(P["repeatability"]) * rng.standard_normal(len(w_cmd))
    return SimpleNamespace(n=len(w_cmd), w_cmd=w_cmd, rep=rep, holds=holds, acc=acc, t_acc=t_acc, t_hold_end=t_hold_end,
                           t_end=t_end, t_stop=t_stop, rate=rate, dt=dt, n_sub=n_sub, dt_s=dt_s, n_samp=n_samp,
                           t_start=t_start, scale=scale)


def _runs(speeds_rpm, repetitions: int, duration, profile: str, options, top_speed_rpm, P: dict,
          rng: np.random.Generator) -> tuple[SimpleNamespace, list, Reference | None]:
    """The runs (:func:`_schedule`, plus the motion profile ``prof`` and its position ``ref``), the
    speeds (rpm) and the profile: a profile is one "speed" 0 (no ramps) held for its duration."""
    if (speeds_rpm is not None) if profile != "plateaus" else (options or top_speed_rpm is not None):
        raise InputError("silo4_twin: speeds_rpm is for plateaus, top_speed_rpm and profile_options for a profile")
    prof, top = None, float(DEFAULT_SPEEDS_RPM[-1] if top_speed_rpm is None else top_speed_rpm)
    if profile != "plateaus":  # at the control rate, below the motor's no-load speed
        if not 0 < top < P["supply_voltage"] / P["torque_constant"] / RPM:
            raise InputError(f"silo4_twin: top speed {top:g} rpm is not between 0 and the motor's no-load speed "
                             f"{P['supply_voltage'] / P['torque_constant'] / RPM:.0f} rpm")
        prof = reference(profile, top_speed=top * RPM, duration=PROFILE_DURATION if duration is None else duration,
                         fs=float(P["control_rate"]), options=options, who="silo4_twin")
    if speeds_rpm is None:
        speeds_rpm = [s * d for s in DEFAULT_SPEEDS_RPM for d in (1, -1)]
    speeds_rpm = [float(s) for s in np.atleast_1d(speeds_rpm)]
    if not speeds_rpm or any(s == 0 or not math.isfinite(s) for s in speeds_rpm):
        raise InputError("silo4_twin: speeds must be nonzero finite motor speeds in rpm")
    runs = _schedule([0.0] if prof else speeds_rpm, repetitions, prof.duration if prof else duration, P, rng)
    runs.prof, runs.ref = prof, prof.position() if prof else None
    return runs, speeds_rpm, prof


class _Bench:
    """The plant and the controller of :data:`PLANT` (see the module docstring): motor constants, the
    PID gains tuned for a triple pole at the bandwidth with the nominal inertia, the encoder step
    and the current filter discretised for the control period ``dt``."""

    def __init__(self, P: dict, extra_inertia: float, dt: float):
        self.kM, self.Rw, self.Vmax = float(P["torque_constant"]), float(P["resistance"]), float(P["supply_voltage"])
        self.J = float(P["inertia"]) + extra_inertia
        self.b_emf = self.kM * self.kM / self.Rw
        wc = 2 * _PI * float(P["bandwidth_hz"])
        Jd = float(P["inertia"])  # the controller is tuned for the nominal inertia
        self.Kd = max(3 * Jd * wc - self.b_emf, 0.0)
        self.Kp = 3 * Jd * wc ** 2
        self.Ki = Jd * wc ** 3
        self.volt = self.Rw / self.kM  # V per Nm of commanded torque
        self.q = 2 * _PI / float(P["counts_per_rev"])
        self.m_der = max(1, int(round(float(P["derivative_interval"]) * float(P["control_rate"]))))
        self.Ad, self.Bd, self.Cd, self.Dd = _bessel_zoh(int(P["filter_order"]), float(P["filter_cutoff"]), dt)


class _Channels:
    """The channels (load, temperature) of the runs: constant per run or functions of the
    experiment clock (``dynamic``: they change within a run, warming or a callable load)."""

    def __init__(self, effects, load, t_start: np.ndarray, rep: np.ndarray):
        self.effects, self.load, self.t_start, self.rep = effects, load, t_start, rep
        self.dynamic = callable(load) or any(e.name == "warming" for e in effects)

    def at(self, tl, idx):
        """``(channels, names recorded)`` at run times ``tl`` of the runs ``idx``; the ``load``
        argument: a scalar, a sequence (one value per repetition, cycled) or callable(t, run)."""
        clock = self.t_start[idx] + tl
        ch, rec_names = effect_channels(self.effects, clock, idx)
        if self.load is not None:
            if "load" in ch:
                raise InputError("silo4_twin: both the load argument and an effect supply the load")
            if callable(self.load):
                ch["load"] = np.asarray(self.load(clock, idx), dtype=float) * np.ones(np.shape(clock))
            elif np.ndim(self.load) == 0:
                ch["load"] = np.full(np.shape(clock), float(self.load))
            else:
                vals = np.asarray(self.load, dtype=float)
                ch["load"] = vals[np.asarray(self.rep[idx]) % len(vals)] * np.ones(np.shape(clock))
            rec_names = rec_names | {"load"}
        return ch, rec_names


def _closed_loop(runs: SimpleNamespace, bench: _Bench, lf: _LoopFriction, channels: _Channels, ch0: dict,
                 starts: np.ndarray, ff: Callable | None = None) -> SimpleNamespace:
    """Every run of a twin integrated together to its stop: one numpy step per control period over
    the vector of runs, ordered by stop time (longest first) so that the runs still active are a
    prefix.  Returns what is recorded at each sample (``out_*``, per run slot; ``inv`` maps a run
    to its slot)."""
    R_, dt, n_sub, rate = runs.n, runs.dt, runs.n_sub, runs.rate
    kM, Rw, Vmax, q, m_der = bench.kM, bench.Rw, bench.Vmax, bench.q, bench.m_der
    Bd, Cd, Dd = bench.Bd, bench.Cd, bench.Dd
    run_idx = np.argsort(-runs.t_stop, kind="stable")  # run id of each state slot
    TA, TH, TE, TS, SC, NS, T0, W = (getattr(runs, k)[run_idx] for k in (
        "t_acc", "t_hold_end", "t_end", "t_stop", "scale", "n_samp", "t_start", "w_cmd"))
    TH0, const_ch, dynamic_ch = starts[run_idx], {k: v[run_idx] for k, v in ch0.items()}, channels.dynamic
    shape = (int(runs.n_samp.max()), R_)
    out_th, out_i, out_f, out_v = (np.full(shape, np.nan) for _ in range(4))
    out_ch = {k: np.full(shape, np.nan) for k in ch0}
    needs_t = any("t" in TERMS[t["kind"]].needs for t in lf.model.terms)
    needs_run = bool(lf.history) or any("run" in TERMS[t["kind"]].needs for t in lf.model.terms)
    sw, Wa = np.sign(W), np.abs(W)
    half_a, profile_ref = 0.5 * runs.acc, runs.ref
    # state per slot; f_acc: the friction summed over the current sample interval
    theta, turn_theta = TH0.copy(), np.full(R_, np.nan)
    vel, integ, last_sign, f_acc = (np.zeros(R_) for _ in range(4))
    ebuf = np.zeros((m_der, R_))
    X = np.zeros((R_, len(Bd)))
    AdT = np.ascontiguousarray(bench.Ad.T)
    n_steps = int(round(TS.max() * rate)) + 1
    kp_v, ki_v, kd_v = bench.volt * bench.Kp, bench.volt * bench.Ki, bench.volt * bench.Kd / (m_der * dt)
    dt_J = dt / bench.J
    n_act = R_
    chunk = 1024  # control steps whose reference trajectory is computed at once
    for k0 in range(0, n_steps, chunk):
        # reference trajectory of the chunk: acceleration-limited ramp, hold, ramp down
        tl_c = (k0 + np.arange(min(chunk, n_steps - k0)))[:, None] * dt
        a = slice(0, n_act)
        if profile_ref is not None:  # a motion profile, the same for every run
            ref_c = TH0[a] + profile_ref[np.minimum(k0 + np.arange(len(tl_c)), len(profile_ref) - 1), None]
        else:
            t1 = np.minimum(tl_c, TA[a])
            t2 = np.maximum(np.minimum(tl_c, TH[a]) - TA[a], 0.0)
            t3 = np.maximum(np.minimum(tl_c, TE[a]) - TH[a], 0.0)
            ref_c = TH0[a] + sw[a] * (half_a * t1 * t1 + Wa[a] * (t2 + t3) - half_a * t3 * t3)
        if ff is not None:  # the reference velocity of the chunk (rad/s), for the feed-forward
            if profile_ref is not None:
                vref_c = np.repeat(runs.prof.v[np.minimum(k0 + np.arange(len(tl_c)), len(runs.prof.v) - 1), None],
                                   n_act, axis=1)
            else:
                vref_c = sw[a] * np.maximum(np.minimum(np.minimum(runs.acc * tl_c, Wa[a]), runs.acc * (TE[a] - tl_c)),
                                            0.0)
        for kk_ in range(len(tl_c)):
            k = k0 + kk_
            tl = k * dt
            while n_act > 0 and tl > TS[n_act - 1] + 1e-9:
                n_act -= 1
            if n_act == 0:
                break
            a = slice(0, n_act)
            th = theta[a]
            v = vel[a]
            # PID on the encoder count (voltage out, anti-windup: no integration while the
            # voltage saturates in the direction of the error)
            e = ref_c[kk_, :n_act] - np.floor(th / q) * q
            j = k % m_der
            u_v = kp_v * e + ki_v * integ[a] + kd_v * (e - ebuf[j, a])
            if ff is not None:
                u_v = u_v + bench.volt * np.asarray(ff(np.floor(th / q) * q, vref_c[kk_, :n_act]), dtype=float)
            ebuf[j, a] = e
            U = np.minimum(np.maximum(u_v, -Vmax), Vmax)
            integ[a] += np.where((U != u_v) & ((e > 0) == (u_v > 0)), 0.0, e * dt)
            current = (U - kM * v) * (1.0 / Rw)
            # channels, external torques, friction (at rest: the static friction, the model at
            # 0+ in the direction the drive pushes)
            ch = channels.at(np.full(n_act, tl), run_idx[a])[0] if dynamic_ch else \
                {kk: vv[a] for kk, vv in const_ch.items()}
            kw = {kk: ch.get(kk) for kk in ("load", "temperature")} if ch else {}
            if needs_t:
                kw["t"] = T0[a] + tl
            if needs_run:
                kw["run"] = run_idx[a]
            drive = kM * current
            if kw.get("load") is not None:
                drive = drive - kw["load"] / RATIO
            if lf.signed:
                drive = drive - lf.external(th, v, **kw)
            moving = v != 0
            v_eval = np.where(moving, v, np.sign(drive) * 1e-12)
            F = lf.friction(th, v_eval, turn_theta[a], last_sign[a], **kw)
            if lf.scatter is not None:  # each run's own levels and amplitudes
                F = F + lf.scatter.extra(th, v_eval, run_idx[a], **{kk: vv for kk, vv in kw.items() if kk != "run"})
            F = SC[a] * F
            # record the state at the start of the step (filter output up to the previous step)
            if k % n_sub == 0 and k // n_sub < shape[0]:  # (a stop on a sample edge rounded up)
                i = k // n_sub
                cols_ = np.flatnonzero(i < NS[a])
                out_th[i, cols_] = (np.floor(th / q) * q)[cols_]
                out_i[i, cols_] = (X[a] @ Cd)[cols_] + Dd * current[cols_]
                out_f[i, cols_] = (f_acc[a] / n_sub)[cols_] if k else 0.0
                out_v[i, cols_] = v[cols_]
                for kk, vv in ch.items():
                    out_ch[kk][i, cols_] = vv[cols_]
                f_acc[a] = 0.0
            # mechanics with stick-slip: at rest while |drive| <= static friction; a velocity
            # that would change sign within the step stops instead
            v_new = v + (drive - F) * dt_J
            v_new[(moving & (v_new * v <= 0)) | (~moving & (np.abs(drive) <= np.abs(F)))] = 0.0
            f_acc[a] += drive - (v_new - v) / dt_J  # the friction that acted (momentum balance)
            if lf.history:
                s_new = np.sign(v_new)
                ls = last_sign[a]
                rev = (s_new != 0) & (ls != 0) & (s_new != ls)
                turn_theta[a] = np.where(rev, th, turn_theta[a])
                last_sign[a] = np.where(s_new != 0, s_new, ls)
            theta[a] = th + v_new * dt
            vel[a] = v_new
            X[a] = X[a] @ AdT + current[:, None] * Bd
    inv = np.empty(R_, int)
    inv[run_idx] = np.arange(R_)
    return SimpleNamespace(inv=inv, out_th=out_th, out_i=out_i, out_f=out_f, out_v=out_v, out_ch=out_ch)


def _twin_columns(runs: SimpleNamespace, out: SimpleNamespace, model: FrictionModel, P: dict, rng: np.random.Generator,
                  speeds_rpm, repetitions: int, starts: np.ndarray) -> tuple[dict, list[dict]]:
    """The columns of the recording (runs in their own order, the current with its measurement
    noise) and one row of truth per run (the held part, its true friction and velocity)."""
    noise = float(P["current_noise"])
    out_ch, dt_s = out.out_ch, runs.dt_s
    per_run = [(int(runs.n_samp[r]), out.inv[r]) for r in range(runs.n)]  # samples, state slot

    def column(a):
        return np.concatenate([a[:n, s] for n, s in per_run])

    total = int(runs.n_samp.sum())
    cols = {"t": np.concatenate([runs.t_start[r] + np.arange(n) * dt_s for r, (n, _) in enumerate(per_run)]),
            "theta": column(out.out_th),
            "current": column(out.out_i) + (noise * rng.standard_normal(total) if noise else 0.0),
            "run": np.repeat(np.arange(runs.n, dtype=np.int64), runs.n_samp), "velocity": column(out.out_v),
            **{k: column(v) for k, v in out_ch.items()}}
    rows = []
    prof = runs.prof
    for r, (n, s) in enumerate(per_run if prof else ()):  # a motion profile: how well each run followed it
        n_m, t0 = int(np.floor(prof.duration / dt_s)) + 1, runs.t_start[r]  # samples of the motion
        rows.append({"run": r, "repetition": r, "profile": prof.kind, "theta_start": starts[r], "t_start": t0,
                     "t_stop": t0 + (n - 1) * dt_s, "t0": t0, "t1": t0 + (n_m - 1) * dt_s, "scale": runs.scale[r],
                     "top_speed": prof.top_speed, **tracking(out.out_v[:n_m, s], prof.v[::runs.n_sub][:n_m])})
    for r, (n, s) in enumerate(() if prof else per_run):
        tl = np.arange(n) * dt_s
        held = (tl >= runs.t_acc[r] + 0.25 * min(1.0, runs.holds[r])) & (tl <= runs.t_hold_end[r])
        if not held.any():
            held = (tl >= runs.t_acc[r]) & (tl <= runs.t_hold_end[r])
        d = 1 if runs.w_cmd[r] > 0 else -1
        f_mag = d * out.out_f[:n, s][held]
        v_held = out.out_v[:n, s][held]
        kw_lvl = {"load": np.array([np.nanmean(out_ch["load"][:n, s][held])])} if "load" in out_ch else {}
        try:
            lvl = float(model.mean_level(abs(runs.w_cmd[r]), d, **kw_lvl)[0]) * runs.scale[r]
        except InputError:
            lvl = float("nan")
        t0 = runs.t_start[r]
        rows.append({"run": r, "speed_rpm": speeds_rpm[r // repetitions], "velocity": runs.w_cmd[r], "direction": d,
                     "repetition": int(runs.rep[r]), "theta_start": starts[r], "t_start": t0,
                     "t_stop": t0 + (n - 1) * dt_s, "t0": t0 + tl[held][0], "t1": t0 + tl[held][-1],
                     "hold": runs.holds[r], "scale": runs.scale[r], "level": lvl,
                     "friction_mean": float(np.mean(f_mag)),
                     "velocity_mean": float(np.mean(v_held)), "stuck_fraction": float(np.mean(v_held == 0)),
                     "n_held": int(held.sum())})
    return cols, rows


def stick_slip_run(joint_speed: float = FIG3_JOINT_SPEED, duration: float = 30.0, *, seed: int | None = 0,
                   sample_interval: float = 4e-3, **kw) -> tuple[Recording, TwinTruth]:
    """The paper's Fig. 3: one run at a creeping joint speed (default 1e-4 rad/s, 0.029 rad/s or
    0.27 rpm at the motor), held ``duration`` s, with the true velocity recorded.  Other keywords
    go to :func:`silo4_twin`."""
    rpm = joint_speed * RATIO / RPM
    return silo4_twin([rpm], repetitions=1, duration=duration, seed=seed, record_velocity=True,
                      sample_interval=sample_interval, **kw)
