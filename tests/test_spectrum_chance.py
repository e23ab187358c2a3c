"""Peaks no declared line explains, counted against chance: a peak's false-alarm probability counts
the frequencies searched in its own segment only, so a recording of S segments shows about
``fap x S`` peaks from noise alone; the console and the report say how many that is beside the
count (400 segments of white noise around the declared lines gave 4 peaks at fap <= 0.01, which
the console had called "4 significant peak(s)")."""

from __future__ import annotations

import numpy as np
import pytest

from gearspec.gears import load_gear
from gearspec.simulate import Ripple, plateau_recording
from gearspec.spectrum import analyze


@pytest.fixture(scope="module")
def noise_only():
    """120 plateaus (60 speeds per direction, 1.5 s at 1 kHz): the gear's declared lines and white
    noise, nothing else."""
    gear = load_gear("silo4-joint3")
    rpm = np.geomspace(60, 3000, 60)
    speeds = [d * r * 2 * np.pi / 60 for r in rpm for d in (1, -1)]
    lines = [Ripple(ln.frequency, 2e-4) for ln in gear.declared_lines(1)]
    rec, _ = plateau_recording(speeds, ripples=lines, level=0.008, duration=1.5, fs=1000.0, noise=3e-4,
                               one_run_per_plateau=True, seed=5, gear=gear)
    return analyze(rec, gear, progress=False, keep_spectra=False)


def test_peaks_from_noise_are_as_many_as_chance_says(noise_only):
    res = noise_only
    S = len(res.segments)
    assert S == 120
    assert res.chance_peaks(0.01) == pytest.approx(1.2)
    # noise alone: a count of mean at most about 1.2 (each segment's search calibrated to 0.01 or
    # below; measured: 0.4 on average over seeds 0-9); 7 or more has probability 1.6e-4 at 1.2
    n = len(res.unexplained(0.01))
    assert n <= 6, res.unexplained(0.01)
    text = res.unexplained_sentence(0.01)
    assert text.startswith(f"{n} peak(s) no declared line explains")
    assert "120 segment(s) searched: up to about 1.2 expected from noise alone" in text
