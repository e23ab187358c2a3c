"""A fleet twin: robots x joints x dates of short plateau recordings as ROS 2 bags (mcap), with two
known changes among noise and scatter (for ``gearspec batch`` and its fleet report).

Every robot has ``joints`` joints behind the same one-stage spur gear (:data:`FLEET_GEAR`: ratio 4,
5 teeth, so lines at the output shaft 0.0398, the motor shaft 0.159 and the tooth mesh 0.796
cycles/rad of motor position); each joint's friction is the SILO4 law (eq. 11) with a tooth-mesh
ripple, its own level (Coulomb friction 0.08-0.13 Nm), and at every date an independent
multiplicative scatter of ``scatter`` (sd, default 1 %) on the Coulomb, static and viscous friction
and the ripple amplitude.  On top: one joint's Coulomb friction (both directions) rises by
``coulomb_rise`` (20 %) linearly from the first date to the last, and another joint's mesh ripple
amplitude grows by ``ripple_growth`` (50 %).  White torque noise 1 mNm per sample.

A recording: the six joints on one ``/joint_states`` topic, plateaus at +-1, 3, 8, 20 rad/s held
1 s each at 250 Hz (11 s, 2800 messages), stamped at the date (dates ``days`` apart from 2026-01-05).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from ..gears import load_gear
from ..model import FrictionModel
from .synthetic import model_recording

__all__ = ["FLEET_GEAR", "fleet_twin", "T0"]

#: the fleet's gear spec (motor-side positions, rad)
FLEET_GEAR = {"name": "fleet twin spur drive", "reference": "motor", "unit": "rad",
              "description": "One spur stage, ratio 4, 5 teeth on the motor pinion (gearspec.simulate.fleet).",
              "stages": [{"name": "spur", "kind": "spur", "ratio": 4.0, "teeth": 5}]}
#: the first date, s since 1970 (2026-01-05 00:00 UTC)
T0 = 1_767_571_200.0
#: plateau speeds, rad/s
SPEEDS = (1.0, 3.0, 8.0, 20.0, -1.0, -3.0, -8.0, -20.0)
FS = 250.0
NOISE = 1e-3


def _mesh_frequency() -> float:
    return next(ln.frequency for ln in load_gear(FLEET_GEAR).declared_lines() if ln.kind == "mesh")


def _joint_model(level: float, factors: dict, rise: float, growth: float) -> FrictionModel:
    """One joint at one date: the SILO4 law with a tooth-mesh ripple (SI at the motor)."""
    f = factors
    mesh = {"frequency": _mesh_frequency(), "amplitude": 0.01 * f["ripple"] * (1 + growth), "decay": 0.0,
            "phase": 1.0, "label": "spur tooth mesh"}
    pos = {"tau_c": level * f["tau_c"] * (1 + rise), "tau_s": 1.5 * level * f["tau_s"] * (1 + rise), "v_s": 2.0,
           "viscous": 1e-3 * f["viscous"], "harmonics": [mesh]}
    neg = dict(pos, tau_c=1.1 * pos["tau_c"], tau_s=1.1 * pos["tau_s"])
    return FrictionModel("silo4", pos, neg)


def fleet_twin(out, *, robots: int = 4, joints: int = 6, dates: int = 10, days: float = 7.0,
               coulomb_rise: float = 0.20, ripple_growth: float = 0.50, coulomb_joint=("robot2", "joint3"),
               ripple_joint=("robot3", "joint5"), scatter: float = 0.01, seed: int = 0) -> dict:
    """Write the fleet twin's bags under ``out`` (``out/robotR/dateD`` rosbag2 folders, one mcap each).

    Parameters
    ----------
    out : path
        Folder written (created).
    robots, joints, dates : int
        Fleet size; robots are named ``robot1`` ..., joints ``joint1`` ..., dates ``days`` days apart.
    coulomb_rise : float
        Relative rise of ``coulomb_joint``'s Coulomb and static friction from the first to the last date.
    ripple_growth : float
        Relative growth of ``ripple_joint``'s tooth-mesh ripple amplitude over the dates.
    scatter : float
        Standard deviation of the independent date-to-date factors (relative).
    seed : int
        Random seed (scatter and noise).

    Returns
    -------
    dict
        ``bags`` (the bag folders), ``gear`` (the spec as a dict, :data:`FLEET_GEAR`), ``changed``
        (``{(robot, joint): "coulomb" | "ripple"}``, the truth) and ``start_times`` (s since 1970).
    """
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    rng = np.random.default_rng(seed)
    out = Path(out)
    if out.exists() and any(out.iterdir()):
        raise InputError(f"{out}: the fleet twin is written into a new or empty folder, and this one is not empty")
    ts = get_typestore(Stores.ROS2_HUMBLE)
    names = [f"joint{j + 1}" for j in range(joints)]
    levels = np.linspace(0.08, 0.13, joints)
    changed = {tuple(coulomb_joint): "coulomb", tuple(ripple_joint): "ripple"}
    bags, starts = [], []
    for r in range(robots):
        robot = f"robot{r + 1}"
        for d in range(dates):
            frac = d / max(dates - 1, 1)
            recs = []
            for j, name in enumerate(names):
                f = {k: 1 + scatter * rng.standard_normal() for k in ("tau_c", "tau_s", "viscous", "ripple")}
                kind = changed.get((robot, name))
                model = _joint_model(levels[j], f, coulomb_rise * frac if kind == "coulomb" else 0.0,
                                     ripple_growth * frac if kind == "ripple" else 0.0)
                rec, _ = model_recording(model, SPEEDS, duration=1.0, fs=FS, noise=NOISE,
                                         seed=int(rng.integers(2**31)), one_run_per_plateau=False)
                recs.append(rec)
            start = T0 + d * days * 86400.0 + r * 3600.0
            path = out / robot / f"date{d + 1:02d}"
            path.parent.mkdir(parents=True, exist_ok=True)
            _write_bag(path, start, names, recs, ts, Writer, StoragePlugin.MCAP)
            bags.append(path)
            starts.append(start)
    return {"bags": bags, "gear": FLEET_GEAR, "changed": changed, "start_times": starts}


def _write_bag(path: Path, start: float, names: list, recs: list, ts, Writer, storage) -> None:
    """All joints' samples as one JointState message per sample, stamped ``start + t``."""
    t = recs[0].t
    stamps = np.round((start + t) * 1e9).astype(np.int64)
    pos = np.array([r.theta for r in recs])
    vel = np.array([np.gradient(r.theta, t) for r in recs])
    eff = np.array([r.tau for r in recs])
    T = ts.types
    JS = "sensor_msgs/msg/JointState"
    with Writer(path, version=9, storage_plugin=storage) as w:
        conn = w.add_connection("/joint_states", JS, typestore=ts)
        for i, ns in enumerate(stamps):
            header = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=int(ns // 10**9),
                                                                                      nanosec=int(ns % 10**9)),
                                              frame_id="")
            msg = T[JS](header=header, name=list(names), position=pos[:, i].copy(), velocity=vel[:, i].copy(),
                        effort=eff[:, i].copy())
            w.write(conn, int(ns), ts.serialize_cdr(msg, JS))
