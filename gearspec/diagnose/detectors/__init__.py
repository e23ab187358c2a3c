"""Detectors: one per term kind (or family), each turning what the residual analyses of a round
show into candidate terms for the closed loop.

Every module of this package registers its detectors (:func:`register_detector`) when the package
is imported; the loop asks them all (:func:`propose`) in the order of their ``order`` numbers
(:func:`detectors` lists them).  A new term kind with a detector: declare the term in
:mod:`gearspec.terms`, and add one module here with a function decorated
``@register_detector("my_kind", effect=..., order=...)`` that returns candidates (usually a
:class:`~gearspec.diagnose.candidates.GridCandidate` of
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
