"""Declared sidebands in diagnose (issue 10, item 7): a mesh line amplitude-modulated by a slower
shaft, against another amplitude law of the carrier.

Twins: a spur stage of 24 teeth (mesh at 24/(2 pi) cycles/rad, shaft at 1/(2 pi)), plateaus at
4..35 rad/s both ways for 1.5 s at 1 kHz, white noise 0.005 Nm.

* AM twin: carrier 0.02 Nm modulated with depth m = 0.5 by the shaft: sidebands of m/2 = 0.25 of
  the carrier.  Sidebands are fitted on the plateaus travelling two shaft periods (12.6 rad) or
  more: about 6 per direction, ~8000 samples, so a sideband amplitude has a standard error of
  ~0.005 sqrt(2/8000) = 8e-5 Nm, i.e. 0.004 on the ratio; the tolerance 0.03 is ~7 of those.
* amplitude-law twin: no modulation, the carrier amplitude grows like sqrt(|v|) (0.01 Nm at
  4 rad/s, 0.03 Nm at 35 rad/s), which the baseline's exponential law cannot follow.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from gearspec.diagnose import detectors as C
from gearspec.diagnose.candidates import SidebandCandidate
from gearspec.diagnose import loop
from gearspec.gears import load_gear
from gearspec.simulate.synthetic import Ripple, plateau_recording

GEAR = {"name": "sideband twin", "reference": "motor", "unit": "rad",
        "stages": [{"name": "spur", "kind": "spur", "ratio": 1, "teeth": 24}]}
FC = 24 / (2 * math.pi)
FM = 1 / (2 * math.pi)
SPEEDS = [4, 8, 15, 25, 35, -4, -8, -15, -25, -35]
A, M, PHI, PSI = 0.02, 0.5, 0.7, 1.1
FS = 1000.0


@pytest.fixture(scope="module")
def gear():
    return load_gear(GEAR)


@pytest.fixture(scope="module")
def am(gear):
    rips = [Ripple(FC, A, PHI), Ripple(FC + FM, A * M / 2, PHI + PSI), Ripple(FC - FM, A * M / 2, PHI - PSI)]
    rec, _ = plateau_recording(SPEEDS, ripples=rips, level=0.1, duration=1.5, fs=FS, noise=0.005, gear=gear, seed=3)
    return rec


@pytest.fixture(scope="module")
def law(gear):
    rec, _ = plateau_recording(SPEEDS, ripples=[], level=0.1, duration=1.5, fs=FS, noise=0.005, gear=gear, seed=3)
    th = rec.theta
    v = np.gradient(th, rec.t)
    d = rec.data.copy()
    d["torque"] = d["torque"] + np.sign(v) * 0.03 * np.sqrt(np.abs(v) / 35) * np.sin(2 * np.pi * FC * th + PHI)
    return dataclasses.replace(rec, data=d, _tau=None)


def first_round(rec, gear):
    """The loop's first round on the baseline model, and every candidate it could propose
    (``gate`` above 1: the amplitude laws of the carrier and the sidebands are proposed whatever the
    residual spectrum shows, so that they can be compared head to head)."""
    dd = loop._as_data(rec, None, gear)
    model = loop.baseline_model(dd, "silo4", gear=gear)
    from gearspec.diagnose.design import state_from_model

    rnd = loop.Round(dd, loop._settle(state_from_model(model, dd), dd), loop.folds_of(dd, 5))
    analyses = loop.analyse(rnd, per_segment=False)
    cands = C.propose(rnd, analyses, gate=1.01, skip=("lines",))
    sb = [c for c in cands if isinstance(c, SidebandCandidate)]
    laws = [c for c in cands if c.kind == "speed_law" and c.name.startswith("amplitude law of spur tooth mesh")]
    return rnd, sb, laws


def held_out(rnd, cands):
    from scipy import stats

    z_crit = float(stats.t.isf(0.01 / 6, rnd.dd.n_groups - 1))
    return [loop.evaluate_candidate(rnd, c, z_crit=z_crit, min_gain=0.005) for c in cands]


@pytest.fixture(scope="module")
def am_round(am, gear):
    rnd, sb, laws = first_round(am, gear)
    return rnd, sb, laws, held_out(rnd, sb), held_out(rnd, laws)


@pytest.fixture(scope="module")
def law_round(law, gear):
    rnd, sb, laws = first_round(law, gear)
    return rnd, sb, laws, held_out(rnd, sb), held_out(rnd, laws)


def test_sideband_columns_only_on_plateaus_that_resolve_them(am_round):
    rnd, sb, _, _, _ = am_round
    assert len(sb) == 1
    cand = sb[0]
    assert cand.min_travel == pytest.approx(C.SIDEBAND_CYCLES / FM)
    prop = cand.propose(rnd, rnd.all_groups())
    cols = prop.columns(rnd.dd)
    dd = rnd.dd
    th = dd.at("theta")
    n_short = 0
    for a, z in zip(dd.starts, dd.stops):
        travel = np.ptp(th[a:z])
        nz = np.any(cols[a:z] != 0)
        n_short += travel < cand.min_travel
        assert nz == (travel >= cand.min_travel), (travel, nz)
    assert 4 <= n_short <= dd.n_groups - 6     # the twin has both kinds of plateau
    # both declared sidebands, pooled per direction (one sin/cos pair per direction and line)
    assert sorted(round(b.frequency, 9) for b in prop.add) == [round(FC - FM, 9), round(FC + FM, 9)]
    assert all(b.dirs == (1, -1) for b in prop.add)


def test_sidebands_beat_the_carrier_law_on_a_modulated_mesh(am_round):
    _, sb, laws, ev_sb, ev_laws = am_round
    assert sb and laws
    assert ev_sb[0].passed
    assert all(ev_sb[0].drop > 2 * e.drop for e in ev_laws)


def test_carrier_law_beats_sidebands_on_a_speed_dependent_carrier(law_round):
    _, sb, laws, ev_sb, ev_laws = law_round
    assert sb and laws
    assert not ev_sb[0].passed
    assert any(e.passed for e in ev_laws)
    assert max(e.drop for e in ev_laws) > 2 * max(ev_sb[0].drop, 0.0)


def test_diagnose_accepts_sidebands_with_their_amplitudes(am, gear):
    from gearspec.diagnose import diagnose

    diag = diagnose(am, gear=gear, kinds=["periodic", "speed_law"], max_rounds=2)
    acc = [e for e in diag.effects if e.accepted]
    assert any(isinstance(e.name, str) and e.name.startswith("sidebands") for e in acc)
    assert not any(e.kind == "speed_law" and "spur tooth mesh" in e.name for e in acc)
    for dname in ("positive", "negative"):
        hs = diag.final_model.directions[dname]["harmonics"]
        car = next(h for h in hs if math.isclose(h["frequency"], FC, rel_tol=1e-9))
        assert car["amplitude"] == pytest.approx(A, rel=0.05)
        for f in (FC - FM, FC + FM):
            h = next(h for h in hs if math.isclose(h["frequency"], f, rel_tol=1e-9))
            assert h["label"].startswith("spur tooth mesh") and "motor shaft" in h["label"]
            assert h["amplitude"] / car["amplitude"] == pytest.approx(M / 2, abs=0.03)


def test_a_lag_is_not_credited_with_what_the_lines_taylor_columns_do(law_round):
    # the lag candidate replaces every line by its lagged form; it must keep their Taylor columns
    # (decay refits), or the held-out comparison credits it with dropping them (here ~20 %)
    rnd = law_round[0]
    cand, = C.lag_candidates(rnd, gate=1.01)
    ev = held_out(rnd, [cand])[0]
    assert not ev.passed and abs(ev.gain) < 0.005
