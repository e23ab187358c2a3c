"""False discoveries of the closed loop (issue 13, the ``diagnose`` half): on complete-model twins
``diagnose`` accepts nothing in at least 95 % of the recordings.

A complete-model twin: plateaus whose friction is the SILO4 twin's truth (:func:`table2_model`,
eq. 11 with every line at a shaft the ``silo4-joint3`` gear declares), the twin's rotor inertia in
the drive torque and removed again as the gear spec declares it (SILO4 eq. 2), white torque noise
of 0.2 mNm (the default twin's in-sample rmse is 0.19 mNm).  The baseline ``silo4`` law with the
declared lines is then the truth's structure: every term the loop adds is a false discovery.

The rule is built for a family-wise level of alpha = 1 % per round (Bonferroni over the round's
candidates, a t quantile over the held-out groups), so a recording gets a false term with a
probability of about 1 %.  Over ``SEEDS`` = 20 recordings at most one is allowed (binomial: at a
true rate of 1 %, P(>= 2 of 20) = 1.7 %; at the 5 % the issue tolerates, P(<= 1 of 20) = 74 %), so
the test fails on a rule that accepts noise often, not on one unlucky seed.

Measured 2026-11-24 (0.7 work): nothing accepted on all 24 seeds 0-23.  Before, 22 of 24: seed 3
accepted a second Stribeck term standing in for the truth's output-shaft line (one cycle per
1803 rad, 0.27 of a cycle covered, so not identified and left out of the baseline: the plateaus'
levels of its partial cycle, 0.1-0.27 mNm at 79-218 rad/s, made a speed law); seed 16 one fitting
the ramp rows at the plateaus' edges (inertia torque of the ramp in the first and last 5 samples, up
to 3.5 mNm at 600 rad/s).  The fixes: the declared line stays in the null model
when the held-out test wants it (:mod:`gearspec.diagnose.nuisance`), and the edge rows are cut
(:meth:`DiagnoseData.without_edges`).  Trimming alone left 22 of 24.
"""

from __future__ import annotations

import numpy as np
import pytest

import gearspec.diagnose as dg
from gearspec.diagnose.nuisance import PartialLineBlock, unresolved_lines
from gearspec.simulate import model_recording, table2_model, twin_gear
from gearspec.simulate.silo4 import RATIO

#: recordings of the false-discovery test
SEEDS = 20
#: plateau speeds per direction, geometric from 0.5 to 600 rad/s at the motor (5-5700 rpm: the twin's range,
#: from below its Stribeck velocities of 2.8-3.0 rad/s, so that the data identify the whole law)
N_SPEEDS = 8
NOISE = 2e-4


def complete_twin(seed: int, *, one_run_per_plateau: bool = True):
    """A plateau recording of the twin's truth (both directions, shuffled order; one run per
    plateau as the SILO4 twin records them, or all in one run), and its gear."""
    rng = np.random.default_rng(seed)
    mag = np.geomspace(0.5, 600.0, N_SPEEDS)
    speeds = [x for a, b in zip(rng.permutation(mag), rng.permutation(mag)) for x in (a, -b)]
    gear = twin_gear()
    rec, _ = model_recording(table2_model(), speeds, noise=NOISE, gear=gear, seed=seed, duration=0.8, fs=500.0,
                             one_run_per_plateau=one_run_per_plateau, inertia=gear.inertia)
    return rec, gear


@pytest.mark.slow
def test_diagnose_accepts_nothing_on_complete_model_twins():
    accepted = {}
    for seed in range(SEEDS):
        rec, gear = complete_twin(seed)
        d = dg.diagnose(rec, law="silo4", gear=gear, per_segment_spectra=False)
        accepted[seed] = [e.name for e in d.accepted]
        # nothing accepted: the final model is the baseline, and every candidate says why not
        if not d.accepted:
            assert d.final_model.rmse_holdout == pytest.approx(d.baseline_model.rmse_holdout, rel=1e-12)
        assert all(e.verdict is not None and e.verdict.status == e.status for e in d.effects)
    false = {s: a for s, a in accepted.items() if a}
    rate = 1 - len(false) / SEEDS
    print(f"diagnose on {SEEDS} complete-model twins: nothing accepted in {100 * rate:.0f} % ({false})")
    assert len(false) <= 1, false


def test_a_declared_line_seen_in_partial_cycles_stays_in_the_null_model():
    """Seed 3: the truth's output-shaft line (one cycle per 2 pi 287 rad) is not identified from
    plateaus covering 0.27 of its cycle; the held-out test wants it (Z 6.1, needs 2.6), so the loop
    keeps it as a partial line in its null model, and its baseline's held-out rmse is 0.219 mNm:
    the noise (0.2 mNm) plus the error of predicting a held-out plateau's level from the others
    (~0.09 mNm rms).  Without the line it was 0.45 mNm and a second Stribeck term was accepted in
    its place (Z 6.9, needs 3.5).  The bound 1.25 sigma lies between the two with a margin on
    each side (the recording is fixed: the number is deterministic)."""
    rec, gear = complete_twin(3)
    d = dg.diagnose(rec, law="silo4", gear=gear, per_segment_spectra=False)
    partial = [b for b in d.baseline.state.blocks if isinstance(b, PartialLineBlock)]
    assert [(b.label, b.dirs) for b in partial] == [("output shaft", (1, -1))]
    assert partial[0].frequency == pytest.approx(1 / (2 * np.pi * RATIO), rel=1e-9)
    # written as fitted (constant amplitude, flagged), still listed as not identified; the model
    # evaluates as the loop fitted it
    assert "partial cycle" in d.final_model.not_identified["positive.output shaft"]
    (h,) = [h for h in d.final_model.harmonics(1) if h.label == "output shaft"]
    assert h.extra.get("partial_cycles") is True and h.amplitude_law == "const"
    pred = dg.predict_model(d.final_model, d.data)
    assert np.sqrt(np.mean((d.data.y - pred) ** 2)) == pytest.approx(d.final.rmse, rel=1e-6)
    assert any("output shaft" in n and "partial cycles only" in n and "kept in the model" in n for n in d.notes)
    assert d.baseline_model.rmse_holdout < 1.25 * NOISE
    assert [e.name for e in d.accepted] == []
    # a model that has the line (fitted elsewhere) gets no partial line
    assert unresolved_lines(table2_model(), d.data, gear=gear) == []
