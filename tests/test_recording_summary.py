"""Recording.summary counts the distinct runs as numpy.unique does, in order or not."""

import numpy as np
import pandas as pd
import pytest

from gearspec.recording import Recording


@pytest.mark.parametrize("runs,expect", [([0, 0, 1, 1, 1, 2], 3), ([2, 0, 2, 1, 0, 5], 4), ([7] * 6, 1)])
def test_summary_counts_distinct_runs(runs, expect):
    n = len(runs)
    data = pd.DataFrame({"t": np.arange(n) * 0.01, "theta": np.arange(n) * 0.1, "torque": np.ones(n),
                         "run": np.array(runs, dtype=np.int64)})
    rec = Recording(data=data, n_read=n)
    assert len(np.unique(runs)) == expect
    assert f", {expect} run(s), " in rec.summary()
