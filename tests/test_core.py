"""gearspec.core: one cross-validation for the three engines (issue "One estimation core").

Known answers of the fold rule, the held-out Z, the held-out loop, the parameter count and the
harmonic columns; and the issue's case: on uneven data (9 positive, 10 negative plateaus)
``identify.fit``, the closed loop's baseline and the explorer deal the same folds and report the
same held-out rmse for the same model.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from gearspec import identify
from gearspec.core import crossval
from gearspec.core.crossval import critical_z, deal_folds, group_summary, held_out, n_params, row_folds, z_statistic
from gearspec.core.reduction import harmonic_columns
from gearspec.diagnose import DiagnoseData, diagnose
from gearspec.diagnose.loop import folds_of
from gearspec.discover import discover
from gearspec.discover.law import Part, cross_validate, fold_ids
from gearspec.discover.moments import moments
from gearspec.errors import InputError
from gearspec.fitdata import FitData
from gearspec.model import FrictionModel


# ====================================================================== the fold rule, closed form
def _deal(n_pos, n_neg, k):
    """Groups 0..n_pos-1 positive, then n_neg negative, speeds rising with the id."""
    sign = np.array([1] * n_pos + [-1] * n_neg)
    speed = np.concatenate([np.arange(n_pos), np.arange(n_neg)]) + 1.0
    return deal_folds(sign, speed, np.arange(n_pos + n_neg), k).tolist()


def test_one_segment_per_direction_gives_two_folds():
    # clamped to two folds (there are two groups), the negative direction starts where the
    # positive one stopped: each segment is held out alone (without the rotation both share fold 0)
    assert _deal(1, 1, 5) == [0, 1]


def test_two_plus_two_in_four_folds_leaves_no_fold_empty():
    assert _deal(2, 2, 4) == [0, 1, 2, 3]


def test_nine_plus_ten_in_five_folds():
    # positive speeds dealt 0 1 2 3 4 0 1 2 3; the negative ones start at 9 % 5 = 4
    assert _deal(9, 10, 5) == [0, 1, 2, 3, 4, 0, 1, 2, 3] + [4, 0, 1, 2, 3, 4, 0, 1, 2, 3]


def test_one_fold_asked_gives_two():
    # at least two folds, so that something is held out
    assert _deal(2, 2, 1) == [0, 1, 0, 1]


def test_folds_sort_by_speed_then_id_and_keep_the_order_given():
    sign = np.array([-1, 1, 1, -1, 1])
    speed = np.array([2.0, 3.0, 1.0, 1.0, 3.0])
    ids = np.array([7, 9, 4, 5, 2])
    # k = 5: positive by (speed, id): id 4 (1.0), id 2 (3.0), id 9 (3.0) -> folds 0, 1, 2; negative:
    # id 5 (1.0), id 7 (2.0) from 3 % 5 = 3 -> 3, 4.  k = 2: 0, 1, 0 and from 3 % 2 = 1: 1, 0
    assert deal_folds(sign, speed, ids, 5).tolist() == [4, 2, 0, 3, 1]
    assert deal_folds(sign, speed, ids, 2).tolist() == [0, 0, 0, 1, 1]


def test_speeds_equal_to_rounding_are_a_tie_broken_by_id():
    # plateaus at one commanded speed: mean speeds 1e-14 apart (rounding), dealt by group id
    speed = np.array([1.0, 1.0 + 1e-14, 1.0 - 1e-14, 2.0])
    assert deal_folds(np.ones(4, int), speed, np.array([2, 0, 1, 3]), 4).tolist() == [2, 0, 1, 3]
    # a real difference (1e-6 relative) still orders by speed
    speed = np.array([1.0, 1.0 + 1e-6, 1.0 - 1e-6, 2.0])
    assert deal_folds(np.ones(4, int), speed, np.array([2, 0, 1, 3]), 4).tolist() == [1, 2, 0, 3]


def test_group_summary_is_the_rows_mean_speed_and_direction():
    g = np.array([3, 3, 1, 1, 1, 8, 8])
    d = np.array([1, 1, -1, -1, 1, -1, 1])          # group 8: a tie, its first row says -1
    v = np.array([2.0, 4.0, -1.0, -2.0, 6.0, -5.0, 5.0])
    ids, sign, speed = group_summary(g, d, v)
    assert ids.tolist() == [1, 3, 8] and sign.tolist() == [-1, 1, -1]
    assert speed.tolist() == [3.0, 3.0, 5.0]
    # rows standing for several samples (segment summaries): weighted
    ids, sign, speed = group_summary([0, 0], [1, 1], [1.0, 4.0], weight=[3, 1])
    assert speed.tolist() == [7.0 / 4.0]


def test_fold_rule_refuses_groups_without_a_direction():
    with pytest.raises(InputError):
        deal_folds([1, 0], [1.0, 2.0], [0, 1], 2)


# ====================================================================== the held-out Z, closed form
def test_z_statistic_known_answer():
    # two groups of 8 rows, 8 blocks of one row each: V_g = max(<e, d>^2, sum (e_i d_i)^2)
    d = np.ones(16)
    e = np.array([1, -1] * 4 + [0.5] * 8)
    r0 = d + e
    num = float(r0 @ d)                               # 16 + 0 + 4 = 20
    v1 = max(0.0 ** 2, 8 * 1.0)                       # group 1: <e, d> = 0, blocks 8 x 1
    v2 = max(4.0 ** 2, 8 * 0.25)                      # group 2: <e, d> = 4, blocks 8 x 0.25
    assert z_statistic(r0, d, e, [0, 8], [8, 16]) == pytest.approx(num / math.sqrt(v1 + v2), rel=1e-15)
    assert z_statistic(r0, d, e, [0, 8], [8, 16]) == pytest.approx(20 / math.sqrt(24), rel=1e-15)


def test_z_statistic_without_noise_is_what_the_ratio_says():
    # the change explains the held-out data exactly: no noise left, Z = +inf (not 0)
    d = np.linspace(1, 2, 16)
    assert z_statistic(d, d, np.zeros(16), [0], [16]) == math.inf
    assert z_statistic(-d, d, np.zeros(16), [0], [16]) == -math.inf
    assert z_statistic(d, np.zeros(16), d, [0], [16]) == 0.0


def test_critical_z_is_the_bonferroni_t_quantile():
    # t table: one-sided 0.0025 with 9 degrees of freedom is 3.690; normal 0.01 is 2.326
    assert critical_z(0.01, 4, 10) == pytest.approx(3.690, abs=5e-4)
    assert critical_z(0.01, 0, 10 ** 6) == pytest.approx(2.326, abs=1e-3)


# ====================================================================== the held-out loop
def test_held_out_loop_known_answer():
    # units with levels; the "model" is the mean of the training units: held-out errors by hand
    y = np.array([1.0, 2.0, 3.0, 6.0])
    fold = np.array([0, 1, 0, 1])
    h = held_out(fold, lambda train: y[train].mean(), lambda m, test: (y[test] - m) ** 2)
    # fold 0 predicted by mean(2, 6) = 4: errors 9, 1; fold 1 by mean(1, 3) = 2: errors 0, 16
    assert h.sse.tolist() == [9.0, 0.0, 1.0, 16.0]
    assert h.fold_sse().tolist() == [10.0, 16.0]
    assert h.rmse == pytest.approx(math.sqrt(26 / 4), rel=1e-15)
    # a fold that cannot be fitted is skipped and said
    def fail_fold_1(train):
        if not train[0]:
            raise InputError("needs unit 0")
        return y[train].mean()
    h = held_out(fold, fail_fold_1, lambda m, test: (y[test] - m) ** 2, weight=[2, 2, 2, 2])
    assert h.failed == ["needs unit 0"] and h.ran == 2 and h.covered == 4
    assert h.rmse == pytest.approx(math.sqrt(16 / 4), rel=1e-15)
    assert list(crossval.splits([0, 0])) == []          # one fold: nothing to train on


# ====================================================================== the parameter count
def test_n_params_counts_free_values():
    h_exp = {"frequency": 1.0, "amplitude": 0.1, "phase": 0.0, "decay": 0.0, "law": "exp"}
    h_const = {"frequency": 2.0, "amplitude": 0.1, "phase": 0.0, "decay": 0.0, "law": "const"}
    P = {"tau_c": 1.0, "viscous": 0.1, "harmonics": [h_exp, h_const]}
    m = FrictionModel("coulomb_viscous", P, dict(P), terms=[
        {"kind": "temperature", "coefficient": 1e-3, "coefficient_se": 1e-4, "reference": 25.0},
        {"kind": "stribeck_extra", "amplitude": 0.2, "v_s": 0.5, "shape": "exp", "direction": 1}])
    # per direction 2 + (3 + 2); terms: coefficient; amplitude and v_s
    assert n_params(m) == 2 * (2 + 3 + 2) + 1 + 2


# ====================================================================== phases about the group mean
def test_harmonic_columns_are_sin_and_cos_of_the_positions():
    th = np.linspace(3.0, 9.0, 101)
    f = np.array([0.37, 2.0, 5.5])
    s, c = harmonic_columns(th, f)
    assert np.allclose(s, np.sin(2 * np.pi * np.outer(th, f)), rtol=0, atol=1e-12)
    assert np.allclose(c, np.cos(2 * np.pi * np.outer(th, f)), rtol=0, atol=1e-12)


# ====================================================================== one cross-validation for three engines
def _uneven(law="coulomb_viscous", seed=1):
    """9 positive, 10 negative plateaus of 200 samples: friction [0.3 + 0.01 |v| (+ 0.15
    exp(-|v|/2))] sign(v) + white noise 0.02, in random time order, segment ids not in time order,
    two positive plateaus at the same speed (a tie broken by the segment id, not by which came first)."""
    rng = np.random.default_rng(seed)
    pos = np.geomspace(0.5, 40, 9)
    pos[4] = pos[3]
    speeds = list(pos) + list(-np.geomspace(0.4, 50, 10))
    ids = rng.permutation(100)[:19]
    order = rng.permutation(19).tolist()
    if (order.index(3) < order.index(4)) == (ids[3] < ids[4]):
        ids[[3, 4]] = ids[[4, 3]]          # the tied pair: ids in the reverse of their time order
    th, vv, yy, ss = [], [], [], []
    t0 = 0.0
    for i in order:
        v, n = speeds[i], 200
        mag = 0.3 + 0.01 * abs(v) + (0.15 * np.exp(-abs(v) / 2.0) if law == "stribeck" else 0.0)
        vv.append(np.full(n, v))
        yy.append(np.sign(v) * mag + 0.02 * rng.standard_normal(n))
        th.append(t0 + v * np.arange(n) * 1e-3)
        t0 = th[-1][-1]
        ss.append(np.full(n, ids[i]))
    return FitData(theta=np.concatenate(th), v=np.concatenate(vv), y=np.concatenate(yy), segment=np.concatenate(ss))


def _fold_of_segment(segments, folds) -> dict:
    out = {}
    for s, f in zip(np.asarray(segments).tolist(), np.asarray(folds).tolist()):
        assert out.setdefault(int(s), int(f)) == f, "a segment split over folds"
    return out


def test_fit_diagnose_and_discover_deal_identical_folds_on_uneven_data():
    fd = _uneven()
    dd = DiagnoseData.from_fitdata(fd)
    M = moments(fd)
    by_fit = _fold_of_segment(fd.segment, identify.validate._folds(fd, "segment", 5))
    by_loop = _fold_of_segment(dd.fit.segment, folds_of(dd, 5)[dd.group])
    by_discover = _fold_of_segment(M.segment, fold_ids(M, "segment", 5))
    assert by_fit == by_loop == by_discover
    assert by_fit == _fold_of_segment(fd.segment, row_folds(fd.segment, fd.direction, fd.v, 5))
    assert np.bincount(list(by_fit.values())).tolist() == [4, 4, 4, 4, 3]


def test_fit_diagnose_and_discover_report_the_same_holdout_rmse():
    # the same model (Coulomb + viscous per direction, ordinary least squares) on the same folds:
    # all three fit it in closed form (no optimiser iterations), so they agree to rounding; 1e-9
    # relative leaves 1e4 times the double-precision error of a 3800-row least-squares solve
    fd = _uneven()
    fit = identify.fit(fd, "coulomb_viscous", weights="uniform", holdout="segment", folds=5).rmse_holdout
    diag = diagnose(fd, law="coulomb_viscous", folds=5, max_rounds=0).to_dict()["baseline"]["rmse_holdout"]
    res = discover(fd, folds=5, references=("coulomb_viscous",), thresholds=6, local_search=False)
    paper = res.references[0].rmse_holdout
    M = res.moments
    sse, _ = cross_validate(M, (Part("coulomb", split=True), Part("viscous", split=True)), res.fold)
    explorer = math.sqrt(float(np.sum(sse)) / M.N)
    assert fit == pytest.approx(diag, rel=1e-9)
    assert fit == pytest.approx(paper, rel=1e-9)
    assert fit == pytest.approx(explorer, rel=1e-9)
    # and the directions coupled (one Coulomb and one viscous coefficient for both directions):
    # the loop's symmetric baseline and the explorer's symmetric law, where a fold's pairing of
    # positive with negative segments matters
    sym = diagnose(fd, law="coulomb_viscous", folds=5, max_rounds=0, symmetric=True).baseline_model.rmse_holdout
    sse, _ = cross_validate(M, (Part("coulomb"), Part("viscous")), res.fold)
    assert sym == pytest.approx(math.sqrt(float(np.sum(sse)) / M.N), rel=1e-9)
    sym_cand = [c for c in res.candidates if c.terms() == ["coulomb", "viscous"]]
    assert sym_cand and sym_cand[0].rmse_holdout == pytest.approx(sym, rel=1e-9)


def test_compare_counts_parameters_by_the_core_rule():
    # Coulomb + viscous per direction: 2 values in each of 2 directions, and nothing else
    table = identify.compare(_uneven(), {"cv": {"law": "coulomb_viscous"}})
    assert int(table["parameters"].iloc[0]) == 4


def test_fit_and_discover_report_the_same_holdout_rmse_for_stribeck():
    # eq. 3 per direction, every parameter refitted in every fold by both engines (identify's
    # variable projection and the explorer's): equal to their optimisers' convergence (relative
    # steps of 1e-8 on the parameters move a least-squares minimum's rmse by ~1e-16; 1e-6 leaves
    # room for the explorer's 40 steps per fold)
    fd = _uneven("stribeck")
    fit = identify.fit(fd, "stribeck", weights="uniform", holdout="segment", folds=5).rmse_holdout
    M = moments(fd)
    parts = (Part("coulomb", split=True), Part("viscous", split=True), Part("stribeck_exp", split=True, param0=1.0))
    sse, _ = cross_validate(M, parts, fold_ids(M, "segment", 5))
    assert fit == pytest.approx(math.sqrt(float(np.sum(sse)) / M.N), rel=1e-6)


def test_normal_equations_per_group_are_the_groups_own_least_squares():
    # known answer: y = 2 + 3 x exactly in group 0, y = -1 x in group 1; the normal equations of
    # each group solve to its own coefficients and leave a residual of 0 (to rounding)
    from gearspec.core.reduction import group_normal_equations, normal_equations

    x = np.array([0.0, 1.0, 2.0, 3.0, 10.0, 11.0, 12.0])
    X = np.column_stack([np.ones_like(x), x])
    y = np.where(np.arange(7) < 4, 2 + 3 * x, -x)
    G, b, yy = group_normal_equations(X, y, [0, 4], [4, 7])
    assert np.allclose(np.linalg.solve(G[0], b[0]), [2, 3], atol=1e-12)
    assert np.allclose(np.linalg.solve(G[1], b[1]), [0, -1], atol=1e-12)
    for g, (a, z) in enumerate([(0, 4), (4, 7)]):
        beta = np.linalg.solve(G[g], b[g])
        assert yy[g] - beta @ b[g] == pytest.approx(0.0, abs=1e-9)
        G1, b1, yy1 = normal_equations(X[a:z], y[a:z])
        assert np.array_equal(G1, G[g]) and np.array_equal(b1, b[g]) and yy1 == yy[g]
    assert G[0][0, 0] == 4 and G[1][0, 0] == 3          # the group sizes, not the whole
