"""The one per-group reduction of the three engines (gearspec.core.reduction.GroupNormals): known
answers against numpy on a small synthetic problem, and the engines' containers built on it."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from gearspec.core.reduction import GroupNormals
from gearspec.discover.moments import Moments
from gearspec.identify.stats import SegmentStats

STARTS, STOPS = [0, 3, 7], [3, 7, 12]


@pytest.fixture
def problem():
    rng = np.random.default_rng(5)
    X = rng.normal(size=(12, 3))
    y = rng.normal(size=12)
    return X, y, GroupNormals.of(X, y, STARTS, STOPS)


def test_each_group_holds_its_own_normal_equations(problem):
    X, y, gn = problem
    assert len(gn) == 3
    assert gn.n.tolist() == [3, 4, 5]
    for g, (a, z) in enumerate(zip(STARTS, STOPS)):
        np.testing.assert_allclose(gn.G[g], X[a:z].T @ X[a:z], rtol=1e-14, atol=1e-14)
        np.testing.assert_allclose(gn.b[g], X[a:z].T @ y[a:z], rtol=1e-14, atol=1e-14)
        assert gn.yy[g] == pytest.approx(float(y[a:z] @ y[a:z]), rel=1e-14)


def test_take_with_repeats_and_sum_are_those_of_the_rows_stacked(problem):
    X, y, gn = problem
    bs = gn.take([2, 0, 2])
    rows = np.r_[7:12, 0:3, 7:12]
    assert bs.n.tolist() == [5, 3, 5]
    G, b, yy = bs.sum()
    np.testing.assert_allclose(G, X[rows].T @ X[rows], rtol=1e-13)
    np.testing.assert_allclose(b, X[rows].T @ y[rows], rtol=1e-13)
    assert yy == pytest.approx(float(y[rows] @ y[rows]), rel=1e-13)
    # sum over a boolean mask of groups: groups 0 and 2
    G, b, yy = gn.sum(np.array([True, False, True]))
    rows = np.r_[0:3, 7:12]
    np.testing.assert_allclose(G, X[rows].T @ X[rows], rtol=1e-13)
    assert yy == pytest.approx(float(y[rows] @ y[rows]), rel=1e-13)


def test_rss_is_the_residual_sum_of_squares_of_each_groups_samples(problem):
    X, y, gn = problem
    beta = np.array([0.3, -1.2, 2.0])
    r = y - X @ beta
    want = [float(r[a:z] @ r[a:z]) for a, z in zip(STARTS, STOPS)]
    np.testing.assert_allclose(gn.rss(beta), want, rtol=1e-12)
    np.testing.assert_allclose(gn.rss(beta, [1, 1]), [want[1], want[1]], rtol=1e-12)
    # at the least-squares solution of all groups, the total is lstsq's residual
    w, res, *_ = np.linalg.lstsq(X, y, rcond=None)
    assert float(np.sum(gn.rss(w))) == pytest.approx(float(res[0]), rel=1e-10)


def test_pseudo_rows_reproduce_every_residual(problem):
    X, y, gn = problem
    P, q, rest = gn.pseudo_rows()
    np.testing.assert_allclose(np.einsum("gkp,gkq->gpq", P, P), gn.G, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(np.einsum("gkp,gk->gp", P, q), gn.b, rtol=1e-10, atol=1e-12)
    beta = np.array([1.0, 0.5, -0.25])
    r = q - np.einsum("gkp,p->gk", P, beta)
    np.testing.assert_allclose(np.sum(r * r, axis=1) + rest, gn.rss(beta), rtol=1e-10)


def test_columns_are_the_normal_equations_of_the_columns_alone(problem):
    X, y, gn = problem
    G, b = gn.columns([2, 0])
    Xc = X[:, [2, 0]]
    np.testing.assert_allclose(G[1], Xc[3:7].T @ Xc[3:7], rtol=1e-14)
    np.testing.assert_allclose(b[1], Xc[3:7].T @ y[3:7], rtol=1e-14)


def _taken_along(obj, shared=("frequencies",)):
    """Every array of ``obj`` (3 groups) taken at [2, 2]: its rows are group 2's, twice."""
    sub = obj.take([2, 2])
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        if isinstance(v, np.ndarray) and f.name not in shared:
            np.testing.assert_array_equal(getattr(sub, f.name), v[[2, 2]], err_msg=f.name)


def test_the_engines_containers_are_group_normals_and_take_their_metadata_along(problem):
    X, y, gn = problem
    per = {k: np.arange(3.0) + 10 * i for i, k in enumerate(("segment", "speed", "load", "sigma2", "rss_hat"))}
    st = SegmentStats(gn.G, gn.b, gn.yy, gn.n, **per, active=np.eye(3, 2, dtype=bool), sampled=np.ones((3, 2), bool),
                      cycles=np.arange(6.0).reshape(3, 2), beta_hat=np.arange(9.0).reshape(3, 3),
                      frequencies=np.array([0.5, 1.5]))
    assert st.g is st.b
    _taken_along(st)
    per = {k: np.arange(3.0) + 10 * i for i, k in enumerate(("segment", "run", "direction", "speed", "load",
                                                              "temperature", "noise", "vabs"))}
    M = Moments(gn.G, gn.b, gn.yy, gn.n, basis=("1", "load", "acc"), cycles=np.arange(6.0).reshape(3, 2), **per)
    assert isinstance(M, GroupNormals)
    _taken_along(M)
    assert M.take([1]).q.shape == (1, 3)
    np.testing.assert_allclose(M.sse(M.P.reshape(-1, 3), np.ones(3)), gn.rss(np.ones(3)), rtol=1e-10)


def test_new_columns_enter_through_their_cross_products(problem):
    # the closed loop's candidate columns C join the reduced design X: the normal equations of the
    # stacked columns [X, C] of each group are [[G_X, X^T C], [C^T X, G_C]], exactly
    from gearspec.core.reduction import group_cross
    X, y, gn = problem
    C = np.random.default_rng(6).normal(size=(12, 2))
    xc = group_cross(X, C, STARTS, STOPS)
    both = GroupNormals.of(np.hstack([X, C]), y, STARTS, STOPS)
    assert xc.shape == (3, 3, 2)
    np.testing.assert_allclose(xc, both.G[:, :3, 3:], rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(GroupNormals.of(C, y, STARTS, STOPS).G, both.G[:, 3:, 3:], rtol=1e-13, atol=1e-13)
