"""The one JSON conversion (gearspec.jsonsafe): strict JSON from numpy results."""
import json

import numpy as np

from gearspec.jsonsafe import dumps, plain


def test_plain_converts_numpy_and_non_finite_values():
    out = plain({1: np.float64(2.5), "a": (np.int64(3), np.bool_(True)), "nan": np.nan,
                 "inf": float("inf"), "arr": np.array([1.0, np.nan]), "f": np.sin})
    assert out == {"1": 2.5, "a": [3, True], "nan": None, "inf": None, "arr": [1.0, None], "f": "sin"}
    assert type(out["a"][0]) is int and type(out["a"][1]) is bool


def test_dumps_is_strict_json():
    text = dumps({"x": np.float32(-np.inf), "y": [np.nan]})
    assert json.loads(text) == {"x": None, "y": [None]}
    assert "NaN" not in text and "Infinity" not in text
