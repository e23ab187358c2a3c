"""Work ``gearspec fit`` now does once (0.10), with the numbers it gave before.

- BLAS runs on one thread through :func:`gearspec.identify.identify_recording` and
  :meth:`JointFit.fit` (:func:`gearspec.core.reduction.on_one_blas_thread`): their products are of
  few columns, where OpenBLAS's threads only contended for the cores (10^7 rows: 85 -> 52 s of CPU).
- :func:`gearspec.core.reduction.harmonic_columns` rotates the phases once per run of equal
  centres (a segment's) instead of once per sample: two sines and cosines per sample and line
  instead of four, the same values bit for bit.
- The held-out folds (``validate._folds``) are dealt once per data, not once per model.
"""

import numpy as np
import pytest
from threadpoolctl import threadpool_info

from gearspec.core.crossval import row_folds
from gearspec.core.reduction import harmonic_columns, on_one_blas_thread
from gearspec.fitdata import FitData
from gearspec.identify import fit, joint, pipeline, validate
from gearspec.model import FrictionModel
from gearspec.segment import find_segments
from gearspec.simulate import model_recording


def _blas_threads() -> int:
    return max((i["num_threads"] for i in threadpool_info() if i.get("user_api") == "blas"), default=1)


@pytest.fixture(scope="module")
def small():
    truth = FrictionModel.from_dict({"law": "silo4", "directions": {
        d: {"tau_c": 0.01, "viscous": 1e-4, "tau_s": 0.015, "v_s": 0.5,
            "harmonics": [{"frequency": 0.8, "amplitude": 2e-3, "decay": 0.02, "phase": 0.3}]}
        for d in ("positive", "negative")}})
    speeds = [0.4, 0.9, 1.7, 3.1, 5.0]
    sp = (speeds + [-s for s in speeds]) * 2
    rec, _ = model_recording(truth, sp, duration=[max(1.0, 3.0 / (0.8 * abs(v))) for v in sp], fs=500, ramp=0.1,
                             noise=2e-4, seed=3)
    return rec


@pytest.mark.skipif(_blas_threads() < 2, reason="BLAS runs on one thread here anyway")
def test_fits_run_blas_on_one_thread(small, monkeypatch):
    seen = []
    stats = joint.segment_stats

    def spy(*args, **kwargs):
        seen.append(_blas_threads())
        return stats(*args, **kwargs)

    monkeypatch.setattr(joint, "segment_stats", spy)
    before = _blas_threads()
    fit(FitData.from_recording(small, find_segments(small)), "silo4", harmonics=[{"frequency": 0.8}], holdout=None)
    assert seen and set(seen) == {1} and _blas_threads() == before     # restored after the fit
    seen.clear()
    amps = pipeline.line_amplitudes

    def spy_amps(*args, **kwargs):       # identify_recording's own work (before any JointFit.fit)
        seen.append(_blas_threads())
        return amps(*args, **kwargs)

    monkeypatch.setattr(pipeline, "line_amplitudes", spy_amps)
    pipeline.identify_recording(small, "silo4", harmonics=[{"frequency": 0.8}], compare_with=[])
    assert seen and seen[0] == 1 and _blas_threads() == before


def test_on_one_blas_thread_returns_and_restores():
    before = _blas_threads()
    f = on_one_blas_thread(lambda x, y=1: (x + y, _blas_threads()))
    assert f(2, y=3) == (5, 1) and _blas_threads() == before


def test_harmonic_columns_rotate_once_per_group_the_same_values():
    rng = np.random.default_rng(1)
    n = rng.integers(1, 3000, 60)
    n[5] = 1                                                    # a one-row group
    th = np.cumsum(rng.normal(0.01, 0.002, n.sum())) + 1e4      # far from 0: the rotation matters
    starts = np.concatenate(([0], np.cumsum(n)[:-1]))
    center = np.repeat(np.add.reduceat(th, starts) / n, n)
    center[starts[7]:starts[8]] = center[starts[6]]             # two neighbouring groups, one centre
    fr = np.array([0.00055, 0.0113, 0.159, 3.7])
    sn, cs = harmonic_columns(th, fr, center)
    # the formula of 0.9 (the rotation of every sample)
    ph = 2 * np.pi * ((th[:, None] - center[:, None]) * fr)
    rot = 2 * np.pi * fr * center[:, None]
    c, s = np.cos(rot), np.sin(rot)
    assert np.array_equal(sn, np.sin(ph) * c + np.cos(ph) * s)
    assert np.array_equal(cs, np.cos(ph) * c - np.sin(ph) * s)
    # and what they mean: sin and cos of 2 pi f theta (to the rounding of 2 pi f theta at 1e4 rad)
    np.testing.assert_allclose(sn, np.sin(2 * np.pi * np.outer(th, fr)), atol=1e-9)


def test_folds_are_dealt_once_per_data(small):
    data = FitData.from_recording(small, find_segments(small))
    for by, k in (("segment", 5), ("segment", 3), ("run", 2), ("segment", 5)):
        got = validate._folds(data, by, k)
        assert np.array_equal(got, row_folds(data.groups(by), data.direction, data.v, k))
    assert validate._folds(data, "segment", 5) is validate._folds(data, "segment", 5)
    sub = data.subset(data.segment % 2 == 0)                  # a subset deals its own
    assert np.array_equal(validate._folds(sub, "segment", 3), row_folds(sub.segment, sub.direction, sub.v, 3))


def test_a_line_above_a_segments_position_nyquist_has_no_columns_there():
    """Segment statistics with every line sampled skip the mask (times 1); where a line lies above
    the measurable fraction of a segment's position Nyquist frequency its columns are zero there."""
    from gearspec.identify.stats import segment_stats

    fs, n = 500.0, 2000
    v = np.r_[np.full(n, 0.4), np.full(n, 5.0)]                 # position Nyquist 625 and 50 cycles/rad
    theta = np.r_[np.arange(n) * 0.4 / fs, 10 + np.arange(n) * 5.0 / fs]
    f = 45.0                                                    # above 0.8 x 50, below 0.8 x 625
    y = 0.01 + 1e-3 * np.sin(2 * np.pi * f * theta)
    data = FitData(theta=theta, v=v, y=y, segment=np.repeat([0, 1], n))
    st = segment_stats(data, [f])
    assert st.sampled.tolist() == [[True], [False]]
    assert np.all(st.G[1, 1:, :] == 0) and np.all(st.G[1, :, 1:] == 0) and st.G[1, 0, 0] == n
    assert np.all(np.abs(np.diag(st.G[0])[1:] - n / 2) < 0.01 * n)    # sin^2, cos^2 over whole cycles
    np.testing.assert_allclose(np.hypot(*st.beta_hat[0, 1:]), 1e-3, rtol=1e-9)
    both = segment_stats(FitData(theta=theta[:n], v=v[:n], y=y[:n]), [f])    # every line sampled: no mask
    assert np.array_equal(both.G[0], st.G[0]) and np.array_equal(both.g[0], st.g[0])
