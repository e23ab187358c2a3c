"""Calibrated uncertainty (issue 13 item 2): the twins' repetition scatter, the cluster-robust
covariance of the joint fit against known answers, its fallback, and the coverage of its 95 %
intervals over many twins with repetition scatter (slow)."""

import json
import math
import warnings

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from gearspec import identify
from gearspec.cli import main
from gearspec.fitdata import FitData
from gearspec.identify.covariance import _bread, _cr2, fit_covariance, small_sample_factor
from gearspec.model import FrictionModel
from gearspec.simulate import model_recording
from gearspec.simulate.scatter import run_scatter
from gearspec.simulate.silo4 import silo4_twin, table2_model

F_A, F_B = 0.8, 5.0  # cycles/rad
LINES = [{"frequency": F_A, "label": "A"}, {"frequency": F_B, "label": "B"}]
TRUTH = FrictionModel("silo4", {"tau_c": 0.1, "tau_s": 0.15, "v_s": 2.0, "viscous": 6e-4,
                                "harmonics": [{"frequency": F_A, "amplitude": 0.01, "decay": 0.01, "phase": 1.0,
                                               "label": "A"},
                                              {"frequency": F_B, "amplitude": 0.004, "decay": 0.006, "phase": -0.5,
                                               "label": "B"}]})
#: a bench's plan: six speeds below and around the Stribeck velocity (2 rad/s), four above, three
#: repetitions each, both directions (30 runs per direction)
SPEEDS = (0.3, 0.6, 1.0, 1.5, 2.2, 3.0, 5.0, 10.0, 30.0, 100.0)
SCATTER = 0.03


def plateau_data(rec, plateaus) -> FitData:
    """Fit data of the held part of every plateau, the segments known from the twin (the
    segmentation is tested elsewhere; here it would cost 2 s per twin); speed = travel / time."""
    t, th, y, run = rec.t, rec.theta, rec.tau, rec.run
    idx, v, seg, rows = [], [], [], []
    for i, p in enumerate(plateaus):
        ii = np.flatnonzero((run == p["run"]) & (t >= p["t0"]) & (t <= p["t1"]))
        vel = (th[ii[-1]] - th[ii[0]]) / (t[ii[-1]] - t[ii[0]])
        idx.append(ii)
        v.append(np.full(len(ii), vel))
        seg.append(np.full(len(ii), i))
        rows.append({"segment": i, "run": p["run"], "direction": p["direction"], "speed": abs(vel),
                     "velocity": vel, "n": len(ii), "t0": p["t0"], "t1": p["t1"], "kind": "plateau"})
    idx, v = np.concatenate(idx), np.concatenate(v)
    return FitData(theta=th[idx], v=v, y=y[idx], t=t[idx], run=run[idx], segment=np.concatenate(seg),
                   direction=np.where(v > 0, 1, -1).astype(np.int8), segments=pd.DataFrame(rows))


def scatter_twin(seed, reps=3, speeds=SPEEDS, scatter=SCATTER):
    """Plateaus of TRUTH, one run each, ``reps`` repetitions per speed, both directions; levels and
    amplitudes scattering 3 % between runs, AR(1) noise (correlation 0.8 between samples: a
    filtered current) of 2 % of tau_c, position quantised to 2000 counts/rev."""
    sp = [s for s in speeds for _ in range(reps)]
    sp = sp + [-s for s in sp]
    dur = [max(0.6, 1.5 / (F_A * abs(v))) for v in sp]
    rec, truth = model_recording(TRUTH, sp, duration=dur, fs=500, ramp=0.05, noise=0.002, seed=seed, scatter=scatter,
                                 noise_correlation=0.8, quantum=2 * math.pi / 2000)
    plateaus, sc = truth if scatter else (truth, None)
    return plateau_data(rec, plateaus), sc


def estimates(model):
    """(name, estimate, se, truth) of every parameter the issue names, both directions."""
    out = []
    for d in ("positive", "negative"):
        P, T = model.params(d), TRUTH.params(d)
        out += [(k, P[k], P.se[k], T[k]) for k in ("tau_c", "tau_s", "viscous")]
        for h, ht in zip(P.harmonics, T.harmonics):
            out += [(h.label + " amplitude", h.amplitude, h.se["amplitude"], ht.amplitude),
                    (h.label + " decay", h.decay, h.se["decay"], ht.decay)]
    return out


# ---------------------------------------------------------------------- the scatter of the twins
def test_scatter_parts_add_up_to_the_model_and_scale_each_parameter():
    m = table2_model()
    sc = run_scatter(m, 0.03, 4, np.random.default_rng(0), [1, 1, -1, -1])
    # 3 base-law parameters and 3 line amplitudes per direction
    assert len(sc.names) == 12 and sc.factors.shape == (4, 12)
    th = np.linspace(0.0, 3000.0, 2001)
    v = np.where(np.arange(len(th)) % 2, 5.0, -30.0)
    # the parts are exact: the model is linear in these parameters (to rounding)
    total = sum(f(th, v) for f in sc._eval)
    assert np.max(np.abs(total - m.evaluate(th, v))) < 1e-15
    # run 2 with tau_c of the negative direction 10 % up: exactly 0.1 tau_c more friction there
    sc.factors[:] = 1.0
    j = sc.names.index("negative.tau_c")
    sc.factors[2, j] = 1.1
    extra = sc.extra(np.zeros(2), np.array([-50.0, 50.0]), np.array([2, 2]))
    tau_c = m.params("negative")["tau_c"]
    assert extra[1] == 0.0
    assert extra[0] == pytest.approx(-0.1 * tau_c * (1 - math.exp(-50 / m.params("negative")["v_s"])),
                                     rel=1e-12)
    # the run mean: the negative runs (2 and 3) average 1.05
    assert sc.run_mean(m).params("negative")["tau_c"] == pytest.approx(1.05 * tau_c, rel=1e-12)
    assert sc.run_mean(m).params("positive")["tau_c"] == pytest.approx(m.params("positive")["tau_c"], rel=1e-12)


def test_no_scatter_leaves_the_twins_as_they_were():
    a, _ = model_recording(TRUTH, [1.0, -2.0], duration=0.5, noise=1e-3, seed=4)
    b, _ = model_recording(TRUTH, [1.0, -2.0], duration=0.5, noise=1e-3, seed=4, scatter=0.0)
    assert np.array_equal(a.tau, b.tau)
    with pytest.raises(Exception, match="scatter must be a fraction"):
        model_recording(TRUTH, [1.0], duration=0.5, scatter=0.7)


def test_model_recording_scatter_moves_each_runs_level_by_its_factors():
    base = FrictionModel("silo4", {k: TRUTH.params("positive")[k] for k in ("tau_c", "tau_s", "v_s", "viscous")})
    rec, (plateaus, sc) = model_recording(base, [5.0] * 40, duration=0.4, seed=3, scatter=0.05)
    lv = np.array([np.mean(rec.tau[(rec.run == p["run"]) & (rec.t >= p["t0"]) & (rec.t <= p["t1"])])
                   for p in plateaus])
    # the level at 5 rad/s: tau_c, tau_s and viscous parts, each times its run's factor (no noise,
    # no lines: exact to rounding)
    P = base.params("positive")
    e = math.exp(-5.0 / P["v_s"])  # SILO4 eq. 3: exp(-|v| / v_s)
    parts = np.array([P["tau_c"] * (1 - e), P["tau_s"] * e, P["viscous"] * 5.0])
    want = np.array(sc["factors"])[:, :3] @ parts
    assert np.allclose(lv, want, rtol=1e-12)
    assert np.std(lv / (parts.sum())) > 0.02   # the runs do scatter (5 % factors)


def test_ar1_noise_has_its_correlation_and_sd():
    rec, _ = model_recording(FrictionModel("silo4", {"tau_c": 0.0, "tau_s": 0.0, "v_s": 1.0, "viscous": 0.0}),
                             [1.0], duration=40.0, ramp=0.01, noise=0.01, noise_correlation=0.8, seed=1)
    x = rec.tau
    # 40000 samples of AR(1) with rho 0.8: sd and lag-1 correlation to ~1.5 % (effective n = n (1-rho)/(1+rho))
    assert np.std(x) == pytest.approx(0.01, rel=0.05)
    assert np.corrcoef(x[:-1], x[1:])[0, 1] == pytest.approx(0.8, abs=0.02)


def test_silo4_twin_scatter_option_and_truth(tmp_path):
    kw = dict(repetitions=2, duration=0.3, seed=2, plant={"control_rate": 1000.0})
    rec0, t0 = silo4_twin([300, -300], **kw)
    rec1, t1 = silo4_twin([300, -300], scatter=0.0, **kw)
    assert np.array_equal(rec0.data["current"], rec1.data["current"]) and t1.scatter is None
    rec2, t2 = silo4_twin([300, -300], scatter=0.04, **kw)
    sc = t2.scatter
    assert sc["fraction"] == 0.04 and np.array(sc["factors"]).shape == (4, 12)
    f = np.array(sc["factors"])[:, sc["parameters"].index("positive.tau_c")]
    run_mean = FrictionModel.from_dict(sc["run_mean"])
    # the positive runs are 0 and 1 (each speed's repetitions in a row)
    assert run_mean.params("positive")["tau_c"] == pytest.approx(t2.model.params("positive")["tau_c"] * f[:2].mean())
    assert "scatter" in json.loads(t2.to_json(tmp_path / "t.json").read_text())
    # the recorded current moves with the run's friction: not equal to the run without scatter
    assert not np.allclose(rec2.data["current"], rec0.data["current"])


def test_cli_simulate_scatter(tmp_path, capsys):
    code = main(["simulate", "silo4", "--out", str(tmp_path), "--speeds-rpm", "300,-300", "--repetitions", "1",
                 "--duration", "0.3", "--scatter", "0.03"])
    assert code == 0
    truth = json.loads((tmp_path / "silo4_twin_truth.json").read_text())
    assert truth["scatter"]["fraction"] == 0.03 and len(truth["scatter"]["factors"]) == 2
    assert "repetition scatter: 3 %" in capsys.readouterr().out
    assert main(["simulate", "silo4", "--out", str(tmp_path), "--scatter", "0.9"]) == 2


# ---------------------------------------------------------------------- the covariance, known answers
def test_cr2_with_single_rows_is_hc2_and_its_df_for_a_mean_is_n_minus_1():
    rng = np.random.default_rng(5)
    n = 12
    X = np.column_stack([np.ones(n), rng.normal(size=n)])
    r = rng.normal(size=n)
    B = _bread(X)
    cov, df = _cr2(X, r, np.arange(n), B)
    h = np.einsum("ij,jk,ik->i", X, B, X)
    hc2 = B @ (X.T * (r ** 2 / (1 - h))) @ X @ B     # MacKinnon & White's HC2, written out
    assert np.allclose(cov, hc2, rtol=1e-10)
    # the mean of n samples, each its own cluster: Bell-McCaffrey degrees of freedom n - 1 exactly
    one = np.ones((n, 1))
    _, df1 = _cr2(one, r, np.arange(n), _bread(one))
    assert df1[0] == pytest.approx(n - 1, rel=1e-10)
    # ... and the standard error scaled by t_0.975(11) / 1.96
    assert small_sample_factor([n - 1])[0] == pytest.approx(stats.t.ppf(0.975, n - 1) / stats.norm.ppf(0.975))


def test_cr2_of_clustered_means_equals_the_spread_of_the_cluster_means():
    # y = mean + cluster effect + noise, 8 clusters of 5: CR2 of the mean with equal clusters is
    # exactly var(cluster means) / C (the textbook between-cluster variance of the mean)
    rng = np.random.default_rng(7)
    C, m = 8, 5
    y = np.repeat(rng.normal(0, 1, C), m) + rng.normal(0, 0.3, C * m)
    X = np.ones((C * m, 1))
    r = y - y.mean()
    cov, df = _cr2(X, r, np.repeat(np.arange(C), m), _bread(X))
    means = y.reshape(C, m).mean(axis=1)
    assert cov[0, 0] == pytest.approx(np.var(means, ddof=1) / C, rel=1e-10)
    assert df[0] == pytest.approx(C - 1, rel=1e-10)
    # the covariance of independent samples ignores the clusters: far smaller
    cov_i, method = fit_covariance(X, r, float(r @ r) / (C * m - 1), method="independent")
    assert method == "covariance of independent samples" and cov_i[0, 0] < 0.5 * cov[0, 0]


def test_fit_says_which_covariance_and_falls_back_with_too_few_runs():
    data, _ = scatter_twin(1, reps=3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = identify.fit(data, "silo4", harmonics=LINES, holdout=None)
    # 30 runs per direction, 10 parameters: cluster-robust over runs
    assert m.params("positive").se_method == "cluster-robust (CR2, t-scaled) over 30 runs"
    assert m.to_dict()["directions"]["negative"]["se_method"].startswith("cluster-robust (CR2, t-scaled)")
    # 6 speeds x 1 run per direction (< 10 parameters + 2): independent samples, and it says so
    few, _ = scatter_twin(1, reps=1, speeds=(0.3, 1.0, 2.2, 5.0, 30.0, 100.0))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m2 = identify.fit(few, "silo4", harmonics=LINES, holdout=None)
    meth = m2.params("positive").se_method
    assert meth.startswith("covariance of independent samples: only 6 runs and 6 segments for 10 parameters")
    assert "likely too small" in meth
    # the old covariance on request
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m3 = identify.fit(data, "silo4", harmonics=LINES, holdout=None, se="independent")
    assert m3.params("positive").se_method == "covariance of independent samples"
    assert m3.params("positive").se["tau_c"] < 0.5 * m.params("positive").se["tau_c"]


# ---------------------------------------------------------------------- coverage (slow)
#: 50 twins x 2 directions = 100 intervals per parameter.  At a true coverage of 95 % the count of
#: 100 has a binomial sd of 2.2: a parameter passes with at least 88 (2.5 % of the time below at
#: 93 % true coverage); the pooled coverage of the 500 intervals lies within the issue's 90-98 %
#: (the parameters of one fit are correlated, so the pooled count is no sharper than +-2 %).
SEEDS = 50
PARAMETERS = ("tau_c", "tau_s", "viscous", "A amplitude", "A decay", "B amplitude", "B decay")


def coverage(se: str = "covariance") -> tuple[dict, dict]:
    hits, z = {}, {}
    for seed in range(SEEDS):
        data, _ = scatter_twin(seed)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            m = identify.fit(data, "silo4", harmonics=LINES, holdout=None, se=se)
        for name, est, se_, true in estimates(m):
            hits.setdefault(name, []).append(abs(est - true) <= stats.norm.ppf(0.975) * se_)
            z.setdefault(name, []).append((est - true) / se_)
    return {k: float(np.mean(v)) for k, v in hits.items()}, {k: float(np.std(v)) for k, v in z.items()}


@pytest.mark.slow
def test_95_percent_intervals_cover_the_truth_90_to_98_percent_of_the_time():
    cov, zsd = coverage()
    print("\ncoverage of the 95 % intervals over", SEEDS, "twins x 2 directions:")
    for k in PARAMETERS:
        print(f"  {k:12s} {100 * cov[k]:5.1f} %   sd of (estimate - truth) / se {zsd[k]:.2f}")
    pooled = float(np.mean([cov[k] for k in PARAMETERS]))
    print(f"  pooled       {100 * pooled:5.1f} %")
    assert set(cov) == set(PARAMETERS)
    for k in PARAMETERS:
        assert cov[k] >= 0.88, (k, cov[k])
        # and not uselessly wide: the errors are at least half the standard errors on average
        assert zsd[k] >= 0.5, (k, zsd[k])
    assert 0.90 <= pooled <= 0.98
