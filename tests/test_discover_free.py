"""discover on free motion (issue 12 item 2, issue 13 "one acceptance rule"): the held-out unit of a
block of free motion is its whole stretch of motion, and a block's own noise estimate (a few samples
over which the speed changes) is not used as the yardstick of held-out comparisons.  Known answer:
the bell-moves twin of ``tests/test_free_motion.py`` (SILO4 law per direction, a decaying line at 3
cycles/rad, inertia 2e-3 kg m^2 undeclared, white noise 2 mNm)."""

from __future__ import annotations

import numpy as np
import pytest
from test_free_motion import LINE, NEG, NOISE, POS, bell_moves, recording

from gearspec.discover import discover
from gearspec.discover.moments import moments
from gearspec.fitdata import FitData
from gearspec.simulate import model_recording


@pytest.fixture(scope="module")
def bells():
    return FitData.from_recording(recording(bell_moves(n_moves=6)), motion="auto")


def test_blocks_of_free_motion_are_held_out_by_stretch_and_have_no_noise_of_their_own(bells):
    M = moments(bells, [LINE["frequency"]], inertia=True)
    # six moves: their stretches of motion (a move is split where it stops) hold the ~1600 blocks of
    # 4-8 samples; the few segments the segmentation finds (near rest) are their own units
    units, counts = np.unique(M.groups("segment"), return_counts=True)
    block = M.groups("segment") != M.segment
    assert block.mean() > 0.95
    assert len(units) < 4 * 6
    assert np.min(counts[np.isin(units, M.groups("segment")[block])]) >= 10
    assert np.array_equal(M.take(np.arange(M.S)).groups("segment"), M.groups("segment"))
    # a block's own residual variance mixes the friction's change over the block into the noise (it
    # was 120 times the noise variance on these moves): blocks take the median of the other
    # segments' estimates (here the few near-rest segments: 4.5 times the noise variance, still
    # contaminated by the change of speed, but 27 times less than the blocks' own)
    own = M.noise[~block]
    assert np.all(M.noise[block] == np.median(own))
    assert np.median(own) < 10 * NOISE ** 2


def test_plateaus_keep_their_segments_and_their_noise():
    from gearspec.model import FrictionModel

    rec, _ = model_recording(FrictionModel("silo4", POS, NEG), [2.0, -2.0, 8.0, -8.0], duration=1.0, fs=1000,
                             noise=NOISE, seed=3)
    M = moments(FitData.from_recording(rec), [LINE["frequency"]])
    assert M.group is None
    assert np.array_equal(M.groups("segment"), M.segment)
    # each plateau's own estimate of the white noise's variance (4e-6 Nm^2): the larger of the
    # residual variance (1000 samples: within 20 %) and the scatter of 10 block means (9 degrees of
    # freedom: below 3 times the variance with probability 0.999)
    assert np.all((M.noise > 0.8 * NOISE ** 2) & (M.noise < 3.0 * NOISE ** 2))


def test_discover_selects_the_true_law_of_bell_moves(bells):
    # the truth in discover's terms: Coulomb and viscous per direction, an exponential Stribeck term
    # per direction (SILO4's amplitude tau_s - tau_c differs: 0.10 | 0.15 Nm), the inertia, the
    # line per direction with an exponential decay: 15 parameters.  Before, the blocks' own noise
    # (11 times the noise's sd) made every law look within the noise of the best: an 8-term law
    # whose held-out error is 2.9 times the true law's was selected
    res = discover(bells, frequencies=[LINE], references=(), n_models=0)
    sel = res.candidates[res.selected]
    assert sorted(sel.terms(res.library.frequencies)) == sorted(
        ["coulomb[dir]", "viscous[dir]", "stribeck_exp[dir]", "inertia", "ripple_exp@3[dir]"])
    best = min(c.rmse_holdout for c in res.candidates)
    assert sel.rmse_holdout <= 1.05 * best
    # held-out error at the noise (2 mNm; the moments take the change of speed within a block out,
    # and a share of the noise with it): within 0.8-1.1 of it
    assert 0.8 * NOISE < sel.rmse_holdout < 1.1 * NOISE
    # the parameters: Coulomb within 2 % of the truth (0.3 | 0.25 Nm), the inertia within 1 %
    # (free motion without plateaus: tests/test_free_motion.py's fit gets 0.07 % and 0.15 %)
    part = {p.family: i for i, p in enumerate(sel.parts)}
    vals = {(v["part"], v["slot"]): v["value"] for v in sel.fit.values() if v["kind"] == "linear"}
    assert vals[(part["coulomb"], 1)] == pytest.approx(POS["tau_c"], rel=0.02)
    assert vals[(part["coulomb"], -1)] == pytest.approx(NEG["tau_c"], rel=0.02)
    assert abs(vals[(part["inertia"], 0)]) == pytest.approx(2e-3, rel=0.01)
