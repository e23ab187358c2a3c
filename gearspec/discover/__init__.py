"""Sparse-regression explorer for alternative friction laws (``gearspec discover``).

The papers each propose one law; the explorer asks which laws the data support.  It searches a
library of physically meaningful candidate terms with sparse regression (pysindy's optimisers)
and hands back a short list of readable laws, ranked by how well they predict data they were not
fitted on, against how complex they are.

Pipeline, one module each: ``moments`` (the exact per-segment reduction), ``library`` (the
candidate terms, printed as equations), ``search`` (pysindy's optimisers over a path of
thresholds; a bootstrap over whole segments for inclusion probabilities), ``law`` (a structure
fitted with its nonlinear parameters, scored by cross-validation over whole segments or runs,
exported as a FrictionModel), ``explorer`` (:func:`discover`: the paths, the hill climb and the
selection -- its search pool in ``pool``, the papers' laws in ``references``, its result in
``results``), ``published`` (models published with the real data sets).

Choices worth knowing: one term per slot of equivalent shapes (several neighbouring Stribeck
velocities are how least squares spends collinearity, not physics); power-law exponents stay on
their grid (a free exponent imitates Coulomb or viscous friction); nonlinear parameters are
bounded to what the plateau speeds can identify and flagged when they end on a bound; a ripple
line enters the library only when it completes a cycle in at least 3 segments.

The package exports what a user calls (:func:`discover`, its result, the terms to build a library
of one's own); the engine's parts (moments, law fits, folds) are imported from their modules.
``gearspec.discover(data)`` is :func:`discover` (the package is callable).
"""

import sys

from .. import _CallablePackage
from .explorer import PAPER_LAWS, DiscoveryResult, discover
from .library import FAMILIES, Library, Term
from .published import published_models

__all__ = ["discover", "DiscoveryResult", "PAPER_LAWS", "published_models", "Library", "Term", "FAMILIES"]

sys.modules[__name__].__class__ = _CallablePackage
