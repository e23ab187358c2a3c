"""False discoveries (issue 13): on twins whose friction is a complete model of known structure,
``discover`` selects that structure -- no extra line, no extra or missing term -- in at least 90 % of
the seeds, with decoy lines offered beside the true ones (what a spectrum analysis hands in: a
harmonic, a sideband and unrelated frequencies).  The rule that decides is the closed loop's
held-out test (gearspec.discover.screen, gearspec.discover.accept), never a threshold tuned here."""

from __future__ import annotations

import numpy as np
import pytest

from gearspec.core.crossval import critical_z
from gearspec.discover import discover
from gearspec.discover.accept import CONSISTENCY, held_out_z
from gearspec.discover.moments import moments
from gearspec.discover.screen import screen_lines
from gearspec.discover.law import fold_ids
from gearspec.fitdata import FitData
from gearspec.model import RPM, FrictionModel
from gearspec.simulate import model_recording

F2, F3 = 1 / (2 * np.pi * 14), 1 / (2 * np.pi)      # SILO4 worm-shaft and motor-shaft lines, cycles/rad
#: decoys: 2x the motor shaft, a sideband of the motor shaft by the worm shaft, 3x the worm shaft, an unrelated line
DECOYS = (2 * F3, F3 + F2, 3 * F2, 0.0668)


def truth(extra=()) -> FrictionModel:
    """SILO4 eq. 11 (Table 2): direction-dependent Coulomb and viscous friction, a symmetric Stribeck
    term (the two directions' static-minus-Coulomb values made equal, as in test_discover), and the
    worm- and motor-shaft lines with decaying amplitudes (as published, per direction)."""
    p = {"tau_c": 7.106e-3, "tau_s": 7.106e-3 + 1.49e-3, "v_s": 28.18 * RPM, "viscous": 0.0134e-3 / RPM}
    n = {"tau_c": 7.909e-3, "tau_s": 7.909e-3 + 1.49e-3, "v_s": 28.18 * RPM, "viscous": 0.0138e-3 / RPM}
    p["harmonics"] = [dict(frequency=F2, amplitude=0.576e-3, decay=1.27e-4 / RPM, phase=np.pi / 2),
                      dict(frequency=F3, amplitude=0.133e-3, decay=5.28e-5 / RPM, phase=np.pi)]
    n["harmonics"] = [dict(frequency=F2, amplitude=0.526e-3, decay=1.12e-4 / RPM, phase=np.pi / 2),
                      dict(frequency=F3, amplitude=0.152e-3, decay=7.49e-6 / RPM, phase=np.pi)]
    for h in extra:                          # further lines, the same in both directions
        p["harmonics"].append(dict(h))
        n["harmonics"].append(dict(h))
    return FrictionModel("silo4", p, n)


#: the truth's structure: (slot, line) of each term -- a term's shape within its slot (which Stribeck
#: form, which amplitude law) and its direction dependence are its parameters, not extra terms
TRUE_STRUCTURE = {("coulomb", None), ("viscous", None), ("stribeck", None), ("ripple", round(F2, 6)),
                  ("ripple", round(F3, 6))}


def twin(seed: int, model=None, noise=0.1e-3) -> FitData:
    """8 log-spaced motor speeds 2..600 rad/s per direction, 2 s each at 1 kHz, white torque noise
    0.1 mNm (SILO4 Table 3's model errors are 0.12..0.21 mNm)."""
    speeds = [s * d for s in np.geomspace(2, 600, 8) for d in (1, -1)]
    rec, _ = model_recording(model or truth(), speeds, duration=2.0, fs=1000, noise=noise, gear="silo4-joint3",
                             seed=seed, one_run_per_plateau=False)
    return FitData.from_recording(rec)


def structure(res) -> set:
    out = set()
    for p in res.best.parts:
        out.add((p.fam.slot, None if p.freq is None else round(float(res.frequencies[p.freq]), 6)))
    return out


SEEDS = range(20)


@pytest.mark.slow
def test_discover_selects_the_true_structure_in_at_least_90_percent_of_twins():
    # 20 twins; the library holds the declared lines, the four decoys, every Stribeck shape, power
    # laws, residual inertia and a direction-dependent version of all.  The rule is the held-out
    # one at its default level (0.01 per round, Bonferroni): a false discovery in more than 10 % of
    # the twins would mean the rule does not hold its level.
    wrong = []
    for seed in SEEDS:
        res = discover(twin(seed), gear="silo4-joint3", frequencies=DECOYS, references=(), n_models=0)
        got = structure(res)
        if got != TRUE_STRUCTURE:
            wrong.append(f"seed {seed}: extra {sorted(got - TRUE_STRUCTURE, key=str)}, missing "
                         f"{sorted(TRUE_STRUCTURE - got, key=str)}: {res.best.equation}")
    rate = 1 - len(wrong) / len(SEEDS)
    print(f"true structure in {len(SEEDS) - len(wrong)}/{len(SEEDS)} twins ({100 * rate:.0f} %)")
    assert rate >= 0.9, "\n".join(wrong)


def test_decoy_lines_fail_the_line_screen_and_true_lines_pass():
    # seed 0: the true lines' held-out Z is far above the critical value (amplitudes 0.13-0.58 mNm
    # against 0.1 mNm of noise over tens of thousands of samples); the decoys' are noise
    data = twin(0)
    M0 = moments(data)
    fold = fold_ids(M0, "segment", 5)
    freqs = [F2, F3, *DECOYS]
    res = screen_lines(data, freqs, fold, M0.groups("segment"), alpha=0.01)
    zc = critical_z(0.01, len(freqs), M0.S)
    assert res[0]["z"] > 2 * zc and res[1]["z"] > 2 * zc
    assert all(not r["passed"] for r in res[2:]), res
    # ... each failing on its own (round 0): only lines that pass alone are fitted jointly, which
    # keeps the screen's cost at rows x lines for the many lines a spectrum hands in
    assert all(r["round"] == 0 for r in res[2:]), res


def test_a_weak_real_line_is_kept_and_a_missing_one_is_not_invented():
    # a third line at 3x the worm shaft with 0.3 mNm (3x the noise) is real: it passes the screen
    # and the acceptance; without it in the twin, it does not (same seed, same decoy)
    m = truth([dict(frequency=3 * F2, amplitude=0.3e-3, decay=0.0, phase=0.3)])
    res = discover(twin(1, m), gear="silo4-joint3", frequencies=[3 * F2], references=(), n_models=0)
    assert ("ripple", round(3 * F2, 6)) in structure(res)
    res0 = discover(twin(1), gear="silo4-joint3", frequencies=[3 * F2], references=(), n_models=0)
    assert ("ripple", round(3 * F2, 6)) not in structure(res0)


def test_held_out_z_on_pseudo_rows_equals_z_statistic_on_the_samples():
    # the exactness the acceptance rests on: Z from the segments' block normal equations equals
    # gearspec.core.crossval.z_statistic on the samples themselves (same groups, same 8 blocks)
    from gearspec.core.crossval import z_statistic
    from gearspec.core.reduction import harmonic_columns

    data = twin(2)
    M = moments(data, [F2, F3])
    rng = np.random.default_rng(0)
    p0, p1 = rng.normal(size=(M.S, M.K)) * 1e-4, rng.normal(size=(M.S, M.K)) * 1e-4
    z = held_out_z(M, p0, p1, M.segment)
    order = np.argsort(data.segment, kind="stable")
    seg = data.segment[order]
    _, starts = np.unique(seg, return_index=True)
    stops = np.append(starts[1:], len(seg))
    Phi = np.zeros((len(seg), M.K))
    th, acc = data.theta[order], (None if data.acc is None else data.acc[order])
    for s, (a, b) in enumerate(zip(starts, stops)):
        sn, cs = harmonic_columns(th[a:b], M.frequencies)
        for k, name in enumerate(M.basis):
            Phi[a:b, k] = (1.0 if name == "1" else acc[a:b] if name == "acc" else
                           (sn if name.startswith("sin") else cs)[:, int(name[3:])])
    rows = np.repeat(np.arange(M.S), stops - starts)
    y = data.y[order]
    f0, f1 = np.sum(Phi * p0[rows], axis=1), np.sum(Phi * p1[rows], axis=1)
    z_samples = z_statistic(y - f0, f1 - f0, y - f1, starts, stops)
    assert z == pytest.approx(z_samples, rel=1e-8)
    assert CONSISTENCY == 0.9


def test_the_acceptance_defaults_are_the_closed_loops():
    # one acceptance rule: discover's level and minimum gain default to diagnose's
    import inspect

    from gearspec.diagnose import diagnose

    d, e = inspect.signature(diagnose).parameters, inspect.signature(discover).parameters
    assert e["test_alpha"].default == d["alpha"].default == 0.01
    assert e["min_gain"].default == d["min_gain"].default


def test_a_line_that_passes_alone_by_leakage_fails_beside_the_true_line():
    # 0.002 cycles/rad above the motor-shaft line (0.24 cycles apart over a 120 rad plateau): alone,
    # the strong line's leakage into its columns passes the screen; beside it, it adds nothing
    data = twin(0)
    M0 = moments(data)
    fold = fold_ids(M0, "segment", 5)
    res = screen_lines(data, [F2, F3, F3 + 0.002], fold, M0.groups("segment"), alpha=0.01)
    assert res[0]["passed"] and res[1]["passed"]
    assert not res[2]["passed"] and res[2]["round"] > 0, res[2]


def _true_parts():
    from gearspec.discover.law import Part

    return [Part("coulomb", None, True), Part("viscous", None, True), Part("stribeck_exp", None, False, 3.0),
            Part("ripple_exp", 0, True, 1e-3), Part("ripple_exp", 1, True, 5e-4)]


def test_the_acceptance_test_removes_a_false_term_and_keeps_the_true_ones():
    # the true law plus a sqrt-type power term the twin does not have: backward elimination by the
    # held-out Z removes it, every true term (slot) stays
    from gearspec.discover.accept import backward
    from gearspec.discover.law import Part

    data = twin(3)
    M = moments(data, [F2, F3])
    fold = fold_ids(M, "segment", 5)
    parts = _true_parts() + [Part("power", None, False, 0.5)]
    final, verdicts = backward(M, fold, M.groups("segment"), parts, alpha=0.01, min_gain=0.005, n_candidates=20,
                               families={"ripple_const", "ripple_exp"})
    slots = {(p.fam.slot, p.freq) for p in final}
    assert slots == {("coulomb", None), ("viscous", None), ("stribeck", None), ("ripple", 0), ("ripple", 1)}
    assert any(v.term.startswith("power") and not v.passed for v in verdicts)


def test_the_independent_recording_removes_a_line_it_does_not_have():
    # estimation twin with a line at 3x the worm shaft (0.3 mNm), validation twin without it: the
    # line helps on the estimation data and not on the independent recording, so it goes
    from gearspec.discover.accept import validate_law
    from gearspec.discover.law import Part

    extra = dict(frequency=3 * F2, amplitude=0.3e-3, decay=0.0, phase=0.3)
    M = moments(twin(4, truth([extra])), [F2, F3, 3 * F2])
    Mv = moments(twin(5), [F2, F3, 3 * F2]).restrict(M.basis)
    parts = _true_parts() + [Part("ripple_const", 2, False)]
    final, verdicts = validate_law(M, Mv, parts, alpha=0.01, min_gain=0.005, families={"ripple_const", "ripple_exp"})
    assert all(p.freq != 2 for p in final)
    assert {p.freq for p in final if p.freq is not None} == {0, 1}
    assert any(v.data == "validation" and not v.passed and "@0.0341" in v.term for v in verdicts)


def test_each_condition_of_the_rule_can_reject_a_true_term():
    # the motor-shaft line of the twin (0.13 mNm, Z about 30): accepted at the default level; rejected
    # when the critical Z is out of reach (the Z gate alone decides: gain and consistency pass), and
    # when the minimum gain is out of reach (the gain alone decides: Z passes)
    from gearspec.discover.accept import TERM, judge

    data = twin(3)
    M = moments(data, [F2, F3])
    fold, groups = fold_ids(M, "segment", 5), M.groups("segment")
    law = _true_parts()
    without = law[:4]
    ok = judge(M, fold, groups, law, without, z_crit=critical_z(0.01, 20, M.S), min_gain=0.005, term="F3",
               move=TERM)
    assert ok.passed and ok.gain > 0.005 and ok.consistency >= CONSISTENCY
    no_z = judge(M, fold, groups, law, without, z_crit=10 * ok.z, min_gain=0.005, term="F3", move=TERM)
    assert not no_z.passed
    no_gain = judge(M, fold, groups, law, without, z_crit=ok.z_crit, min_gain=2 * ok.gain, term="F3", move=TERM)
    assert not no_gain.passed and no_gain.z >= no_gain.z_crit


def test_no_more_lines_are_searched_than_a_law_can_hold():
    # four real lines pass the screen; with at most 3 terms in a law, the 3 strongest (largest
    # held-out Z) are searched and the note names the one left (bounded memory on long recordings)
    extra = [dict(frequency=3 * F2, amplitude=0.3e-3, decay=0.0, phase=0.3),
             dict(frequency=2 * F3, amplitude=0.2e-3, decay=0.0, phase=1.0)]
    res = discover(twin(6, truth(extra)), gear="silo4-joint3", frequencies=[3 * F2, 2 * F3], references=(),
                   n_models=0, max_parts=3, local_search=False)
    assert sum(ln["passed"] for ln in res.lines) == 4
    assert len(res.frequencies) == 3
    assert any("passed the screen" in n for n in res.notes)
