"""The one conversion of gearspec's results to strict JSON (every ``to_dict`` / ``--json`` writer uses
:func:`plain`): strict JSON has no NaN, and a reader in another language must not meet one.
"""
from __future__ import annotations

import json
import math
from collections.abc import Mapping

import numpy as np

__all__ = ["plain", "dumps", "finite_or_none"]


def finite_or_none(x):
    """``float(x)``, or ``None`` for ``None``, NaN and infinity."""
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


def plain(obj):
    """``obj`` as strict JSON values: numpy scalars and arrays become Python numbers and lists, tuples
    lists, keys strings, NaN and infinity ``None``, callables (a load profile given as a function)
    their name.  Strings and ``None`` pass through; an object of any other type is returned
    unchanged (``json.dumps`` then says which)."""
    if isinstance(obj, Mapping):      # dicts and the model's typed records (gearspec.model)
        return {str(k): plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [plain(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return plain(obj.tolist())
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return finite_or_none(obj)
    if callable(obj):
        return getattr(obj, "__name__", "callable")
    return obj


def dumps(obj, **kwargs) -> str:
    """``json.dumps(plain(obj))`` with ``allow_nan=False``: a value :func:`plain` cannot convert is
    reported by name rather than written as something a strict reader refuses. Objects of other
    types are written as ``str(obj)``."""
    return json.dumps(plain(obj), allow_nan=False, default=str, **kwargs)
