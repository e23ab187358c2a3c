"""The nonlinear shapes friction laws and terms share, written once (laws, term kinds, the explorer's
library all evaluate these).  Speeds ``|v| >= 0`` in rad/s (m/s), decay constants s/rad (s/m),
positions rad (m), frequencies in cycles per unit of position, loads Nm; equations of SILO4 and
Lola/CROPS as cited in :mod:`gearspec.laws`.
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
    """A Stribeck term ``h g(x)``, ``x = speed / v_s``: height ``h`` (Nm or N, e.g. static minus
    Coulomb friction) at standstill, falling with ``speed = |v|``; ``v_s`` > 0 in the unit of speed.

    ``shape``: ``"exp"`` ``g = exp(-x)`` (SILO4 eq. 3), ``"gauss"`` ``exp(-x^2)`` or ``"rational"``
    ``1 / (1 + x^2)`` (Lola/CROPS law (11), Hess and Soom; evaluated as ``h / (1 + x^2)`` as printed).
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
    """Dimensionless amplitude factor of a position-locked line at ``speed = |v|``: ``law`` ``"exp"``
    ``exp(-b |v|)`` (SILO4 eq. 8), ``"const"`` 1 (eq. 6), ``"rational"`` ``1 / (1 + (b |v|)^2)`` or
    ``"power"`` ``(1 + |v|)^(-b)``; ``decay`` b in s/rad (s/m), dimensionless for ``power``."""
    if law == "exp":
        x = np.multiply(-decay, speed)
        return np.exp(x, out=x) if isinstance(x, np.ndarray) else np.exp(x)
    if law == "const":
        return np.ones_like(speed)
    if law == "rational":
        return 1.0 / (1.0 + (decay * speed) ** 2)
    if law == "power":
        return (1.0 + speed) ** (-decay)
    raise InputError(f"unknown amplitude law '{law}' (exp, const, rational, power)")


def clamp_speed(speed, speed_range):
    """``|v|`` held within ``speed_range`` (``[min, max]``, either may be None; None: unchanged), so
    that an amplitude law is not extrapolated past the speeds it was fitted on."""
    if not speed_range:
        return speed
    lo, hi = speed_range
    # np.minimum(np.maximum()) is np.clip (NaN kept), without its per-call overhead on short arrays
    out = speed if lo is None or float(lo) == -np.inf else np.maximum(speed, float(lo))
    return out if hi is None or float(hi) == np.inf else np.minimum(out, float(hi))


def sinusoid(theta, frequency, phase=0.0):
    """``sin(2 pi f theta + phi)`` (SILO4 eqs. 6, 8): ``frequency`` in cycles per unit of theta,
    ``phase`` in rad."""
    x = np.multiply(_TWO_PI * frequency, np.asarray(theta, dtype=float))     # a new array: worked in place
    if not isinstance(x, np.ndarray):
        return np.sin(x + phase)
    try:
        np.add(x, phase, out=x)
    except ValueError:          # phase of a larger shape than theta and frequency
        x = x + phase
    return np.sin(x, out=x)


def load_amplitude(load, amplitude0, load_coefficient):
    """Meshing amplitude growing with the square of the load (SILO4 eq. 14, 'future work'):
    ``A = A0 + k tau_L^2`` (A0 Nm, k 1/Nm, load Nm at the output)."""
    load = np.asarray(load, dtype=float)
    return amplitude0 + load_coefficient * load * load
