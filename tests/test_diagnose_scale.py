"""What keeps the closed loop's cost linear in the rows and its memory bounded (issue 13, "Scale"):
the per-group normal equations by BLAS on plateau-sized groups, speed laws evaluated once per
distinct speed, and a column cache bounded in bytes, not blocks.  Known answers: the same numbers
as the direct computation (to round-off: 1e-12 relative), counts of evaluations.  The timings of
the default twin are a benchmark (README proposal), not a test.
"""

from __future__ import annotations

import numpy as np
import pytest

import gearspec.diagnose as dg
from gearspec.core.reduction import GroupNormals
from gearspec.diagnose import budget, context, design
from gearspec.diagnose.data import per_speed
from gearspec.model import FrictionModel
from gearspec.simulate import model_recording


def _groups(sizes):
    stops = np.cumsum(sizes)
    return stops - np.asarray(sizes), stops


@pytest.mark.parametrize("sizes", [[2000, 1500, 3000, 2500],          # plateaus: one BLAS product per group
                                   [3, 7, 1, 12, 5] * 20])             # free-motion blocks: batched
def test_group_normals_equal_the_reduction_of_core(sizes):
    rng = np.random.default_rng(0)
    starts, stops = _groups(sizes)
    X = rng.normal(size=(stops[-1], 9))
    y = rng.normal(size=stops[-1])
    got = context.group_normals(X, y, starts, stops)
    ref = GroupNormals.of(X, y, starts, stops)
    for a, b in ((got.G, ref.G), (got.b, ref.b), (got.yy, ref.yy), (got.n, ref.n)):
        assert np.allclose(a, b, rtol=1e-12, atol=1e-9)
    # and the exact sums of one group by hand
    g = 1
    Xg, yg = X[starts[g]:stops[g]], y[starts[g]:stops[g]]
    assert np.allclose(got.G[g], Xg.T @ Xg, rtol=1e-12) and got.yy[g] == pytest.approx(yg @ yg, rel=1e-12)


def _plateau_data(n_speeds=6, fs=500.0, duration=1.0):
    model = FrictionModel("stribeck", {"tau_c": 0.05, "tau_s": 0.08, "v_s": 1.5, "viscous": 2e-3})
    speeds = [x for s in np.geomspace(0.5, 16, n_speeds) for x in (s, -s)]
    rec, _ = model_recording(model, speeds, noise=1e-3, seed=0, duration=duration, fs=fs)
    return dg.DiagnoseData.from_recording(rec)


def test_speed_laws_are_evaluated_once_per_distinct_speed():
    """On plateaus every sample of a segment has the segment's speed: a law of the speed alone is
    evaluated on the distinct speeds (6 here: 12 plateaus, each speed in both directions), gathered
    to the samples, and equals the evaluation on every sample exactly."""
    dd = _plateau_data()
    seen = []

    def law(sp):
        seen.append(len(sp))
        return np.exp(-0.1 * sp) / (1 + sp ** 2)

    out = per_speed(dd, law)
    assert seen == [6] and len(out) == len(dd.fit) > 100 * 6
    assert np.array_equal(out, law(np.abs(dd.fit.v)))
    # samples that each have their own speed (free motion): evaluated on the samples
    n = 200
    free = dg.DiagnoseData.from_fitdata(dd.fit.subset(np.arange(n)))
    free.fit.v = np.linspace(0.1, 2.0, n)
    seen.clear()
    assert np.array_equal(per_speed(free, law), law(free.fit.v)) and seen[-1] == n


def test_column_cache_is_bounded_in_bytes_not_blocks(monkeypatch):
    """The cache of design columns holds at most ``budget.CACHE_BYTES`` bytes whatever the number of
    blocks (a long recording: each column is rows x 8 bytes), and still serves repeated requests
    from memory."""
    dd = _plateau_data(n_speeds=4)
    monkeypatch.setattr(budget, "CACHE_BYTES", 6 * 8 * len(dd))          # six columns' worth
    const = ((1, "const"), (-1, "const"))
    blocks = [design.HarmonicBlock(key=f"l{k}", frequency=0.3 + 0.1 * k, dirs=(1, -1), law=const,
                                   decay=((1, 0.0), (-1, 0.0))) for k in range(5)]      # 4 columns each
    for b in blocks:
        b.columns(dd)
    cache = dd.cache["columns"]
    assert sum(v[1].nbytes for v in cache.values()) <= 6 * 8 * len(dd) and len(cache) == 1
    last = blocks[-1].columns(dd)
    assert blocks[-1].columns(dd) is last                             # served from the cache
    # within a large budget, a short recording's cache holds at most _CACHE_COLUMNS columns' worth
    monkeypatch.setattr(budget, "CACHE_BYTES", 2 ** 40)
    monkeypatch.setattr(design, "_CACHE_COLUMNS", 9)
    for b in blocks:
        b.columns(dd)
    assert sum(v[1].shape[1] for v in cache.values()) == 8 and len(cache) == 2
