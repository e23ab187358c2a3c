"""Digital twin of a direct drive with strong cogging: a torque motor on the load, no gear.

The same bench as :mod:`gearspec.simulate.silo4` (one closed-loop code path, so the PID speed loop,
the quantised encoder, the current filter, the stick-slip and the ``feedforward`` hook are the
same), with another plant (:data:`PLANT`) and another friction (:func:`truth_model`): Coulomb +
viscous per direction and a cogging torque of :data:`COGGING_COUNT` cycles per turn, which does not
reverse with the motion.  A parameter set of the SILO4 loop rather than a second loop: a second
copy of the integrator would be a second source of truth for the loop the compensation is judged on.

SI throughout: theta in rad at the motor (= the load), speeds in rad/s, torques in Nm, current in A.

The choices (a frameless torque motor of a robot joint or a rotary table)
-------------------------------------------------------------------------
* ``k_M = 0.2 Nm/A``, ``R = 2 ohm``, 48 V: no-load speed 2290 rpm; electrical damping
  ``k_M^2 / R = 0.02 Nm s/rad``; ``J = 5e-4 kg m^2`` (rotor and load).
* A 16-bit encoder (65536 counts/rev): with a 2000-count encoder the derivative's one-count steps,
  ``Kd q / 5 ms``, would be 0.08 Nm, larger than the cogging; 16 bits are usual on direct drives.
* The PID of the SILO4 bench (triple pole at 15 Hz, derivative over 5 ms), acceleration 200 rad/s^2.
* Friction: 50 / 55 mNm Coulomb (positive / negative), 0.2 mNm s/rad viscous; cogging 24 cycles
  per turn, 30 mNm (60 % of the Coulomb level: "strong", as on a slotted motor without skew).
  At 30 rpm the cogging is at 12 Hz, near the loop's bandwidth, where the loop rejects it least.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Callable, Sequence

from ..gears import load_gear
from ..model import FrictionModel
from ..recording import Recording
from .effects import Cogging
from .silo4 import PLANT as SILO4_PLANT, TwinTruth, silo4_twin

__all__ = ["PLANT", "COGGING_COUNT", "COGGING_AMPLITUDE", "COGGING_FREQUENCY", "DEFAULT_SPEEDS_RPM", "truth_model",
           "cogging", "direct_drive_twin"]

#: the plant and controller: the SILO4 bench's entries with a torque motor's constants
PLANT = {**SILO4_PLANT, "torque_constant": 0.2, "resistance": 2.0, "inertia": 5e-4, "supply_voltage": 48.0,
         "counts_per_rev": 65536, "acceleration": 200.0}
#: cogging cycles per turn and amplitude (Nm)
COGGING_COUNT = 24
COGGING_AMPLITUDE = 0.03
#: motor speeds (rpm) of the default twin, each in both directions
DEFAULT_SPEEDS_RPM = (10, 20, 30, 60, 120, 240)
#: cycles per rad of the cogging (the frequency a fit is given as a line)
COGGING_FREQUENCY = COGGING_COUNT / (2 * math.pi)


def truth_model() -> FrictionModel:
    """Coulomb + viscous per direction (Nm, Nm s/rad), without the cogging (see :func:`cogging`)."""
    return FrictionModel("coulomb_viscous", {"tau_c": 0.050, "viscous": 2e-4}, {"tau_c": 0.055, "viscous": 2e-4},
                         name="direct drive (twin truth)")


def cogging(amplitude: float = COGGING_AMPLITUDE, count: int = COGGING_COUNT, phase: float = 0.3) -> Cogging:
    """The twin's cogging as an :class:`~gearspec.simulate.effects.Cogging` effect (Nm, cycles per turn, rad)."""
    return Cogging(count=count, amplitude=amplitude, phase=phase)


def direct_drive_twin(speeds_rpm: Sequence[float] | None = None, repetitions: int = 1, *,
                      truth: FrictionModel | None = None, effects=None, duration: float = 3.0, seed: int | None = 0,
                      theta0: float = 0.0, record_velocity: bool = True, feedforward: Callable | None = None,
                      plant: dict | None = None, **kw) -> tuple[Recording, TwinTruth]:
    """Simulate the direct drive: one closed-loop run per (speed, repetition).

    Parameters
    ----------
    speeds_rpm : sequence of float, optional
        Signed motor speeds (rpm); default :data:`DEFAULT_SPEEDS_RPM`, each forwards then backwards.
    repetitions : int
        Runs per speed.
    truth : FrictionModel, optional
        The friction without cogging (default :func:`truth_model`).
    effects : sequence of Effect, optional
        Default: the cogging of :func:`cogging`; ``[]``: none.
    duration : float
        Seconds held at each speed.
    seed : int or None
        Noise and repetition-to-repetition variation.
    theta0 : float
        Position at the start of every run (rad).
    record_velocity : bool
        Record the true motor velocity (``velocity``, rad/s): default True.
    feedforward : callable(theta, velocity) -> torque, optional
        As in :func:`~gearspec.simulate.silo4.silo4_twin`: Nm at the motor for the encoder position
        (rad) and the reference velocity (rad/s), added to the PID's command.
    plant : dict, optional
        Entries of :data:`PLANT` to override.
    **kw
        Other keywords of :func:`~gearspec.simulate.silo4.silo4_twin` (``current_noise``, ...).

    Returns
    -------
    recording, truth
        As :func:`~gearspec.simulate.silo4.silo4_twin`'s, with the ``direct-drive`` gear preset
        (the twin's torque constant and inertia) and ``truth.twin == "direct-drive"``.
    """
    if speeds_rpm is None:
        speeds_rpm = [s * d for s in DEFAULT_SPEEDS_RPM for d in (1, -1)]
    P = {**PLANT, **(plant or {})}
    rec, tr = silo4_twin(speeds_rpm, repetitions, truth=truth if truth is not None else truth_model(),
                         effects=[cogging()] if effects is None else effects, duration=duration, seed=seed,
                         theta0=theta0, record_velocity=record_velocity, plant=P, feedforward=feedforward, **kw)
    gear = load_gear("direct-drive")
    gear = dataclasses.replace(gear, name="direct drive (twin)", torque_constant=float(P["torque_constant"]),
                               inertia=float(P["inertia"]), source="gearspec.simulate.directdrive")
    rec = Recording.from_arrays(gear=gear, source="direct-drive twin", **{c: rec.data[c].to_numpy() for c in rec.data})
    tr.twin, tr.gear = "direct-drive", gear
    return rec, tr


