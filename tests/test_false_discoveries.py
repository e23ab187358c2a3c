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
"""

from __future__ import annotations

import numpy as np
import pytest

import gearspec.diagnose as dg
from gearspec.simulate import model_recording, table2_model, twin_gear

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
@pytest.mark.xfail(strict=True, reason=(
    "measured 2026-11-24: 18 of these 20 recordings clean (90 %; 22 of 24 seeds), seeds 3 and 16 accept an extra "
    "Stribeck term (Z 6.0 and 4.0, needed 3.5). Not noise: the truth's output-shaft line (one cycle per 1803 rad) "
    "is left out of the baseline (plateaus cover 0.27 of a cycle) and, every run starting at theta 0, adds a level "
    "that depends on the plateau's speed; and each segment's first samples carry ramp residuals up to 1.6 mNm at "
    "the top speeds. The 95 % target is not met; this test fails as an unexpected pass once it is"))
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
