"""Does the compensation work?  A fitted model as a friction feed-forward in a twin's speed loop.

:func:`compensate` runs the same plateaus of a twin (:func:`~gearspec.simulate.silo4.silo4_twin` or
:func:`~gearspec.simulate.directdrive.direct_drive_twin`) three times, with the same seed:

* ``none``: the PID alone;
* ``model``: the model as feed-forward, computed by the C that ``gearspec export --format c`` writes,
  compiled (``cc -std=c99 -O2 -shared -fPIC``) and called through ctypes (:func:`c_feedforward`);
* ``coulomb_viscous``: a plain Coulomb + viscous feed-forward from the model's own ``tau_c`` and
  ``viscous`` per direction (:func:`coulomb_viscous`; no Stribeck part, no lines, no terms), exported
  and compiled the same way.

Each feed-forward gets the encoder position and the reference velocity (what a drive has in its
loop) and returns the torque (Nm at the motor) added to the PID's command.  On the held part of
every plateau (the twin's ``t0..t1``) it measures, from the twin's true motor velocity: the velocity
ripple (standard deviation and peak-to-peak, rpm and % of the speed), its position-locked part (the
rms of the sinusoids at the model's line and cogging frequencies fitted to the velocity over
position, :func:`gearspec.spectrum.harmonic.harmonic_fit`) and the speed tracking error (commanded
minus true velocity: mean and rms, rpm).
"""

from __future__ import annotations

import ctypes
import math
import os
import shutil
import subprocess
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
import pandas as pd

from ..errors import InputError
from ..model import RPM, FrictionModel
from ..spectrum.harmonic import harmonic_fit
from ..terms import TERMS
from .check import check_exportable, read_model

__all__ = ["compensate", "CompensationResult", "c_feedforward", "python_feedforward", "coulomb_viscous",
           "TWINS", "COMPENSATIONS", "LABELS", "not_better", "plateau_metrics", "find_compiler"]

#: the twins and their default speeds (rpm, each run in both directions) and trace speed (rpm)
TWINS = {"silo4": {"speeds_rpm": (50, 100, 280, 560, 1000, 3000), "trace_rpm": 280.0},
         "direct-drive": {"speeds_rpm": (10, 20, 30, 60, 120, 240), "trace_rpm": 30.0}}
#: the three runs, in the order they are reported
COMPENSATIONS = ("none", "coulomb_viscous", "model")
#: how each run is named in the report and the figures
LABELS = {"none": "no compensation", "coulomb_viscous": "Coulomb + viscous", "model": "full model (exported C)"}
#: load (Nm) and temperature (degC) given to the feed-forward: the twins have neither channel
LOAD, TEMPERATURE = 0.0, 20.0
#: fewest cycles of a line over a plateau's travel for it to count in the position-locked ripple:
#: below two, a sinusoid is not told apart from the slow drift the fit removes (a straight line)
MIN_LOCKED_CYCLES = 2.0

_WRAPPER = """#include "gearspec_model.h"
/* gearspec compensate: gearspec_torque over arrays, acceleration 0 (the feed-forward is friction) */
void gearspec_ff_array(const double *theta, const double *velocity, double *out, long n, double load,
                       double temperature)
{
    long i;
    for (i = 0; i < n; i++)
        out[i] = gearspec_torque(theta[i], velocity[i], 0.0, load, temperature);
}
"""


def find_compiler(cc: str | None = None) -> str:
    """The C compiler: ``cc``, else ``$CC``, else ``cc`` on the PATH; one sentence when there is none."""
    name = cc or os.environ.get("CC") or "cc"
    path = shutil.which(name)
    if path is None:
        raise InputError(f"no C compiler '{name}' found: gearspec compensate builds the exported C model to run it as "
                         f"the feed-forward, so install one (e.g. apt install gcc) or name it with --cc or $CC")
    return path


class _CModel:
    """The exported C of a model, compiled into a shared library in a temporary folder (kept while
    this object lives); calling it evaluates ``gearspec_torque`` over arrays."""

    def __init__(self, model: FrictionModel, cc: str | None = None, smooth_velocity: float = 0.0,
                 source: str | None = None):
        from . import export

        compiler = find_compiler(cc)
        self._dir = tempfile.TemporaryDirectory(prefix="gearspec-ff-")
        out = Path(self._dir.name)
        export(model, "c", out, smooth_velocity=smooth_velocity, source=source)
        (out / "gearspec_ff.c").write_text(_WRAPPER)
        lib = out / "libgearspec_ff.so"
        cmd = [compiler, "-std=c99", "-O2", "-shared", "-fPIC", "-o", str(lib), str(out / "gearspec_model.c"),
               str(out / "gearspec_ff.c"), "-lm"]
        res = subprocess.run(cmd, capture_output=True, text=True)
        if res.returncode != 0:   # a broken or wrong compiler (the exported C compiles under -Werror in the tests)
            first = (res.stderr.strip().splitlines() or ["no message"])[0]
            raise InputError(f"the C compiler '{compiler}' failed on the exported model ({first}); name a working "
                             f"C99 compiler with --cc or $CC")
        self.command = " ".join(cmd)
        self._lib = ctypes.CDLL(str(lib))
        f = self._lib.gearspec_ff_array
        dp = ctypes.POINTER(ctypes.c_double)
        f.restype, f.argtypes = None, [dp, dp, dp, ctypes.c_long, ctypes.c_double, ctypes.c_double]
        self._f, self._dp = f, dp

    def __call__(self, theta, velocity):
        th = np.ascontiguousarray(np.broadcast_to(np.asarray(theta, dtype=float), np.shape(velocity)), dtype=float)
        v = np.ascontiguousarray(velocity, dtype=float)
        out = np.empty(v.shape)
        self._f(th.ctypes.data_as(self._dp), v.ctypes.data_as(self._dp), out.ctypes.data_as(self._dp), v.size,
                LOAD, TEMPERATURE)
        return out


def c_feedforward(model: FrictionModel, cc: str | None = None, smooth_velocity: float = 0.0, *,
                  source: str | None = None) -> Callable:
    """``feedforward(theta, velocity) -> torque`` (rad, rad/s -> Nm, arrays) computed by the model's
    exported C (``gearspec_torque`` with acceleration 0, load :data:`LOAD`, temperature
    :data:`TEMPERATURE`), compiled with ``cc`` (default ``$CC`` or ``cc``) and loaded with ctypes.
    ``smooth_velocity``: ``GEARSPEC_SMOOTH_VELOCITY`` (rad/s; 0, the default: the exact sign);
    ``source``: the model's file, named in a refusal (default: the model's name)."""
    return _CModel(model, cc, smooth_velocity, source)


def python_feedforward(model: FrictionModel) -> Callable:
    """The same feed-forward as :func:`c_feedforward`, computed by :meth:`FrictionModel.evaluate`."""
    return lambda theta, velocity: model.evaluate(theta, velocity, load=LOAD, temperature=TEMPERATURE, acc=0.0)


def coulomb_viscous(model: FrictionModel) -> FrictionModel:
    """The plain compensation: Coulomb + viscous with the model's own ``tau_c`` and ``viscous`` per
    direction (Nm, Nm s/rad; a viscous not identified counts 0)."""
    dirs = {}
    for name, p in model.directions.items():
        tau_c = p.values.get("tau_c")
        if tau_c is None:
            raise InputError(f"the model (law {model.law}) has no {name}-direction tau_c, so no Coulomb + viscous "
                             f"compensation can be taken from it")
        dirs[name] = {"tau_c": float(tau_c), "viscous": float(p.values.get("viscous") or 0.0)}
    return FrictionModel("coulomb_viscous", dirs["positive"], dirs["negative"], name="Coulomb + viscous of the model")


def locked_frequencies(model: FrictionModel) -> list[float]:
    """Frequencies (cycles/rad) of the model's lines and periodic/cogging terms, each once."""
    fs = [h.frequency for p in model.directions.values() for h in p.harmonics if h.amplitude is not None]
    fs += [t["frequency"] for t in model.terms if t["kind"] in ("periodic", "cogging")]
    out: list[float] = []
    for f in sorted(float(f) for f in fs if f):
        if not out or abs(f - out[-1]) > 1e-9 * f:
            out.append(f)
    return out


def plateau_metrics(theta, velocity, command: float, frequencies: Sequence[float]) -> dict:
    """The measures of one plateau: ``theta`` (rad), true ``velocity`` (rad/s), ``command`` (rad/s).

    Returns ``n``, ``ripple_std_rpm``, ``ripple_pp_rpm`` (standard deviation and peak-to-peak of the
    velocity), the same in % of ``|command|``, ``locked_rpm`` (rms of the sinusoids at the
    ``frequencies`` with at least :data:`MIN_LOCKED_CYCLES` cycles over the travel, fitted with a
    straight line over position; NaN when none has), ``error_mean_rpm`` and ``error_rms_rpm`` of
    ``command - velocity``.
    """
    v = np.asarray(velocity, dtype=float)
    th = np.asarray(theta, dtype=float)
    travel = float(np.ptp(th)) if len(th) else 0.0
    use = [f for f in frequencies if f * travel >= MIN_LOCKED_CYCLES]
    locked = float("nan")
    if use and len(v) > 2 * len(use) + 3:
        amp = np.asarray(harmonic_fit(th, v, np.asarray(use), degree=1).amplitude, dtype=float)
        locked = float(np.sqrt(np.sum(amp * amp) / 2)) / RPM
    err = command - v
    speed = abs(command) / RPM
    std, pp = float(np.std(v)) / RPM, float(np.ptp(v)) / RPM
    return {"n": int(len(v)), "ripple_std_rpm": std, "ripple_pp_rpm": pp, "ripple_std_pct": 100 * std / speed,
            "ripple_pp_pct": 100 * pp / speed, "locked_rpm": locked, "error_mean_rpm": float(np.mean(err)) / RPM,
            "error_rms_rpm": float(np.sqrt(np.mean(err * err))) / RPM}


def not_better(table: pd.DataFrame, column: str = "ripple_std_rpm") -> pd.DataFrame:
    """The (speed, direction) rows where the full model's ``column`` is not below Coulomb + viscous's:
    ``speed_rpm, direction, model, coulomb_viscous``."""
    w = table.pivot_table(index=["speed_rpm", "direction"], columns="compensation", values=column).reset_index()
    bad = w[~(w["model"] < w["coulomb_viscous"])]
    return bad[["speed_rpm", "direction", "model", "coulomb_viscous"]].reset_index(drop=True)


@dataclass
class CompensationResult:
    """What :func:`compensate` measured.

    ``table``: one row per (speed, direction, compensation) with ``twin, speed_rpm, direction,
    compensation`` and :func:`plateau_metrics`'s columns (one repetition's mean when there are more),
    plus ``in_fitted_range`` (the speed lies within the speeds the model's lines were fitted on, from
    the lowest edge of their speed ranges to the highest, +-1 %; None when the model does not say);
    ``traces``: per compensation, the held part of the positive run at ``trace_rpm``: ``t`` (s from
    the start of the hold), ``velocity`` (rpm); ``not_better``: :func:`not_better` of the table;
    ``settings``: the twin, speeds, durations, seed, compiler command, what each compensation is.
    """

    twin: str
    model: FrictionModel
    table: pd.DataFrame
    traces: dict
    trace_rpm: float
    not_better: pd.DataFrame
    settings: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)

    def to_dict(self) -> dict:
        """The JSON form: ``twin``, ``model`` (its JSON), ``rows`` (the table's records), ``not_better``,
        ``trace_rpm``, ``settings``, ``notes``; SI inside the model, rpm and % in the rows (named so)."""
        from ..jsonsafe import plain

        return plain({"twin": self.twin, "model": self.model.to_dict(), "rows": self.table.to_dict("records"),
                      "not_better": self.not_better.to_dict("records"), "trace_rpm": self.trace_rpm,
                      "settings": self.settings, "notes": self.notes})


def _speeds(speeds_rpm, twin: str) -> list[float]:
    speeds = TWINS[twin]["speeds_rpm"] if speeds_rpm is None else speeds_rpm
    out = []
    for s in np.atleast_1d(np.asarray(speeds, dtype=float)):
        if not (math.isfinite(s) and s > 0):
            raise InputError(f"speeds must be positive motor speeds in rpm (each is run in both directions), got {s:g}")
        out.append(float(s))
    if not out:
        raise InputError("no speed given: list motor speeds in rpm, e.g. 100,280,560")
    return list(dict.fromkeys(out))


def _run(twin: str, speeds_rpm, ff, duration: float, repetitions: int, seed):
    signed = [s * d for s in speeds_rpm for d in (1, -1)]
    if twin == "silo4":
        from ..simulate.silo4 import silo4_twin

        return silo4_twin(signed, repetitions, duration=duration, seed=seed, record_velocity=True, feedforward=ff)
    from ..simulate.directdrive import direct_drive_twin

    return direct_drive_twin(signed, repetitions, duration=duration, seed=seed, feedforward=ff)


def _fitted_range(model: FrictionModel) -> tuple[float, float] | None:
    """The speeds (rad/s) the model's lines were fitted on, from the lowest edge of their speed ranges
    to the highest; None when no line says."""
    rs = [h.speed_range for p in model.directions.values() for h in p.harmonics
          if h.amplitude is not None and h.speed_range]
    if not rs:
        return None
    return min(float(r[0] or 0.0) for r in rs), max(float(r[1] if r[1] is not None else np.inf) for r in rs)


def _measure(rec, truth, label: str, freqs, trace_rpm: float, rng_fit) -> tuple[list[dict], dict]:
    d = rec.data
    rows, trace = [], {}
    for _, r in truth.runs.iterrows():
        m = ((d["run"] == r["run"]) & (d["t"] >= r["t0"]) & (d["t"] <= r["t1"])).to_numpy()
        th, v = d["theta"].to_numpy()[m], d["velocity"].to_numpy()[m]
        speed = abs(float(r["speed_rpm"]))
        row = {"speed_rpm": speed, "direction": int(r["direction"]), "compensation": label,
               **plateau_metrics(th, v, float(r["velocity"]), freqs)}
        # 1 %: a line's speed range holds measured plateau speeds, which differ from the commanded ones
        inside = rng_fit is not None and 0.99 * rng_fit[0] <= speed * RPM <= 1.01 * rng_fit[1]
        row["in_fitted_range"] = None if rng_fit is None else bool(inside)
        rows.append(row)
        if speed == trace_rpm and r["direction"] > 0 and not trace:
            t = d["t"].to_numpy()[m]
            trace = {"t": t - t[0], "velocity": v / RPM}
    return rows, trace


def compensate(model, twin: str = "silo4", speeds_rpm: Sequence[float] | None = None, *, duration: float = 3.0,
               repetitions: int = 1, seed: int | None = 1, cc: str | None = None, trace_rpm: float | None = None,
               smooth_velocity: float = 0.0) -> CompensationResult:
    """Run a twin's plateaus without, with a Coulomb + viscous and with the full model as feed-forward.

    Parameters
    ----------
    model : FrictionModel, a model file's path or its JSON dict (``gearspec fit --json``)
        The identified model (SI, theta at the motor).  Checked as ``gearspec export`` checks it.
    twin : ``"silo4"`` or ``"direct-drive"``
    speeds_rpm : sequence of float, optional
        Motor speeds (rpm, > 0), each run in both directions (default: :data:`TWINS`' speeds).
    duration : float
        Seconds held at each speed (s).
    repetitions : int
        Runs per speed and direction (the table holds their mean).
    seed : int or None
        The twin's seed, the same for the three runs.
    cc : str, optional
        The C compiler (default ``$CC`` or ``cc``).
    trace_rpm : float, optional
        The speed of the time traces (default: the given speed nearest :data:`TWINS`' trace speed).
    smooth_velocity : float
        ``GEARSPEC_SMOOTH_VELOCITY`` of the compiled C (rad/s; 0: the exact sign).

    Returns
    -------
    CompensationResult

    Raises
    ------
    InputError
        An unknown twin, a speed that is not positive, a model the exporter refuses or without
        ``tau_c``, a model that needs a load or temperature the twins do not have, no C compiler.
    """
    if twin not in TWINS:
        raise InputError(f"unknown twin '{twin}' (known: {', '.join(TWINS)})")
    where = f"model '{getattr(model, 'name', None)}'"
    if not isinstance(model, FrictionModel):
        where = Path(model).name if isinstance(model, (str, Path)) else "the model"
        model = read_model(model, where)[0]
    check_exportable(model, where)
    needs = {n for t in model.terms for n in TERMS[t["kind"]].needs} & {"load", "temperature"}
    if model.law_spec.needs_load or needs:
        raise InputError(f"model '{model.name}' needs a {' and '.join(sorted(needs) or ['load'])} channel, which the "
                         f"{twin} twin does not have; compensate a model of load-free friction")
    speeds = _speeds(speeds_rpm, twin)
    if int(repetitions) < 1 or not (math.isfinite(duration) and duration > 0):
        raise InputError("repetitions must be at least 1 and duration a positive number of seconds")
    if trace_rpm is None:
        trace_rpm = min(speeds, key=lambda s: abs(math.log(s / TWINS[twin]["trace_rpm"])))
    elif float(trace_rpm) not in speeds:
        listed = ", ".join(f"{s:g}" for s in speeds)
        raise InputError(f"trace speed {trace_rpm:g} rpm is not one of the speeds {listed}")
    cv = coulomb_viscous(model)
    cmodel = c_feedforward(model, cc, smooth_velocity, source=where)
    ffs = {"none": None, "coulomb_viscous": c_feedforward(cv, cc, smooth_velocity), "model": cmodel}
    freqs, rng_fit = locked_frequencies(model), _fitted_range(model)
    rows, traces = [], {}
    for label in COMPENSATIONS:
        rec, truth = _run(twin, speeds, ffs[label], float(duration), int(repetitions), seed)
        r, traces[label] = _measure(rec, truth, label, freqs, float(trace_rpm), rng_fit)
        rows += r
    table = pd.DataFrame(rows)
    keys = ["speed_rpm", "direction", "compensation"]
    table = table.groupby(keys, sort=False).agg(
        {c: ("first" if c == "in_fitted_range" else "mean") for c in table.columns if c not in keys}).reset_index()
    table.insert(0, "twin", twin)
    table = table.sort_values(["direction", "speed_rpm"], ascending=[False, True], kind="stable").reset_index(drop=True)
    bad = not_better(table)
    settings = {"twin": twin, "speeds_rpm": speeds, "duration": float(duration), "repetitions": int(repetitions),
                "seed": seed, "compiler": cmodel.command, "smooth_velocity": smooth_velocity,
                "feedforward_inputs": "encoder position (rad) and reference velocity (rad/s); load "
                                      f"{LOAD:g} Nm, temperature {TEMPERATURE:g} degC, acceleration 0",
                "model": "the model's exported C (gearspec_torque), compiled and called through ctypes",
                "coulomb_viscous": "the model's own tau_c and viscous per direction (no Stribeck part, no lines), "
                                   "exported and compiled the same way",
                "locked_frequencies": freqs, "fitted_speed_range": rng_fit}
    notes = [f"at {r.speed_rpm:g} rpm ({'positive' if r.direction > 0 else 'negative'}) the full model does not "
             f"lower the velocity ripple below Coulomb + viscous ({r.model:.3g} against {r.coulomb_viscous:.3g} "
             f"rpm std)"
             for r in bad.itertuples()]
    return CompensationResult(twin, model, table, traces, float(trace_rpm), bad, settings, notes)
