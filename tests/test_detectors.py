"""The closed loop's detectors (issue 11, item 5): one registered detector per term kind, the
candidates they propose equal to those of the if-chain they replace, and a newcomer's detector
asked by the loop.

Twin: 12 constant-speed plateaus (0.6-14 rad/s, six per direction, shuffled, one run: reversals
within the run), 1.5 s at 250 Hz, friction from SILO4 eq. 3 per direction with a motor-shaft and a
tooth-mesh line (the gear of tests/test_diagnose.py: motor reference, spur 10:1 with 17 teeth),
white noise 1 mNm, the load and the temperature varying, and undeclared effects (cogging 7 per
motor turn, a line growing with load^2, warming, a drift, presliding).  Every detector has
something to propose on it with its gate opened (``gate`` 1.01), so that every branch of the old
``term_candidates`` if-chain is exercised.

Known answer (``KNOWN``): the candidates the old code (commit 60171f3, before the registry)
proposed on this twin -- per candidate its kind, its name, and the proposal on all data: its
description, the parameter count, and the sum and the norm of its columns.  The new code runs the
same arithmetic, so the names must be identical and the numbers equal to rounding (rel 1e-9: the
columns are the same floating-point operations; only a summation order could differ).
"""

from __future__ import annotations

import numpy as np
import pytest

from gearspec.diagnose import loop
from gearspec.diagnose.design import state_from_model
from gearspec.gears import GearTrain
from gearspec.model import FrictionModel
from gearspec.simulate import effects as fx
from gearspec.simulate import model_recording

GEAR = GearTrain.from_dict({"name": "test drive", "reference": "motor", "unit": "rad",
                            "stages": [{"name": "spur", "kind": "spur", "ratio": 10, "teeth": 17}]})
F_MOTOR = 1 / (2 * np.pi)
_rng = np.random.default_rng(11)
_mag = np.geomspace(0.6, 30, 6)
SPEEDS = [x for a, b in zip(_rng.permutation(_mag), _rng.permutation(_mag)) for x in (a, -b)]
LOADS = [0, 5, 10, 15, 20, 8] * 2


def _truth() -> FrictionModel:
    def lines(a, ph):
        return [{"frequency": F_MOTOR, "amplitude": a, "decay": 0.05, "phase": ph, "label": "motor shaft"},
                {"frequency": 17 * F_MOTOR, "amplitude": 0.6 * a, "decay": 0.15, "phase": ph + 1,
                 "label": "spur tooth mesh"}]
    pos = {"tau_c": 0.05, "tau_s": 0.08, "v_s": 1.5, "viscous": 2e-3, "harmonics": lines(5e-3, 0.3)}
    neg = {"tau_c": 0.055, "tau_s": 0.085, "v_s": 1.5, "viscous": 2.2e-3, "harmonics": lines(4e-3, 1.0)}
    return FrictionModel("silo4", pos, neg, name="truth")


def make_twin():
    eff = [fx.cogging(count=7, amplitude=2e-3), fx.load_meshing(target="motor shaft", coefficient=5e-5),
           fx.warming(coefficient=-4e-4, rise=15, time_constant=10.0), fx.drift(coefficient=2e-4),
           fx.hysteresis(scale=5e-3, length=1.0)]
    model = fx.apply_effects(_truth(), eff)
    rec, _ = model_recording(model, SPEEDS, noise=1e-3, gear=GEAR, seed=0, duration=1.2, fs=250.0,
                             one_run_per_plateau=False, load=LOADS,
                             temperature=fx.channel_function(eff, "temperature"))
    return rec


@pytest.fixture(scope="module")
def twin():
    return make_twin()


def first_round(rec, *, symmetric: bool):
    """The loop's first round on the baseline model (per direction, or symmetric) and its
    residual analyses."""
    dd = loop._as_data(rec, None, GEAR)
    model = loop.baseline_model(dd, "silo4", gear=GEAR, symmetric=symmetric)
    st = state_from_model(model, dd, symmetric=symmetric)
    rnd = loop.Round(dd, loop._settle(st, dd), loop.folds_of(dd, 5))
    return rnd, loop.analyse(rnd, per_segment=False)


def fingerprint(rnd, cands) -> list:
    """Per candidate: kind, name, and its proposal on all data (description, parameter count, sum
    and norm of its columns), or None."""
    out = []
    for c in cands:
        p = c.propose(rnd, rnd.all_groups())
        if p is None:
            out.append((c.kind, c.name, None))
            continue
        cols = p.columns(rnd.dd)
        out.append((c.kind, c.name, (p.describe, p.n_params(rnd), float(cols.sum()), float(np.linalg.norm(cols)))))
    return out


#: what the old if-chain (and the loop's spectrum-line builder) proposed on the twin, gate 1.01
KNOWN = {'per_direction': [('periodic',
                    'line at 1.11423 cycles/rad',
                    ('1.11378 cycles/rad; positive: exp (decay -0.0333), negative: const',
                     4,
                     -53.45834760225201,
                     78.54212364574288)),
                   ('speed_law',
                    'nonlinear viscous |v|^p',
                    ('exponent 2', 2, -26.854472806473495, 22543.67018336925)),
                   ('speed_law', 'Stribeck term (exp)', ('v_s 0.2', 2, -0.29872417641605464, 1.2077502257228592)),
                   ('speed_law', 'Stribeck term (gauss)', ('v_s 3.557', 2, -7.3968198706908765, 34.00415377002377)),
                   ('speed_law',
                    'Stribeck term (rational)',
                    ('v_s 2.202', 2, -6.6969702591401585, 30.19693910067952)),
                   ('speed_law',
                    'amplitude law of motor shaft (positive)',
                    ('rational (1)', 0, -82.59565192391804, 49.177005122278445)),
                   ('speed_law',
                    'amplitude law of motor shaft (negative)',
                    ('exp (2)', 0, -93.82572219598515, 45.93482245109304)),
                   ('speed_law',
                    'amplitude law of spur tooth mesh (positive)',
                    ('exp (5)', 0, -11.211453911196234, 34.79335131481665)),
                   ('speed_law',
                    'amplitude law of spur tooth mesh (negative)',
                    ('exp (5)', 0, -10.61952842379997, 33.18038046352607)),
                   ('load', 'load-dependent Coulomb mu|load|', ('', 2, 976.0, 693.626700754808)),
                   ('load', 'load-speed coupling gamma|load||v|', ('', 2, -35873.005091229454, 6582.141043203314)),
                   ('load',
                    'amplitude of motor shaft growing with load^2 (SILO4 eq. 14)',
                    ('', 2, 56622.621217271735, 6687.300506773306)),
                   ('load',
                    'amplitude of spur tooth mesh growing with load^2 (SILO4 eq. 14)',
                    ('', 2, -3908.8800090751784, 4918.308125823735)),
                   ('temperature', 'temperature', ('', 1, -1782.0493837077536, 203.05757669489432)),
                   ('drift', 'drift', ('', 1, -2503.676571428571, 288.8194814798436)),
                   ('inertia', 'inertia J thetadd', ('', 1, 118.66508591547625, 168.82058698103174)),
                   ('hysteresis',
                    'presliding hysteresis',
                    ('length 0.0251', 1, -1.9022345624315837, 1.2694748433420495)),
                   ('hysteresis', 'backlash', ('gap 4.392', 1, 179.0, 45.46427168667722)),
                   ('lag', 'torque channel lag', ('lag 1.875 ms', 0, -99.50483556079081, 58.01278749944788)),
                   ('periodic',
                    'sidebands spur tooth mesh - motor shaft and spur tooth mesh + motor shaft',
                    ('sidebands spur tooth mesh - motor shaft and spur tooth mesh + motor shaft',
                     8,
                     -0.26631872834398884,
                     3.790914105470519))],
 'symmetric': [('periodic',
                'line at 1.11418 cycles/rad',
                ('1.11347 cycles/rad; both: power (decay 3)', 2, -4.526766917291846, 6.2449004920487265)),
               ('speed_law', 'nonlinear viscous |v|^p', ('exponent 2', 1, -26.85447280644439, 22543.670183369246)),
               ('speed_law', 'Stribeck term (exp)', ('v_s 15', 1, -8.24246408352748, 42.35718179269362)),
               ('speed_law', 'Stribeck term (gauss)', ('v_s 9.284', 1, -8.701765295564641, 43.252069488560764)),
               ('speed_law', 'Stribeck term (rational)', ('v_s 9.284', 1, -8.713536403627273, 44.41826238098047)),
               ('speed_law',
                'amplitude law of motor shaft',
                ('power (0.5)', 0, -85.5827462020214, 30.185463463118165)),
               ('speed_law',
                'amplitude law of spur tooth mesh',
                ('exp (5)', 0, -11.22675605122835, 34.059959907884334)),
               ('load', 'load-dependent Coulomb mu|load|', ('', 1, 976.0, 693.626700754808)),
               ('load', 'load-speed coupling gamma|load||v|', ('', 1, -35873.00509122946, 6582.1410432033135)),
               ('load',
                'amplitude of output shaft growing with load^2 (SILO4 eq. 14)',
                ('', 1, 66179.9174939429, 6231.258958786505)),
               ('load',
                'amplitude of motor shaft growing with load^2 (SILO4 eq. 14)',
                ('', 1, 80660.06162242519, 6931.365745900588)),
               ('load',
                'amplitude of spur tooth mesh growing with load^2 (SILO4 eq. 14)',
                ('', 1, -2864.030009657883, 4992.521742263196)),
               ('temperature', 'temperature', ('', 1, -1782.0493837077536, 203.05757669489432)),
               ('drift', 'drift', ('', 1, -2503.676571428571, 288.8194814798436)),
               ('asymmetry', 'tau_c different by direction', ('', 1, -1634.0887506534632, 39.1590910257047)),
               ('asymmetry', 'tau_s different by direction', ('', 1, -144.9112493465367, 6.652586613678615)),
               ('asymmetry', 'viscous different by direction', ('', 1, -16387.25116013149, 584.1251655921236)),
               ('inertia', 'inertia J thetadd', ('', 1, 118.66508591547625, 168.82058698103174)),
               ('hysteresis', 'presliding hysteresis', ('length 19.21', 1, 252.7221222211184, 46.47509427058182)),
               ('hysteresis', 'backlash', ('gap 2.1', 1, 75.0, 40.162171256046406)),
               ('lag', 'torque channel lag', ('lag 1.875 ms', 0, 222.8281610817686, 82.43191286958381)),
               ('periodic',
                'sidebands spur tooth mesh - motor shaft and spur tooth mesh + motor shaft',
                ('sidebands spur tooth mesh - motor shaft and spur tooth mesh + motor shaft',
                 4,
                 -0.19614647837192267,
                 3.3543918584193992))]}


def _check(got, want):
    assert [g[:2] for g in got] == [w[:2] for w in want]
    for g, w in zip(got, want):
        if w[2] is None:
            assert g[2] is None, g[1]
            continue
        assert g[2][:2] == w[2][:2], g[1]
        assert g[2][2:] == pytest.approx(w[2][2:], rel=1e-9, abs=1e-12), g[1]


#: the detectors that replace the if-chain of the old ``term_candidates`` (and the loop's builder of
#: spectrum lines), with the effect kind of their candidates, in the order the loop asks them
OLD_CHAIN = [("lines", "periodic"), ("viscous_power", "speed_law"), ("stribeck_extra", "speed_law"),
             ("line_amplitude_law", "speed_law"), ("load_coulomb", "load"), ("load_viscous", "load"),
             ("load_line", "load"), ("temperature", "temperature"), ("drift", "drift"), ("asymmetry", "asymmetry"),
             ("inertia", "inertia"), ("hysteresis", "hysteresis"), ("backlash", "hysteresis"), ("lag", "lag"),
             ("sidebands", "periodic")]


@pytest.fixture(scope="module")
def rounds(twin):
    return {"per_direction": first_round(twin, symmetric=False), "symmetric": first_round(twin, symmetric=True)}


def test_one_detector_per_kind_of_the_old_chain_in_its_order():
    from gearspec.diagnose.detectors import detectors
    assert [(d.name, d.effect) for d in detectors()] == OLD_CHAIN


@pytest.mark.parametrize("which", ["per_direction", "symmetric"])
def test_each_detector_proposes_what_the_old_chain_did(rounds, which):
    from gearspec.diagnose.detectors import detectors, propose
    rnd, analyses = rounds[which]
    got, seen = [], set()
    for det in detectors():
        fp = fingerprint(rnd, det.function(rnd, analyses, gate=1.01))
        assert all(kind == det.effect for kind, _, _ in fp), det.name
        seen |= {det.name} if fp else set()
        got += fp
    _check(got, KNOWN[which])
    # every detector but asymmetry (symmetric models only) has something to propose on the twin
    assert seen == {n for n, _ in OLD_CHAIN} - ({"asymmetry"} if which == "per_direction" else set())
    # what the loop asks for: the registry in order (the spectrum's lines, then the term detectors)
    assert [(c.kind, c.name) for c in propose(rnd, analyses, gate=1.01)] == [w[:2] for w in KNOWN[which]]


def test_the_loops_old_entry_points_ask_the_registry(rounds):
    from gearspec.diagnose import candidates as C
    rnd, analyses = rounds["per_direction"]
    cands = loop._periodic_candidates(rnd, analyses) + C.term_candidates(rnd, analyses, gate=1.01)
    assert [(c.kind, c.name) for c in cands] == [w[:2] for w in KNOWN["per_direction"]]
    # at the loop's gate, fewer: the speed-law family needs evidence
    names = [c.name for c in C.term_candidates(rnd, analyses, gate=1e-300)]
    assert "nonlinear viscous |v|^p" not in names and "drift" in names


def test_the_round_context_is_read_only(rounds):
    import dataclasses
    rnd, _ = rounds["per_direction"]
    with pytest.raises(dataclasses.FrozenInstanceError):
        rnd.state = None
    assert rnd.keys == frozenset(b.key for b in rnd.state.blocks)


def test_candidates_and_detectors_do_not_import_the_loop():
    import ast
    from pathlib import Path

    import gearspec.diagnose as dg
    root = Path(dg.__file__).parent
    files = [root / "candidates.py", root / "context.py", *sorted((root / "detectors").glob("*.py"))]
    for f in files:
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.ImportFrom):
                assert node.module is None or not node.module.split(".")[-1] == "loop", (f.name, node.module)
                assert not any(a.name == "loop" for a in node.names), f.name


def test_a_newcomers_detector_is_asked_by_the_loop(twin):
    """A toy term kind's detector (a torque offset, a kind of the terms registry no detector
    proposed) registered here: the loop proposes its candidate and tests it; unregistered, it is
    gone."""
    import gearspec.diagnose as dg
    from gearspec.diagnose.candidates import GridCandidate, per_direction
    from gearspec.diagnose.context import Round
    from gearspec.diagnose.detectors import detectors, register_detector, unregister_detector
    from gearspec.errors import InputError

    asked = []

    @register_detector("toy_offset", effect="other")
    def toy(rnd, analyses, *, gate):
        asked.append(rnd)
        return [GridCandidate("other", "torque offset",
                              lambda _: (per_direction(rnd, "offset", key="toy offset", effect_kind="other"), []),
                              [None], evidence="a toy")]

    try:
        assert detectors()[-1].name == "toy_offset"
        with pytest.raises(InputError):
            register_detector("toy_offset", effect="other")(toy)
        d = dg.diagnose(twin, law="silo4", gear=GEAR, kinds=["other"], max_rounds=1)
    finally:
        unregister_detector("toy_offset")
    assert asked and all(isinstance(r, Round) for r in asked)
    (e,) = [e for e in d.effects if e.name == "torque offset"]
    assert e.kind == "other" and e.round == 1 and np.isfinite(e.z)
    assert list(d.trace["candidate"]) == ["torque offset"]
    assert "toy_offset" not in [x.name for x in detectors()]
