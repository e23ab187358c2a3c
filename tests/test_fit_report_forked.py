"""``gearspec fit``'s report draws its figures in forked workers (:func:`gearspec.core.parallel.forked_map`):
the files are those of the loop in this process, byte for byte (GEARSPEC_THREADS=1 against 2)."""

import os

import numpy as np
import pytest

from gearspec.core import parallel
from gearspec.identify import identify_recording
from gearspec.model import FrictionModel
from gearspec.report.fit import write_fit_report
from gearspec.segment import find_segments
from gearspec.simulate import model_recording


@pytest.fixture(scope="module")
def result():
    truth = FrictionModel("silo4", {"tau_c": 0.02, "tau_s": 0.03, "v_s": 2.0, "viscous": 1e-4,
                                    "harmonics": [{"frequency": 0.8, "amplitude": 2e-3, "decay": 0.01}]})
    sp = [1.0, -1.0, 5.0, -5.0, 30.0, -30.0, 80.0, -80.0] * 2
    rec, _ = model_recording(truth, sp, duration=[max(1.0, 3.0 / (0.8 * abs(v))) for v in sp], fs=500, ramp=0.1,
                             noise=2e-4, seed=2)
    return identify_recording(rec, "silo4", segmentation=find_segments(rec), harmonics=[{"frequency": 0.8}],
                              published=False)


@pytest.mark.skipif(not parallel.can_fork(), reason="forked workers need fork")
def test_forked_figures_are_the_loop_s(result, tmp_path, monkeypatch):
    calls = []
    orig = parallel.forked_map

    def spy(fn, items, **kw):
        calls.append((os.environ.get("GEARSPEC_THREADS"), len(items)))
        return orig(fn, items, **kw)

    monkeypatch.setattr("gearspec.report.fit.forked_map", spy)
    files = {}
    for threads in ("1", "2"):
        monkeypatch.setenv("GEARSPEC_THREADS", threads)
        write_fit_report(result, tmp_path / threads, command="gearspec fit x")
        files[threads] = {p.name: p.read_bytes() for p in sorted((tmp_path / threads).iterdir())}
    assert calls == [("1", 4), ("2", 4)]          # four figures: Stribeck, amplitudes, position, residuals
    assert set(files["1"]) == set(files["2"]) >= {"stribeck.png", "model_vs_data.png",
                                                   "residuals.png", "report.md"}
    for name in files["1"]:
        assert files["1"][name] == files["2"][name], name
    assert np.all([len(b) > 1000 for n, b in files["2"].items() if n.endswith(".png")])
