"""The faster paths of ``gearspec fit`` give the numbers of the formulas they replace.

- :func:`gearspec.identify.covariance._cr2` applies the CR2 adjustment ``A_c = (I - H_cc)^-1/2``
  through a reduced QR of the cluster's rows (rows x p^2) instead of an eigen-decomposition of the
  dense rows x rows matrix, and the Bell-McCaffrey degrees of freedom of all parameters at once.
  Reference: the dense formula of gearspec 0.7 (:func:`_dense_cr2` below, copied as it was).  Both
  are the same matrix algebra; they differ by rounding only, ~1e-15 relative times the condition of
  the bread (scaled columns here: < 1e3), so 1e-10 relative is a bound with room, not a fit.
- ``pipeline._segment_errors`` takes each plateau model's errors from the segments' normal equations
  (:func:`gearspec.identify.validate.segment_rows`; models it cannot score so are evaluated once on
  all rows, once per direction when they cannot predict one): the numbers of :func:`segment_errors`
  to 1e-10 (sums in another order; ``tests/test_fit_scores.py`` bounds the rounding).
- The held-out folds of :meth:`JointFit.fit` (``joint.fold_fit``) skip the in-sample rmse and the
  checks' flags of the fold's model, which nobody reads: its predictions are those of
  :func:`refit` bit for bit, and so is the held-out rmse.
"""

import numpy as np
import pytest

from gearspec.fitdata import FitData
from gearspec.identify import covariance, fit, joint, pipeline
from gearspec.identify.validate import holdout, segment_errors
from gearspec.model import FrictionModel
from gearspec.segment import find_segments
from gearspec.simulate import model_recording


def _dense_cr2(J, r, row_cluster, bread, floor=1e-2):
    """gearspec 0.7's CR2: dense (I - H_cc) per cluster, degrees of freedom parameter by parameter."""
    p = J.shape[1]
    meat = np.zeros((p, p))
    order = np.argsort(row_cluster, kind="stable")
    _, starts = np.unique(row_cluster[order], return_index=True)
    JA = []
    for rows in np.split(order, starts[1:]):
        Jc, rc = J[rows], r[rows]
        H = Jc @ bread @ Jc.T
        lam, U = np.linalg.eigh(np.eye(len(rows)) - 0.5 * (H + H.T))
        A = (U / np.sqrt(np.clip(lam, floor, None))) @ U.T
        u = Jc.T @ (A @ rc)
        meat += np.outer(u, u)
        JA.append((Jc, A @ Jc))
    df = np.empty(p)
    for j in range(p):
        g = [AJ @ bread[:, j] for _, AJ in JA]
        D = np.array([gc @ gc for gc in g])
        Q = np.column_stack([Jc.T @ gc for (Jc, _), gc in zip(JA, g)])
        GG = np.diag(D) - Q.T @ bread @ Q
        den = float(np.sum(GG * GG))
        df[j] = float(np.trace(GG)) ** 2 / den if den > 0 else np.inf
    return bread @ meat @ bread, df


def _case(rng, n, p, clusters, pinned=False):
    J = rng.normal(size=(n, p)) * np.logspace(-2, 1, p)
    cl = rng.integers(0, clusters, n)
    if pinned:
        # the last parameter is seen by cluster 0 alone (a run that alone pins a parameter):
        # its eigenvalue of I - H_cc is ~0 and the floor (_MIN_RESIDUAL_FRACTION) decides
        J[:, -1] = np.where(cl == 0, J[:, -1], 0.0)
    r = rng.normal(size=n) + 0.3 * rng.normal(size=clusters)[cl]     # scatter between clusters
    return J, r, cl


@pytest.mark.parametrize("n,p,clusters,pinned", [(300, 6, 9, False), (900, 11, 14, True), (40, 5, 12, False),
                                              (2000, 8, 600, False), (3000, 9, 700, True)])
def test_cr2_matches_the_dense_formula(n, p, clusters, pinned):
    J, r, cl = _case(np.random.default_rng(n + p), n, p, clusters, pinned)
    bread = covariance._bread(J)
    cov, df = covariance._cr2(J, r, cl, bread)
    cov0, df0 = _dense_cr2(J, r, cl, bread)
    scale = np.sqrt(np.outer(np.diag(cov0), np.diag(cov0)))
    assert np.max(np.abs(cov - cov0) / scale) < 1e-10
    # the degrees of freedom from p x p products, or from GG's rows where that sum cancels (pinned)
    assert np.allclose(df, df0, rtol=1e-9, atol=0)
    if pinned:   # the floor was active: without it the pinned parameter's variance is far larger
        cov_nofloor, _ = _dense_cr2(J, r, cl, bread, floor=1e-12)
        assert cov_nofloor[-1, -1] > 10 * cov0[-1, -1]


@pytest.fixture(scope="module")
def small():
    """A SILO4-like twin: Stribeck + one line, 6 speeds per direction, 2 runs, white noise 0.2 mNm
    (1 % of the Coulomb level)."""
    truth = FrictionModel("silo4", {"tau_c": 0.02, "tau_s": 0.03, "v_s": 2.0, "viscous": 1e-4,
                                    "harmonics": [{"frequency": 0.8, "amplitude": 2e-3, "decay": 0.01, "phase": 0.3}]},
                          {"tau_c": 0.022, "tau_s": 0.031, "v_s": 2.5, "viscous": 1.2e-4,
                           "harmonics": [{"frequency": 0.8, "amplitude": 1.5e-3, "decay": 0.01, "phase": -1.0}]})
    speeds = [1.0, 2.0, 5.0, 10.0, 30.0, 80.0]
    sp = (speeds + [-s for s in speeds]) * 2
    rec, _ = model_recording(truth, sp, duration=[max(1.0, 3.0 / (0.8 * abs(v))) for v in sp], fs=500, ramp=0.1,
                             noise=2e-4, seed=3)
    return FitData.from_recording(rec, find_segments(rec))


def test_segment_errors_fast_path_matches(small):
    m = fit(small, "silo4", harmonics=[{"frequency": 0.8}], holdout=None)
    one_way = m.copy()                                  # a model that cannot predict the negative direction
    one_way.directions["negative"].values["tau_c"] = None
    fast = pipeline._segment_errors({"a": m, "b": one_way}, small)
    for name, model in (("a", m), ("b", one_way)):
        ref = segment_errors(model, small)
        assert list(fast[name].columns) == list(ref.columns) and len(fast[name]) == len(ref)
        # from the segments' normal equations: the same numbers to rounding (sums in another order)
        np.testing.assert_allclose(fast[name].to_numpy(float), ref.to_numpy(float), rtol=1e-10, atol=0)
    assert len(fast["b"]) == int(np.sum(fast["a"]["direction"] == 1)) > 0   # the negative segments left out


def test_fold_fit_predicts_as_refit(small):
    m = fit(small, "silo4", harmonics=[{"frequency": 0.8}], holdout="segment", folds=3)
    train = small.subset(small.segment % 3 != 0)
    test = small.subset(small.segment % 3 == 0)
    quick, full = joint.fold_fit(m, train), joint.refit(m, train, holdout=None)
    assert np.array_equal(quick.evaluate(**test.inputs()), full.evaluate(**test.inputs()))
    assert quick.rmse is None and full.rmse is not None     # the unread in-sample rmse is skipped
    ref, _ = holdout(lambda tr: joint.refit(m, tr, holdout=None), small, by="segment", folds=3)
    assert m.rmse_holdout == ref


def test_weighted_design_is_the_full_contraction(small):
    """``_Problem.weighted_design`` against ``Lt @ design`` contracted over all local columns (the
    formula it replaces): every entry is one product plus exact zeros, so equal bit for bit; with
    the inertia column too."""
    from gearspec.identify.stats import segment_stats

    pos = small.direction_subset(1)
    for acc in (False, True):
        stats = segment_stats(pos, [0.8], acc=acc)
        prob = joint._make_problem(stats, "silo4", [{"frequency": 0.8}], "segment")
        for vs, decay in ((1.5, 0.0), (3.0, 0.02)):
            M = prob.design([vs], np.array([decay]))
            full = np.einsum("spq,sql->spl", prob.Lt, M).reshape(-1, M.shape[2])
            assert np.array_equal(prob.weighted_design([vs], np.array([decay])), full)


def test_grid_costs_are_reused_only_for_the_same_columns(small):
    """The grid's costs of :func:`~gearspec.identify.jointlines.grid_starts` are kept per statistics
    and columns: a second problem with the same statistics and columns (a held shape at decay 0 is
    the same column) starts where a fresh computation starts; other weights are not reused."""
    from gearspec.identify.jointlines import grid_starts, held
    from gearspec.identify.stats import segment_stats

    pos = small.direction_subset(1)
    stats = segment_stats(pos, [0.8])
    prob = joint._make_problem(stats, "silo4", [{"frequency": 0.8}], "segment")
    first = grid_starts(held(prob, [0]))
    assert len(stats.grid_costs) > 0
    fresh = joint._make_problem(segment_stats(pos.subset(np.arange(len(pos))), [0.8]), "silo4",
                                [{"frequency": 0.8}], "segment")
    assert grid_starts(prob)[0] == grid_starts(fresh)[0] == first[0]
    n = len(stats.grid_costs)
    uniform = joint._make_problem(stats, "silo4", [{"frequency": 0.8}], "uniform")
    grid_starts(uniform)
    assert len(stats.grid_costs) == 2 * n          # other weights: other costs, computed
