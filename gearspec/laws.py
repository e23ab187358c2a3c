"""Friction laws as plain functions of arrays (SI units).

Each law is declared once in :mod:`gearspec.terms.registry` (parameters, units, columns, degraded
forms); these functions are its signed form ``sign(v) * magnitude(|v|)``.  Sign convention
(``CONTRACTS.md``): friction torque is the torque the drive must supply, with the sign of the
velocity; the Lola/CROPS laws, printed as the torque on the motor, are returned converted to it.
Units: positions rad (m), velocities rad/s (m/s), torques Nm (N), frequencies in cycles per unit of
position (the papers' ``omega = 2 pi f``), decay constants s/rad (s/m), loads Nm at the output.

References: SILO4 (Garcia, Gonzalez de Santos, Canudas de Wit, IJRR 21(9), 2002) eqs. (3), (6),
(8), (11), (14); Lola/CROPS ("Experimental friction identification in robot drives") eqs. (8),
(11), (12), (13).
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from .terms.registry import BASE_LAWS
from .terms.shapes import amplitude_law, load_amplitude, sinusoid

__all__ = ["stribeck", "position_ripple", "meshing_ripple", "silo4_full", "load_dependent_amplitude",
           "lola8", "lola11", "friction_from_load_current", "efficiency", "efficiency_from_friction",
           "motor_torque_from_efficiency"]


def _signed(law: str, v, load, *params):
    v = np.asarray(v, dtype=float)
    return np.sign(v) * BASE_LAWS[law].magnitude(np.abs(v), load, *params)


def stribeck(v, tau_c, tau_s, v_s, viscous):
    """Static + Stribeck + Coulomb + viscous friction (SILO4 eq. 3), 0 at v = 0:
    ``[tau_c + (tau_s - tau_c) exp(-|v| / v_s) + viscous |v|] sign(v)``.

    ``v`` rad/s (m/s); ``tau_c`` Coulomb and ``tau_s`` static (the paper's tau_E) friction, Nm (N);
    ``v_s`` Stribeck velocity > 0, rad/s (m/s); ``viscous`` B, Nm s/rad (N s/m).
    """
    return _signed("stribeck", v, None, tau_c, tau_s, v_s, viscous)


def position_ripple(theta, amplitude, frequency, phase):
    """Position-dependent friction (SILO4 eq. 6), a magnitude: ``A sin(2 pi f theta + phi)``,
    ``frequency`` in cycles per unit of theta."""
    return amplitude * sinusoid(theta, frequency, phase)


def meshing_ripple(theta, v, amplitude, decay, frequency, phase):
    """Meshing friction (SILO4 eq. 8), a magnitude: ``A exp(-b |v|) sin(2 pi f theta + phi)``,
    ``decay`` b in s/rad (s/m)."""
    v = np.asarray(v, dtype=float)
    return amplitude * amplitude_law("exp", np.abs(v), decay) * sinusoid(theta, frequency, phase)


def silo4_full(theta, v, positive: Mapping, negative: Mapping):
    """The full SILO4 model (eq. 11) with parameters per direction i of motion:

    ``[tau_c,i + (tau_s,i - tau_c,i) exp(-|v|/v_s,i) + B_i |v|
       + sum_k A_k,i exp(-b_k,i |v|) sin(2 pi f_k theta + phi_k,i)] sign(v)``

    (eq. 6 is ``decay = 0``; the paper has one Stribeck velocity for both directions).
    ``theta``, ``v`` broadcast together; ``positive``, ``negative``: mappings of ``tau_c``,
    ``tau_s``, ``v_s``, ``viscous`` and ``harmonics``, a sequence of mappings (``frequency``,
    ``amplitude``, ``decay`` default 0, ``phase`` default 0) or of tuples ``(frequency,
    amplitude, decay, phase)``.  Returns the friction torque with the sign of ``v``.
    """
    theta = np.asarray(theta, dtype=float)
    v = np.asarray(v, dtype=float)
    out = np.zeros(np.broadcast(theta, v).shape)
    for d, p in ((1.0, positive), (-1.0, negative)):
        sel = np.sign(v) == d
        if not np.any(sel):
            continue
        th = np.broadcast_to(theta, out.shape)[sel]
        vv = np.broadcast_to(v, out.shape)[sel]
        ripple = np.zeros(th.shape)
        for h in p.get("harmonics", ()):
            if isinstance(h, Mapping):
                h = h["frequency"], h["amplitude"], h.get("decay", 0.0), h.get("phase", 0.0)
            f, a, b, ph = h
            ripple = ripple + meshing_ripple(th, vv, a, b, f, ph)
        out[sel] = d * (np.abs(stribeck(vv, p["tau_c"], p["tau_s"], p["v_s"], p["viscous"])) + ripple)
    return out


def load_dependent_amplitude(load, amplitude0, load_coefficient):
    """Meshing amplitude growing with the square of the load (SILO4 eq. 14, 'future work', whose
    form the paper leaves open; Doehring et al.: worm-gear friction ~ load^2): ``A0 + k tau_L^2``
    (k in 1/Nm), the ``amplitude`` of :func:`meshing_ripple`."""
    return load_amplitude(load, amplitude0, load_coefficient)


def lola8(v, load, t_f0, mu, b, gamma):
    """Lola/CROPS law (8), as the torque the motor must supply (the paper's sign reversed):
    ``sgn(v) (T_f0 + mu |T_l|) + (b + gamma |T_l|) v``.

    ``v`` motor velocity, rad/s; ``load`` T_l at the output, Nm; ``t_f0`` load-free Coulomb
    friction, Nm; ``mu`` load coefficient (per Nm of output load); ``b`` viscous, Nm s/rad;
    ``gamma`` coupled load-speed coefficient, s/rad.
    """
    return _signed("lola8", v, load, t_f0, mu, b, gamma)


def lola11(v, load, t_f0, mu, b, t_fs, v_s):
    """Lola/CROPS law (11) with a Hess-and-Soom Stribeck term, in the drive-must-supply convention:
    ``sgn(v) [T_f0 + mu |T_l| + (T_fS - T_f0) / (1 + (v/v_S)^2)] + b v``.

    As printed, its Stribeck term carries no sign and would not reverse with the motion; it is
    made odd here, so friction starts at ``T_fS + mu |T_l|`` and falls towards ``T_f0 + mu |T_l|``
    above ``v_S``.  ``v``, ``load``, ``t_f0``, ``mu``, ``b`` as in :func:`lola8`; ``t_fs``
    friction at standstill without load, Nm; ``v_s`` Stribeck velocity > 0, rad/s (motor).
    """
    return _signed("lola11", v, load, t_f0, mu, b, t_fs, v_s)


def friction_from_load_current(load, current, ratio, torque_constant):
    """Friction the motor supplies, from output load and motor current (Lola/CROPS eq. 12, sign
    reversed): ``k_m I - T_l / N`` (positive when the drive lifts the load turning forwards)."""
    return torque_constant * np.asarray(current, dtype=float) - np.asarray(load, dtype=float) / ratio


def efficiency(load, current, ratio, torque_constant):
    """Drive efficiency from output load and motor current (Lola/CROPS eq. 13):
    ``eta = T_l / (N k_m I)``."""
    return np.asarray(load, dtype=float) / (ratio * torque_constant * np.asarray(current, dtype=float))


def efficiency_from_friction(friction, load, ratio):
    """Efficiency a friction law predicts when the motor drives the load (forward power flow):
    ``eta = (T_l/N) / (T_l/N + |tau_f|)``, with tau_f the friction at the motor."""
    out_at_motor = np.abs(np.asarray(load, dtype=float)) / ratio
    return out_at_motor / (out_at_motor + np.abs(np.asarray(friction, dtype=float)))


def motor_torque_from_efficiency(eta, load, ratio):
    """Motor torque implied by an efficiency at a load: ``T_l / (N eta)`` (inverse of eq. 13)."""
    return np.asarray(load, dtype=float) / (ratio * np.asarray(eta, dtype=float))
