"""The compiled kernels of the order analysis (gearspec/spectrum/_kernels.py) against direct numpy
computations on small cases: the kernels are the only implementation, so these are the checks of
what they compute."""

from __future__ import annotations

import numpy as np
import pytest

from gearspec.recording import Recording


def _chirp(n=6000, fs=1000.0, seed=3, top=40.0):
    rng = np.random.default_rng(seed)
    t = np.arange(n) / fs
    v = top * np.sin(2 * np.pi * (0.3 * t + 0.2 * t**2))
    theta = np.cumsum(v) / fs
    tau = np.sign(v) * 0.3 + 0.05 * np.sin(2 * np.pi * 3.0 * theta) + 0.02 * rng.standard_normal(n)
    return Recording.from_arrays(t=t, theta=theta, torque=tau, velocity=v)


def test_track_normal_equations_are_the_dense_least_squares_to_rounding():
    # X'X, X'y, y'y of the track design (B-splines x [1, sin, cos] of two lines, acceleration) from
    # the kernel's moments equal those of the dense design built with scipy's BSpline and the same
    # single-precision sines: 1e-10 of the largest entry (the moments are double sums of a few
    # thousand terms, summed in another order: rounding near 1e-13)
    from scipy.interpolate import BSpline

    from gearspec.spectrum import motion
    from gearspec.spectrum.ordertrack import _normal_equations_many

    m = motion(_chirp(), 1, need_acc=True)
    use = np.ones(len(m), bool)
    use[::5] = False
    r = np.flatnonzero(use)
    lo, hi = m.speed[r].min(), m.speed[r].max()
    tk = np.concatenate([[lo] * 4, np.linspace(lo, hi, 5)[1:-1], [hi] * 4])
    freqs = [3.0, 0.7]
    got = _normal_equations_many(m, use, freqs, tk, True)
    B = BSpline.design_matrix(m.speed[r], tk, 3).toarray()
    for f, (A, b, yy) in zip(freqs, got):
        p = m.theta[r] * f
        ph = ((p - np.floor(p)) * 2 * np.pi).astype(np.float32)
        s, c = np.sin(ph).astype(float), np.cos(ph).astype(float)
        X = np.hstack([B, B * s[:, None], B * c[:, None], m.acc[r][:, None]])
        XtX, Xty = X.T @ X, X.T @ m.y[r]
        assert np.abs(A - XtX).max() <= 1e-10 * np.abs(XtX).max()
        assert np.abs(b - Xty).max() <= 1e-10 * np.abs(Xty).max()
        assert yy == pytest.approx(m.y[r] @ m.y[r], rel=1e-12)


def _pieces(rng, monotone: bool):
    """Positions of three pieces (increasing along the motion; with ``monotone`` False one piece
    steps back now and then, as a noisy encoder at low speed does), values, times."""
    th, lens = [], [400, 20, 900]
    x0 = 0.013
    for k, n in enumerate(lens):
        step = rng.uniform(0.2, 1.8, n) * 0.01
        if not monotone and k == 2:
            step[::7] *= -0.5  # backwards every seventh sample
        th.append(x0 + np.cumsum(step))
        x0 = th[-1][-1] + 0.5
    th = np.concatenate(th)
    stops = np.cumsum(lens)
    return th, rng.standard_normal(len(th)), np.arange(len(th)) * 1e-3, stops - np.array(lens), stops


@pytest.mark.parametrize("monotone", [True, False])
def test_window_layout_interpolates_as_np_interp_bit_for_bit(monotone):
    # the grid of every piece and the times at the windows' edges are np.interp's numbers exactly,
    # for positions that never decrease (the forward walk) and for positions that step back (numpy's
    # own search, replicated); a piece shorter than a window gets no grid
    from gearspec.spectrum._kernels import layout_sizes, window_layout

    rng = np.random.default_rng(41 + monotone)
    th, y, t, starts, stops = _pieces(rng, monotone)
    spacing, window = 0.0093, 32
    g0s, n_grids, n_wins = layout_sizes(th, starts, stops, spacing, window)
    assert n_wins[1] == 0 and n_wins[0] > 0 and n_wins[2] > 0
    n_g, n_w, n_p = int(n_grids.sum()), int(n_wins.sum()), 2
    outs = (np.empty(n_g), np.empty(n_w, np.int64), np.empty(n_w), np.empty(n_w), np.empty(n_w),
            np.empty(n_w + n_p, np.int64), np.empty(n_w, np.int64), np.empty(n_p, np.int64),
            np.empty(n_p, np.int64), np.empty(n_p, np.int64))
    window_layout(th, y, t, starts, stops, spacing, window, g0s, (n_grids, n_wins), outs)
    grid, first, a_edge, b_edge, dur = outs[:5]
    ref_grid, ref_dur = [], []
    for k in (0, 2):
        s, e = starts[k], stops[k]
        x = np.arange(g0s[k], g0s[k] + n_grids[k]) * spacing
        ref_grid.append(np.interp(x, th[s:e], y[s:e]))
        step = window // 2
        xa = x[0:n_wins[k] * step:step]
        xb = x[window - 1:window - 1 + n_wins[k] * step:step]
        tt = np.interp(np.concatenate([xb, xa]), th[s:e], t[s:e])
        ref_dur.append(tt[:n_wins[k]] - tt[n_wins[k]:])
    assert np.array_equal(grid, np.concatenate(ref_grid))
    assert np.array_equal(dur, np.concatenate(ref_dur))
    assert np.array_equal(first[1:] - first[:-1] > 0, np.ones(n_w - 1, bool))


def test_direction_runs_and_gather_are_the_mask_and_compress():
    # the runs moving one way (NaN speeds and, with J removed, NaN accelerations never move; runs
    # shorter than 16 samples left out but counted) and their samples gathered with y = d (tau - J
    # acc) are numpy's mask-and-compress, exactly, in both directions
    from gearspec.spectrum._kernels import direction_runs, gather_runs

    rng = np.random.default_rng(7)
    n = 5000
    v = np.repeat(rng.uniform(-3, 3, n // 10), 10) + 0.01 * rng.standard_normal(n)
    v[rng.integers(0, n, 40)] = np.nan
    acc = rng.standard_normal(n)
    acc[rng.integers(0, n, 40)] = np.nan
    t, theta, tau = np.arange(n) * 1e-3, np.cumsum(np.nan_to_num(v)), rng.standard_normal(n)
    starts, stops = np.array([0, 1800, 3300]), np.array([1800, 3300, n])
    J, min_speed = 0.01, 0.5
    for d in (1, -1):
        rs = np.empty(n // 16 + 4, np.int64)
        re = np.empty_like(rs)
        k, n_moving = direction_runs(v, min_speed, d, acc, True, starts, stops, 16, rs, re)
        moving = (d * v > min_speed) & np.isfinite(acc)
        keep = np.zeros(n, bool)
        for a, b in zip(starts, stops):
            edges = np.flatnonzero(np.diff(moving[a:b].astype(np.int8), prepend=0, append=0))
            for s, e in zip(edges[0::2], edges[1::2]):
                keep[a + s:a + e] = e - s >= 16
        assert n_moving == moving.sum() and keep.sum() == (re[:k] - rs[:k]).sum() < n_moving
        m = int(keep.sum())
        out = [np.empty(m) for _ in range(5)]
        gather_runs(rs[:k], re[:k], t, theta, v, tau, acc, J, d, True, *out)
        assert np.array_equal(out[0], t[keep]) and np.array_equal(out[1], theta[keep])
        assert np.array_equal(out[2], np.abs(v[keep])) and np.array_equal(out[4], acc[keep])
        assert np.array_equal(out[3], d * (tau[keep] - J * acc[keep]))
