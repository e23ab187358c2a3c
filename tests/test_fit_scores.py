"""A fitted model's errors on plateaus from the segments' normal equations
(:mod:`gearspec.identify.scores`) against the direct computation: the model evaluated at every
sample, residuals squared and summed per segment.

The two differ by rounding only: ``y'y - 2 b'X'y + b'X'X b`` is a difference of sums of the
torque's size, so its rounding is ~1e-15 of ``y'y``; a segment whose residual is below
``scores.CANCEL`` (1e-5) of ``y'y`` is computed sample by sample, so 1e-10 relative is a bound with
room.  Each test also checks that the shortcut was taken (the model evaluated at few or no rows),
so that it cannot pass by falling back everywhere.
"""

from dataclasses import replace

import numpy as np
import pytest

from gearspec.fitdata import FitData
from gearspec.identify import fit, scores
from gearspec.identify.published import silo4_published
from gearspec.identify.validate import _safe_rmse, holdout, segment_errors, segment_rows
from gearspec.model import FrictionModel
from gearspec.segment import find_segments
from gearspec.simulate import model_recording


def _truth(frequency):
    return FrictionModel("silo4", {"tau_c": 0.02, "tau_s": 0.03, "v_s": 2.0, "viscous": 1e-4,
                                   "harmonics": [{"frequency": frequency, "amplitude": 2e-3, "decay": 0.01,
                                                  "phase": 0.3}]},
                         {"tau_c": 0.022, "tau_s": 0.031, "v_s": 2.5, "viscous": 1.2e-4,
                          "harmonics": [{"frequency": frequency, "amplitude": 1.5e-3, "decay": 0.01, "phase": -1.0}]})


def _data(frequency=0.8, noise=2e-4, top=80.0):
    speeds = [1.0, 2.0, 5.0, 10.0, 30.0, top]
    sp = (speeds + [-s for s in speeds]) * 2
    rec, _ = model_recording(_truth(frequency), sp, duration=[max(1.0, 3.0 / (frequency * abs(v))) for v in sp],
                             fs=500, ramp=0.1, noise=noise, seed=3, theta0=1e3)
    return FitData.from_recording(rec, find_segments(rec))


@pytest.fixture(scope="module")
def small():
    return _data()


class _Count:
    """Rows at which FrictionModel.evaluate was called (monkeypatched)."""

    def __init__(self, monkeypatch):
        self.rows = 0
        orig = FrictionModel.evaluate

        def counted(model, theta=None, v=None, **kw):
            self.rows += int(np.size(v))
            return orig(model, theta, v, **kw)

        monkeypatch.setattr(FrictionModel, "evaluate", counted)


def _direct(model, data):
    """(sse, sum of predicted magnitudes, sum of measured magnitudes) per segment, sample by sample."""
    lay = scores.layout(data)
    pred = model.evaluate(**data.inputs())
    r = data.y - pred
    d = data.direction
    return (np.add.reduceat(r * r, lay.starts), np.add.reduceat(d * pred, lay.starts),
            np.add.reduceat(d * data.y, lay.starts))


def _models(data):
    return {"silo4": fit(data, "silo4", harmonics=[{"frequency": 0.8}], holdout=None),
            "stribeck": fit(data, "stribeck", holdout=None),
            "published": silo4_published(data, harmonics=[{"frequency": 0.8, "label": "l"}], holdout=None)}


def test_segment_sums_are_the_sums_over_the_samples(small, monkeypatch):
    models = _models(small)
    count = _Count(monkeypatch)
    for name, m in models.items():
        got = scores.segment_sums(m, small)
        assert got is not None and got.ok.all(), name
        sse, pred, y = _direct(m, small)
        count.rows = 0
        got = scores.segment_sums(m, small)
        assert count.rows == 0, name                          # no sample evaluated: the statistics only
        np.testing.assert_allclose(got.sse, sse, rtol=1e-10, atol=0)
        np.testing.assert_allclose(got.pred, pred, rtol=1e-12, atol=0)
        np.testing.assert_allclose(got.y, y, rtol=1e-12, atol=0)
        # the in-sample rmse (JointFit.fit, the comparison table) from them
        assert _safe_rmse(m, small) == pytest.approx(float(np.sqrt(np.mean((small.y - m.evaluate(**small.inputs())) ** 2))),
                                                   rel=1e-10)


def test_a_line_above_the_nyquist_limit_is_scored_by_samples(monkeypatch):
    """At 80 rad/s and 500 Hz a line of 3 cycles/rad is at 240 Hz: beyond the position-Nyquist limit
    of those plateaus, whose statistics hold no columns for it; the model still predicts it there."""
    data = _data(frequency=3.0)
    m = fit(data, "silo4", harmonics=[{"frequency": 3.0}], holdout=None)
    m.directions["positive"].harmonics[0].speed_range = None      # its amplitude not held at the edge: > 0 at 80 rad/s
    st = scores._stats(data, [3.0], __import__("gearspec.identify.stats", fromlist=["x"]).segment_stats)
    assert not st.sampled.all() and st.sampled.any()
    sse, pred, _ = _direct(m, data)
    count = _Count(monkeypatch)
    got = scores.segment_sums(m, data)
    n_unsampled = int(np.sum(scores.layout(data).n[~st.sampled[:, 0]]))
    assert 0 < count.rows == n_unsampled          # those segments' samples, and only those
    np.testing.assert_allclose(got.sse, sse, rtol=1e-10, atol=0)
    np.testing.assert_allclose(got.pred, pred, rtol=1e-12, atol=0)


def test_a_residual_that_cancels_is_scored_by_samples(small):
    """The torque replaced by a model's own prediction plus a tiny error: every residual is 1e-8 of
    the torque (1e-16 of y'y), below what the normal equations can resolve (~1e-15 of y'y); those
    segments are summed sample by sample."""
    m = _truth(0.8)
    pred = m.evaluate(**small.inputs())
    tiny = 1e-8 * np.abs(pred) * np.cos(np.arange(len(pred)))
    data = replace(small, y=pred + tiny, cache={}, notes=list(small.notes))
    sse, _, _ = _direct(m, data)
    got = scores.segment_sums(m, data)
    assert np.max(sse / np.add.reduceat(data.y ** 2, scores.layout(data).starts)) < 1e-15
    np.testing.assert_allclose(got.sse, sse, rtol=1e-10, atol=0)


def test_held_out_rmse_by_segments_is_the_one_by_samples(small, monkeypatch):
    m = fit(small, "silo4", harmonics=[{"frequency": 0.8}], holdout=None)
    one_way = m.copy()                                  # a model that cannot predict the negative direction
    one_way.directions["negative"].values["tau_c"] = None
    for model, by in ((m, "segment"), (m, "run"), (one_way, "segment")):
        def refit(train, model=model):
            f = fit(train, "silo4", harmonics=[{"frequency": 0.8}], holdout=None, check=False)
            if model is one_way:
                f.directions["negative"].values["tau_c"] = None
            return f

        by_rows = holdout(refit, small, by=by, folds=3, residual=lambda mm, t: mm.residual(t))   # sample by sample
        count = _Count(monkeypatch)
        fast = holdout(refit, small, by=by, folds=3)
        monkeypatch.undo()
        assert count.rows == 0
        assert fast[1] == by_rows[1]                     # the same reason (or none)
        assert (fast[0] is None and by_rows[0] is None) or fast[0] == pytest.approx(by_rows[0], rel=1e-10)
    assert "could not" in fast[1]                        # the one-way model: its negative folds fail


def test_segment_rows_are_segment_errors(small, monkeypatch):
    models = _models(small)
    count = _Count(monkeypatch)
    fast = segment_rows(models, small)
    rows = count.rows
    monkeypatch.undo()
    assert rows < len(small)                              # few segments (if any) by samples
    for name, m in models.items():
        ref = segment_errors(m, small)
        assert list(fast[name].columns) == list(ref.columns)
        np.testing.assert_allclose(fast[name].to_numpy(float), ref.to_numpy(float), rtol=1e-10, atol=0)


def test_free_motion_and_terms_are_not_scored_from_statistics(small):
    m = fit(small, "silo4", harmonics=[{"frequency": 0.8}], holdout=None)
    assert scores.segment_sums(m.with_terms({"kind": "inertia", "inertia": 1e-3}), small) is None
    reversed_rows = small.subset(np.arange(len(small))[::-1])      # rows not in segment order
    assert scores.layout(reversed_rows) is None


def test_a_biased_segment_s_spread_is_taken_from_the_samples(small):
    """Data 0.1 % above a model with a spread of 1e-8 of the torque about it: the residual sum of
    squares is resolved (1e-6 of y'y) but the spread about the mean error (1e-16 of y'y) is not; its
    standard deviation comes from the samples (without that rule it would be rounding noise)."""
    m = _truth(0.8)
    pred = m.evaluate(**small.inputs())
    y = pred * (1 + 1e-3) + 1e-8 * np.abs(pred) * np.cos(np.arange(len(pred)))
    data = replace(small, y=y, cache={}, notes=list(small.notes))
    fast = segment_rows({"m": m}, data)["m"]
    ref = segment_errors(m, data)
    np.testing.assert_allclose(fast.to_numpy(float), ref.to_numpy(float), rtol=1e-10, atol=0)


@pytest.mark.parametrize("by", ["segment", "run"])
def test_segment_folds_are_the_rows_folds(small, by):
    from gearspec.identify.validate import _folds, _segment_folds

    lay = scores.layout(small)
    fold = _segment_folds(small, lay, by, 3)
    assert np.array_equal(fold[lay.row_segment()], _folds(small, by, 3))
    assert len(np.unique(fold)) == 3
