"""Friction laws, once each, as plain functions of arrays (SI units).

Sign convention (``CONTRACTS.md``): *friction torque* is the torque the drive must supply to
overcome friction; it has the sign of the velocity.  The SILO4 laws are written that way.  The
Lola/CROPS laws (8) and (11) give the torque friction exerts *on the motor* (the opposite sign);
:func:`lola8` and :func:`lola11` return it converted to the convention above, and say so.

Units: positions rad (or m), velocities rad/s (or m/s) of the reference shaft, torques Nm (or N),
frequencies in cycles per unit of position (``omega = 2 pi f`` of the papers), decay constants in
s/rad (or s/m), loads in Nm at the output.

References
----------
SILO4: E. Garcia, P. Gonzalez de Santos, C. Canudas de Wit, "Velocity dependence in the cyclic
friction arising with gears", Int. J. Robotics Research 21(9), 2002 -- eqs. (3), (6), (8), (11),
(14).
Lola/CROPS: "Experimental friction identification in robot drives" (the Lola/CROPS testbed
paper) -- eqs. (8), (11), (12), (13).

Each law is declared once in the term registry (:mod:`gearspec.terms.registry`: parameters,
units, linear columns, degraded forms); these functions are its signed form,
``sign(v) * magnitude(|v|)``, and the shapes they use are those of :mod:`gearspec.terms.shapes`.
"""

from __future__ import annotations

from typing import Iterable, Mapping

import numpy as np

from .terms.registry import BASE_LAWS
from .terms.shapes import amplitude_law, load_amplitude, sinusoid

__all__ = ["stribeck", "position_ripple", "meshing_ripple", "silo4_full", "load_dependent_amplitude",
           "lola8", "lola11", "friction_from_load_current", "efficiency", "efficiency_from_friction",
           "motor_torque_from_efficiency"]

def stribeck(v, tau_c, tau_s, v_s, viscous):
    """Static + Stribeck + Coulomb + viscous friction (SILO4 eq. 3).

    ``tau_f = [tau_c + (tau_s - tau_c) exp(-|v| / v_s) + viscous |v|] sign(v)``

    Parameters
    ----------
    v : array_like
        Velocity, rad/s (m/s).
    tau_c : float
        Coulomb friction, Nm (N).
    tau_s : float
        Static friction (the paper's tau_E), Nm (N).
    v_s : float
        Stribeck velocity, rad/s (m/s); > 0.
    viscous : float
        Viscous coefficient B, Nm s/rad (N s/m).

    Returns
    -------
    ndarray
        Friction torque with the sign of ``v`` (0 at v = 0).
    """
    v = np.asarray(v, dtype=float)
    return BASE_LAWS["stribeck"].magnitude(np.abs(v), None, tau_c, tau_s, v_s, viscous) * np.sign(v)


def position_ripple(theta, amplitude, frequency, phase):
    """Position-dependent friction (SILO4 eq. 6): ``A sin(2 pi f theta + phi)``.

    ``frequency`` in cycles per unit of theta (the paper's omega is ``2 pi f``).  A magnitude: in
    eq. 11 it is multiplied by sign(v) with the rest.
    """
    return amplitude * sinusoid(theta, frequency, phase)


def meshing_ripple(theta, v, amplitude, decay, frequency, phase):
    """Meshing friction (SILO4 eq. 8): ``A exp(-b |v|) sin(2 pi f theta + phi)``.

    ``decay`` b in s/rad (s/m); a magnitude, like :func:`position_ripple`.
    """
    v = np.asarray(v, dtype=float)
    return amplitude * amplitude_law("exp", np.abs(v), decay) * sinusoid(theta, frequency, phase)


def _harmonic_sum(theta, v, harmonics: Iterable) -> np.ndarray:
    out = np.zeros(np.broadcast(np.asarray(theta), np.asarray(v)).shape)
    for h in harmonics:
        if isinstance(h, Mapping):
            f, a, b, ph = h["frequency"], h["amplitude"], h.get("decay", 0.0), h.get("phase", 0.0)
        else:
            f, a, b, ph = h
        out = out + meshing_ripple(theta, v, a, b, f, ph)
    return out


def silo4_full(theta, v, positive: Mapping, negative: Mapping):
    """The full SILO4 model (eq. 11) with direction-dependent parameters.

    ``tau_f = [tau_c,i + (tau_s,i - tau_c,i) exp(-|v|/v_s,i) + B_i |v|
               + sum_k A_k,i exp(-b_k,i |v|) sin(2 pi f_k theta + phi_k,i)] sign(v)``

    with i the direction of motion.  Eq. 6 (a position ripple of constant amplitude) is the case
    ``decay = 0``; the paper uses one Stribeck velocity for both directions, this function allows
    one per direction.

    Parameters
    ----------
    theta, v : array_like
        Position and velocity (broadcast together).
    positive, negative : mapping
        ``tau_c``, ``tau_s``, ``v_s``, ``viscous`` and ``harmonics``: a sequence of mappings with
        ``frequency``, ``amplitude``, ``decay`` (default 0) and ``phase`` (default 0), or of
        tuples ``(frequency, amplitude, decay, phase)``.

    Returns
    -------
    ndarray
        Friction torque with the sign of ``v``.
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
        mag = np.abs(stribeck(vv, p["tau_c"], p["tau_s"], p["v_s"], p["viscous"]))
        mag = mag + _harmonic_sum(th, vv, p.get("harmonics", ()))
        out[sel] = d * mag
    return out


def load_dependent_amplitude(load, amplitude0, load_coefficient):
    """Meshing amplitude that grows with the square of the load (SILO4 eq. 14, 'future work').

    The paper writes ``A2(tau_L^2)`` without a form; the simplest one consistent with Doehring
    et al. (worm-gear friction ~ load^2) is used: ``A = A0 + k tau_L^2`` (k in 1/Nm).
    Use it as the ``amplitude`` of :func:`meshing_ripple`.
    """
    return load_amplitude(load, amplitude0, load_coefficient)


def lola8(v, load, t_f0, mu, b, gamma):
    """Lola/CROPS law (8): load-dependent Coulomb, viscous and coupled load-speed friction.

    The paper gives the torque on the motor, ``T_f = -sgn(v)(T_f0 + mu |T_l|) - (b + gamma |T_l|) v``;
    this returns its negative, the friction torque the motor must supply:

    ``tau_f = sgn(v) (T_f0 + mu |T_l|) + (b + gamma |T_l|) v``

    Parameters
    ----------
    v : array_like
        Motor (input) velocity, rad/s.
    load : array_like
        Load torque T_l at the output, Nm.
    t_f0 : float
        Static (load-free Coulomb) friction, Nm.
    mu : float
        Load coefficient of Coulomb friction, dimensionless (per Nm of output load).
    b : float
        Viscous coefficient, Nm s/rad.
    gamma : float
        Coupled load-speed coefficient, s/rad (Nm s/rad per Nm of load).
    """
    v = np.asarray(v, dtype=float)
    return np.sign(v) * BASE_LAWS["lola8"].magnitude(np.abs(v), load, t_f0, mu, b, gamma)


def lola11(v, load, t_f0, mu, b, t_fs, v_s):
    """Lola/CROPS law (11), with a Stribeck term of the Hess-and-Soom (rational) form.

    As printed the law is ``T_f = -sgn(v)(T_f0 + mu|T_l|) - b v - (T_fS - T_f0)/(1 + (v/v_S)^2)``:
    its last term carries no sign and so does not reverse with the motion, which no friction
    law can do.  Here it is made odd in velocity (multiplied by sgn(v)), and the whole law is
    returned in the drive-must-supply convention:

    ``tau_f = sgn(v) [T_f0 + mu |T_l| + (T_fS - T_f0) / (1 + (v/v_S)^2)] + b v``

    so that friction starts at ``T_fS + mu |T_l|`` at standstill and falls towards
    ``T_f0 + mu |T_l|`` above ``v_S``.

    Parameters
    ----------
    v, load : array_like
        Motor velocity (rad/s) and output load (Nm).
    t_f0, mu, b : float
        As in :func:`lola8` (the paper's barred values).
    t_fs : float
        Friction at standstill without load, Nm.
    v_s : float
        Stribeck velocity, rad/s (motor); > 0.
    """
    v = np.asarray(v, dtype=float)
    return np.sign(v) * BASE_LAWS["lola11"].magnitude(np.abs(v), load, t_f0, mu, b, t_fs, v_s)


def friction_from_load_current(load, current, ratio, torque_constant):
    """Friction at the motor from output load and motor current (Lola/CROPS eq. 12).

    The paper's ``T_f = T_l / N - k_m I`` is the torque on the motor; this returns the friction
    torque the motor supplies, ``k_m I - T_l / N`` (positive when the drive lifts the load while
    turning forwards).
    """
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
