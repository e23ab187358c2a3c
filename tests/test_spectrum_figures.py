"""The spectrum report's figures drawn in worker processes (``report.spectrum._draw_figures`` on
``core.parallel.forked_map``) and saved at a cheaper zlib level (``plots.save``): the same pictures
as the serial loop, the pages numbered as that loop numbers them.

The recording: 4 speeds x 2 directions x 2 repetitions = 16 plateaus, a motor-shaft ripple; one
segment is marked not fitted (it has no spectra to draw), so that the pages hold 8 and 7 panels.
"""

import copy
from dataclasses import replace

import numpy as np
import pytest
from matplotlib.image import imread

from gearspec import plots
from gearspec.core import parallel
from gearspec.gears import load_gear
from gearspec.report.spectrum import write_spectrum_report
from gearspec.segment import find_segments
from gearspec.simulate import Ripple, plateau_recording
from gearspec.spectrum import analyze
from gearspec.spectrum.pipeline import attach_spectra, can_hold_spectra

fork_only = pytest.mark.skipif(parallel.can_fork() is False, reason="no fork on this system")
UNFITTED = 3


@pytest.fixture(scope="module")
def case():
    speeds = [d * v for _ in range(2) for v in (20, 35, 60, 100) for d in (1, -1)]
    rec, _ = plateau_recording(speeds, ripples=[Ripple(1 / (2 * np.pi), 1e-3)], level=0.01, duration=1.0,
                               fs=1000, noise=1e-4, seed=3, gear=load_gear("silo4-joint3"), one_run_per_plateau=True)
    seg = find_segments(rec)
    res = analyze(rec, segmentation=seg, progress=False)
    assert len(res.segments) == 16 and all(s.fit is not None for s in res.segments)
    res.segments[UNFITTED] = replace(res.segments[UNFITTED], fit=None)
    assert not can_hold_spectra(res.segments[UNFITTED])
    return rec, seg, res


def _pixels(path):
    return imread(str(path))


@fork_only
def test_figures_from_two_workers_are_those_of_the_serial_loop(case, tmp_path, monkeypatch):
    rec, seg, res = case
    monkeypatch.setenv("GEARSPEC_THREADS", "2")     # two workers, whatever the test run's default
    # the reference: every page drawn in one call after the spectra are attached (the code before)
    ref = copy.deepcopy(res)
    assert attach_spectra(ref, rec, range(16)) == [i for i in range(16) if i != UNFITTED]
    ref_pages = plots.plot_order_spectra(ref, str(tmp_path / "ref_{:02d}.png"), indices=range(16))
    assert [p.name for p in ref_pages] == ["ref_01.png", "ref_02.png"]      # 15 panels: 8 + 7

    work = copy.deepcopy(res)
    write_spectrum_report(work, rec, seg, tmp_path / "two", pages="all")
    # drawn in the workers: the spectra were computed there, this process's result is untouched
    assert all(s.fft_frequency is None for s in work.segments)
    monkeypatch.setenv("GEARSPEC_THREADS", "1")
    one = copy.deepcopy(res)
    write_spectrum_report(one, rec, seg, tmp_path / "one", pages="all")
    assert sum(s.fft_frequency is not None for s in one.segments) == 15   # the loop, here

    for k in (1, 2):
        ref_px = _pixels(tmp_path / f"ref_{k:02d}.png")
        for d in ("two", "one"):
            assert np.array_equal(_pixels(tmp_path / d / f"spectra_{k:02d}.png"), ref_px), (d, k)
    assert not (tmp_path / "two" / "spectra_03.png").exists()
    names = sorted(p.name for p in (tmp_path / "two").glob("*.png"))
    assert names == sorted(p.name for p in (tmp_path / "one").glob("*.png")) and len(names) == 6   # nothing unexplained: no such figure
    for n in names:
        assert np.array_equal(_pixels(tmp_path / "two" / n), _pixels(tmp_path / "one" / n)), n
    assert (tmp_path / "two" / "report.md").read_text() == (tmp_path / "one" / "report.md").read_text()


def _zlib_level_flag(path) -> int:
    """FLEVEL of the zlib stream in a PNG's first IDAT chunk: 0 fastest, 1 fast, 2 default, 3 best."""
    data = path.read_bytes()
    at = data.index(b"IDAT") + 4
    return data[at + 1] >> 6


def test_save_writes_the_default_pixels_at_a_faster_zlib_level(tmp_path):
    def figure():
        fig, ax = plots.plt.subplots(figsize=(4, 3))
        x = np.linspace(0, 10, 2000)
        ax.plot(x, np.sin(3 * x) + 0.1 * np.cos(40 * x), lw=0.7)
        ax.set_title("zlib")
        return fig

    fig = figure()
    fig.savefig(tmp_path / "default.png", dpi=110)     # matplotlib / PIL default: zlib level 6
    plots.plt.close(fig)
    path = plots.save(figure(), tmp_path / "fast.png", tight=False)
    assert plots.PNG_COMPRESS_LEVEL == 3
    assert _zlib_level_flag(tmp_path / "default.png") == 2 and _zlib_level_flag(path) == 1
    assert np.array_equal(_pixels(path), _pixels(tmp_path / "default.png"))
