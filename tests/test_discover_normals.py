"""discover's law fits on the normal equations, cheaper per evaluation (issue 13): the batched
projections of the variable-projection Jacobian, the design built column-scaled in one pass, the
residual and final coefficients kept from the refined solve, all against the QR path and a known
answer (a law whose truth is in the library)."""

from __future__ import annotations

import numpy as np
import pytest

from gearspec.discover import law, lsq
from gearspec.discover.law import Part, fit_law
from gearspec.discover.lsq import NormalSolver
from gearspec.discover.moments import moments
from gearspec.fitdata import FitData
from gearspec.model import FrictionModel
from gearspec.simulate import model_recording

F3 = 1 / (2 * np.pi)                 # SILO4 motor-shaft line, cycles/rad
#: the truth: Coulomb and viscous per direction, a motor-shaft line decaying exponentially with speed
TRUTH = {1: {"tau_c": 7.1e-3, "viscous": 1.28e-4, "amplitude": 0.6e-3, "decay": 0.01},
         -1: {"tau_c": 7.9e-3, "viscous": 1.32e-4, "amplitude": 0.5e-3, "decay": 0.02}}


def _design(rng, n=3000, p=12, spread=1e-4):
    """Columns whose scales differ by decades, two of them correlated to 1 - spread^2 / 2 (the
    scaled design's condition number about 2e4)."""
    X = rng.standard_normal((n, p)) * np.logspace(-4, 3, p)
    X[:, 1] = X[:, 0] * 10 + spread * 10 * rng.standard_normal(n) * np.std(X[:, 0])
    return X


def test_projections_of_many_targets_at_once_equal_one_at_a_time_and_qr():
    # the Jacobian's directions are projected out together (one pass over the design per
    # refinement step): each column equals its projection alone and QR's to 1e-12 of its norm
    # (rounding of either is about eps x cond = 2e-12 relative to the design's scale)
    rng = np.random.default_rng(7)
    X = _design(rng)
    ns = NormalSolver.of(X)
    assert ns is not None
    V = np.column_stack([rng.standard_normal(len(X)), X @ rng.standard_normal(X.shape[1]),
                         X[:, 1] + 1e-6 * rng.standard_normal(len(X)), np.zeros(len(X))])
    R = ns.residual(V)
    U = law._solve(X, V[:, 0])[1]
    for k in range(V.shape[1]):
        scale = max(np.linalg.norm(V[:, k]), 1e-300)
        assert np.max(np.abs(R[:, k] - ns.residual(V[:, k]))) <= 1e-12 * scale
        assert np.max(np.abs(R[:, k] - (V[:, k] - U @ (U.T @ V[:, k])))) <= 1e-12 * scale
    # a column in the design's span projects to (almost) nothing; a zero column stays zero
    assert np.linalg.norm(R[:, 1]) < 1e-10 * np.linalg.norm(V[:, 1])
    assert not np.any(R[:, 3])


def test_a_design_given_column_scaled_gives_the_same_solver():
    # (X / norms, norms): the same coefficients as from X itself (to rounding, 1e-12 relative),
    # and the known answer: y = X w + noise of sd 0.1, the residual's rms 0.1 within 5 % (its
    # standard error over 3000 samples is 0.1 / sqrt(6000) = 1.3e-3: four of them)
    rng = np.random.default_rng(8)
    X = _design(rng)
    y = X @ (rng.standard_normal(X.shape[1]) / np.logspace(-4, 3, X.shape[1])) + 0.1 * rng.standard_normal(len(X))
    nrm = np.linalg.norm(X, axis=0)
    a, b = NormalSolver.of(X), NormalSolver.of((X / nrm, nrm))
    wa, wb = a.solve(y), b.solve(y)
    assert np.allclose(wb, wa, rtol=1e-12, atol=0)
    assert np.sqrt(np.mean((y - X @ wb) ** 2)) == pytest.approx(0.1, rel=0.05)
    # too small a design is left to QR in either form
    small = X[: lsq.MIN_SIZE // X.shape[1] - 1]
    assert NormalSolver.of((small / nrm, nrm)) is None


@pytest.fixture(scope="module")
def known_law():
    """Plateaus of the TRUTH at 8 speeds per direction (1 to 600 rad/s), 0.5 s at 1 kHz, 0.1 mNm
    white noise, repeated 60 times: 960 segments of 3 pseudo rows (the 8 columns of PARTS on them are
    above MIN_SIZE entries)."""
    dirs = {d: {"tau_c": t["tau_c"], "viscous": t["viscous"],
                "harmonics": [{"frequency": F3, "amplitude": t["amplitude"], "decay": t["decay"], "phase": 0.4,
                               "law": "exp"}]} for d, t in TRUTH.items()}
    model = FrictionModel("coulomb_viscous", dirs[1], dirs[-1])
    speeds = [s * d for s in np.geomspace(1.0, 600, 8) for d in (1, -1)]
    rec, _ = model_recording(model, speeds, duration=0.5, fs=1000, noise=0.1e-3, seed=3, one_run_per_plateau=False)
    M = moments(FitData.from_recording(rec), [F3], inertia=False)
    return M.take(np.tile(np.arange(M.S), 60))


PARTS = (Part("coulomb", split=True), Part("viscous", split=True), Part("ripple_exp", 0, True, 3e-3))


def test_a_large_law_fit_finds_the_truth_and_agrees_with_qr(known_law, monkeypatch):
    M = known_law
    assert M.S * M.K * 8 >= lsq.MIN_SIZE                   # 960 x 3 x 8 entries: the normal equations
    fast = fit_law(M, PARTS)
    vals = {(v["part"], v["name"], v["slot"]): v["value"] for v in fast.values()}
    # known answer: per direction 8 plateaus x 500 samples at 0.1 mNm noise; the level's standard
    # error is about 0.1 mNm / sqrt(4000) x 3 (its correlation with the viscous column) = 5e-6 Nm:
    # Coulomb within 3e-5 Nm (6 of them; measured 2e-6), viscous within 0.1 % (its lever arm, 600
    # rad/s, makes its error about 1e-8 Nm s/rad, 1e-4 relative; measured 6e-5), the decays within
    # 10 % (the line's amplitude at 0.1 mNm noise over 8 speeds: the decay's error is a few %;
    # measured 2 and 4.5 %)
    for d, t in TRUTH.items():
        assert vals[(0, "1", d)] == pytest.approx(t["tau_c"], abs=3e-5)
        assert vals[(1, "1", d)] == pytest.approx(t["viscous"], rel=1e-3)
        assert vals[(2, "decay", d)] == pytest.approx(t["decay"], rel=0.1)
    # the in-sample rms is the noise's (0.1 mNm within 5 %: the law is the truth's structure)
    assert fast.rmse == pytest.approx(0.1e-3, rel=0.05)
    # the residual kept from the refined solve is the design's own: per-segment sse as recomputed
    # from the pseudo-row design (rest included) to 1e-12
    Mr = M.restrict({b for _, _, b in fast.layout.cols})
    again = Mr.sse(law._design(PARTS, fast.layout, Mr, fast.z), fast.w)
    assert np.allclose(fast.sse, again, rtol=1e-12, atol=0)
    # QR at every evaluation (MIN_SIZE raised): the same fit to the optimiser's tolerance (log
    # parameters to 1e-8), coefficients to 1e-9 of the largest, sse to 1e-12
    monkeypatch.setattr(lsq, "MIN_SIZE", 10 ** 12)
    slow = fit_law(M, PARTS)
    assert np.allclose(fast.z, slow.z, rtol=0, atol=1e-8)
    assert np.allclose(fast.w, slow.w, rtol=0, atol=1e-9 * np.max(np.abs(slow.w)))
    assert float(np.sum(fast.sse)) == pytest.approx(float(np.sum(slow.sse)), rel=1e-12)


def test_a_small_law_fit_keeps_the_qr_arithmetic(known_law):
    # under MIN_SIZE entries (25 segments here) every number is the QR path's, bit for bit: the
    # final coefficients are those of law._solve on the design at the refined parameters
    M = known_law.take(np.arange(25))
    fit = fit_law(M, PARTS)
    Mr = M.restrict({b for _, _, b in fit.layout.cols})
    X = law._design(PARTS, fit.layout, Mr, fit.z)
    assert X.size < lsq.MIN_SIZE
    assert np.array_equal(fit.w, law._solve(X, Mr.q.reshape(-1))[0])
    assert np.array_equal(fit.sse, Mr.sse(X, fit.w))
