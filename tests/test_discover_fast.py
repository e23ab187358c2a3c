"""The refinement's least squares through the p x p normal equations (:mod:`gearspec.discover.lsq`):
the same coefficients, residuals and fitted laws as the QR path of :func:`gearspec.discover.law._solve`
to rounding, and the designs it refuses (too ill-conditioned, too small) left to QR."""

from __future__ import annotations

import numpy as np
import pytest

from gearspec.discover import law, lsq
from gearspec.discover.law import Part, fit_law
from gearspec.discover.lsq import NormalSolver
from gearspec.discover.moments import moments
from gearspec.fitdata import FitData
from gearspec.simulate import model_recording

F2, F3 = 1 / (2 * np.pi * 14), 1 / (2 * np.pi)      # SILO4 worm-shaft and motor-shaft lines, cycles/rad


def _design(rng, n=3000, p=12, spread=1e-3):
    """Columns whose scales differ by decades (as a law's: |v| at 600 rad/s beside a level) and two
    of them correlated to 1 - spread^2 / 2."""
    X = rng.standard_normal((n, p)) * np.logspace(-4, 3, p)
    X[:, 1] = X[:, 0] * 10 + spread * 10 * rng.standard_normal(n) * np.std(X[:, 0])
    return X


def test_normal_equations_give_the_qr_coefficients_and_residuals():
    # y = X w + noise, the columns' scales 1e-4..1e3 and two of them correlated to 1 - 5e-9
    # (condition number of the scaled design about 2e4, of the normal matrix 4e8: unrefined, a
    # Cholesky solve would be off by about 1e-8): coefficients equal to the QR path's to 1e-9
    # relative (the rounding error of either is about eps x cond = 1e-12), the residual to 1e-12 of |y|
    rng = np.random.default_rng(3)
    X = _design(rng, spread=1e-4)
    w_true = rng.standard_normal(X.shape[1]) / np.logspace(-4, 3, X.shape[1])
    y = X @ w_true + 0.1 * rng.standard_normal(len(X))
    ns = NormalSolver.of(X)
    assert ns is not None
    w_qr, U = law._solve(X, y)
    w = ns.solve(y)
    assert np.allclose(w, w_qr, rtol=1e-9, atol=0)
    # the known answer: the residual's rms is the noise's, 0.1 within 5 % (its standard error over
    # 3000 samples is 0.1 / sqrt(2 x 3000) = 1.3e-3, so 5 % is about four of them)
    assert np.sqrt(np.mean((y - X @ w) ** 2)) == pytest.approx(0.1, rel=0.05)
    v = rng.standard_normal(len(X))
    r_qr = v - U @ (U.T @ v)
    assert np.max(np.abs(ns.residual(v) - r_qr)) < 1e-12 * np.linalg.norm(v)


def test_an_ill_conditioned_design_is_left_to_qr():
    # two columns equal to 1e-7 of their size: the scaled design's condition number is about 1e7,
    # its normal matrix's 1e14, where a Cholesky solve keeps only two digits: refused (MIN_RATIO)
    rng = np.random.default_rng(4)
    X = _design(rng, spread=1e-7)
    assert NormalSolver.of(X) is None
    y = X @ np.ones(X.shape[1]) + rng.standard_normal(len(X))
    w, basis = law._solve_fast(X, y)
    assert not isinstance(basis, NormalSolver)
    assert np.array_equal(w, law._solve(X, y)[0])


def test_a_small_design_is_left_to_qr():
    # below MIN_SIZE entries QR is as fast: the path (and every number) of short recordings unchanged
    rng = np.random.default_rng(5)
    X = rng.standard_normal((lsq.MIN_SIZE // 10 - 1, 10))
    assert NormalSolver.of(X) is None
    assert NormalSolver.of(rng.standard_normal((lsq.MIN_SIZE // 10 + 1, 10))) is not None


def count_normal_solves(monkeypatch) -> list:
    """A list that records, for every :meth:`NormalSolver.of` from now on, whether the normal
    equations took the solve (True) or left it to QR (False)."""
    used = []
    of = NormalSolver.of.__func__

    def counting(cls, X):
        s = of(cls, X)
        used.append(s is not None)
        return s

    monkeypatch.setattr(NormalSolver, "of", classmethod(counting))
    return used


@pytest.fixture(scope="module")
def many_segments():
    """The SILO4 truth (eq. 11, Table 2) at 8 speeds per direction, 0.5 s at 1 kHz, 0.1 mNm noise,
    its 16 segments repeated 25 times: 400 segments (the default twin's count) of 6 pseudo rows."""
    from gearspec.simulate.silo4 import table2_model

    speeds = [s * d for s in np.geomspace(1.0, 600, 8) for d in (1, -1)]
    rec, _ = model_recording(table2_model(), speeds, duration=0.5, fs=1000, noise=0.1e-3, gear="silo4-joint3",
                             seed=2, one_run_per_plateau=False)
    M = moments(FitData.from_recording(rec), [F2, F3], inertia=False)
    return M.take(np.tile(np.arange(M.S), 25))


def test_a_law_fitted_through_the_normal_equations_equals_the_qr_fit(many_segments, monkeypatch):
    # the same law fitted with the normal equations (400 x 6 pseudo rows x 13 columns: above
    # MIN_SIZE) and with QR at every evaluation (MIN_SIZE raised): the optimiser sees the same cost
    # and Jacobian to rounding, so it ends at the same point: nonlinear parameters to 1e-8
    # (relative, measured 1e-10 on discover's fits: its steps differ at rounding level), the
    # coefficients to 1e-7 of the largest of their part, the residual sum of squares to 1e-12
    M = many_segments
    parts = (Part("coulomb", split=True), Part("viscous", split=True), Part("stribeck_exp", param0=5.0),
             Part("ripple_exp", 0, True, 1e-3), Part("ripple_rational", 1, False, 1e-3))
    used = count_normal_solves(monkeypatch)
    fast = fit_law(M, parts, se=True)
    assert sum(used) > 10                       # the normal equations did the refinement
    monkeypatch.setattr(lsq, "MIN_SIZE", 10 ** 12)
    used.clear()
    slow = fit_law(M, parts, se=True)
    assert not any(used)
    assert np.allclose(fast.z, slow.z, rtol=1e-8, atol=0)
    assert np.allclose(fast.w, slow.w, rtol=0, atol=1e-7 * np.max(np.abs(slow.w)))
    assert float(np.sum(fast.sse)) == pytest.approx(float(np.sum(slow.sse)), rel=1e-12)
