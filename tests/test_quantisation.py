"""Spectrum honesty (issue 13 item 3): integer-order hints only for multiples a gear can plausibly
make (no "53x planetary output shaft")."""

import math

from gearspec.gears import MAX_SLOW_SHAFT_MULTIPLE, integer_hint, integer_order, load_gear

SILO4 = load_gear("silo4-joint3")          # motor-referenced: shafts motor, planetary output, output
F_MOTOR = 1 / (2 * math.pi)               # cycles per motor rad
F_PLANETARY = F_MOTOR / 14                # the planetary output (worm) shaft


def test_no_high_multiple_of_a_slow_shaft_however_sharp_the_frequency():
    # 53x the planetary output shaft, known to 1e-7 cycles/rad (the chance rule alone lets it through)
    f = 53 * F_PLANETARY
    assert integer_hint(SILO4, f, 1e-7) is None
    assert integer_order(SILO4, f, 1e-7) is None
    # its low harmonics (run-out, eccentricity) are still hinted, up to the bound
    assert integer_hint(SILO4, 3 * F_PLANETARY, 1e-7) == "3x planetary output shaft"
    assert integer_hint(SILO4, MAX_SLOW_SHAFT_MULTIPLE * F_PLANETARY, 1e-7) == "4x planetary output shaft"
    assert integer_hint(SILO4, (MAX_SLOW_SHAFT_MULTIPLE + 1) * F_PLANETARY, 1e-7) is None


def test_the_motor_shaft_keeps_its_high_orders():
    # pole pairs, slots and commutator segments make high orders of the motor shaft: 53x is hinted
    assert integer_hint(SILO4, 53 * F_MOTOR, 1e-4) == "53x motor shaft"
    io = integer_order(SILO4, 7 * F_MOTOR, 1e-4)
    assert io.multiple == 7 and io.shaft == "motor shaft" and io.frequency == 7 * F_MOTOR


# --- issue 13 item 2: no confident lines out of position quantisation -------------------------------
#
# Known answers.  The SILO4 twin's encoder has 2000 counts per motor turn: step q = 2 pi / 2000 =
# 3.1416e-3 rad.  At 2 rpm (0.2094 rad/s) and one sample per 4 ms it moves 8.378e-4 rad = 4/15 of a
# count per sample (3.75 samples per count): the closed loop's reaction to every count is a torque
# periodic at the count rate whose 4th and 8th harmonics the sampling folds to 1/(4 q) = 79.6 and
# 1/(2 q) = 159.2 cycles/rad, where the analysis found "lines" with fap 1e-7..1e-15 in every segment.
# The twin's friction has no line there (its lines are at 1/(2 pi 287), 1/(2 pi 14), 1/(2 pi)).

from functools import lru_cache  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from gearspec.gears import GearTrain  # noqa: E402
from gearspec.simulate.silo4 import silo4_twin, twin_gear  # noqa: E402
from gearspec.spectrum import analyze, analyze_segment  # noqa: E402
from gearspec.spectrum.analysis import (QUANTISATION_FRACTION, quantisation_limit, quantisation_lines,  # noqa: E402
                                        quantisation_step)
from gearspec.spectrum.harmonic import harmonic_fit  # noqa: E402
from gearspec.spectrum.periodogram import false_alarm_probability  # noqa: E402

Q_COARSE = 2 * math.pi / 2000      # the twin's encoder (500 lines, quadrature)
Q_FINE = 2 * math.pi / 65536       # a 16-bit encoder
SPACING_2RPM = 2 * 2 * math.pi / 60 * 4e-3   # rad per 4 ms sample at 2 rpm


@lru_cache(maxsize=None)
def _twin_spectrum(counts_per_rev: int, rpm: float, repetitions: int = 2):
    rec, _ = silo4_twin([rpm], repetitions=repetitions, seed=1, plant={"counts_per_rev": counts_per_rev})
    return analyze(rec, twin_gear())


def test_the_encoder_step_is_read_from_the_positions_and_only_from_a_lattice():
    rng = np.random.default_rng(3)
    true = 25.0 + SPACING_2RPM * (np.arange(2400) + rng.uniform(-0.1, 0.1, 2400))   # 10 % timing jitter
    # a staircase (3.75 samples per count): the changes are 0 or 1 count
    assert quantisation_step(Q_COARSE * np.rint(true / Q_COARSE)) == pytest.approx(Q_COARSE, rel=1e-9)
    # a fine encoder moves 8 or 9 counts per sample: the step, not the smallest change, is found
    assert quantisation_step(Q_FINE * np.rint(true / Q_FINE)) == pytest.approx(Q_FINE, rel=1e-9)
    # a staircase dithering by a count (stick-slip, a position loop at rest) keeps its lattice
    dither = Q_COARSE * (np.rint(true / Q_COARSE) + rng.integers(-1, 2, true.size))
    assert quantisation_step(dither) == pytest.approx(Q_COARSE, rel=1e-9)
    # positions in floating point have no lattice: no step, no limit
    assert quantisation_step(true) == 0.0 and quantisation_limit(0.0) == math.inf
    # an exact position sampled at a uniform spacing changes by one amount only: not an encoder
    assert quantisation_step(3.0 + 0.05 * np.arange(4000)) == 0.0
    assert quantisation_limit(Q_COARSE) == pytest.approx(QUANTISATION_FRACTION / Q_COARSE)
    assert quantisation_limit(Q_COARSE) == pytest.approx(39.79, abs=0.01)


def test_a_coarse_encoder_at_2_rpm_makes_no_line_the_truth_lacks():
    res = _twin_spectrum(2000, 2.0)
    assert len(res.segments) == 2
    for s in res.segments:
        assert s.quantisation_step == pytest.approx(Q_COARSE, rel=1e-6)
        d = s.to_dict()
        assert d["quantisation_limit"] == pytest.approx(1 / (8 * Q_COARSE), rel=1e-6)
        assert d["quantisation_step"] == pytest.approx(Q_COARSE, rel=1e-6)
        # no peak the truth does not have: before the limit, 79.6 and 158.4 cycles/rad (fap 1e-7..1e-15)
        false = [(p.frequency, p.fap) for p in s.peaks if not p.declared and p.fap < 1e-3]
        assert false == []
        assert all(p.frequency < d["quantisation_limit"] for p in s.peaks)


def test_a_fine_encoder_at_2_rpm_is_not_limited():
    res = _twin_spectrum(65536, 2.0)
    for s in res.segments:
        assert s.quantisation_step == pytest.approx(Q_FINE, rel=1e-6)
        # 1 / (8 q) = 1304 cycles/rad lies above the position Nyquist frequency (579): it limits nothing
        assert s.quantisation_limit > s.nyquist
        assert [p for p in s.peaks if not p.declared and p.fap < 1e-3] == []


def test_the_folded_count_rate_is_labelled_where_the_arithmetic_puts_it():
    # 15.38 rpm: 2.051 counts per sample; the count rate's harmonics m = 1, 2, 3 fold to
    # 0.0507 m counts per sample = 7.86, 15.73, 23.59 cycles/rad, below the limit (39.8): they are real
    # torque (the loop's reaction to the counts, 0.02-0.13 mNm) but not position-locked lines
    res = _twin_spectrum(2000, 15.38)
    # where the arithmetic puts them at the commanded speed; the loop holds the mean speed to about a
    # count over the travel (q / 15.8 rad = 2e-4 relative), which moves harmonic m by up to
    # m 2e-4 / q = 0.064 m cycles/rad
    predicted = quantisation_lines(Q_COARSE, 15.38 * 2 * math.pi / 60 * 4e-3)
    assert [round(f, 2) for f, m in predicted if m <= 3] == [7.86, 15.73, 23.59]
    n_labelled = 0
    for s in res.segments:
        for p in s.peaks:
            if p.quantisation_harmonic is not None:
                n_labelled += 1
                m = p.quantisation_harmonic
                assert p.label == f"encoder counts x{m}, folded"
                assert min(abs(f - p.frequency) for f, mm in predicted if mm == m) < 0.07 * m
        # the motor shaft line (declared) is still measured: 0.133 mNm in the truth, 1 % scatter
        # between runs and se ~ 4e-6 Nm: within 10 %
        assert s.peak("motor shaft").amplitude == pytest.approx(1.33e-4, rel=0.1)
    assert n_labelled >= 4
    assert res.unexplained(max_fap=1e-3).empty


def test_a_line_above_the_limit_is_not_measured_and_below_it_is():
    # 2 rpm sampling, one line at 60 cycles/rad (a 377-tooth mesh on the motor shaft), noise 1e-4 Nm:
    # amplitude se = 1e-4 sqrt(2 / 2400) = 2.9e-6, so 3 % of 1e-3 is 10 se
    rng = np.random.default_rng(5)
    true = 25.0 + SPACING_2RPM * np.arange(2400)
    f_mesh = 377 / (2 * math.pi)
    y = 8.5e-3 + 1e-3 * np.sin(2 * math.pi * f_mesh * true + 0.3) + rng.normal(0, 1e-4, true.size)
    gear = GearTrain.from_dict({"name": "mesh", "reference": "motor", "unit": "rad",
                                "stages": [{"name": "spur", "kind": "spur", "ratio": 3, "teeth": 377}]})
    for theta in (true, Q_FINE * np.rint(true / Q_FINE)):     # float, fine encoder: measured
        s = analyze_segment(theta, y, gear)
        assert s.peak("spur tooth mesh").amplitude == pytest.approx(1e-3, rel=0.03)
    coarse = analyze_segment(Q_COARSE * np.rint(true / Q_COARSE), y, gear)   # limit 39.8 < 60
    assert coarse.peak("spur tooth mesh") is None
    assert coarse.to_dict()["above_quantisation_limit"] == ["spur tooth mesh"]
    assert all(p.frequency < 1 / (8 * Q_COARSE) for p in coarse.peaks)
    assert analyze_segment(true, y, gear).to_dict()["quantisation_limit"] is None   # JSON: no limit


def test_no_false_alarm_probability_or_standard_error_of_zero_by_underflow():
    # a power ratio of 1e20 over 50 noise bins (k = 25): (1 + z/k)^-k = 1e-475 underflows a double;
    # the probability is below the float precision, not 0; 0 only for an infinite ratio
    p = false_alarm_probability(np.array([1e20, np.inf]), 100.0, np.array([50, 50]), 2.0)
    assert p[0] == np.finfo(float).tiny and p[1] == 0.0
    assert false_alarm_probability(5.0) == pytest.approx(math.exp(-5.0))   # unchanged where it is representable
    # a fit whose covariance is 0: standard errors at the float precision of the estimate, not 0
    theta = np.linspace(0, 10, 500)
    fit = harmonic_fit(theta, 2e-3 * np.sin(2 * math.pi * 1.3 * theta), [1.3]).scaled([0.0])
    assert fit.amplitude_se[0] == pytest.approx(np.finfo(float).eps * 2e-3, rel=1e-6, abs=0)
    assert fit.phase_se[0] > 0


def test_the_report_states_the_limit_where_it_limits():
    from gearspec.report.spectrum import _quantisation_sentence

    text = " ".join(_quantisation_sentence(_twin_spectrum(2000, 2.0)))
    assert "encoder step 0.003142 rad" in text and "segments 0-1" in text and "(39.79 cycles/rad)" in text
    assert _quantisation_sentence(_twin_spectrum(65536, 2.0)) == []   # above the Nyquist frequency: not stated


def test_the_speed_ripple_sidebands_of_a_folded_count_line_are_labelled():
    # 50 rpm: 6.67 counts per sample, the count rate folds to 1/(3 spacing) = 15.92 cycles/rad; the
    # speed ripple at the motor shaft's frequency (1/(2 pi) = 0.159 cycles/rad) modulates it: lines at
    # 15.92 +- j 0.159 (fap 1e-5..1e-14 without a label before), labelled as its sidebands
    res = _twin_spectrum(2000, 50.0, repetitions=1)
    s = res.segments[0]
    carrier = [p for p in s.peaks if p.label == "encoder counts x1, folded"]
    assert len(carrier) == 1 and carrier[0].frequency == pytest.approx(2000 / (2 * math.pi) / 20, abs=1 / s.span)
    side = [p for p in s.peaks if p.label is not None and p.label.startswith("encoder counts x1, folded, ")]
    assert len(side) >= 3
    for p in side:
        j = int(p.label.split(", ")[2].split("x")[0])
        assert p.frequency == pytest.approx(carrier[0].frequency + j / (2 * math.pi), abs=1 / s.span)
    assert res.unexplained(max_fap=1e-3).empty


def test_a_count_line_at_the_limit_leaks_below_it_and_is_labelled():
    # 20 rpm, one of the default twin's speeds: 8/3 counts per sample folds the count rate to
    # 1/(3 spacing) = 1/(8 q) = 39.79 cycles/rad, exactly the quantisation limit; its leakage into
    # the last bins searched (39.71, fap 1e-11 and 1e-18) is that line, within 3 resolution steps
    res = _twin_spectrum(2000, 20.0)
    edge = [p for s in res.segments for p in s.peaks
            if p.frequency > s.quantisation_limit - 3 / s.span and not p.declared]
    assert len(edge) >= 1 and all(p.label == "encoder counts x1, folded" for p in edge)
    assert res.unexplained(max_fap=1e-3).empty
