"""The sparse-regression explorer (gearspec.discover): exactness of the reduction, names that are
equations, laws that evaluate as FrictionModels, rediscovery of the papers' laws from their twins,
sanity with highly correlated columns, the command line, and the real data sets."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from gearspec.cli import main
from gearspec.discover import Library, Term, discover, published_models
from gearspec.discover.law import Part, fit_law
from gearspec.discover.library import default_library
from gearspec.discover.moments import moments
from gearspec.fitdata import FitData
from gearspec.model import RPM, FrictionModel
from gearspec.simulate import model_recording

F2, F3 = 1 / (2 * np.pi * 14), 1 / (2 * np.pi)      # SILO4 worm-shaft and motor-shaft lines, cycles/rad


# ---------------------------------------------------------------------- twins of the papers' laws
def silo4_eq3() -> FrictionModel:
    """SILO4 eq. 3 with Table 2's direction-dependent Coulomb and viscous friction and Stribeck
    velocity 28.18 rpm.  Table 2's two static-minus-Coulomb values (1.474 and 1.501 mNm) differ by
    2 %, below what any recording resolves; the twin gives both directions 1.49 mNm, so that its
    structure is unambiguous: Coulomb and viscous direction-dependent, Stribeck symmetric."""
    p = {"tau_c": 7.106e-3, "tau_s": 7.106e-3 + 1.49e-3, "v_s": 28.18 * RPM, "viscous": 0.0134e-3 / RPM}
    n = {"tau_c": 7.909e-3, "tau_s": 7.909e-3 + 1.49e-3, "v_s": 28.18 * RPM, "viscous": 0.0138e-3 / RPM}
    return FrictionModel("stribeck", p, n)


def silo4_eq11() -> FrictionModel:
    """Eq. 3 above plus the meshing ripple of eq. 11 at the worm-shaft and motor-shaft lines with
    Table 2's direction-dependent amplitudes and decay constants (A1, one joint turn, is left out:
    no plateau of a bench run completes a cycle of it)."""
    m = silo4_eq3()
    p, n = dict(m.directions["positive"]), dict(m.directions["negative"])
    p["harmonics"] = [dict(frequency=F2, amplitude=0.576e-3, decay=1.27e-4 / RPM, phase=np.pi / 2),
                      dict(frequency=F3, amplitude=0.133e-3, decay=5.28e-5 / RPM, phase=np.pi)]
    n["harmonics"] = [dict(frequency=F2, amplitude=0.526e-3, decay=1.12e-4 / RPM, phase=np.pi / 2),
                      dict(frequency=F3, amplitude=0.152e-3, decay=7.49e-6 / RPM, phase=np.pi)]
    return FrictionModel("silo4", p, n)


def lola8() -> FrictionModel:
    """Lola law (8): Table III module A, with gamma from Table V (HFUC-25-100; Table III's is 0)."""
    return FrictionModel("lola8", {"t_f0": 0.098, "mu": 3.1e-3, "b": 2.73e-4, "gamma": 9.44e-6})


def lola11() -> FrictionModel:
    """Lola law (11): Table IV module A (T_fS < T_f0: friction rises towards T_f0 above v_S)."""
    return FrictionModel("lola11", {"t_f0": 0.174, "mu": 3.1e-3, "b": 4.41e-5, "t_fs": 0.079, "v_s": 99.98})


def silo_data(model, seed, duration=4.0, noise=0.1e-3) -> FitData:
    """10 log-spaced motor speeds 0.5..600 rad/s per direction, `duration` s each at 1 kHz, white
    torque noise `noise` Nm (SILO4 Table 3: model errors of 0.12..0.21 mNm)."""
    speeds = [s * d for s in np.geomspace(0.5, 600, 10) for d in (1, -1)]
    rec, _ = model_recording(model, speeds, duration=duration, fs=1000, noise=noise, gear="silo4-joint3", seed=seed,
                             one_run_per_plateau=False)
    return FitData.from_recording(rec)


def lola_data(model, seed, noise=0.01) -> FitData:
    """A test-bench grid as in the Lola/CROPS paper: 6 motor speeds 5..600 rad/s x 4 output loads
    0..90 Nm x both directions, 0.5 s per point at 1 kHz, torque noise `noise` Nm."""
    speeds = (5, 15, 40, 100, 250, 600)
    loads = (0, 30, 60, 90)
    sp = [s * d for s in speeds for _ in loads for d in (1, -1)]
    ld = [load for _ in speeds for load in loads for _ in (1, -1)]
    rec, _ = model_recording(model, sp, load=ld, duration=0.5, fs=1000, noise=noise, gear="lola-a", seed=seed,
                             one_run_per_plateau=True)
    return FitData.from_recording(rec)


def structure(result) -> set:
    """The selected law's terms: (family, ripple frequency rounded, direction-dependent)."""
    out = set()
    for p in result.best.parts:
        f = None if p.freq is None else float(f"{result.frequencies[p.freq]:.4g}")
        out.add((p.family, f, p.split))
    return out


TRUTHS = {
    "silo4_eq3": (silo4_eq3, silo_data, "silo4-joint3",
                  {("coulomb", None, True), ("viscous", None, True), ("stribeck_exp", None, False)}),
    "silo4_eq11": (silo4_eq11, silo_data, "silo4-joint3",
                   {("coulomb", None, True), ("viscous", None, True), ("stribeck_exp", None, False),
                    ("ripple_exp", float(f"{F2:.4g}"), True), ("ripple_exp", float(f"{F3:.4g}"), True)}),
    "lola8": (lola8, lola_data, "lola-a",
              {("coulomb", None, False), ("viscous", None, False), ("load_coulomb", None, False),
               ("load_viscous", None, False)}),
    "lola11": (lola11, lola_data, "lola-a",
               {("coulomb", None, False), ("viscous", None, False), ("load_coulomb", None, False),
                ("stribeck_rational", None, False)}),
}


@pytest.mark.slow
@pytest.mark.parametrize("name", list(TRUTHS))
def test_rediscovers_the_true_structure_in_9_of_10_seeds(name):
    # the twin's library also holds the gear's declared ripple lines (none in the Lola truths), every
    # other Stribeck shape, power laws, residual inertia, and a direction-dependent version of all
    make, data_fn, gear, truth = TRUTHS[name]
    model = make()
    picks = []
    for seed in range(10):
        res = discover(data_fn(model, seed), gear=gear, references=(), n_models=0)
        got = structure(res)
        picks.append((seed, got == truth, res.best.equation if got != truth else ""))
    hits = sum(ok for _, ok, _ in picks)
    wrong = "\n".join(f"seed {s}: {eq}" for s, ok, eq in picks if not ok)
    assert hits >= 9, f"{name}: true structure in {hits}/10 seeds; picked instead:\n{wrong}"


def test_rediscovered_parameters_match_the_truth_within_their_errors():
    # SILO4 eq. 3 twin, seed 0: every parameter of the selected law within 4 of its (cluster-robust)
    # standard errors of the truth, and those errors small (the noise is 0.1 mNm on 80 000 samples)
    res = discover(silo_data(silo4_eq3(), 0), gear="silo4-joint3", references=(), n_models=0)
    m = res.best.model
    truth = silo4_eq3()
    for d in ("positive", "negative"):
        p, t = m.params(d), truth.params(d)
        assert abs(p["tau_c"] - t["tau_c"]) < 4 * p["tau_c_se"] and p["tau_c_se"] < 2e-6
        assert abs(p["viscous"] - t["viscous"]) < 4 * p["viscous_se"]
    st = [t for t in m.terms if t["kind"] == "stribeck_extra"][0]
    assert st["shape"] == "exp"
    assert abs(st["v_s"] - 28.18 * RPM) < 4 * st["v_s_se"] and st["v_s_se"] < 0.02
    assert abs(st["amplitude"] - 1.49e-3) < 4 * st["amplitude_se"]


# ---------------------------------------------------------------------- exactness of the reduction
@pytest.fixture(scope="module")
def rich_data():
    """Plateaus with load, temperature, ripple and a speed ripple (non-zero acceleration)."""
    m = silo4_eq11().with_terms({"kind": "load_coulomb", "mu": 2e-4}, {"kind": "temperature", "coefficient": 5e-5,
                                                                      "reference": 30.0})
    speeds = [s * d for s in (2.0, 20.0, 200.0) for d in (1, -1)]
    rec, _ = model_recording(m, speeds, duration=1.0, fs=500, noise=1e-4, load=[1.0, 2.0, 3.0, 1.5, 2.5, 0.5],
                             temperature=lambda t: 30 + 2 * np.sin(t), speed_ripple=0.02, seed=3,
                             gear="silo4-joint3", one_run_per_plateau=True)
    return FitData.from_recording(rec)


def test_reduction_is_exact_for_every_library_column(rich_data):
    M = moments(rich_data, [F2, F3], inertia=True)
    lib = default_library(M)
    assert {"load", "temperature", "acc", "sin0", "cos1"} <= set(M.basis)
    X = lib.evaluate(rich_data, M)            # dense columns at every sample
    Xp = lib.design(M)                        # the same columns on the pseudo rows
    y = rich_data.y
    G, Gp = X.T @ X, Xp.T @ Xp
    scale = np.sqrt(np.outer(np.diag(G), np.diag(G)))
    assert np.max(np.abs(G - Gp) / scale) < 1e-9
    h, hp = X.T @ y, Xp.T @ M.q.reshape(-1)
    assert np.max(np.abs(h - hp) / np.sqrt(np.diag(G) * (y @ y))) < 1e-9
    w = np.random.default_rng(0).normal(size=X.shape[1]) * 1e-4
    r = y - X @ w
    assert np.sum(M.sse(Xp, w)) == pytest.approx(r @ r, rel=1e-8)


def test_column_names_are_the_equations_of_the_columns(rich_data):
    M = moments(rich_data, [F2, F3], inertia=True)
    lib = default_library(M)
    X = lib.evaluate(rich_data, M)
    env = {"v": rich_data.v, "theta": rich_data.theta, "T": rich_data.temperature, "a": rich_data.acc,
           "np": np, "pi": np.pi}

    def as_python(name):
        s = name.replace("|T_l|", "abs(load)").replace("|v|", "abs(v)").replace("sign(v)", "np.sign(v)")
        s = s.replace("exp(", "np.exp(").replace("sin(", "np.sin(").replace("cos(", "np.cos(")
        return s.replace("2pi*", "2*pi*").replace("^", "**")

    env["load"] = rich_data.load
    theta_max = np.max(np.abs(rich_data.theta))
    for j, name in enumerate(lib.names):
        val = np.broadcast_to(eval(as_python(name), env), X[:, j].shape)  # noqa: S307 (our own strings)
        tol = 1e-12
        if "theta" in name:
            # frequencies print with 6 significant digits: a phase error up to 2 pi theta df, with df
            # half a unit of the 6th digit
            f = float(name.split("2pi*")[1].split("*theta")[0])
            tol = 2 * np.pi * theta_max * 0.5 * 10 ** (math.floor(math.log10(f)) - 5)
        assert np.allclose(val, X[:, j], rtol=1e-9, atol=tol * np.max(np.abs(X[:, j]))), name


def test_a_fitted_law_evaluates_identically_as_a_friction_model(rich_data):
    M = moments(rich_data, [F2, F3], inertia=True)
    parts = (Part("coulomb", split=True), Part("viscous"), Part("stribeck_exp", param0=5.0),
             Part("load_coulomb"), Part("temperature"), Part("ripple_exp", 0, True, 1e-3),
             Part("ripple_rational", 1, False, 1e-3), Part("power", None, False, 0.5), Part("inertia"))
    fit = fit_law(M, parts)
    from gearspec.discover.law import to_model

    model = to_model(fit, M.frequencies, M.labels, M.t_ref, M.unit)
    assert model.rmse_on(rich_data) == pytest.approx(fit.rmse, rel=1e-7)
    again = FrictionModel.from_dict(json.loads(json.dumps(model.to_dict())))
    assert again.rmse_on(rich_data) == pytest.approx(fit.rmse, rel=1e-7)


# ---------------------------------------------------------------------- correlated columns
def test_correlated_stribeck_columns_give_sane_weights_where_least_squares_does_not():
    # truth: Coulomb + viscous + exponential Stribeck at v_s = 3.3 rad/s; library: Coulomb, viscous
    # and exponential Stribeck columns at six neighbouring velocities 2.5..4.0 rad/s (pairwise
    # correlation above 0.99 over the plateaus).  Plain least squares spreads the Stribeck term
    # over them with large weights of both signs; the explorer returns one Stribeck term with the
    # true amplitude and velocity.
    truth = FrictionModel("stribeck", {"tau_c": 0.2, "tau_s": 0.26, "v_s": 3.3, "viscous": 1e-3})
    speeds = [s * d for s in np.geomspace(0.3, 100, 12) for d in (1, -1)]
    rec, _ = model_recording(truth, speeds, duration=1.0, fs=500, noise=2e-3, seed=11)
    data = FitData.from_recording(rec)
    M = moments(data)
    grid = np.linspace(2.5, 4.0, 6)
    lib = Library([Term("coulomb"), Term("viscous")] + [Term("stribeck_exp", float(v)) for v in grid])
    X = lib.evaluate(data, M)
    strib = X[:, 2:]
    corr = np.corrcoef((strib - strib.mean(0)).T)
    assert corr[np.triu_indices(6, 1)].min() > 0.99
    w = np.linalg.lstsq(X, data.y, rcond=None)[0]
    amp = 0.06
    assert np.max(np.abs(w[2:])) > 10 * amp and w[2:].min() < 0 < w[2:].max()      # the nonsense weights
    res = discover(data, library=lib, references=(), n_models=20)
    best = res.best
    st = [p for p in best.parts if p.family == "stribeck_exp"]
    assert len(st) == 1
    m = best.model
    term = [t for t in m.terms if t["kind"] == "stribeck_extra"][0]
    assert abs(term["amplitude"] - amp) < max(4 * term["amplitude_se"], 0.02 * amp)
    assert abs(term["v_s"] - 3.3) < max(4 * term["v_s_se"], 0.05 * 3.3)
    # every law the search scored keeps its weights within a few times the friction level
    for c in res.candidates:
        lin = [abs(v["value"]) for v in c.fit.values() if v["kind"] == "linear" and v["name"] == "1"]
        assert max(lin) < 1.0, c.equation


# ---------------------------------------------------------------------- command line
@pytest.fixture
def twin_csv(tmp_path):
    speeds = [s * d for s in np.geomspace(1, 300, 5) for d in (1, -1)]
    rec, _ = model_recording(silo4_eq11(), speeds, duration=2.0, fs=1000, noise=1e-4, seed=2,
                             one_run_per_plateau=False, gear="silo4-joint3")
    return rec.save(tmp_path / "twin.csv")


@pytest.mark.slow
def test_cli_writes_contract_json_and_report(twin_csv, tmp_path, capsys):
    out = tmp_path / "out"
    code = main(["discover", str(twin_csv), "--gear", "silo4-joint3", "--out", str(out), "--json",
                 str(out / "d.json"), "--bootstrap", "10", "--no-spectrum", "--compare", "stribeck,silo4"])
    assert code == 0
    d = json.loads((out / "d.json").read_text())
    assert isinstance(d["selected"], int) and 0 <= d["selected"] < len(d["candidates"])
    for c in d["candidates"]:
        assert isinstance(c["equation"], str) and c["equation"].startswith("tau = ")
        assert isinstance(c["terms"], list) and all(isinstance(t, str) for t in c["terms"])
        assert isinstance(c["complexity"], int) and c["rmse_holdout"] > 0
    cx = [c["complexity"] for c in d["candidates"]]
    ho = [c["rmse_holdout"] for c in d["candidates"]]
    assert cx == sorted(cx) and all(b < a for a, b in zip(ho, ho[1:]))       # a Pareto front
    assert {r["name"] for r in d["references"]} >= {"SILO4 eq. 3 (per direction)"}
    for name in ("report.md", "pareto.png", "levels.png", "inclusion.png", "candidates.csv", "comparison.csv"):
        assert (out / name).stat().st_size > 0, name
    text = (out / "report.md").read_text()
    assert "## Selected law" in text and "![pareto](pareto.png)" in text and "SILO4 eq. 3" in text
    assert "laws scored on held-out segments" in capsys.readouterr().out


def test_cli_bad_input_exits_2_with_a_clear_message(twin_csv, tmp_path, capsys):
    assert main(["discover", str(twin_csv), "--gear", "silo4-joint3", "--frequencies", "0.1,abc"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("gearspec: error:") and "--frequencies" in err and "'abc'" in err
    assert main(["discover", str(twin_csv), "--gear", "silo4-joint3", "--compare", "dahl"]) == 2
    assert "unknown law" in capsys.readouterr().err
    # two plateaus: too few segments to hold any out
    rec, _ = model_recording(silo4_eq3(), [5.0, -5.0], duration=1.0, fs=500, noise=1e-4, seed=1,
                             one_run_per_plateau=False)
    short = rec.save(tmp_path / "short.csv")
    assert main(["discover", str(short), "--no-spectrum"]) == 2
    assert "held-out errors need at least 3" in capsys.readouterr().err


# ---------------------------------------------------------------------- real data
@pytest.mark.realdata
def test_emps_discovered_law_beats_the_papers_laws_and_idim_ls(data_dir):
    import gearspec.datasets as ds

    rec = ds.load("emps")
    data = FitData.from_recording(rec)
    res = discover(data, gear=rec.gear, references=("coulomb_viscous", "stribeck"),
                   published=published_models(rec.gear), n_models=0)
    refs = {r.name: r for r in res.references}
    best = res.best
    # held-out error below the published IDIM-LS models (fitted by the data set's authors on this very
    # recording, scored here on all of it).  The IDIM-LS structure refitted on the same folds has the
    # same columns as the candidates, inertia included (issue 13: without it, 1.78 N against 1.02 N);
    # the selected law's terms each passed the held-out test, so it cannot be worse than that
    # structure by more than the noise of the comparison (its standard error, paired over segments)
    for name in ("IDIM-LS (published)", "IDIM-LS asymmetric (published)"):
        assert best.rmse_holdout < refs[name].rmse_holdout, (name, best.equation)
    cv = refs["Coulomb + viscous (IDIM-LS structure, per direction)"]
    assert any(t["kind"] == "inertia" and 60 < t["inertia"] < 130 for t in cv.model.terms)
    row = res.comparison().set_index("law").loc[cv.name]
    assert row["delta_mse"] > -2 * row["delta_mse_se"], best.equation
    dirs = {p.family for p in best.parts if p.split}
    assert dirs & {"coulomb", "viscous"}                 # friction differs between the directions
    inertia = [v["value"] for v in best.fit.values() if best.parts[v["part"]].family == "inertia"]
    assert inertia and 60 < inertia[0] < 130             # residual inertia near IDIM-LS's M = 95 kg


@pytest.mark.slow
@pytest.mark.realdata
def test_kinova_discovered_law_beats_coulomb_viscous(data_dir):
    import gearspec.datasets as ds

    from gearspec.spectrum import analyze

    rec = ds.load("kinova_gen3_joint7")
    data = FitData.from_recording(rec)
    spec = analyze(rec, keep_spectra=False, progress=False)        # lines the gear spec does not declare
    res = discover(data, gear=rec.gear, spectrum=spec, references=("coulomb_viscous",), n_models=0)
    ref = res.references[0]
    # the ripple at twice the wave-generator frequency (31.8 cycles/rad, declared) and at 7x the
    # motor shaft (found) carry a third of the friction variance left by Coulomb + viscous
    assert res.best.rmse_holdout < 0.85 * ref.rmse_holdout, res.best.equation
    lines = {round(float(res.frequencies[p.freq]), 1) for p in res.best.parts if p.freq is not None}
    assert 31.8 in lines, res.best.equation
