"""The nonlinear shapes friction laws and terms share, written once.

Every law of :mod:`.registry`, every term kind of :mod:`.kinds`, the plain functions of
:mod:`gearspec.laws` and the families of the explorer's library (:mod:`gearspec.discover.library`)
evaluate these functions; none writes its own copy.

Units: speeds rad/s (m/s on a linear axis) and >= 0 (a magnitude's argument ``|v|``), Stribeck
velocities in the same unit, decay constants in s/rad (s/m), positions rad (m), frequencies in
cycles per unit of position, loads Nm.

References
----------
SILO4: E. Garcia, P. Gonzalez de Santos, C. Canudas de Wit, "Velocity dependence in the cyclic
friction arising with gears", IJRR 21(9), 2002 -- eqs. (3), (6), (8), (14).
Lola/CROPS: "Experimental friction identification in robot drives" -- eq. (11).
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError

__all__ = ["STRIBECK_SHAPES", "AMPLITUDE_LAWS", "stribeck_shape", "stribeck_term", "amplitude_law", "clamp_speed", "sinusoid",
           "load_amplitude"]

_TWO_PI = 2.0 * np.pi

#: shapes of a Stribeck term ``g(|v| / v_s)``
STRIBECK_SHAPES = ("exp", "gauss", "rational")
#: amplitude laws of a position-locked line against speed
AMPLITUDE_LAWS = ("exp", "const", "rational", "power")


def stribeck_term(shape: str, height, speed, v_s):
    """A Stribeck term ``h g(|v| / v_s)``: the height ``h`` at standstill, falling with speed.

    Parameters
    ----------
    shape : {"exp", "gauss", "rational"}
        ``g(x) = exp(-x)`` (SILO4 eq. 3), ``exp(-x^2)`` (Gaussian) or ``1 / (1 + x^2)`` (Lola/CROPS
        law (11), Hess and Soom; evaluated as ``h / (1 + x^2)``, as the paper writes it), with
        ``x = speed / v_s``.
    height : float or array_like
        h, Nm (N): e.g. static minus Coulomb friction.
    speed : array_like
        ``|v|``, rad/s (m/s).
    v_s : float or array_like
        Stribeck velocity, rad/s (m/s); > 0.

    Returns
    -------
    ndarray
        The term, in the unit of ``height``.
    """
    x = np.asarray(speed, dtype=float) / v_s
    if shape == "exp":
        return height * np.exp(-x)
    if shape == "gauss":
        return height * np.exp(-x * x)
    if shape == "rational":
        return height / (1.0 + x * x)
    raise InputError(f"unknown Stribeck shape '{shape}' (exp, gauss, rational)")


def stribeck_shape(shape: str, speed, v_s):
    """The dimensionless Stribeck shape ``g(|v| / v_s)`` in (0, 1] (:func:`stribeck_term` of
    height 1); ``speed`` and ``v_s`` in rad/s (m/s)."""
    return stribeck_term(shape, 1.0, speed, v_s)


def amplitude_law(law: str, speed, decay):
    """Amplitude factor of a position-locked line against speed (SILO4 eqs. 6 and 8 and others).

    Parameters
    ----------
    law : {"exp", "const", "rational", "power"}
        ``exp(-b |v|)`` (SILO4 eq. 8), 1 (eq. 6), ``1 / (1 + (b |v|)^2)`` (a Lorentzian fall-off) or
        ``(1 + |v|)^(-b)`` (slow algebraic decay).
    speed : array_like
        ``|v|``, rad/s (m/s).
    decay : float
        b, s/rad (s/m); dimensionless for ``power``.

    Returns
    -------
    ndarray
        Dimensionless factor.
    """
    if law == "exp":
        return np.exp(-decay * speed)
    if law == "const":
        return np.ones_like(speed)
    if law == "rational":
        return 1.0 / (1.0 + (decay * speed) ** 2)
    if law == "power":
        return (1.0 + speed) ** (-decay)
    raise InputError(f"unknown amplitude law '{law}' (exp, const, rational, power)")


def clamp_speed(speed, speed_range):
    """``|v|`` held within ``speed_range`` (``[min, max]``, either may be None; None: unchanged):
    where an amplitude law is evaluated outside the speeds it was fitted on, it gives the value at
    the nearest edge of that range."""
    if not speed_range:
        return speed
    lo, hi = speed_range
    return np.clip(speed, -np.inf if lo is None else float(lo), np.inf if hi is None else float(hi))


def sinusoid(theta, frequency, phase=0.0):
    """``sin(2 pi f theta + phi)``: the position-locked factor of SILO4 eqs. 6 and 8.

    ``theta`` in rad (m), ``frequency`` in cycles per unit of theta (the paper's omega is
    ``2 pi f``), ``phase`` in rad.
    """
    return np.sin(_TWO_PI * frequency * np.asarray(theta, dtype=float) + phase)


def load_amplitude(load, amplitude0, load_coefficient):
    """Meshing amplitude growing with the square of the load (SILO4 eq. 14, 'future work'):
    ``A = A0 + k tau_L^2`` (A0 Nm, k 1/Nm, load Nm at the output)."""
    load = np.asarray(load, dtype=float)
    return amplitude0 + load_coefficient * load * load
