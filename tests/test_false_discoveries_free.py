"""False discoveries on free motion (issue 13: "on >= 20 complete-model twins (plateaus and, once it
exists, free motion) ``discover`` selects the true structure in >= 90 %; ``diagnose`` accepts
nothing in >= 95 %").  The plateau half is tests/test_false_discoveries.py (diagnose) and
tests/test_discover_false.py (discover); this is the free-motion half.

A complete-model twin of free motion: bell-shaped point-to-point moves (minimum jerk, 1-3 s each,
peak speeds 6-20 rad/s, 0.2 s at rest between them, no plateau anywhere; the moves' durations,
speeds and the noise differ with the seed), the friction of tests/test_free_motion.py (SILO4 law
per direction with a line at 3 cycles/rad decaying as exp(-0.05 |v|)), the inertia 2e-3 kg m^2 in
the torque and declared nowhere, white noise 2 mNm.  The SILO4 law with the line and the inertia is
then the truth's structure: anything ``diagnose`` adds to it, or ``discover`` selects beside it, is
a false discovery.  ``discover`` is offered decoy lines as a spectrum analysis hands them in (the
line's second harmonic, an unrelated line, one close to it).

The level: both rules hold a family-wise alpha of 1 % per round.  At most one of 20 recordings may
get a false term from ``diagnose`` (at a true rate of 1 %, P(>= 2 of 20) = 1.7 %; at the 5 % the
issue tolerates, P(<= 1 of 20) = 74 %) and at most two of 20 a wrong structure from ``discover``
(the issue's 90 %).  Both tests would pass for a rule that never accepts anything:
:func:`test_a_real_line_is_found_in_free_motion` is the other side, a line of twice the noise's
size that the twin has and the model lacks, found by both.

Measured 2026-11-25 (0.12): ``diagnose`` accepted nothing on seeds 0-39 (it tests drift, inertia,
presliding hysteresis and backlash there, speed laws where the speed detector fires; no residual
peak passes the periodic detector's gate); ``discover`` selected the true structure on 19 of 20.
Before two fixes found here, ``diagnose`` accepted something on 3 of seeds 0-39 (14, 22, 28): an
amplitude law of the line (seed 14, the law held at the wrong speeds:
:func:`test_the_loop_holds_a_line_law_over_the_speeds_the_fit_does`) and, with that mended, a
nonlinear viscous law (Z 5.5-7.0, needed 3.3): the loop evaluated the laws at each block's mean
speed, leaving f'(v) x the change of speed within the block in its residual (the fit takes that out
of each block's normal equations); the loop now fits the samples at their own speeds
(:class:`gearspec.diagnose.DiagnoseData`).
"""

from __future__ import annotations

import numpy as np
import pytest
from test_free_motion import LINE, NEG, POS, bell_moves, recording

import gearspec.diagnose as dg
from gearspec.diagnose.baseline import baseline_model
from gearspec.diagnose.coverage import line_speed_range
from gearspec.discover import discover
from gearspec.fitdata import FitData
from gearspec.model import FrictionModel

SEEDS = range(20)
#: moves per recording (about 24 s at 1 kHz, 20k samples)
N_MOVES = 8
#: decoys offered to discover: the line's second harmonic, an unrelated line, one 0.5 cycles/rad off it
DECOYS = (2 * LINE["frequency"], 1.37, LINE["frequency"] + 0.5)
#: the truth's structure as discover names it: (slot, line) -- shapes within a slot (which Stribeck
#: form, which amplitude law) and direction dependence are a term's parameters, not extra terms
TRUE_STRUCTURE = {("coulomb", None), ("viscous", None), ("stribeck", None), ("inertia", None),
                  ("ripple", LINE["frequency"])}


def free_twin(seed: int, model=None):
    """Bell moves of the complete model (or ``model``): the moves and the noise drawn from ``seed``."""
    kw = {} if model is None else {"model": model}
    return recording(bell_moves(n_moves=N_MOVES, seed=seed), seed=1000 + seed, **kw)


def structure(res) -> set:
    return {(p.fam.slot, None if p.freq is None else round(float(res.frequencies[p.freq]), 6))
            for p in res.best.parts}


def run_diagnose(rec):
    return dg.diagnose(dg.DiagnoseData.from_recording(rec, motion="auto"), law="silo4", harmonics=[LINE])


def run_discover(rec):
    return discover(FitData.from_recording(rec, motion="auto"), frequencies=[LINE, *DECOYS], references=(),
                    n_models=0)


@pytest.mark.slow
def test_diagnose_accepts_nothing_on_free_motion_twins():
    false = {}
    for seed in SEEDS:
        d = run_diagnose(free_twin(seed))
        assert d.effects, "the loop tested no candidate: the test would measure nothing"
        assert all(e.verdict is not None and e.verdict.status == e.status for e in d.effects)
        if d.accepted:
            false[seed] = [e.name for e in d.accepted]
    print(f"diagnose on {len(SEEDS)} free-motion complete-model twins: nothing accepted in "
          f"{len(SEEDS) - len(false)} ({false})")
    assert len(false) <= 1, false


@pytest.mark.slow
def test_discover_selects_the_true_structure_of_free_motion_twins():
    wrong = []
    for seed in SEEDS:
        res = run_discover(free_twin(seed))
        got = structure(res)
        if got != TRUE_STRUCTURE:
            wrong.append(f"seed {seed}: extra {sorted(got - TRUE_STRUCTURE, key=str)}, missing "
                         f"{sorted(TRUE_STRUCTURE - got, key=str)}: {res.best.equation}")
    print(f"discover: true structure of free motion in {len(SEEDS) - len(wrong)}/{len(SEEDS)} twins", wrong)
    assert len(wrong) <= 0.1 * len(SEEDS), "\n".join(wrong)


@pytest.mark.slow
def test_a_real_line_is_found_in_free_motion():
    # the complete model plus a constant line of 4 mNm (twice the noise's sd) at 1.37 cycles/rad, the
    # same in both directions: the baseline lacks it, so diagnose must accept it (measured: Z 72,
    # against a critical value near 3) and discover must select it among the decoys.  (At 2 mNm the
    # held-out test would accept it too, Z 28 on seed 1, but diagnose's residual spectrum proposes it
    # on some seeds only: each block's mean is removed before the spectrum, and a block of free
    # motion covers a tenth of this line's cycle; see the README, "Honest at scale".)
    extra = {"frequency": 1.37, "amplitude": 4e-3, "decay": 0.0, "phase": 0.3}
    model = FrictionModel("silo4", dict(POS, harmonics=POS["harmonics"] + [extra]),
                          dict(NEG, harmonics=NEG["harmonics"] + [extra]))
    rec = free_twin(0, model)
    d = run_diagnose(rec)
    (acc,) = d.accepted
    assert acc.frequency == pytest.approx(1.37, rel=1e-3)
    assert acc.verdict.z > 2 * acc.verdict.z_crit
    res = run_discover(rec)
    assert structure(res) == TRUE_STRUCTURE | {("ripple", 1.37)}


def test_the_loop_holds_a_line_law_over_the_speeds_the_fit_does():
    # blocks of free motion hold a fraction of a cycle each (here 4-20 samples, 0.01-0.3 of a cycle
    # of the 3 cycles/rad line): the amplitude law's speed range is where the blocks together hold a
    # cycle (identify.stats.free_speed_range), in the fit and in the closed loop alike.  Before, the
    # loop took only blocks holding 0.1 cycle each: on seed 14 its range started at 3.9 rad/s instead
    # of 1.19, the law was held at its 3.9 rad/s value below, and the loop's baseline refit moved the
    # line to 0.0227 Nm, decay 0.062 s/rad (truth 0.02, 0.05; the fit's 0.0203 +- 0.0001,
    # 0.0523 +- 0.0005), after which a power law of the line was "accepted" at Z 5.7.  A segment's
    # speed is its samples' mean speed in both
    dd = dg.DiagnoseData.from_recording(free_twin(14), motion="auto")
    fitted = baseline_model(dd, "silo4", harmonics=[LINE])
    for sign in (1, -1):
        (h,) = fitted.harmonics(sign)
        assert line_speed_range(dd, LINE["frequency"], sign) == pytest.approx(tuple(h.speed_range), rel=1e-12)
        assert h.speed_range[0] < 1.5
    d = dg.diagnose(dd, law="silo4", harmonics=[LINE], max_rounds=0)
    (h,) = d.baseline_model.harmonics(1)
    assert h.amplitude == pytest.approx(0.02, rel=0.03)
    assert h.decay == pytest.approx(0.05, rel=0.1)


def test_the_loop_fits_free_motion_at_each_samples_speed():
    # a block of free motion is 4-20 samples over which the speed changes by up to 3 %: the loop's
    # laws see each sample's own speed (FitData.inputs), not the block's mean.  With the mean, seed 28
    # "accepted" a nonlinear viscous law at Z 7.0 (needed 3.3): f'(v) x the change of speed within
    # each block was left in the residual, and a steeper speed law took up part of it
    rec = free_twin(28)
    fd = FitData.from_recording(rec, motion="auto")
    dd = dg.DiagnoseData.from_recording(rec, motion="auto")
    assert np.array_equal(dd.fit.v, fd.direction * fd.speed)
    assert not np.array_equal(dd.fit.v, fd.v)          # the blocks' means, which the fit uses
    d = run_diagnose(rec)
    assert [e.name for e in d.accepted] == []
    assert all(e.verdict.z < e.verdict.z_crit for e in d.effects)
