"""gearspec export: the generated C computes what FrictionModel.evaluate computes (every law, every
term kind the registry has), YAML reads back to the same numbers, the one-revolution table reproduces
the position-locked part within the error it states, and bad input is refused with one sentence.

The C is compiled with the system compiler (cc -std=c99 -Wall -Wextra -Werror -pedantic -O2) into a
shared library and called through ctypes.
"""
import copy
import ctypes
import json
import math
import shutil
import subprocess

import numpy as np
import pytest
import yaml

from gearspec.errors import InputError
from gearspec.export import export, read_model
from gearspec.export.c import C_LAWS, C_TERMS
from gearspec.export.table import position_locked
from gearspec.model import LAWS, FrictionModel
from gearspec.terms import TERMS, evaluate_term

CC = shutil.which("cc")
needs_cc = pytest.mark.skipif(CC is None, reason="no C compiler (cc) on this machine to build the exported C")

#: term kinds whose value depends on the history of the motion: a controller-side function without
#: state cannot compute them, so every format but json must refuse them (the known answer)
STATEFUL = {"hysteresis", "backlash", "drift"}

#: an example of every term kind (parameters of the size a fit gives); a kind missing here gets 0.5 for
#: each parameter
EXAMPLES = {
    "periodic": {"frequency": 0.37, "amplitude": 0.02, "decay": 0.01, "phase": 0.4, "law": "rational",
                 "speed_range": [0.5, 40.0]},
    "viscous_power": {"coefficient": 0.001, "exponent": 1.5},
    "stribeck_extra": {"amplitude": 0.05, "v_s": 0.7, "shape": "gauss"},
    "load_coulomb": {"mu": 0.01},
    "load_viscous": {"gamma": 0.0004},
    "temperature": {"coefficient": -0.002, "reference": 30.0},
    "drift": {"coefficient": 1e-4, "reference": 10.0},
    "inertia": {"inertia": 0.003},
    "offset": {"offset": -0.01},
    "hysteresis": {"scale": 0.02, "length": 0.5},
    "cogging": {"frequency": 7 / (2 * math.pi), "amplitude": 0.004, "phase": 0.3},
    "backlash": {"scale": 0.01, "gap": 0.2},
}


def _term(kind, **kw):
    t = {"kind": kind, **EXAMPLES.get(kind, {p: 0.5 for p in TERMS[kind].params})}
    return {**t, **kw}


def _lines(rng, scale):
    """Lines with every amplitude law, a speed range on three of them, a load coefficient on one."""
    out = []
    for i, law in enumerate(("exp", "const", "rational", "power")):
        h = {"frequency": [1 / (2 * math.pi), 0.0113682, 3 / (2 * math.pi), 2.3][i],
             "amplitude": scale * rng.uniform(0.02, 0.1), "decay": rng.uniform(0.005, 0.2),
             "phase": rng.uniform(-3, 3), "law": law, "label": f"line {law}", "amplitude_se": 1e-4}
        if i < 3:
            h["speed_range"] = [rng.uniform(0.3, 2.0), rng.uniform(20.0, 60.0)]
        if law == "rational":
            h["load_coefficient"] = 1e-4
        out.append(h)
    return out


def _law_model(law, seed=0, degraded=False):
    """A model of ``law`` with different parameters per direction and lines of every amplitude law;
    ``degraded``: its optional parameters not identified (None)."""
    rng = np.random.default_rng(seed)
    spec = LAWS[law]
    dirs = {}
    for d in ("positive", "negative"):
        vals = {}
        for k, u in zip(spec.params, spec.units):
            vals[k] = rng.uniform(0.5, 3.0) if k == "v_s" else rng.uniform(0.05, 0.3) if u == "Nm" else \
                rng.uniform(1e-4, 2e-3) if k in ("viscous", "b") else rng.uniform(0.005, 0.02)
            if degraded and k in spec.optional:
                vals[k] = None
        dirs[d] = {**vals, "harmonics": _lines(rng, 1.0), **{k + "_se": 1e-3 for k in vals}}
    return FrictionModel(law, dirs["positive"], dirs["negative"], name=f"test {law}")


def _points(model, n=3000, seed=1):
    """Random inputs: theta over +-100 rad, |v| log-uniform 1e-3..1e3 of both signs, and every
    speed-range edge approached from both sides in both directions; v = 0; load, temperature, acc."""
    rng = np.random.default_rng(seed)
    v = rng.choice([-1.0, 1.0], n) * 10 ** rng.uniform(-3, 3, n)
    edges = [x for p in model.directions.values() for h in p.harmonics if h.speed_range for x in h.speed_range]
    edges += [x for t in model.terms if t.get("speed_range") for x in t["speed_range"]]
    near = np.array([s * e * f for e in edges for s in (-1, 1) for f in (1 - 1e-9, 1.0, 1 + 1e-9, 0.5, 2.0)])
    v = np.concatenate([v, near, [0.0, 1e-12, -1e-12]])
    m = len(v)
    return dict(theta=rng.uniform(-100, 100, m), v=v, load=rng.uniform(-30, 30, m),
                temperature=rng.uniform(-10, 90, m), acc=rng.uniform(-100, 100, m))


def _scale(model, x):
    """A torque scale of the model on these inputs: the sum over its parts (base law of each
    direction, each line, each term) of the largest magnitude the part reaches."""
    law = model.law_spec
    s = 0.0
    for p in model.directions.values():
        if law.params:
            s += float(np.max(np.abs(law.magnitude(np.abs(x["v"]), x["load"], *[p.values[k] for k in law.params]))))
        s += sum(abs(h.amplitude) * (1 + abs(h.load_coefficient or 0) * 900) for h in p.harmonics)
    for t in model.terms:
        s += float(np.max(np.abs(evaluate_term(t, **x)[0])))
    return s


def _build(model, tmp_path, smooth=None, define=None):
    """Export ``model`` as C, compile it into a shared library, return (friction, friction_f, torque,
    torque_f) as Python functions over arrays."""
    out = tmp_path / "c"
    model.export("c", out, **({} if smooth is None else {"smooth_velocity": smooth}))
    lib = tmp_path / "libgs.so"
    cmd = [CC, "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O2", "-fPIC", "-shared", "-o", str(lib),
           str(out / "gearspec_model.c"), "-lm"]
    if define is not None:
        cmd.insert(1, f"-DGEARSPEC_SMOOTH_VELOCITY={define!r}")
    res = subprocess.run(cmd, capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    so = ctypes.CDLL(str(lib))
    fns = []
    for name, ct, nargs in (("gearspec_friction", ctypes.c_double, 4), ("gearspec_friction_f", ctypes.c_float, 4),
                            ("gearspec_torque", ctypes.c_double, 5), ("gearspec_torque_f", ctypes.c_float, 5)):
        f = getattr(so, name)
        f.restype, f.argtypes = ct, [ct] * nargs
        fns.append(np.vectorize(f, otypes=[float]))
    return fns


def _compare(model, tmp_path, x=None):
    """Largest error of the C functions against Python, relative to the tolerance (<= 1 passes)."""
    x = _points(model) if x is None else x
    fr, fr_f, tq, tq_f = _build(model, tmp_path)
    S = _scale(model, x)
    want_fr = model.friction(x["theta"], x["v"], load=x["load"], temperature=x["temperature"])
    want_tq = model.evaluate(x["theta"], x["v"], load=x["load"], temperature=x["temperature"], acc=x["acc"])
    got_fr = fr(x["theta"], x["v"], x["load"], x["temperature"])
    got_tq = tq(x["theta"], x["v"], x["acc"], x["load"], x["temperature"])
    # double: the same operations in the same order; only libm's exp/sin/pow and numpy's differ, by
    # <= 1 ulp each, so the error is a few eps of the parts summed: 1e-12 relative, plus an absolute
    # floor of 1e-14 of the model's torque scale S (~45 eps) where parts cancel (near a zero crossing)
    tol = 1e-12 * np.abs(want_fr) + 1e-14 * S
    worst = [np.max(np.abs(got_fr - want_fr) / tol), np.max(np.abs(got_tq - want_tq) / (1e-12 * np.abs(want_tq)
                                                                                           + 1e-14 * S))]
    # float: inputs rounded to float (what the function receives), computed in float: each operation
    # within ~1 float ulp (6e-8), a dozen of them: 1e-5 relative, floor 1e-6 of S where parts cancel
    xf = {k: np.asarray(v, dtype=np.float32).astype(float) for k, v in x.items()}
    want_f = model.friction(xf["theta"], xf["v"], load=xf["load"], temperature=xf["temperature"])
    want_tf = model.evaluate(xf["theta"], xf["v"], load=xf["load"], temperature=xf["temperature"], acc=xf["acc"])
    got_f = fr_f(xf["theta"], xf["v"], xf["load"], xf["temperature"])
    got_tf = tq_f(xf["theta"], xf["v"], xf["acc"], xf["load"], xf["temperature"])
    worst += [np.max(np.abs(got_f - want_f) / (1e-5 * np.abs(want_f) + 1e-6 * S)),
              np.max(np.abs(got_tf - want_tf) / (1e-5 * np.abs(want_tf) + 1e-6 * S))]
    return worst


# ------------------------------------------------------------------ C against Python
LAW_CASES = [(law, False) for law in LAWS] + [(law, True) for law in LAWS if LAWS[law].optional]


@needs_cc
@pytest.mark.parametrize("law,degraded", LAW_CASES, ids=[f"{a}{'-degraded' if b else ''}" for a, b in LAW_CASES])
def test_c_computes_every_law_as_python_does(law, degraded, tmp_path):
    assert law in C_LAWS, f"law {law} has no C form"
    worst = _compare(_law_model(law, seed=list(LAWS).index(law), degraded=degraded), tmp_path)
    assert max(worst) <= 1.0, worst


@needs_cc
@pytest.mark.parametrize("kind", sorted(k for k in TERMS if k not in STATEFUL))
def test_c_computes_every_term_kind_as_python_does(kind, tmp_path):
    if kind not in C_TERMS:          # a kind registered after this exporter: refused until given a C form
        with pytest.raises(InputError, match=kind):
            _law_model("coulomb_viscous").with_terms(_term(kind)).export("c", tmp_path)
        return
    # the term for both directions and once more for one direction only, on a direction-dependent base
    model = _law_model("coulomb_viscous", seed=3).with_terms(_term(kind), _term(kind, direction=-1))
    worst = _compare(model, tmp_path)
    assert max(worst) <= 1.0, worst


@pytest.mark.parametrize("fmt", ["c", "yaml", "table"])
@pytest.mark.parametrize("kind", sorted(STATEFUL))
def test_terms_that_need_state_are_refused(kind, fmt, tmp_path):
    model = _law_model("stribeck").with_terms(_term(kind))
    with pytest.raises(InputError, match=f"term 1 \\({kind}\\): cannot be exported"):
        model.export(fmt, tmp_path)
    assert not list(tmp_path.iterdir())          # nothing half written
    assert model.export("json", tmp_path)        # the model's own JSON can hold it


@needs_cc
def test_c_of_a_fitted_silo4_model_file(tmp_path):
    """The 0.4.1 SILO4 joint fit file (lines with speed ranges, negative Stribeck part not identified)."""
    golden = json.loads((__import__("pathlib").Path(__file__).parent / "data" / "models_0.4.1.json").read_text())
    d = golden["models"]["silo4 joint fit, harmonics with speed_range"]["model"]
    model, _ = read_model(d)
    assert max(_compare(model, tmp_path)) <= 1.0


@needs_cc
def test_smoothing_below_the_stated_velocity(tmp_path):
    model = _law_model("silo4", seed=5)
    V = 0.05
    fr, fr_f, _, _ = _build(model, tmp_path, smooth=V)
    rng = np.random.default_rng(2)
    theta = rng.uniform(-10, 10, 2000)
    v = rng.choice([-1, 1], 2000) * 10 ** rng.uniform(-6, 1, 2000)
    got, want = fr(theta, v, 0.0, 20.0), model.friction(theta, v, load=0.0)
    big = np.abs(v) >= V
    assert big.sum() > 200 and (~big).sum() > 200
    # at and above V: the exact model (double, as in the law tests)
    assert np.all(np.abs(got[big] - want[big]) <= 1e-12 * np.abs(want[big]))
    # below: the documented ramp v / V in place of sign(v) (known answer), hence continuous through 0
    assert np.allclose(got[~big], np.abs(v[~big]) / V * want[~big], rtol=1e-12, atol=0)
    tiny = fr(theta[:50], np.full(50, 1e-9), 0.0, 20.0)
    assert np.all(np.abs(tiny) <= 1e-9 / V * 1.0)           # friction magnitudes here are < 1 Nm
    assert fr(1.0, 0.0, 0.0, 20.0) == 0.0 and fr_f(1.0, 0.0, 0.0, 20.0) == 0.0
    # the default (0) is the exact sign; -D overrides the default
    fr0 = _build(model, tmp_path / "exact")[0]
    assert np.allclose(fr0(theta, v, 0.0, 20.0), want, rtol=1e-12, atol=0)
    frd = _build(model, tmp_path / "defined", define=V)[0]
    assert np.array_equal(frd(theta, v, 0.0, 20.0), got)
