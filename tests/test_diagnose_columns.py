"""The closed loop's columns built cheaply with the same numbers (issue 13, "Scale"): on plateaus a
base law's columns and a line's amplitude factor depend on a sample only through its speed, the
sign of its velocity and its direction, so they are built at those few distinct keys and gathered
once; the Taylor columns of the nonlinear parameters take their central differences there too.
Known answer: the columns built sample by sample (the keys switched off), equal exactly for the
plain columns (the same elementwise operations on the same numbers) and to 1e-13 relative for the
Taylor columns (a dot product over the few columns of one row, whose summation order BLAS may
choose differently for a matrix of keys than for one of samples: 1e-16 per operation).
"""

from __future__ import annotations

import numpy as np
import pytest

import gearspec.diagnose as dg
from gearspec.diagnose import design
from gearspec.diagnose.data import speed_keys
from gearspec.diagnose.frommodel import state_from_model
from gearspec.model import FrictionModel
from gearspec.simulate import model_recording

F_MOTOR = 1 / (2 * np.pi)


def _model() -> FrictionModel:
    def lines(a, ph):
        return [{"frequency": F_MOTOR, "amplitude": a, "decay": 0.05, "phase": ph, "label": "motor shaft"},
                {"frequency": 17 * F_MOTOR, "amplitude": 0.6 * a, "decay": 0.15, "phase": ph + 1, "law": "rational",
                 "label": "mesh"}]
    pos = {"tau_c": 0.05, "tau_s": 0.08, "v_s": 1.5, "viscous": 2e-3, "harmonics": lines(5e-3, 0.3)}
    neg = {"tau_c": 0.055, "tau_s": 0.085, "v_s": 1.2, "viscous": 2.2e-3, "harmonics": lines(4e-3, 1.0)}
    return FrictionModel("silo4", pos, neg, name="truth")


def _data():
    speeds = [x for s in np.geomspace(0.5, 16, 6) for x in (s, -1.1 * s)]
    rec, _ = model_recording(_model(), speeds, noise=1e-3, seed=3, duration=1.5, fs=500.0)
    return dg.DiagnoseData.from_recording(rec)


def _columns(dd, state, keyed: bool, monkeypatch) -> tuple[np.ndarray, np.ndarray]:
    dd.cache.clear()
    with monkeypatch.context() as m:
        if not keyed:
            m.setattr(design, "speed_keys", lambda dd: None)
        return state.design(dd), state.design(dd, taylor=True)


def test_keys_are_the_distinct_speed_sign_and_direction_of_plateaus():
    dd = _data()
    keys = speed_keys(dd)
    assert keys is not None
    u, kidx, ksg, kdir, kinv = keys
    f = dd.fit
    # 12 plateaus at 12 distinct signed speeds: 12 keys, each a segment's speed, sign and direction
    assert len(kidx) == 12 and len(u) == 12
    assert np.array_equal(u[kidx][kinv], np.abs(f.v))
    assert np.array_equal(ksg[kinv], np.sign(f.v)) and np.array_equal(kdir[kinv], f.direction)


def test_keyed_columns_equal_the_columns_built_sample_by_sample(monkeypatch):
    dd = _data()
    state = state_from_model(_model(), dd)
    st = state.refreshed(np.linspace(0.5, 1.5, len(state.names)))   # coefficients for the Taylor columns
    assert any(isinstance(b, design.HarmonicBlock) for b in st.blocks)
    X_keyed, T_keyed = _columns(dd, st, True, monkeypatch)
    X_rows, T_rows = _columns(dd, st, False, monkeypatch)
    assert X_keyed.shape == X_rows.shape and T_keyed.shape[1] > X_keyed.shape[1]
    assert np.array_equal(X_keyed, X_rows)          # the same elementwise operations: exact
    scale = np.max(np.abs(T_rows), axis=0)
    assert np.all(scale > 0)
    assert np.max(np.abs(T_keyed - T_rows) / scale) < 1e-13


def test_without_few_distinct_speeds_the_columns_are_built_on_the_samples():
    """Free motion (every sample its own speed): no keys, the columns from the samples."""
    dd = _data()
    v = dd.fit.v * (1 + 1e-3 * np.sin(np.arange(len(dd.fit))))
    from dataclasses import replace
    dd2 = dg.DiagnoseData(replace(dd.fit, v=v, cache={}), by=dd.by, travel=dd.travel)
    assert speed_keys(dd2) is None
    state = state_from_model(_model(), dd2)
    X = state.design(dd2)
    assert X.shape == (len(dd2), len(state.names)) and np.all(np.isfinite(X))


def test_fit_with_keyed_columns_recovers_the_truth():
    """The fit of the model's own structure through the keyed columns returns the model's
    coefficients within their standard errors (noise 1 mNm; 5 se: a failure once in 1e6)."""
    dd = _data()
    state = state_from_model(_model(), dd, symmetric=False)
    fitted = design.fit_state(state, dd)
    m = fitted.model()
    truth = _model()
    for d in ("positive", "negative"):
        for k in ("tau_c", "viscous"):
            got, se = m.directions[d].values[k], m.directions[d].se[k]
            assert abs(got - truth.directions[d].values[k]) < 5 * se
    assert fitted.rmse == pytest.approx(1e-3, rel=0.05)


def test_a_decay_difference_from_its_direction_alone_equals_the_full_difference():
    """A line's decay moves the columns of its own direction only: the difference built from
    that direction (the others left at exactly 0) is the generic one, exactly (the same matrix
    and the same product), for every decay of the model."""
    from gearspec.diagnose.nonlinear import nonlinear_parameters, with_parameter
    dd = _data()
    st = state_from_model(_model(), dd)
    st = st.refreshed(np.linspace(0.5, 1.5, len(st.names)))
    checked = 0
    for blk in st.blocks:
        if not isinstance(blk, design.HarmonicBlock):
            continue
        c = np.asarray(blk.coef, float)
        for key, val, *_ in nonlinear_parameters(blk, dd):
            if key[0] != "decay":
                continue
            h = 1e-4 * (abs(val) or 1.0)
            up, dn = with_parameter(blk, key, val + h), with_parameter(blk, key, val - h)
            fast = blk._difference(dd, up, dn, c, h)
            full = design.Block._difference(blk, dd, up, dn, c, h)
            assert np.any(fast != 0) and np.array_equal(fast, full)
            checked += 1
    assert checked == 4      # two lines, two directions


def test_the_normal_solve_reads_the_lower_triangle_only():
    """:func:`polish` computes the cross block of its normal equations once (C^T X) and mirrors
    it into the upper triangle: the same coefficients only while the solve reads the lower
    triangle alone.  Known answer: the least-squares coefficients of a random design (lstsq),
    unchanged when the upper triangle holds garbage."""
    from gearspec.diagnose.solve import solve_normal
    rng = np.random.default_rng(1)
    X = rng.normal(size=(200, 6)) * np.array([1, 10, 0.1, 1e3, 1, 1e-2])
    y = X @ np.arange(1.0, 7.0) + rng.normal(size=200)
    G, b = X.T @ X, X.T @ y
    beta = solve_normal(G, b)
    assert np.allclose(beta, np.linalg.lstsq(X, y, rcond=None)[0], rtol=1e-9)
    garbage = G + np.triu(rng.normal(size=G.shape) * 1e6, k=1)
    assert np.array_equal(solve_normal(garbage, b), beta)


def test_hstack_by_row_chunks_is_column_stack():
    """The designs are copied a chunk of rows at a time: the same array as ``np.column_stack``,
    for row counts below, at and across the chunk size."""
    from gearspec.diagnose.gram import COPY_ROWS, hstack
    rng = np.random.default_rng(2)
    for n in (1, COPY_ROWS, 2 * COPY_ROWS + 17):
        cols = [rng.normal(size=(n, k)) for k in (3, 1, 2, 5)]
        assert np.array_equal(hstack(cols), np.column_stack(cols))
        out = np.full((n, 11), np.nan)
        assert hstack(cols, out=out) is out and np.array_equal(out, np.column_stack(cols))


def test_no_keys_when_they_would_not_be_fewer_than_a_quarter_of_the_samples():
    """Few distinct speeds, but every sample its own (speed, sign, direction): 8 keys for 16
    samples are no saving, and the columns are built on the samples (the rule of
    :func:`per_speed`: keys only when at most a quarter of the samples)."""
    from dataclasses import replace
    dd = _data()
    f = dd.fit.subset(np.arange(16))
    v = np.tile([1.0, -1.0, 2.0, -2.0], 4)
    direction = np.repeat([1, -1], 8)
    small = dg.DiagnoseData(replace(f, v=v, direction=direction, cache={}), by="segment")
    assert len(np.unique(np.abs(v))) * 4 <= len(v)       # few speeds: per_speed gathers
    assert speed_keys(small) is None
    tiny = dg.DiagnoseData(replace(f, v=np.abs(v), direction=np.ones(16, int), cache={}), by="segment")
    assert len(speed_keys(tiny)[1]) == 2                  # two speeds, one sign and direction: two keys


def test_a_lines_speed_ranges_from_the_cache_are_its_directions_own():
    """The speeds at which the data measure a line, per direction, cached on the data by frequency
    and direction: the same as computed afresh, and different in the two directions here (the
    negative plateaus run 10 % faster: 0.55-17.6 rad/s against 0.5-16)."""
    from gearspec.diagnose.coverage import line_speed_range
    dd = _data()
    st = state_from_model(_model(), dd)
    lines = [b for b in st.blocks if isinstance(b, design.HarmonicBlock)]
    for blk in lines:
        for _ in range(2):                                  # computed, then from the cache
            got = blk.ranges(dd)
            for d in (1, -1):
                assert got[d] == line_speed_range(dd, blk.frequency, d)
        assert blk.ranges(dd)[1] != blk.ranges(dd)[-1]
    assert lines[0].ranges(dd)[-1][1] == pytest.approx(1.1 * 16, rel=1e-6)
