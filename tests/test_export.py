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
from gearspec.export.table import locked_parts, position_locked
from gearspec.model import LAWS, FrictionModel
from gearspec.terms import TERMS, evaluate_term
from term_examples import example_term, law_parameters

CC = shutil.which("cc")
needs_cc = pytest.mark.skipif(CC is None, reason="no C compiler (cc) on this machine to build the exported C")

#: term kinds whose value depends on the history of the motion: a controller-side function without
#: state cannot compute them, so every format but json must refuse them (the known answer)
STATEFUL = {"hysteresis", "backlash", "drift"}



def _term(kind, **kw):
    t = example_term(kind)
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
        vals = law_parameters(spec, rng, degraded)
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


def test_a_parameter_beyond_float_range_is_refused(tmp_path):
    model = _law_model("stribeck").with_terms(_term("offset", offset=3e38), _term("offset", offset=-4e38))
    with pytest.raises(InputError, match="-4e\\+38, does not fit a float"):
        model.export("c", tmp_path)


@needs_cc
def test_c_of_a_fitted_silo4_model_file(tmp_path):
    """The 0.4.1 SILO4 joint fit file (lines with speed ranges, negative Stribeck part not identified)."""
    golden = json.loads((__import__("pathlib").Path(__file__).parent / "data" / "models_0.4.1.json").read_text())
    d = golden["models"]["silo4 joint fit, harmonics with speed_range"]["model"]
    model, _ = read_model(d)
    assert max(_compare(model, tmp_path)) <= 1.0
    h, c = (tmp_path / "c" / "gearspec_model.h").read_text(), (tmp_path / "c" / "gearspec_model.c").read_text()
    import re

    # C99 with <math.h> only, no allocation, no state kept between calls
    assert re.findall(r"#include\s*(\S+)", h + c) == ["<math.h>", '"gearspec_model.h"']
    assert not re.search(r"malloc|calloc|free\(|^static (?!double|float)|^(?:static )?(?:double|float) \w+ *[=;]",
                         c, re.M)
    # the header names the model, law, version, source; every parameter with its unit and error
    assert f"gearspec {__import__('gearspec').__version__}" in h and '"silo4" (law silo4)' in h
    for dname, p in model.directions.items():
        for k, u in zip(LAWS["silo4"].params, LAWS["silo4"].units):
            if p.values[k] is not None:
                assert f"{k} = {p.values[k]:.6g} {u}, se {p.se[k]:.6g}" in h
    flat = re.sub(r"\n \*\s+", " ", h)         # the comment's lines joined
    assert flat.count("fitted on |v| 20.9442..314.158 rad/s, held at the edges outside") == 3     # positive lines
    assert flat.count("held at the edges outside") == 6


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


# ------------------------------------------------------------------ YAML
def test_yaml_reads_back_the_same_numbers(tmp_path):
    terms = [_term(k) for k in sorted(TERMS) if k not in STATEFUL] + [_term("periodic", direction=1)]
    model = _law_model("silo4", seed=7).with_terms(*terms)
    model.directions["positive"].set("tau_s", 1e-05)      # a number PyYAML reads as a string if written 1e-05
    (path,) = model.export("yaml", tmp_path, joint="arm_joint3")
    text = path.read_text()
    assert "# Nm, se 0.001" in text and "# rad/s" in text           # units and errors in comments
    fr = yaml.safe_load(text)["joints"]["arm_joint3"]["friction"]
    assert fr["law"] == "silo4" and fr["unit"] == "rad"
    for d, p in model.directions.items():
        for k in LAWS["silo4"].params:
            assert fr[d][k] == p.values[k] and isinstance(fr[d][k], float)
        assert len(fr[d]["harmonics"]) == len(p.harmonics)
        for got, h in zip(fr[d]["harmonics"], p.harmonics):
            for k in ("frequency", "amplitude", "decay", "phase", "load_coefficient", "speed_range"):
                assert got.get(k) == getattr(h, k), (d, k)
            assert got["law"] == h.amplitude_law
    assert len(fr["terms"]) == len(model.terms)
    for got, t in zip(fr["terms"], model.terms):
        assert got == {k: val for k, val in t.items()}, t["kind"]
    with pytest.raises(InputError, match="joint name"):
        model.export("yaml", tmp_path, joint="3 arm")


# ------------------------------------------------------------------ tables
def _locked_model():
    """Lines of 1 and 3 cycles per revolution and one of 0.0714 (not periodic), a periodic term of 7
    cycles 4e-6 off a whole number (a fitted frequency), and cogging of 5 cycles."""
    m = _law_model("stribeck", seed=11)
    for d, p in m.directions.items():
        p.harmonics = p.harmonics[:3]           # 1, 0.0714 and 3 cycles per revolution
    return m.with_terms(_term("periodic", frequency=7.000004 / (2 * math.pi), speed_range=None, law="exp"),
                        _term("cogging", frequency=5 / (2 * math.pi)))


def test_position_locked_part_is_the_model_minus_its_position_free_part():
    m = _locked_model()
    free = m.copy()
    for p in free.directions.values():
        p.harmonics = []
    free.terms = [t for t in free.terms if "theta" not in TERMS[t["kind"]].needs]
    theta = np.linspace(-20, 20, 501)
    for d in (1, -1):
        for speed in (0.7, 5.0, 300.0):
            v = np.full(theta.shape, d * speed)
            want = m.evaluate(theta, v, load=2.0, acc=0.0) - free.evaluate(theta, v, load=2.0, acc=0.0)
            got = position_locked(m, theta, d, speed, load=2.0)
            # the same terms summed in another order: rounding of the ~0.5 Nm total only
            assert np.max(np.abs(got - want)) <= 1e-14


def _read_table(path):
    lines = path.read_text().splitlines()
    head = [x for x in lines if x.startswith("#")]
    rows = np.array([[float(y) for y in x.split(",")] for x in lines[len(head) + 1:]])
    return head, lines[len(head)], rows


def test_one_revolution_table_reproduces_the_position_locked_part(tmp_path):
    m = _locked_model()
    written = m.export("table", tmp_path, entries=720, speed=2.0, load=1.0)
    head, cols, rows = _read_table(tmp_path / "cogging_table.csv")
    assert cols == "index,theta_rad,positive_Nm,negative_Nm" and rows.shape == (720, 4)
    stated = float(head[1].split("exact model ")[1].split(" Nm")[0])
    assert any(head[1][2:] == n for n in written.notes)            # the error printed is the one in the file
    # the line of 0.0714 cycles per revolution is left out, named, in both directions; nothing else is
    left = [x for x in head if "left out" in x]
    assert len(left) == 2 and all("line line const" in x and "0.0714" in x for x in left)
    rng = np.random.default_rng(4)
    theta = rng.uniform(0, 2 * math.pi, 20000)
    for j, d in ((2, 1), (3, -1)):
        kept = [p for p in locked_parts(m, d) if "const" not in p[0]]
        exact = position_locked(m, theta, d, 2.0, load=1.0, parts=kept)
        interp = np.interp(theta, np.append(rows[:, 1], 2 * math.pi), np.append(rows[:, j], rows[0, j]))
        # the stated error is measured at 16 points per interval (the midpoint, where linear
        # interpolation of a sinusoid errs most, among them): random points stay within 1 % of it
        assert np.max(np.abs(interp - exact)) <= 1.01 * stated
    # and it is no more than linear interpolation of these lines must give: A (2 pi c / N)^2 / 8 per
    # line of c cycles (amplitude laws <= 1, load term 1e-4 x 1 Nm^2) plus the 7-cycle term's phase
    # drift, 2 pi 4e-6 of its amplitude at the end of the revolution (it is tabulated at 7 cycles)
    amp = max(h.amplitude for p in m.directions.values() for h in p.harmonics) * (1 + 1e-4)
    bound = sum(a * (2 * math.pi * c / 720) ** 2 / 8 for a, c in ((amp, 1), (amp, 3), (0.02, 7), (0.004, 5)))
    assert 0 < stated <= bound + 0.02 * 2 * math.pi * 4e-6


def test_friction_grid_holds_the_model_at_its_rows_and_columns(tmp_path):
    m = _locked_model()
    w = m.export("table", tmp_path, positions=(0.0, 6.0, 7), speeds=(-3.0, 3.0, 5), load=1.0)
    head, cols, rows = _read_table(tmp_path / "friction_grid.csv")
    speeds = [float(x) for x in cols.split(",")[1:]]
    assert speeds == [-3.0, -1.5, 0.0, 1.5, 3.0] and list(rows[:, 0]) == list(np.linspace(0, 6, 7))
    for i, th in enumerate(rows[:, 0]):
        assert np.array_equal(rows[i, 1:], m.friction(np.full(5, th), np.array(speeds), load=1.0))
    assert not any("velocities" in n for n in w.notes)     # given, not defaulted


def test_default_table_ranges_come_from_the_model(tmp_path):
    m = _law_model("silo4", seed=2)
    w = m.export("table", tmp_path)
    vmax = max(h.speed_range[1] for p in m.directions.values() for h in p.harmonics if h.speed_range)
    _, cols, rows = _read_table(tmp_path / "friction_grid.csv")
    speeds = [float(x) for x in cols.split(",")[1:]]
    assert speeds[0] == -vmax and speeds[-1] == vmax and len(speeds) == 41 and rows.shape == (360, 42)
    assert rows[:, 0].max() < 2 * math.pi and any("fastest speed a line was fitted on" in n for n in w.notes)
    assert _read_table(tmp_path / "cogging_table.csv")[2].shape == (3600, 4)


# ------------------------------------------------------------------ JSON, model files and refusals
GOLDEN = json.loads((__import__("pathlib").Path(__file__).parent / "data" / "models_0.4.1.json").read_text())


def _file(tmp_path, d, name="model.json"):
    path = tmp_path / name
    path.write_text(json.dumps(d))
    return path


def test_json_export_is_the_model_at_this_version_and_reads_back(tmp_path):
    d = GOLDEN["models"]["every term kind"]["model"]
    (path,) = export(_file(tmp_path, d), "json", tmp_path / "out")
    back = json.loads(path.read_text())
    assert back["meta"]["gearspec_version"] == __import__("gearspec").__version__
    model, _ = read_model(path)
    x = _points(model, n=300)
    kw = dict(load=x["load"], temperature=x["temperature"], acc=x["acc"], t=x["acc"] * 0 + 11.0)
    assert np.array_equal(model.evaluate(x["theta"], x["v"], **kw),
                          FrictionModel.from_dict(d).evaluate(x["theta"], x["v"], **kw))
    # a gearspec diagnose --json file is read through its final model
    wrapped, _ = read_model({"baseline": {}, "final": {"friction_model": d}})
    assert wrapped.to_dict() == FrictionModel.from_dict(d).to_dict()


def _main(argv, capsys):
    from gearspec.cli import main

    code = main(argv)
    cap = capsys.readouterr()
    return code, cap.out, cap.err


def _bad_models():
    good = GOLDEN["models"]["stribeck"]["model"]
    old = copy.deepcopy(good)
    del old["rmse_holdout_reason"]
    yield "older", old, "older than 0.4.0"
    yield "old stamp", {**good, "meta": {"gearspec_version": "0.3.9"}}, "older than 0.4.0"
    yield "newer", {**good, "meta": {"gearspec_version": "9.1.0"}}, "newer than this gearspec"
    top = {**good, "friction_offset": 0.1}
    yield "top key", top, "unknown key 'friction_offset' at the top level"
    dkey = copy.deepcopy(good)
    dkey["directions"]["negative"]["tau_c_scale"] = 2.0
    yield "direction key", dkey, "unknown key 'tau_c_scale' in the negative direction"
    hkey = copy.deepcopy(GOLDEN["models"]["silo4 joint fit, harmonics with speed_range"]["model"])
    hkey["directions"]["positive"]["harmonics"][0]["direction"] = -1
    yield "line key", hkey, "line output shaft: unknown key 'direction'"
    tkey = copy.deepcopy(GOLDEN["models"]["every term kind"]["model"])
    tkey["terms"] = [{"kind": "offset", "offset": 0.1, "ramp": 2.0}]
    yield "term key", tkey, "term 1 \\(offset\\): unknown key 'ramp'"
    hyst = copy.deepcopy(GOLDEN["models"]["every term kind"]["model"])
    yield "stateful", hyst, "term 8 \\(drift\\): cannot be exported: it needs the time"
    missing = copy.deepcopy(good)
    missing["directions"]["negative"]["tau_c"] = None
    yield "not identified", missing, "negative direction has no value for tau_c"
    nan = copy.deepcopy(good)
    nan["directions"]["positive"]["viscous"] = "fast"
    yield "not a number", nan, "positive viscous is 'fast', not a finite number"
    # issue 14, "What must be shown": every refusal names the file, also those the model or the C
    # writer raise (they used to say only "unknown friction term kind 'magic'"), and a malformed list is
    # one sentence, not a traceback (it was exit 1)
    kind = copy.deepcopy(good)
    kind["terms"] = [{"kind": "magic", "x": 1.0}]
    yield "unknown term kind", kind, "unknown friction term kind 'magic'"
    law = {**copy.deepcopy(good), "law": "dahl"}
    yield "unknown law", law, "unknown friction law 'dahl'"
    amp = copy.deepcopy(GOLDEN["models"]["silo4 joint fit, harmonics with speed_range"]["model"])
    amp["directions"]["positive"]["harmonics"][0]["law"] = "cubic"
    yield "amplitude law", amp, "unknown amplitude law 'cubic'"
    term = copy.deepcopy(good)
    term["terms"] = [{"kind": "cogging", "frequency": 1.0}]
    yield "term without a parameter", term, "term 1 \\(cogging\\) has no 'amplitude'"
    yield "terms not a list", {**copy.deepcopy(good), "terms": "offset"}, "'terms' must be a list of objects"
    lines = copy.deepcopy(good)
    lines["directions"]["negative"]["harmonics"] = {"frequency": 1.0}
    yield "lines not a list", lines, "negative direction's 'harmonics' must be a list of objects"
    yield "directions not objects", {**copy.deepcopy(good), "directions": {"positive": 0.1}}, \
        "'directions' must be an object of directions"


@pytest.mark.parametrize("case,d,message", list(_bad_models()), ids=[c for c, _, _ in _bad_models()])
def test_cli_refuses_a_bad_model_file_with_one_sentence(case, d, message, tmp_path, capsys):
    import re

    path = _file(tmp_path, d)
    code, out, err = _main(["export", str(path), "--format", "c", "--out", str(tmp_path / "c")], capsys)
    assert code == 2 and out == ""
    assert err.startswith("gearspec: error: model.json") and err.count("\n") == 1 and re.search(message, err), err
    assert not (tmp_path / "c").exists()          # never C that compiles but computes something else


def test_cli_refuses_a_file_that_is_not_json_or_not_a_model(tmp_path, capsys):
    bad = tmp_path / "model.json"
    bad.write_text('{"law": "stribeck", ')
    code, _, err = _main(["export", str(bad), "--format", "yaml", "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and "model.json: not a friction model JSON file" in err and err.count("\n") == 1
    code, _, err = _main(["export", str(_file(tmp_path, {"segments": []})), "--format", "yaml", "--out",
                          str(tmp_path / "o")], capsys)
    assert code == 2 and "not a friction model" in err
    code, _, err = _main(["export", str(_file(tmp_path, GOLDEN["models"]["stribeck"]["model"])), "--format", "c",
                          "--out", str(tmp_path / "o"), "--entries", "100"], capsys)
    assert code == 2 and "--entries applies to --format table, not c" in err


def test_cli_writes_and_prints_the_files_and_the_table_error(tmp_path, capsys):
    fit_json = {**GOLDEN["models"]["silo4 joint fit, harmonics with speed_range"]["model"], "inertia": 3.1e-6}
    path = _file(tmp_path, fit_json)
    for fmt, names in (("c", ["gearspec_model.h", "gearspec_model.c"]), ("yaml", ["friction_params.yaml"]),
                       ("json", ["friction_model.json"]), ("table", ["friction_grid.csv", "cogging_table.csv"])):
        code, out, err = _main(["export", str(path), "--format", fmt, "--out", str(tmp_path / fmt)], capsys)
        assert code == 0, err
        assert [ln.split("/")[-1] for ln in out.splitlines() if ln.startswith("wrote ")] == names
    assert "largest linear-interpolation error against the exact model" in out
    assert "'inertia' = 3.1e-06 (kg m^2), found beside the model by the fit, is not part of the friction model" in out
    assert "from model.json" in (tmp_path / "c" / "gearspec_model.h").read_text()
