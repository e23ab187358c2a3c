"""Known-answer tests of identification: twins with known direction-dependent parameters.

Tolerances.  The recordings below have white torque noise of 1 % of the Coulomb level per sample
and a few thousand samples per plateau, so the statistical error of a plateau level is ~0.02 % and
of an amplitude ~1 %; the issue's tolerances (3 % static/Coulomb/viscous, 15 % Stribeck velocity,
5 % amplitudes, 20 % decays) are several standard errors wide and test for bias.  Coverage tests
use many seeds and check that (estimate - truth) / se behaves like a standard normal variable.
"""

import json
import math

import numpy as np
import pytest

from gearspec import identify
from gearspec.errors import InputError
from gearspec.fitdata import FitData
from gearspec.model import RPM, FrictionModel
from gearspec.simulate import model_recording
from gearspec.spectrum import analyze

F_A, F_B = 0.8, 5.0  # cycles/rad of two "stages" (fast enough for short test recordings)
SPECS = [{"frequency": F_A, "label": "stage A"}, {"frequency": F_B, "label": "stage B"}]


def random_truth(rng):
    def direction():
        tau_c = rng.uniform(0.05, 0.2)
        return {"tau_c": tau_c, "tau_s": tau_c * rng.uniform(1.2, 1.8), "v_s": rng.uniform(1.0, 4.0),
                "viscous": tau_c * rng.uniform(0.002, 0.01),
                "harmonics": [{"frequency": F_A, "amplitude": tau_c * rng.uniform(0.05, 0.15),
                               "decay": rng.uniform(0.005, 0.02), "phase": rng.uniform(-3, 3), "label": "stage A"},
                              {"frequency": F_B, "amplitude": tau_c * rng.uniform(0.02, 0.06),
                               "decay": rng.uniform(0.003, 0.012), "phase": rng.uniform(-3, 3), "label": "stage B"}]}

    return FrictionModel("silo4", direction(), direction())


SPEEDS = [0.5, 1, 2, 3, 5, 8, 15, 30, 60, 100, 150]


def twin(truth, seed, noise_rel=0.01, speeds=SPEEDS, fs=1000, ripple=0.0, both=True):
    sp = list(speeds) + ([-s for s in speeds] if both else [])
    dur = [max(1.5, 3.0 / (F_A * abs(v))) for v in sp]
    noise = noise_rel * truth.params("positive")["tau_c"]
    rec, _ = model_recording(truth, sp, duration=dur, fs=fs, ramp=0.1, noise=noise, speed_ripple=ripple,
                             speed_ripple_frequency=3.3, seed=seed)
    return rec


def rel(a, b):
    return abs(a - b) / abs(b)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_joint_fit_recovers_direction_dependent_parameters(seed):
    rng = np.random.default_rng(100 + seed)
    truth = random_truth(rng)
    rec = twin(truth, seed, ripple=0.01)
    data = FitData.from_recording(rec)
    m = identify.fit(data, "silo4", harmonics=SPECS, holdout=None)
    for d in ("positive", "negative"):
        t, e = truth.params(d), m.params(d)
        for k in ("tau_c", "tau_s", "viscous"):
            assert rel(e[k], t[k]) < 0.03, (d, k, e[k], t[k])
        assert rel(e["v_s"], t["v_s"]) < 0.15, (d, e["v_s"], t["v_s"])
        for ht, he in zip(t["harmonics"], e["harmonics"]):
            assert he["label"] == ht["label"]
            assert rel(he["amplitude"], ht["amplitude"]) < 0.05, (d, ht["label"])
            assert rel(he["decay"], ht["decay"]) < 0.20, (d, ht["label"], he["decay"], ht["decay"])
            assert abs(np.angle(np.exp(1j * (he["phase"] - ht["phase"])))) < 0.05
    # the fitted model predicts as well as the truth itself evaluated at the segment speeds (the 1 %
    # speed ripple adds a little misfit to both: the laws see the segment's mean speed), the truth's
    # amplitudes held outside the speeds that measured each line as the fitted model's are (stage B
    # is above 0.8 x the position Nyquist frequency at 100 and 150 rad/s)
    held = truth.copy()
    for d in ("positive", "negative"):
        for ht, he in zip(held.harmonics(d), m.harmonics(d)):
            ht.speed_range = he.speed_range
    assert m.harmonics("positive")[1]["speed_range"][1] == pytest.approx(60.0, rel=1e-3)
    assert m.rmse <= 1.01 * held.rmse_on(data)


def test_standard_errors_cover_the_truth():
    """Over 30 seeds, z = (estimate - truth) / se of Coulomb, static, viscous, Stribeck velocity,
    amplitudes and decays: about 95 % within +-1.96 and a spread near 1 (4 sd of the spread of 30 x
    10 correlated z values is ~ +-0.3)."""
    rng = np.random.default_rng(7)
    truth = random_truth(rng)
    z = {}
    for seed in range(30):
        rec = twin(truth, 1000 + seed, noise_rel=0.05, speeds=[0.5, 1, 2, 4, 8, 20, 60, 150], fs=500, both=False)
        m = identify.fit(FitData.from_recording(rec), "silo4", harmonics=SPECS, holdout=None)
        t, e = truth.params("positive"), m.params("positive")
        for k in ("tau_c", "tau_s", "viscous", "v_s"):
            z.setdefault(k, []).append((e[k] - t[k]) / e[k + "_se"])
        for ht, he in zip(t["harmonics"], e["harmonics"]):
            for k in ("amplitude", "decay"):
                z.setdefault(f"{ht['label']} {k}", []).append((he[k] - ht[k]) / he[k + "_se"])
    allz = np.concatenate([np.asarray(v) for v in z.values()])
    coverage = np.mean(np.abs(allz) < 1.96)
    assert 0.88 <= coverage <= 0.99, coverage
    assert 0.75 < np.std(allz) < 1.3
    for k, v in z.items():  # no parameter badly off on its own
        assert np.mean(np.abs(v) < 1.96) >= 0.75, (k, np.mean(np.abs(v) < 1.96))


# The band a bootstrap se over segments may take around the covariance se (which is the sampling sd:
# test_covariance_standard_errors_equal_the_sampling_spread): with n = 11 segments its relative sd is
# 1 / sqrt(2 (n - 1)) = 0.224, plus the noise of B = 150 resamples 1 / sqrt(2 B) = 0.058, together
# sqrt(0.224^2 + 0.058^2) = 0.231; 3 of those on a log scale: exp(+-3 x 0.231) = 0.50 .. 2.0.
BOOT_BAND = (math.exp(-3 * 0.231), math.exp(3 * 0.231))


@pytest.fixture(scope="module")
def boot_ratios():
    rng = np.random.default_rng(3)
    truth = random_truth(rng)
    data = FitData.from_recording(twin(truth, 5, noise_rel=0.05, fs=500, both=False))
    cov = identify.fit(data, "silo4", harmonics=SPECS, holdout=None)
    boot = identify.fit(data, "silo4", harmonics=SPECS, holdout=None, se="bootstrap", bootstrap=150)
    pc, pb = cov.params("positive"), boot.params("positive")
    assert pb["se_method"].startswith("bootstrap")
    return {k: pb[k + "_se"] / pc[k + "_se"] for k in ("tau_c", "viscous", "v_s")}


def test_bootstrap_standard_errors_agree_with_covariance(boot_ratios):
    """The lower edge of BOOT_BAND holds; the upper edge is the old 3.0: the segment bootstrap is
    biased high here (1.4 / 2.5 / 1.7 x the covariance se, which equals the sampling sd), see
    test_bootstrap_standard_errors_within_their_sampling_band."""
    for k, r in boot_ratios.items():
        assert BOOT_BAND[0] < r < 3.0, (k, r)


@pytest.mark.xfail(strict=True, reason="the segment bootstrap over 11 plateaus at 11 distinct speeds overestimates "
                   "the se: a resample holds ~7 distinct speeds and loses the high-leverage ones (viscous: "
                   "bootstrap 2.6e-6, covariance 1.05e-6, sd over 40 twins 1.0e-6)")
def test_bootstrap_standard_errors_within_their_sampling_band(boot_ratios):
    for k, r in boot_ratios.items():
        assert BOOT_BAND[0] < r < BOOT_BAND[1], (k, r)


@pytest.mark.slow
def test_covariance_standard_errors_equal_the_sampling_spread():
    """The twin of the bootstrap test recorded 40 times: the sd of the estimates over the twins
    against the median covariance se.  The sd of 40 values is uncertain by 1 / sqrt(2 x 39) = 0.113
    relative; 3 of those on a log scale: 0.71 .. 1.40."""
    rng = np.random.default_rng(3)
    truth = random_truth(rng)
    est, se = {}, {}
    for seed in range(100, 140):
        p = identify.fit(FitData.from_recording(twin(truth, seed, noise_rel=0.05, fs=500, both=False)), "silo4",
                         harmonics=SPECS, holdout=None).params("positive")
        for k in ("tau_c", "viscous", "v_s"):
            est.setdefault(k, []).append(p[k])
            se.setdefault(k, []).append(p[k + "_se"])
    lo, hi = math.exp(-3 / math.sqrt(78)), math.exp(3 / math.sqrt(78))
    for k in est:
        r = np.std(est[k], ddof=1) / np.median(se[k])
        assert lo < r < hi, (k, r)


def test_published_procedure_is_biased_where_the_joint_fit_is_not():
    """SILO4 Table 2 values, speeds as in the paper.  The published Stribeck step neglects the
    viscous term below 100 rpm (eq. 4): at the paper's B this is not negligible, and the Stribeck
    velocity comes out several times too high; the joint fit recovers it.  The log-linear decay fit
    (eq. 10) weights the small, noisy amplitudes at high speed as much as the large ones."""
    from gearspec.gears import load_gear

    g = load_gear("silo4-joint3")
    F = {ln.label: ln.frequency for ln in g.declared_lines()}
    per_rpm = 60 / (2 * np.pi)
    P = dict(tau_c=7.106e-3, tau_s=8.58e-3, v_s=28.18 * RPM, viscous=0.0134e-3 / RPM,
             harmonics=[dict(frequency=F["planetary output shaft"], amplitude=0.576e-3, decay=1.27e-4 * per_rpm,
                             phase=np.pi / 2, label="planetary output shaft"),
                        dict(frequency=F["motor shaft"], amplitude=0.133e-3, decay=5.28e-5 * per_rpm, phase=np.pi,
                             label="motor shaft")])
    truth = FrictionModel("silo4", P)
    rpm = [5, 10, 20, 40, 80, 150, 280, 560, 1000, 2000, 3000]
    sp = [r * RPM for r in rpm]
    dur = [max(1.0, 1.1 / (F["planetary output shaft"] * v)) for v in sp]
    rec, _ = model_recording(truth, sp, duration=dur, fs=250, noise=0.2e-3, seed=2, gear=g)
    data = FitData.from_recording(rec)
    joint = identify.fit(data, "silo4", gear=g, holdout=None)
    pub = identify.silo4_published(data, analyze(rec), holdout=None)
    j, p = joint.params("positive"), pub.params("positive")
    assert rel(j["v_s"], P["v_s"]) < 0.15
    assert rel(p["v_s"], P["v_s"]) > 1.0          # the published step: more than 100 % off
    assert rel(j["tau_s"], P["tau_s"]) < 0.03
    assert rel(p["tau_s"], P["tau_s"]) > 0.03
    assert rel(j["tau_c"], P["tau_c"]) < 0.03 and rel(p["tau_c"], P["tau_c"]) < 0.03  # both fine here
    assert joint.rmse < pub.rmse


def test_one_direction_fits_what_it_can_and_says_what_not():
    rng = np.random.default_rng(5)
    truth = random_truth(rng)
    data = FitData.from_recording(twin(truth, 2, both=False, fs=500))
    m = identify.fit(data, "silo4", harmonics=SPECS, holdout=None)
    assert m.params("negative")["tau_c"] is None and m.params("negative")["harmonics"] == []
    assert "no segment in the negative direction" in m.not_identified["negative.tau_c"]
    assert rel(m.params("positive")["tau_c"], truth.params("positive")["tau_c"]) < 0.03
    # it predicts the positive direction and refuses the negative one with a reason
    assert np.isfinite(m.evaluate(0.0, 2.0)).all()
    with pytest.raises(InputError, match="negative-direction value"):
        m.evaluate(0.0, -2.0)
    # a harmonic that never completes a cycle is named, not invented
    slow = SPECS + [{"frequency": 1e-4, "label": "output"}]
    m2 = identify.fit(data, "silo4", harmonics=slow, holdout=None)
    assert "output" not in [h.get("label") for h in m2.params("positive")["harmonics"]]
    assert "cover" in m2.not_identified["positive.output"]


def test_stribeck_velocity_not_identified_from_fast_plateaus_only():
    rng = np.random.default_rng(9)
    truth = random_truth(rng)
    data = FitData.from_recording(twin(truth, 3, speeds=[40, 60, 90, 120, 150], both=False, fs=500))
    m = identify.fit(data, "stribeck", holdout=None)
    assert "positive.v_s" in m.not_identified and "record slower plateaus" in m.not_identified["positive.v_s"]
    p = m.params("positive")
    assert p["v_s"] is None and p["tau_s"] is None          # not invented ...
    assert rel(p["tau_c"], truth.params("positive")["tau_c"]) < 0.03   # ... and the rest still fitted
    assert rel(p["viscous"], truth.params("positive")["viscous"]) < 0.03
    assert np.isfinite(m.evaluate(0.0, 100.0)).all()


def test_too_few_speeds_is_a_clear_error():
    rng = np.random.default_rng(9)
    truth = random_truth(rng)
    data = FitData.from_recording(twin(truth, 3, speeds=[5, 50], both=False, fs=500))
    with pytest.raises(identify.ConvergenceError, match="plateaus at only 2 speed"):
        identify.fit(data, "stribeck", holdout=None)
    m = identify.fit(data, "coulomb_viscous", holdout=None)  # what it can fit
    assert m.params("positive")["tau_c"] > 0


def test_json_round_trip_evaluates_identically(tmp_path):
    rng = np.random.default_rng(11)
    truth = random_truth(rng)
    data = FitData.from_recording(twin(truth, 4, fs=500))
    m = identify.fit(data, "silo4", harmonics=SPECS, folds=3)
    path = m.to_json(tmp_path / "model.json")
    d = json.loads(path.read_text())
    # the CONTRACTS.md form
    assert d["law"] == "silo4" and set(d["directions"]) == {"positive", "negative"}
    assert d["rmse"] > 0 and d["rmse_holdout"] > 0
    h = d["directions"]["negative"]["harmonics"][0]
    assert {"frequency", "amplitude", "decay", "phase", "amplitude_se", "decay_se"} <= set(h)
    assert "tau_s_se" in d["directions"]["positive"]
    back = FrictionModel.from_json(path)
    x = data.inputs()
    assert np.array_equal(back.evaluate(**x), m.evaluate(**x))
    assert back.describe() == m.describe()


def test_holdout_by_segments_sees_overfitting():
    """A law with more freedom than the truth fits in sample at least as well, but held out
    (whole segments) it must not win by more than noise; the true law's held-out error is near
    the noise floor."""
    rng = np.random.default_rng(12)
    truth = random_truth(rng)
    data = FitData.from_recording(twin(truth, 6, fs=500))
    table = identify.compare(data, {"coulomb+viscous": {"law": "coulomb_viscous", "harmonics": SPECS},
                                    "silo4": {"law": "silo4", "harmonics": SPECS}}, folds=4)
    t = table.set_index("model")
    noise = 0.01 * truth.params("positive")["tau_c"]
    assert t.loc["silo4", "rmse_holdout"] < 1.1 * noise
    assert t.loc["coulomb+viscous", "rmse_holdout"] > 1.5 * t.loc["silo4", "rmse_holdout"]


# ---------------------------------------------------------------------- Lola/CROPS
LOLA_A = {"t_f0": 0.174, "mu": 3.10e-3, "b": 4.41e-5, "t_fs": 0.079, "v_s": 99.98}  # Table IV, module A
RATIO = 100.0


def lola_points(truth, rng, noise=0.003):
    speeds = np.linspace(20, 400, 10)          # motor rad/s
    loads = np.linspace(5, 60, 8)              # output Nm
    V, L = np.meshgrid(speeds, loads)
    v, load = V.ravel(), L.ravel()
    tau = truth.friction(None, v, load=load)
    return v, load, tau + rng.normal(0, noise, len(v))


def test_lola_law11_recovered_and_law8_fits_worse():
    rng = np.random.default_rng(1)
    truth = FrictionModel("lola11", LOLA_A)
    v, load, tau = lola_points(truth, rng)
    pts = FitData.from_points(v, tau, load=load)
    m11 = identify.fit(pts, "lola11", weights="uniform", folds=5)
    m8 = identify.fit(pts, "lola8", weights="uniform", folds=5)
    p = m11.params("positive")
    for k, tol in (("t_f0", 0.03), ("mu", 0.05), ("t_fs", 0.15), ("v_s", 0.15)):
        assert rel(p[k], LOLA_A[k]) < tol, (k, p[k])
    assert abs(p["b"] - LOLA_A["b"]) < 3 * p["b_se"] + 1e-6
    assert m11.rmse == pytest.approx(0.003, rel=0.2)
    assert m8.rmse > 1.5 * m11.rmse and m8.rmse_holdout > 1.5 * m11.rmse_holdout


def test_lola_efficiency_fit_respects_eq10():
    rng = np.random.default_rng(2)
    truth = FrictionModel("lola11", LOLA_A)
    v, load, _ = lola_points(truth, rng)
    eta = identify.efficiency_model(truth, v, load, RATIO) + rng.normal(0, 0.002, len(v))
    pts = FitData.from_points(v, eta, load=load)
    m11 = identify.fit_efficiency(pts, "lola11", ratio=RATIO)
    m8 = identify.fit_efficiency(pts, "lola8", ratio=RATIO)
    assert m11.rmse == pytest.approx(0.002, rel=0.25)
    assert m8.rmse > 1.5 * m11.rmse
    p = m11.params("positive")
    assert rel(p["t_f0"], LOLA_A["t_f0"]) < 0.05 and rel(p["t_fs"], LOLA_A["t_fs"]) < 0.25
    for k in ("t_f0", "mu", "b"):
        assert m8.params("positive")[k] >= 0


def test_catalog_fit_respects_eq10(data_dir):
    import gearspec.datasets as ds

    table = ds.catalog_efficiency()
    m, out = identify.fit_catalog(table, ratio=100.0)
    p = m.params("positive")
    for k in ("t_f0", "mu", "b"):
        assert p[k] >= 0, k
    assert out["used"].sum() == 36          # 6 speeds x 6 loads (0 rpm and 0 Nm left out)
    # the product table eta_R(n) K(T) is smooth: law (8) follows it to a few % of efficiency
    assert m.rmse < 0.05
    assert np.all(np.isfinite(out.loc[out["used"], "model"]))


# ---------------------------------------------------------------------- no extrapolation (speed_range)
F_COG = 72 / (2 * math.pi)       # a 72-per-turn cogging line, cycles/rad
ALIAS_SPEEDS = [6, 10, 14, 18, 22, 26, 40, 48, 56]   # rad/s; at 1 kHz the line is measurable below ~35


def aliased_line_recording(seed=0, amp0=5e-3, decay=0.03, fs=1000.0, dur=0.6):
    """Plateaus in both directions (one run each) of Coulomb + viscous friction and a 72-per-turn
    line of amplitude ``amp0 exp(-decay |v|)`` where the line lies below 0.8 x the position Nyquist
    frequency of the plateau (``0.5 fs / |v|``); above it the logger's anti-alias filter has removed
    the line (amplitude 0): a law fitted there would see a line that vanishes with speed.  White
    noise 1 mNm."""
    from gearspec.recording import Recording
    rng = np.random.default_rng(seed)
    cols = {k: [] for k in ("t", "theta", "torque", "run")}
    for k, (v, d) in enumerate((v, d) for v in ALIAS_SPEEDS for d in (1, -1)):
        t = np.arange(int(dur * fs)) / fs
        th = rng.uniform(0, 6) + d * v * t
        amp = amp0 * math.exp(-decay * v) if F_COG < 0.8 * 0.5 * fs / v else 0.0
        tau = d * (0.05 + 2e-4 * v + amp * np.sin(2 * np.pi * F_COG * th + 0.4)) + rng.normal(0, 1e-3, len(t))
        for name, x in (("t", t + 10 * k), ("theta", th), ("torque", tau), ("run", np.full(len(t), k))):
            cols[name].append(x)
    return Recording.from_arrays(**{n: np.concatenate(x) for n, x in cols.items()}, source="synthetic")


def test_amplitude_law_fitted_only_where_the_line_is_measurable_and_held_outside():
    data = FitData.from_recording(aliased_line_recording())
    m = identify.fit(data, "coulomb_viscous", harmonics=[{"frequency": F_COG, "label": "cogging"}], holdout=None)
    for d in ("positive", "negative"):
        h = m.harmonics(d)[0]
        # the measurable plateaus only: 40..56 rad/s put the line above their position Nyquist
        assert h["speed_range"] == pytest.approx([6.0, 26.0], rel=1e-9)
        # the law of the measurable speeds (amplitude se ~1.5 %, decay se ~0.002 s/rad here);
        # with the aliased plateaus in, the decay comes out ~0.06 and the range 6..56
        assert h["amplitude"] == pytest.approx(5e-3, rel=0.06)
        assert h["decay"] == pytest.approx(0.03, abs=0.006)
        # outside the range the amplitude is the edge value: at standstill that at 6 rad/s, not
        # the law's extrapolation to v = 0 (exp(6 * 0.03) = 1.2 x more)
        s = 1 if d == "positive" else -1
        th = np.array([(0.25 - h["phase"] / (2 * np.pi)) / F_COG])    # where the line is at its crest
        line = lambda v: s * (m.evaluate(th, [s * v]) - m.evaluate(th + 0.5 / F_COG, [s * v]))[0] / 2  # noqa: E731
        assert line(1e-9) == pytest.approx(line(6.0), rel=1e-12)
        assert line(56.0) == pytest.approx(line(26.0), rel=1e-12)
        assert line(6.0) == pytest.approx(h["amplitude"] * math.exp(-h["decay"] * 6.0), rel=1e-9)


@pytest.mark.parametrize("scale", [0.0, 1e-310])
def test_zero_and_denormal_torque_fit_without_crashing(scale):
    # fuzz findings: all-zero torque divided by the mean friction (e_percent), and a denormal
    # amplitude squared to 0 in the phase standard error; both are numbers (or NaN), not tracebacks
    rec = twin(random_truth(np.random.default_rng(5)), 5, speeds=[0.5, 2, 8, 30])
    rec.data["torque"] = rec.data["torque"] * scale
    data = FitData.from_recording(rec)
    m = identify.fit(data, "silo4", harmonics=SPECS, holdout=None, check=False)
    assert m.rmse == pytest.approx(0.0, abs=1e-300)
    errs = identify.segment_errors(m, data)
    assert len(errs) == data.n_segments
    if scale == 0.0:
        assert errs["e_percent"].isna().all()       # percent of a zero mean friction: undefined
    for h in m.harmonics("positive"):
        assert not (h["phase_se"] < 0)               # finite or NaN


def test_linear_algebra_failure_is_a_one_sentence_convergence_error(monkeypatch):
    # fuzz finding: a 50-stage gear (hundreds of lines) made an SVD fail to converge outside the
    # guarded solve: any LinAlgError of a direction's fit is a ConvergenceError (exit 2 in the CLI)
    def boom(*a, **k):
        raise np.linalg.LinAlgError("SVD did not converge")

    monkeypatch.setattr(identify.joint, "_make_problem", boom)
    data = FitData.from_recording(twin(random_truth(np.random.default_rng(6)), 6, speeds=[0.5, 2, 8, 30]))
    with pytest.raises(identify.ConvergenceError, match="did not converge in the positive direction.*fewer lines"):
        identify.fit(data, "silo4", harmonics=SPECS, holdout=None)
