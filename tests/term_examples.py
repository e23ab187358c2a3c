"""Parameters of the size a fit gives for every term kind of the registry, shared by the tests
that evaluate, export or compile every kind (a kind missing here gets 0.5 for each parameter)."""

from __future__ import annotations

import math

from gearspec.terms import TERMS

TERM_EXAMPLES = {
    "periodic": {"frequency": 0.37, "amplitude": 0.02, "decay": 0.01, "phase": 0.4, "law": "rational",
                 "speed_range": [0.5, 40.0]},
    "viscous_power": {"coefficient": 0.001, "exponent": 1.5},
    "stribeck_extra": {"amplitude": 0.05, "v_s": 0.7, "shape": "gauss"},
    "load_coulomb": {"mu": 0.01},
    "load_viscous": {"gamma": 0.0004},
    "temperature": {"coefficient": -0.002, "reference": 30.0},
    "drift": {"coefficient": 1e-4, "reference": 10.0},
    "inertia": {"inertia": 0.003},
    "offset": {"offset": -0.01},
    "hysteresis": {"scale": 0.02, "length": 0.5},
    "cogging": {"frequency": 7 / (2 * math.pi), "amplitude": 0.004, "phase": 0.3},
    "backlash": {"scale": 0.01, "gap": 0.2},
}


def example_term(kind: str) -> dict:
    """A term of ``kind`` with the parameters above."""
    return {"kind": kind, **TERM_EXAMPLES.get(kind, {p: 0.5 for p in TERMS[kind].params})}


def law_parameters(spec, rng, degraded: bool = False) -> dict:
    """Parameters of the size a fit gives for a law of the registry (``gearspec.model.LAWS[law]``),
    drawn from ``rng``; ``degraded``: its optional parameters None (not identified)."""
    vals = {}
    for k, u in zip(spec.params, spec.units):
        vals[k] = rng.uniform(0.5, 3.0) if k == "v_s" else rng.uniform(0.05, 0.3) if u == "Nm" else \
            rng.uniform(1e-4, 2e-3) if k in ("viscous", "b") else rng.uniform(0.005, 0.02)
        if degraded and k in spec.optional:
            vals[k] = None
    return vals
