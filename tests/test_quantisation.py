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
