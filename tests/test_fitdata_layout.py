"""FitData's segment layout (:meth:`FitData.segment_groups`): the segments of data whose rows are in
segment order, carried to subsets without reading their samples.  A subset and a direction subset
made through it hold the rows, segments and statistics they hold when made from the samples."""

import numpy as np
import pytest

from gearspec.core.reduction import group_rows
from gearspec.fitdata import FitData
from gearspec.identify.stats import segment_stats
from gearspec.model import FrictionModel
from gearspec.segment import find_segments
from gearspec.simulate import model_recording


@pytest.fixture(scope="module")
def data():
    truth = FrictionModel("silo4", {"tau_c": 0.02, "tau_s": 0.03, "v_s": 2.0, "viscous": 1e-4,
                                    "harmonics": [{"frequency": 0.8, "amplitude": 2e-3, "decay": 0.01}]})
    sp = [1.0, -1.0, 5.0, -5.0, 30.0, -30.0] * 2
    rec, _ = model_recording(truth, sp, duration=[max(1.0, 3.0 / (0.8 * abs(v))) for v in sp], fs=500, ramp=0.1,
                             noise=2e-4, seed=1)
    return FitData.from_recording(rec, find_segments(rec))


def _same(a: FitData, b: FitData):
    for name in ("segment", "direction", "y", "theta", "v"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert a.segments.equals(b.segments)


def test_segment_groups_are_group_rows(data):
    order, ids, bounds = data.segment_groups()
    o2, ids2, b2 = group_rows(data.segment)
    assert order is None and np.array_equal(o2, np.arange(len(data)))
    assert np.array_equal(ids, ids2) and np.array_equal(bounds, b2)


def test_subsets_through_the_layout_are_the_subsets_of_the_samples(data):
    rng = np.random.default_rng(0)
    sids = np.unique(data.segment)
    train = np.isin(data.segment, sids[rng.random(len(sids)) < 0.6])        # whole segments
    partial = train & (rng.random(len(data)) < 0.7)                          # and rows taken out of them
    for mask in (train, partial):
        sub = data.subset(mask)
        ref = FitData(**{k: (None if getattr(data, k) is None else getattr(data, k)[mask]) if k in
                         ("theta", "v", "y", "acc", "load", "temperature", "t", "run", "segment", "direction",
                          "group", "speed") else getattr(data, k) for k in
                         ("theta", "v", "y", "acc", "load", "temperature", "t", "run", "segment", "direction",
                          "group", "speed", "unit", "inertia")},
                      segments=data.segments[data.segments["segment"].isin(np.unique(data.segment[mask]))]
                      .reset_index(drop=True))
        ds = {d: sub.direction_subset(d) for d in (1, -1)}
        # known without gathering the samples' segments and directions
        assert "segment" not in sub.__dict__ and "direction" not in sub.__dict__
        _same(sub, ref)
        order, ids, bounds = sub.segment_groups()
        o2, ids2, b2 = group_rows(data.segment[mask])
        assert order is None and np.array_equal(ids, ids2) and np.array_equal(bounds, b2)
        for d in (1, -1):
            _same(ds[d], ref.subset(ref.direction == d))
            st, st2 = segment_stats(ds[d], [0.8]), segment_stats(ref.subset(ref.direction == d), [0.8])
            assert np.array_equal(st.segment, st2.segment) and np.array_equal(st.G, st2.G)
            assert np.array_equal(st.yy, st2.yy)


def test_rows_out_of_order_have_no_layout(data):
    rows = np.arange(len(data))[::-1]
    sub = data.subset(rows)
    order, ids, bounds = sub.segment_groups()
    assert order is not None                             # group_rows: the rows sorted by segment
    assert np.array_equal(ids, np.unique(data.segment))


def test_segment_subsets_are_subsets_of_their_rows(data):
    from gearspec.fitdata import _Ranges

    order, ids, bounds = data.segment_groups()
    rng = np.random.default_rng(3)
    sel = rng.random(len(ids)) < 0.6
    sub = data.segment_subset(sel)
    ranges = sub.__dict__["_lazy"][1]["y"][1]
    assert isinstance(ranges, _Ranges) and ranges._rows is None        # no row index made yet
    mask = np.isin(data.segment, ids[sel])
    idx = np.array([0, 5, len(sub) // 2, len(sub) - 1])
    assert np.array_equal(sub.values_at("y", idx), data.y[mask][idx])    # read through the ranges
    assert ranges._rows is None
    ref = data.subset(mask)
    d2 = sub.direction_subset(-1)           # a segment subset of a segment subset
    _same(sub, ref)
    _same(d2, ref.subset(ref.direction == -1))
    _same(data.direction_subset(1), data.subset(data.direction == 1))
    o, i2, b2 = d2.segment_groups()
    assert o is None and np.array_equal(i2, np.unique(data.segment[mask & (data.direction == -1)]))
