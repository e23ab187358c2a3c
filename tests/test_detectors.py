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
    """A first round of the loop from the twin's declared model (per direction, or symmetric: the
    positive direction's parameters for both), its linear parameters refitted, and the round's
    residual analyses."""
    dd = loop._as_data(rec, None, GEAR)
    model = _truth()
    if symmetric:
        model = FrictionModel("silo4", model.directions["positive"], dict(model.directions["positive"]))
    rnd = loop.Round(dd, state_from_model(model, dd, symmetric=symmetric), loop.folds_of(dd, 5))
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
                    'line at 1.11416 cycles/rad',
                    ('1.1138 cycles/rad; positive: exp (decay -0.0333), negative: const',
                     4,
                     -53.480673762783454,
                     78.54212364574288)),
                   ('speed_law',
                    'nonlinear viscous |v|^p',
                    ('exponent 0.25', 2, -9.185086276391758, 95.46107424186788)),
                   ('speed_law', 'Stribeck term (exp)', ('v_s 0.522', 2, -1.913425103231441, 7.926031329323269)),
                   ('speed_law', 'Stribeck term (gauss)', ('v_s 0.8434', 2, -3.6172269427999826, 14.773732062765113)),
                   ('speed_law',
                    'Stribeck term (rational)',
                    ('v_s 0.8434', 2, -4.2225471554761995, 17.675418987250698)),
                   ('speed_law',
                    'amplitude law of motor shaft (positive)',
                    ('power (0.5)', 0, -100.65534375000918, 38.18572108515822)),
                   ('speed_law',
                    'amplitude law of motor shaft (negative)',
                    ('exp (2)', 0, -97.07206823113005, 43.56359158629982)),
                   ('speed_law',
                    'amplitude law of spur tooth mesh (positive)',
                    ('exp (5)', 0, -11.212061216222772, 34.57043208246344)),
                   ('speed_law',
                    'amplitude law of spur tooth mesh (negative)',
                    ('exp (5)', 0, -11.540730075875173, 34.567323264863894)),
                   ('load', 'load-dependent Coulomb mu|load|', ('', 2, 976.0, 693.626700754808)),
                   ('load', 'load-speed coupling gamma|load||v|', ('', 2, -35873.005091229454, 6582.141043203314)),
                   ('load',
                    'amplitude of motor shaft growing with load^2 (SILO4 eq. 14)',
                    ('', 2, 48213.82872163875, 5950.894865771699)),
                   ('load',
                    'amplitude of spur tooth mesh growing with load^2 (SILO4 eq. 14)',
                    ('', 2, -4095.6352030021194, 5069.371733977498)),
                   ('temperature', 'temperature', ('', 1, -1782.0493837077536, 203.05757669489432)),
                   ('drift', 'drift', ('', 1, -2503.676571428571, 288.8194814798436)),
                   ('inertia', 'inertia J thetadd', ('', 1, 118.66508591547625, 168.82058698103174)),
                   ('hysteresis',
                    'presliding hysteresis',
                    ('length 0.0251', 1, -1.9022345624315837, 1.2694748433420495)),
                   ('hysteresis', 'backlash', ('gap 4.392', 1, 179.0, 45.46427168667722)),
                   ('lag', 'torque channel lag', ('lag 1.875 ms', 0, -100.61033820806122, 56.895652055636084)),
                   ('periodic',
                    'sidebands spur tooth mesh - motor shaft and spur tooth mesh + motor shaft',
                    ('sidebands spur tooth mesh - motor shaft and spur tooth mesh + motor shaft',
                     8,
                     -0.25973014293830043,
                     4.4412409472947))],
 'symmetric': [('periodic',
                'line at 1.11425 cycles/rad',
                ('1.11348 cycles/rad; both: power (decay 3)', 2, -4.526908155624033, 6.2449004920487265)),
               ('speed_law', 'nonlinear viscous |v|^p', ('exponent 0.25', 1, -9.1850862763919, 95.46107424186783)),
               ('speed_law', 'Stribeck term (exp)', ('v_s 0.8434', 1, -3.0457564909064825, 12.963513647685994)),
               ('speed_law', 'Stribeck term (gauss)', ('v_s 0.8434', 1, -3.6172269427999524, 14.773732062765117)),
               ('speed_law', 'Stribeck term (rational)', ('v_s 0.8434', 1, -4.222547155476175, 17.6754189872507)),
               ('speed_law',
                'amplitude law of motor shaft',
                ('power (0.5)', 0, -85.5827462020214, 30.185463463118165)),
               ('speed_law',
                'amplitude law of spur tooth mesh',
                ('exp (5)', 0, -11.22675605122835, 34.059959907884334)),
               ('load', 'load-dependent Coulomb mu|load|', ('', 1, 976.0, 693.626700754808)),
               ('load', 'load-speed coupling gamma|load||v|', ('', 1, -35873.00509122946, 6582.1410432033135)),
               ('load',
                'amplitude of motor shaft growing with load^2 (SILO4 eq. 14)',
                ('', 1, 84118.27403775917, 6903.351260266587)),
               ('load',
                'amplitude of spur tooth mesh growing with load^2 (SILO4 eq. 14)',
                ('', 1, -2888.4300053141064, 5112.176745847855)),
               ('temperature', 'temperature', ('', 1, -1782.0493837077536, 203.05757669489432)),
               ('drift', 'drift', ('', 1, -2503.676571428571, 288.8194814798436)),
               ('asymmetry', 'tau_c different by direction', ('', 1, -1411.3963114659841, 35.12645545358489)),
               ('asymmetry', 'tau_s different by direction', ('', 1, -367.60368853401576, 13.786778079040616)),
               ('asymmetry', 'viscous different by direction', ('', 1, -16387.25116013149, 584.1251655921236)),
               ('inertia', 'inertia J thetadd', ('', 1, 118.66508591547625, 168.82058698103174)),
               ('hysteresis', 'presliding hysteresis', ('length 19.21', 1, 252.7221222211184, 46.47509427058182)),
               ('hysteresis', 'backlash', ('gap 2.1', 1, 75.0, 40.162171256046406)),
               ('lag', 'torque channel lag', ('lag 1.875 ms', 0, -104.05886479348317, 56.889683257822426)),
               ('periodic',
                'sidebands spur tooth mesh - motor shaft and spur tooth mesh + motor shaft',
                ('sidebands spur tooth mesh - motor shaft and spur tooth mesh + motor shaft',
                 4,
                 -0.2597301429383,
                 4.4412409472947))]}


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


def test_the_spectrum_lines_then_the_term_detectors(rounds):
    from gearspec.diagnose import detectors as C
    rnd, analyses = rounds["per_direction"]
    cands = C.line_candidates(rnd, analyses) + C.propose(rnd, analyses, gate=1.01, skip=("lines",))
    assert [(c.kind, c.name) for c in cands] == [w[:2] for w in KNOWN["per_direction"]]
    # at the loop's gate, fewer: the speed-law family needs evidence
    names = [c.name for c in C.propose(rnd, analyses, gate=1e-300, skip=("lines",))]
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
