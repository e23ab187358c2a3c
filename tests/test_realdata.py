"""The spectrum on real measured data (GEARSPEC_DATA): Kinova Gen3 joint 7 and EMPS."""

import numpy as np
import pytest

import gearspec.datasets as ds
from gearspec.spectrum import analyze

pytestmark = pytest.mark.realdata


@pytest.fixture(scope="module")
def kinova(data_dir):
    rec = ds.load("kinova_gen3_joint7")
    return rec, analyze(rec)


def test_kinova_2x_wave_generator_found_and_labelled_at_low_speeds(kinova):
    rec, res = kinova
    assert len(res.segments) == 10                      # one plateau per run, every run
    low = [s for s in res.segments if s.speed < 0.2]
    assert len(low) >= 3
    for s in low:
        p = s.peak("strain-wave 2x wave generator")
        assert p is not None and p.declared
        assert p.frequency == pytest.approx(200 / (2 * np.pi))       # 31.83 cycles/rad at ratio 100
        assert p.amplitude > 4 * p.amplitude_se and p.fap < 1e-3
        assert 0.02 < p.amplitude < 0.06                                 # Nm
    # the same line, with the same phase to within its error, at every speed above the stick-slip
    mid = [s.peak("strain-wave 2x wave generator") for s in res.segments if 0.1 < s.speed < 1.0]
    ph = np.unwrap([p.phase for p in mid])
    assert np.ptp(ph) < 1.0


def test_kinova_strongest_unexplained_line_is_seven_per_motor_turn(kinova):
    rec, res = kinova
    un = res.unexplained()
    fast = un[un["speed"] > 0.3]
    top = fast.loc[fast.groupby("segment")["amplitude"].idxmax()]
    # at every speed above 0.3 rad/s the strongest unexplained peak sits at 7 x the motor shaft
    near7 = np.abs(top["frequency"] / (100 / (2 * np.pi)) - 7) < 0.01
    assert near7.mean() >= 0.8
    assert all(isinstance(h, str) and h.startswith("7x motor shaft") for h in top[near7]["hint"])


def test_emps_spectrum_per_plateau_in_cycles_per_metre(data_dir, tmp_path):
    import json

    rec = ds.load("emps")
    res = analyze(rec, keep_spectra=True)
    d = res.to_dict()
    assert d["frequency_unit"] == "cycles/m" and d["torque_unit"] == "N"
    for direction in (1, -1):
        for target in (0.04, 0.08, 0.12):
            segs = [s for s in res.segments if s.direction == direction and abs(s.speed - target) < 0.2 * target]
            assert segs, (direction, target)
            assert all(s.fft_frequency is not None and s.fft_frequency[-1] > 1000 for s in segs)
    # the strongest position-locked line of the axis: ~400 cycles/m (every 2.5 mm) at 0.08 m/s
    s08 = [s for s in res.segments if abs(s.speed - 0.08) < 0.016]
    f_top = [max(s.peaks, key=lambda p: p.amplitude).frequency for s in s08 if s.peaks]
    assert np.median(f_top) == pytest.approx(400, rel=0.02)
    json.loads(json.dumps(d, default=float))
