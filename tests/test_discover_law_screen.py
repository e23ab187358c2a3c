"""The fast held-out screen (:func:`gearspec.discover.law.cross_validate_linear`): its fold refits go
through the refined normal equations (:class:`gearspec.discover.lsq.NormalSolver`) on a large design
and give what a direct least-squares solve of every fold gives."""

from __future__ import annotations

import numpy as np
import pytest

from gearspec.discover import law
from gearspec.discover.law import Part, cross_validate_linear, fit_law, fold_ids
from gearspec.discover.moments import moments
from gearspec.fitdata import FitData
from gearspec.simulate import model_recording
from test_discover_fast import count_normal_solves

F2, F3 = 1 / (2 * np.pi * 14), 1 / (2 * np.pi)      # SILO4 worm-shaft and motor-shaft lines, cycles/rad


@pytest.fixture(scope="module")
def many_segments():
    """The SILO4 truth at 8 speeds per direction, 0.5 s at 1 kHz, its 16 segments repeated 25 times
    with fresh noise: 400 segments, 7 pseudo rows each (the default twin's segment count)."""
    from gearspec.simulate.silo4 import table2_model

    speeds = [s * d for s in np.geomspace(1.0, 600, 8) for d in (1, -1)] * 25
    rec, _ = model_recording(table2_model(), speeds, duration=0.5, fs=1000, noise=0.1e-3, gear="silo4-joint3",
                             seed=3, one_run_per_plateau=True)
    return moments(FitData.from_recording(rec), [F2, F3, 2 * F3], inertia=False)


def test_the_screens_fold_refits_are_the_direct_least_squares_by_the_normal_equations(many_segments, monkeypatch):
    M = many_segments
    parts = (Part("coulomb", split=True), Part("viscous", split=True), Part("stribeck_exp", param0=5.0),
             Part("ripple_exp", 0, True, 1e-3), Part("ripple_rational", 1, False, 1e-3), Part("ripple_const", 2))
    fit = fit_law(M, parts)
    fold = fold_ids(M)
    used = count_normal_solves(monkeypatch)
    sse, _ = cross_validate_linear(M, fit, fold)
    assert sum(used) == 5                         # every fold's refit by the normal equations
    # the direct computation: each fold's coefficients by numpy's least squares on its training
    # pseudo rows (nonlinear parameters held), its held-out segments' residual sums of squares
    Mr = M.restrict({b for _, _, b in fit.layout.cols})
    X = law._design(fit.parts, fit.layout, Mr, fit.z).reshape(Mr.S, Mr.K, -1)
    want = np.empty(Mr.S)
    for f in range(fold.max() + 1):
        tr, te = fold != f, fold == f
        w = np.linalg.lstsq(X[tr].reshape(-1, X.shape[2]), Mr.q[tr].reshape(-1), rcond=None)[0]
        r = Mr.q[te] - np.einsum("skp,p->sk", X[te], w)
        want[te] = np.sum(r * r, axis=1) + Mr.rest[te]
    assert np.allclose(sse, want, rtol=1e-10, atol=0)
    assert float(np.sum(sse)) < 1.2 * float(np.sum(fit.sse))      # a good law: held out ~ in sample
