"""Identification of friction models (moved from identify.py; split by job in the next commit)."""

from .joint import *  # noqa: F401,F403
from .joint import __all__, _basis, _folds, _make_problem, _n_params  # noqa: F401
