"""Detectors: one per term kind (or family), each turning what the residual analyses of a round
show into candidate terms for the closed loop.

Every module of this package registers its detectors (:func:`register_detector`) when the package
is imported; the loop asks them all (:func:`propose`) in the order of their ``order`` numbers::

    detector            module     effect       proposes
    lines               lines      periodic     a line at a residual-spectrum peak the model lacks
    viscous_power       speed      speed_law    c|v|^p (residual means against speed)
    stribeck_extra      speed      speed_law    an extra Stribeck term, three shapes
    line_amplitude_law  speed      speed_law    another amplitude-vs-speed law of a line of the model
    load_coulomb        load       load         mu |load| (Lola law (8))
    load_viscous        load       load         gamma |load| |v|
    load_line           load       load         a line growing with load^2 (SILO4 eq. 14)
    temperature         channels   temperature  friction linear in temperature
    drift               channels   drift        friction linear in time
    asymmetry           asymmetry  asymmetry    a base-law parameter differing by direction
    inertia             inertia    inertia      J thetadd
    hysteresis          reversal   hysteresis   presliding after reversals
    backlash            reversal   hysteresis   friction missing over a gap after reversals
    lag                 lag        lag          the torque channel logged behind position
    sidebands           sidebands  periodic     declared sidebands of a line of the model

A new term kind with a detector: declare the term in :mod:`gearspec.terms`, and add one module
here with a function decorated ``@register_detector("my_kind", effect=..., order=...)`` that
returns candidates (usually a :class:`~gearspec.diagnose.candidates.GridCandidate` of
:func:`~gearspec.diagnose.candidates.per_direction` blocks).
"""

from __future__ import annotations

import importlib
import pkgutil

from .analyses import analyse, load_line_analysis
from .registry import Detector, detectors, propose, register_detector, unregister_detector

for _m in pkgutil.iter_modules(__path__):
    importlib.import_module(f"{__name__}.{_m.name}")

from .asymmetry import AsymmetryBlock  # noqa: E402
from .lag import lag_candidates, segment_phases  # noqa: E402
from .lines import line_candidates  # noqa: E402
from .sidebands import SIDEBAND_CYCLES, sideband_candidates  # noqa: E402

__all__ = ["register_detector", "unregister_detector", "detectors", "Detector", "propose",
           "analyse", "load_line_analysis", "line_candidates", "lag_candidates", "segment_phases",
           "sideband_candidates", "SIDEBAND_CYCLES", "AsymmetryBlock"]
