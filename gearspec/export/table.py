"""A friction model as lookup tables (CSV) a drive's firmware can load.

``friction_grid.csv``: the friction torque (:meth:`FrictionModel.friction`) over a grid of position
(rows) x velocity (columns).  ``cogging_table.csv``: one revolution of the reference shaft (the shaft
theta measures; ``period`` on a linear axis) in N entries of the position-locked part (lines,
periodic terms, cogging) at a stated speed, per direction, for an anti-cogging feed-forward; with the
largest error of linear interpolation between entries against the exact model, measured at 16 points
per interval.  A line that does not repeat over one revolution is left out, and the file says so.
A line within :data:`PERIODIC_TOL` of a whole number of cycles is tabulated with that number.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .. import __version__
from ..errors import InputError
from ..model import FrictionModel
from ..terms import TERMS, evaluate_term
from .text import speed_unit, torque_unit

__all__ = ["write_tables", "position_locked", "locked_parts", "PERIODIC_TOL", "SUBSTEPS"]

#: a line repeats over one revolution when it makes a whole number (>= 1) of cycles in it within this
#: many cycles: a fitted frequency carries an error, and 1e-3 cycles moves the phase by 0.36 degrees at
#: the end of the revolution (0.6 % of the amplitude, below a fitted amplitude's standard error); the
#: table uses the whole number, and its stated error is against the model's own frequency
PERIODIC_TOL = 1e-3
#: points per table interval at which the interpolation error is measured
SUBSTEPS = 16


def locked_parts(model: FrictionModel, direction: int) -> list[tuple[str, dict, bool]]:
    """The position-locked parts acting while moving in ``direction`` (+1/-1): ``(name, term, signed)``
    with ``term`` a term of :mod:`gearspec.terms` (a line as its ``periodic`` term) without a direction."""
    dname = "positive" if direction > 0 else "negative"
    out = [(f"{dname} line {h.label or i + 1}", h.term(), False)
           for i, h in enumerate(model.directions[dname].harmonics) if h.amplitude is not None]
    for i, t in enumerate(model.terms):
        if "theta" in TERMS[t["kind"]].needs and int(t.get("direction") or 0) in (0, direction):
            out.append((f"term {i + 1} ({t['kind']}{', ' + t['label'] if t.get('label') else ''})",
                        {k: val for k, val in t.items() if k != "direction"}, TERMS[t["kind"]].signed))
    return out


def position_locked(model: FrictionModel, theta, direction: int, speed: float, load=None, parts=None) -> np.ndarray:
    """The position-locked torque (Nm or N, with the friction's sign) at ``theta`` moving in
    ``direction`` at ``|v| = speed`` (``parts``: a subset of :func:`locked_parts`; default all)."""
    theta = np.asarray(theta, dtype=float)
    v = np.full(theta.shape, direction * float(speed))
    out = np.zeros(theta.shape)
    for _, term, signed in (locked_parts(model, direction) if parts is None else parts):
        c = evaluate_term(term, theta=theta, v=v, load=None if load is None else np.full(theta.shape, load))[0]
        out += c if signed else direction * c
    return out


def _defaults(model: FrictionModel, speeds, load, temperature, notes) -> tuple:
    """The speed grid and the load and temperature the tables are computed at (each default noted)."""
    su = speed_unit(model)
    if speeds is None:
        highs = [h.speed_range[1] for p in model.directions.values() for h in p.harmonics if h.speed_range]
        highs += [t["speed_range"][1] for t in model.terms if t.get("speed_range") and t["speed_range"][1]]
        vs = [p.values.get("v_s") for p in model.directions.values() if p.values.get("v_s")]
        vmax = max(highs) if highs else 10 * max(vs) if vs else (100.0 if model.unit == "rad" else 1.0)
        why = ("the fastest speed a line was fitted on" if highs else "10 x the Stribeck velocity" if vs
               else "no speed range recorded")
        notes.append(f"friction grid: velocities -{vmax:.4g}..{vmax:.4g} {su} ({why}; --speeds to change)")
        speeds = (-vmax, vmax, 41)
    needs = {n for t in model.terms for n in TERMS[t["kind"]].needs}
    needs |= {"load"} if model.law_spec.needs_load else set()
    needs |= {"load"} if any(h.load_coefficient for p in model.directions.values() for h in p.harmonics) else set()
    if "load" in needs and load is None:
        load = 0.0
        notes.append("tables computed at output load 0 Nm (--load to change)")
    if "temperature" in needs and temperature is None:
        temperature = next(float(t.get("reference", 0.0)) for t in model.terms if t["kind"] == "temperature")
        notes.append(f"tables computed at the temperature term's reference, {temperature:g} degC (--temperature)")
    return speeds, load, temperature


def _grid(start, stop, n, what):
    if not (math.isfinite(start) and math.isfinite(stop) and stop > start and int(n) >= 2):
        raise InputError(f"{what} must be START,STOP,N with STOP > START and N >= 2, got {start},{stop},{n}")
    return np.linspace(float(start), float(stop), int(n))


def _write_grid(model, out, source, positions, speeds, load, temperature, period) -> Path:
    theta = (_grid(*positions, "--positions") if positions is not None
             else np.linspace(0.0, period or 1.0, 361)[:-1])
    vel = _grid(*speeds, "--speeds")
    th, vv = np.meshgrid(theta, vel, indexing="ij")
    tau = model.friction(th.ravel(), vv.ravel(), load=load, temperature=temperature).reshape(th.shape)
    tu, su = torque_unit(model), speed_unit(model)
    head = [f"# friction torque ({tu}, with the sign of the velocity) of model \"{model.name}\" (law {model.law}), "
            f"exported by gearspec {__version__} from {source}",
            f"# rows: theta in {model.unit} (first column); columns: velocity in {su} (header row); "
            f"load {load if load is not None else 'not used'}, temperature "
            f"{temperature if temperature is not None else 'not used'}; 0 at v = 0 as the model gives it",
            "theta_" + model.unit + "," + ",".join(repr(float(x)) for x in vel)]
    rows = [repr(float(t)) + "," + ",".join(repr(float(x)) for x in r) for t, r in zip(theta, tau)]
    path = out / "friction_grid.csv"
    path.write_text("\n".join(head + rows) + "\n")
    return path


def _split_periodic(model, direction, period):
    """``(kept, left_out)`` parts of :func:`locked_parts`: kept repeat over ``period``."""
    kept, left = [], []
    for name, term, signed in locked_parts(model, direction):
        cycles = float(term["frequency"]) * period
        whole = round(cycles)
        if cycles == 0 or (whole >= 1 and abs(cycles - whole) <= PERIODIC_TOL):
            kept.append((name, term, signed, whole / period))
        else:
            left.append((name, term, signed, cycles))
    return kept, left


def _write_cogging(model, out, source, entries, speed, load, period, notes) -> Path:
    n = int(entries)
    theta = period * np.arange(n) / n
    fine = period * np.arange(n * SUBSTEPS) / (n * SUBSTEPS)
    tu, su = torque_unit(model), speed_unit(model)
    cols, head_notes, errors = {}, [], {}
    for d, dname in ((1, "positive"), (-1, "negative")):
        kept, left = _split_periodic(model, d, period)
        snapped = [(a, {**b, "frequency": f}, c) for a, b, c, f in kept]
        cols[dname] = position_locked(model, theta, d, speed, load, snapped)
        exact = position_locked(model, fine, d, speed, load, [(a, b, c) for a, b, c, _ in kept])
        interp = np.interp(fine, np.append(theta, period), np.append(cols[dname], cols[dname][0]))
        errors[dname] = float(np.max(np.abs(interp - exact))) if len(fine) else 0.0
        for name, term, signed, cycles in left:
            amp = float(np.max(np.abs(position_locked(model, fine, d, speed, load, [(name, term, signed)]))))
            head_notes.append(f"{name} at {term['frequency']:.6g} cycles/{model.unit} makes {cycles:.6g} cycles per "
                              f"revolution: not periodic over one revolution, left out (up to {amp:.3g} {tu} there)")
    err = max(errors.values())
    msg = (f"cogging table: {n} entries over one revolution ({period:.6g} {model.unit}) at |v| = {speed:g} {su}; "
           f"largest linear-interpolation error against the exact model {err:.3g} {tu} (positive "
           f"{errors['positive']:.3g}, negative {errors['negative']:.3g})")
    notes += [msg] + head_notes
    head = [f"# position-locked torque ({tu}, with the sign of the motion; cogging the same both ways) of model "
            f"\"{model.name}\", exported by gearspec {__version__} from {source}", "# " + msg,
            *("# " + x for x in head_notes),
            f"index,theta_{model.unit},positive_{tu},negative_{tu}"]
    rows = [f"{i},{float(theta[i])!r},{float(p)!r},{float(q)!r}"
            for i, (p, q) in enumerate(zip(cols["positive"], cols["negative"]))]
    path = out / "cogging_table.csv"
    path.write_text("\n".join(head + rows) + "\n")
    return path


def write_tables(model: FrictionModel, out: Path, *, source: str = "a FrictionModel", notes: list | None = None,
                 entries: int = 3600, speed: float = 0.0, positions=None, speeds=None, load=None,
                 temperature=None, period=None, **_) -> list[Path]:
    """Write ``out/friction_grid.csv`` and ``out/cogging_table.csv``.

    Parameters
    ----------
    model : the (checked) model.
    out : folder, created when missing.
    source : the model file's name, quoted in the files.
    notes : list the sentences the files state are appended to (defaults, lines left out, errors).
    entries : entries of the one-revolution table (>= 2).
    speed : |v| (rad/s, m/s) the position-locked part is computed at; 0 (default): each amplitude
        law at the low edge of its speed range (the standstill limit).
    positions, speeds : ``(start, stop, n)`` of the grid; default one revolution in 360 rows and
        velocities up to the fastest speed a line was fitted on in 41 columns.
    load : output load, Nm (default 0 when the model uses it); temperature : degC (default the
        temperature term's reference).
    period : one revolution in units of theta (default 2 pi on a rotary axis; needed on a linear one).
    """
    notes = [] if notes is None else notes
    if not (isinstance(entries, (int, np.integer)) and entries >= 2):
        raise InputError(f"--entries must be an integer >= 2, got {entries!r}")
    if not (math.isfinite(speed) and speed >= 0):
        raise InputError(f"--speed must be a speed >= 0, got {speed!r}")
    if period is None and model.unit == "rad":
        period = 2.0 * math.pi
    if period is not None and not (math.isfinite(period) and period > 0):
        raise InputError(f"--period must be a length > 0, got {period!r}")
    speeds, load, temperature = _defaults(model, speeds, load, temperature, notes)
    out.mkdir(parents=True, exist_ok=True)
    paths = [_write_grid(model, out, source, positions, speeds, load, temperature, period)]
    if period is None:
        notes.append("no cogging table: the axis is linear (m) and one revolution of its shaft is not known; "
                     "give --period (m per revolution)")
    else:
        paths.append(_write_cogging(model, out, source, entries, speed, load, period, notes))
    return paths
