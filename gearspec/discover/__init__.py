"""Sparse-regression explorer for alternative friction laws (``gearspec discover``).

The papers each propose one law; the explorer asks which laws the data support.  It searches a
library of physically meaningful candidate terms with sparse regression (pysindy's optimisers)
and hands back a short list of readable laws, ranked by how well they predict data they were not
fitted on, against how complex they are.

Pipeline (one module each):

``moments``  exact reduction of the samples: per segment, the Gram matrix of a few sample bases
             (1, |load|, temperature, acceleration, sin/cos of each ripple line) as K pseudo rows;
             every library column is a per-segment multiplier times one basis, so the normal
             equations of any library -- and any value of its nonlinear parameters -- follow
             exactly from these, whatever the number of samples.
``library``  the candidate terms (:class:`Library` of :class:`Term`): sign, viscous, power laws,
             Stribeck (exponential, Gaussian, rational as in Lola's law (11)) on a grid of
             Stribeck velocities, load-coupled Coulomb and viscous, temperature, ripple at every
             declared and discovered line times an amplitude law (constant, exponential or
             rational decay on a grid), each symmetric and direction-dependent; names print as
             equations.
``search``   pysindy's STLSQ or SR3 over a path of thresholds on standardised columns; a
             bootstrap over whole segments for inclusion probabilities.
``law``      each support of the path becomes a structure, fitted with its nonlinear
             parameters refined by least squares (variable projection), scored by
             cross-validation over whole segments or runs, printed, exported as a FrictionModel.
``explorer`` :func:`discover`: the paths (the friction level first, every segment's ripple
             profiled out; then the ripple with the level law held in; then the level again with
             the ripple held in), a hill climb on held-out error around the best law (terms added,
             dropped, made direction-dependent or symmetric, reshaped), the selection (the
             simplest law whose held-out error exceeds the best one's by at most ``se_rule`` = 4
             standard errors of the noise in that difference -- a margin for the hundreds of laws
             the search scores -- with AIC/BIC beside), a bootstrap over segments for inclusion
             probabilities, and the papers' laws refitted by :func:`gearspec.identify.fit` on the
             same folds (published models, e.g. EMPS's IDIM-LS, scored as they are); its search
             pool and moves in ``pool``, the papers' laws in ``references``, what it returns in
             ``results``.
``published`` friction models published with the real data sets.

Choices worth knowing: one term per slot of equivalent shapes (one Stribeck shape, one amplitude
law per ripple line: several neighbouring Stribeck velocities are how least squares spends
collinearity, not physics); power-law exponents stay on their grid (a free exponent imitates
Coulomb or viscous friction); nonlinear parameters are bounded to what the plateau speeds can
identify and flagged when they end on a bound; a ripple line enters the library only when it
completes a cycle in at least 3 segments; the speed laws need each segment's own velocity
(``FitData(velocity="segment")``), which makes the reduction exact.

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
