"""``gearspec fit`` on long recordings: the cheaper paths of 0.9 give the numbers of what they replace.

- :func:`gearspec.core.reduction.unique_ids` and :func:`~gearspec.core.reduction.group_rows` skip
  the sort of ids already in order (a recording's segments); their arrays are numpy's, exactly.
- :meth:`FitData.subset` gathers an array when it is read: the values are those of the eager
  ``array[mask]`` bit for bit, a fold's fit copies no sample array it does not read, and an array
  assigned to a subset is the one its own subsets take.
- The segments' statistics are computed :data:`~gearspec.identify.stats.CHUNK_ROWS` rows at a time
  and kept once per segment whatever ``min_cycles``: each segment's numbers are computed from its
  own rows alone, so any chunking gives them bit for bit.
- The whole fit (joint fit, published procedure, simpler laws, held-out errors) on a twin with
  known friction is the same number for number with eager subsets and with a tiny chunk, and
  recovers the truth within its noise.
"""

import numpy as np
import pytest

from gearspec import fitdata
from gearspec.core.crossval import splits
from gearspec.core.reduction import group_rows, unique_ids
from gearspec.fitdata import FitData
from gearspec.identify import identify_recording, stats
from gearspec.model import FrictionModel
from gearspec.segment import find_segments
from gearspec.simulate import model_recording


def _as_tuple(x):
    return x if isinstance(x, tuple) else (x,)


@pytest.mark.parametrize("kind", ["sorted", "unsorted", "float", "empty", "one", "int8"])
def test_unique_ids_and_group_rows_are_numpys(kind):
    rng = np.random.default_rng(5)
    a = {"sorted": np.sort(rng.integers(0, 40, 2000)), "unsorted": rng.integers(0, 40, 2000),
         "float": np.repeat(np.sort(rng.random(30)), 3), "empty": np.zeros(0, np.int64), "one": np.array([7]),
         "int8": np.repeat(np.arange(-3, 4), 5).astype(np.int8)}[kind]
    for ri in (False, True):
        for rv in (False, True):
            got = _as_tuple(unique_ids(a, return_index=ri, return_inverse=rv))
            ref = _as_tuple(np.unique(a, return_index=ri, return_inverse=rv))
            assert len(got) == len(ref)
            for x, y in zip(got, ref):
                assert x.dtype == y.dtype and np.array_equal(x, y)
    order, groups, bounds = group_rows(a)
    ref_order = np.argsort(a, kind="stable")
    ref_groups, starts = np.unique(a[ref_order], return_index=True)
    assert np.array_equal(order, ref_order) and np.array_equal(groups, ref_groups)
    assert np.array_equal(bounds, np.append(starts, len(a)))


def test_splits_are_the_folds_in_order():
    fold = np.random.default_rng(1).integers(0, 5, 500)
    fold[fold == 3] = 4                      # an empty fold is skipped, as np.unique skips it
    got = [(f, t) for f, t in splits(fold)]
    assert [f for f, _ in got] == [0, 1, 2, 4]
    assert all(np.array_equal(t, fold == f) for f, t in got)


@pytest.fixture(scope="module")
def twin():
    """Stribeck + one line per direction, 5 speeds per direction, 2 runs, white noise 0.2 mNm."""
    truth = FrictionModel("silo4", {"tau_c": 0.02, "tau_s": 0.03, "v_s": 2.0, "viscous": 1e-4,
                                    "harmonics": [{"frequency": 0.8, "amplitude": 2e-3, "decay": 0.01, "phase": 0.3}]},
                          {"tau_c": 0.022, "tau_s": 0.031, "v_s": 2.5, "viscous": 1.2e-4,
                           "harmonics": [{"frequency": 0.8, "amplitude": 1.5e-3, "decay": 0.01, "phase": -1.0}]})
    speeds = [1.0, 2.0, 5.0, 10.0, 30.0]
    sp = (speeds + [-s for s in speeds]) * 2
    rec, _ = model_recording(truth, sp, duration=[max(1.0, 3.0 / (0.8 * abs(v))) for v in sp], fs=500, ramp=0.1,
                             noise=2e-4, seed=4)
    return truth, rec


def _eager_subset(self, mask):
    """gearspec 0.8's FitData.subset: every array copied at once."""
    from dataclasses import replace

    mask = np.asarray(mask)
    kw = {name: (None if getattr(self, name) is None else getattr(self, name)[mask]) for name in fitdata._ARRAYS}
    keep = np.unique(kw["segment"])
    segs = self.segments[self.segments["segment"].isin(keep)].reset_index(drop=True)
    return replace(self, **kw, segments=segs, notes=list(self.notes), cache=self.cache)


def test_subset_gathers_the_same_values_when_read(twin):
    _, rec = twin
    data = FitData.from_recording(rec, find_segments(rec))
    rng = np.random.default_rng(0)
    mask = rng.random(len(data)) < 0.6
    sub = data.subset(mask)
    # nothing but the segment ids is copied until read (a held-out fold's fit reads cached statistics)
    assert "theta" not in sub.__dict__ and "y" not in sub.__dict__ and len(sub) == int(mask.sum())
    pos = sub.direction_subset(1)
    idx = np.arange(len(pos))[::-3]
    chained = pos.subset(idx)
    ref = _eager_subset(_eager_subset(_eager_subset(data, mask), data.direction[mask] == 1), idx)
    for name in fitdata._ARRAYS:
        a, b = getattr(chained, name), getattr(ref, name)
        assert (a is None and b is None) or (a.dtype == b.dtype and np.array_equal(a, b)), name
    assert chained.segments.equals(ref.segments) and len(chained) == len(ref)
    assert np.array_equal(pos.values_at("y", [0, 5]), _eager_subset(data, mask).y[data.direction[mask] == 1][[0, 5]])
    sub.v = np.zeros(len(sub))              # an array assigned to a subset is the one its subsets take
    assert np.all(sub.subset(np.arange(10)).v == 0) and np.any(data.v != 0)


def test_segment_statistics_do_not_depend_on_the_chunks(twin, monkeypatch):
    _, rec = twin
    data = FitData.from_recording(rec, find_segments(rec))
    sub = data.direction_subset(-1)
    whole = stats.segment_stats(sub, [0.8, 2.4], min_cycles=0.1)
    fresh = FitData.from_recording(rec, find_segments(rec)).direction_subset(-1)
    monkeypatch.setattr(stats, "CHUNK_ROWS", 300)    # a few segments per chunk, a long one alone
    assert len(stats._chunks(np.bincount(fresh.segment)[np.unique(fresh.segment)])) > 3
    chunked = stats.segment_stats(fresh, [0.8, 2.4], min_cycles=0.1)
    for name in ("G", "b", "yy", "n", "speed", "sampled", "cycles", "sigma2", "beta_hat", "rss_hat", "active"):
        assert np.array_equal(getattr(whole, name), getattr(chunked, name)), name
    # another min_cycles reads the same entries: its ``active`` is that of a fresh computation
    again = stats.segment_stats(fresh, [0.8, 2.4], min_cycles=5.0)
    assert len([k for k in fresh.cache if k[0] == "segment_stats"]) == 1
    alone = stats.segment_stats(FitData.from_recording(rec, find_segments(rec)).direction_subset(-1), [0.8, 2.4],
                                min_cycles=5.0)
    assert np.array_equal(again.active, alone.active) and again.active.sum() < chunked.active.sum()


def test_fit_is_the_same_with_eager_subsets_and_tiny_chunks(twin, monkeypatch):
    truth, rec = twin
    fast = identify_recording(rec, "silo4", harmonics=[{"frequency": 0.8, "label": "line"}])
    monkeypatch.setattr(fitdata.FitData, "subset", _eager_subset)
    monkeypatch.setattr(stats, "CHUNK_ROWS", 500)
    slow = identify_recording(rec, "silo4", harmonics=[{"frequency": 0.8, "label": "line"}])
    assert fast.to_dict() == slow.to_dict()                 # every parameter, error and held-out rmse
    for name in fast.errors:
        assert fast.errors[name].equals(slow.errors[name])
    assert fast.comparison.equals(slow.comparison)
    # and it is the truth: Coulomb within 3 % (the twin's 0.2 mNm noise over ~50k samples moves it by
    # < 0.1 %; the Stribeck/Coulomb split at 5 speeds per direction is the larger uncertainty, ~1 %)
    for d in ("positive", "negative"):
        got, want = fast.model.params(d), truth.params(d)
        assert abs(got["tau_c"] - want["tau_c"]) < 0.03 * want["tau_c"]
        assert abs(fast.model.harmonics(d)[0]["amplitude"] - want["harmonics"][0]["amplitude"]) < 0.05 * 2e-3
    assert fast.model.rmse_holdout < 1.2 * 2e-4                # held-out error at the noise


def _plateaus_08(self, blocks=8):
    """gearspec 0.8's FitData.plateaus: every segment computed at each call."""
    import pandas as pd

    rows = []
    mag = self.direction * self.y
    order = np.argsort(self.segment, kind="stable")
    sids, starts = np.unique(self.segment[order], return_index=True)
    bounds = np.append(starts, len(order))
    info = self.segments.set_index("segment") if len(self.segments) else None
    for sid, a, b in zip(sids, bounds[:-1], bounds[1:]):
        ii = order[a:b]
        m = mag[ii]
        nb = min(blocks, len(m))
        se = float(np.array([x.mean() for x in np.array_split(m, nb)]).std(ddof=1) / np.sqrt(nb)) if nb >= 2 \
            else float("nan")
        row = {"segment": int(sid), "run": int(self.run[ii[0]]), "direction": int(self.direction[ii[0]]),
               "speed": float(np.mean(np.abs(self.v[ii]))), "n": len(ii), "level": float(m.mean()), "level_se": se}
        if info is not None and sid in info.index:
            row["speed"] = float(info.loc[sid, "speed"])
        for c in ("load", "temperature", "t"):
            if getattr(self, c) is not None:
                row[c] = float(np.mean(getattr(self, c)[ii]))
        rows.append(row)
    return pd.DataFrame(rows).sort_values(["direction", "speed"], ascending=[False, True]).reset_index(drop=True)


def test_plateaus_are_kept_per_segment(twin):
    _, rec = twin
    data = FitData.from_recording(rec, find_segments(rec))
    ref = _plateaus_08(data)
    assert data.plateaus().equals(ref) and data.plateaus().equals(ref)      # computed, then read back
    train = data.subset(data.segment % 3 != 0)                             # a fold: its rows read from the cache
    assert "y" not in train.__dict__
    assert train.plateaus().equals(_plateaus_08(_eager_subset(data, data.segment % 3 != 0)))
    assert data.plateaus(blocks=4).equals(_plateaus_08(data, blocks=4))
    # other friction values (the same segments): their own rows, never the cached ones
    other = FitData.from_recording(rec, find_segments(rec))
    other.cache = data.cache
    other.y = other.y * 2.0
    assert np.allclose(other.plateaus()["level"], 2 * ref["level"], rtol=1e-15, atol=0)


@pytest.mark.parametrize("n,p", [(25000, 21), (4096, 7), (3, 2)])
def test_gram_on_one_thread_is_the_same_product(n, p):
    """:func:`gearspec.core.reduction.gram` computes ``X^T X`` on one BLAS thread: the threads split
    the p x p result, not the sums over the rows, so the entries are those of ``X.T @ X`` bit for bit
    (25000 x 21 is where two OpenBLAS threads cost 0.77 s of CPU on the busy machine)."""
    from gearspec.core.reduction import gram

    X = np.random.default_rng(p).normal(size=(n, p)) * np.logspace(-3, 3, p)
    assert np.array_equal(gram(X), X.T @ X)
