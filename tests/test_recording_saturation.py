"""The saturation rule's evidence test at its threshold (``recording.cleaning._exclude_saturation``):
a signal that repeats its previous value in more than 20 % of the steps between rows not at an
extreme holds values by nature, and its extremes are no evidence of saturation.  The counts are
those of a plain loop over the rows."""

import numpy as np
import pandas as pd
import pytest

from gearspec.errors import GearspecWarning
from gearspec.recording.cleaning import _exclude_saturation

N, STUCK = 4000, 10


def _signal(n_repeats: int, n: int = N) -> np.ndarray:
    rng = np.random.default_rng(5)
    v = rng.uniform(-1.0, 1.0, n)
    v[2000:2000 + STUCK] = 3.0                       # stuck at the maximum: 10 rows in a row
    # repeats of the previous value, away from the stuck rows and from each other
    at = [i for i in range(2, n, 3) if not 1995 <= i <= 2015][:n_repeats]
    for i in at:
        v[i] = v[i - 1]
    return v


def _loop_counts(v: np.ndarray) -> tuple[int, int]:
    """Steps between two rows not at an extreme, and those of them that repeat the value."""
    hi, lo = max(v), min(v)
    inner = rep = 0
    for a, b in zip(v[:-1], v[1:]):
        if a not in (hi, lo) and b not in (hi, lo):
            inner += 1
            rep += a == b
    return inner, rep


def test_the_repeat_fraction_decides_at_one_fifth():
    # a length whose steps between rows not at an extreme are a multiple of 5: exactly 20 % repeats
    rows = next(m for m in range(N, N + 5) if _loop_counts(_signal(0, m))[0] % 5 == 0)
    inner, _ = _loop_counts(_signal(0, rows))
    k = inner // 5                                   # 20 %, not more: saturation is looked for
    assert _loop_counts(_signal(k, rows)) == (inner, k) and k / inner == 0.2
    with pytest.warns(GearspecWarning, match=f"sits at its extreme value in {STUCK} rows"):
        frame, n = _exclude_saturation("x", pd.DataFrame({"torque": _signal(k, rows)}), "torque")
    assert n == STUCK and len(frame) == rows - STUCK and frame["torque"].max() < 3.0
    # one repeat more: above 20 %, the signal holds values by nature, nothing is excluded
    assert _loop_counts(_signal(k + 1, rows)) == (inner, k + 1)
    frame, n = _exclude_saturation("x", pd.DataFrame({"torque": _signal(k + 1, rows)}), "torque")
    assert n == 0 and len(frame) == rows
