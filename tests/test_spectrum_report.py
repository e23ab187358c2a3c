"""The spectrum report at scale: groups of repetitions, representative segments, pages drawn only
for them (spectra computed afterwards, identical), the console's summary per speed and direction.

The recording: 7 speeds x 2 directions x 2 repetitions = 28 plateaus (more than the console's
one-line-per-segment limit, more groups than ``--pages auto`` draws), a motor-shaft ripple of
1 mNm in both directions and an undeclared 0.5 mNm line at 2.3 cycles/rad in the negative
direction only (so the negative segments are the informative ones).
"""

import json
import re

import numpy as np
import pytest

from gearspec.cli import main
from gearspec.core import parallel
from gearspec.errors import InputError
from gearspec.gears import load_gear
from gearspec.plots.spectrum import _envelope, _spread
from gearspec.report.spectrum import write_spectrum_report
from gearspec.segment import find_segments
from gearspec.simulate import Ripple, plateau_recording
from gearspec.spectrum import analyze
from gearspec.spectrum.pipeline import attach_spectra
from gearspec.spectrum.results import REPRESENTATIVES, SPEED_GROUP_TOL, speed_groups

SPEEDS = [20, 30, 40, 55, 70, 90, 120]  # rad/s, > 5 % apart (one group each)
MOTOR_AMPLITUDE = 1e-3                  # Nm at 1/(2 pi) cycles/rad: the motor shaft of silo4-joint3
EXTRA = Ripple(2.3, (0.0, 5e-4))        # undeclared, negative direction only
NOISE = 1e-4                            # Nm, white


@pytest.fixture(scope="module")
def twin(tmp_path_factory):
    speeds = [d * v for _ in range(2) for v in SPEEDS for d in (1, -1)]  # one run each
    rec, _ = plateau_recording(speeds, ripples=[Ripple(1 / (2 * np.pi), MOTOR_AMPLITUDE), EXTRA], level=0.01,
                               duration=1.5, fs=1000, noise=NOISE, seed=7, gear=load_gear("silo4-joint3"),
                               one_run_per_plateau=True)
    path = rec.save(tmp_path_factory.mktemp("twin") / "rec.csv")
    seg = find_segments(rec)
    res = analyze(rec, segmentation=seg, progress=False)
    return rec, seg, res, path


def test_speed_groups_are_the_repetitions_of_each_speed_and_direction(twin):
    _, seg, res, _ = twin
    assert len(res.segments) == 28
    groups = res.speed_groups()
    # 7 speeds x 2 directions, 2 repetitions each; the median speed within the plateaus' ripple-free 1 %
    assert [(d, len(g)) for d, _, g in groups] == [(1, 2)] * 7 + [(-1, 2)] * 7
    assert [v for _, v, _ in groups] == pytest.approx(SPEEDS * 2, rel=0.01)
    for d, _, g in groups:
        assert all(res.segments[i].direction == d for i in g)
    # the rule: a speed more than SPEED_GROUP_TOL above the previous one starts a group
    assert SPEED_GROUP_TOL == 0.05 and min(np.diff(np.log(SPEEDS))) > np.log(1.05)


def test_representatives_pick_the_informative_groups(twin):
    _, _, res, _ = twin
    neg = {i for d, _, g in res.speed_groups() if d < 0 for i in g}
    # every negative segment shows the undeclared 2.3 cycles/rad line (5 times the noise amplitude
    # sqrt(2/n) * 1e-4 * 30 or so: found at fap < 0.01 whatever the seed), no positive one does
    for i, s in enumerate(res.segments):
        found = [p for p in s.peaks if not p.declared and p.fap <= 0.01 and abs(p.frequency - 2.3) < 0.05]
        assert bool(found) == (i in neg), i
    picks = res.representatives(7)
    assert len(picks) == 7 and set(picks) <= neg  # the seven negative groups, one segment each
    assert len({res.segments[i].speed // 1 for i in picks}) == 7
    assert len(res.representatives()) == REPRESENTATIVES == 12  # 14 groups: the default limit binds
    assert len(res.representatives(100)) == 14                  # one per group when there is room


def test_attached_spectra_equal_those_of_a_full_pass(twin):
    rec, seg, res, _ = twin
    full = analyze(rec, segmentation=seg, progress=False, keep_spectra=True)
    assert all(s.fft_frequency is None for s in res.segments)
    done = attach_spectra(res, rec, [3, 20])
    assert done == [3, 20] and attach_spectra(res, rec, [3]) == []  # computed once
    for i in (3, 20):
        for name in ("fft_frequency", "fft_amplitude", "ls_frequency", "ls_amplitude", "noise_amplitude"):
            np.testing.assert_array_equal(getattr(res.segments[i], name), getattr(full.segments[i], name))
    assert res.segments[4].fft_frequency is None


def test_envelope_keeps_every_peak_and_bounds_the_points():
    f = np.linspace(0, 100, 200_001)
    a = np.full_like(f, 1e-6)
    a[[5000, 123_457, 199_999]] = [3e-3, 2e-3, 1e-3]
    fe, ae = _envelope(f, a, 1500)
    assert len(fe) <= 1500 and (fe > 0).all()
    assert sorted(ae)[-3:] == [1e-3, 2e-3, 3e-3]
    # each peak at a frequency within its bin (log width 100/5e-4 over 1500 bins: 0.8 %)
    for k in (5000, 123_457, 199_999):
        j = np.flatnonzero(ae == a[k])[0]
        assert fe[j] == pytest.approx(f[k], rel=0.01)
    assert len(_envelope(f[:2000], a[:2000], 1500)[0]) == 1999  # short: as is (f = 0 left out)


def test_spread_keeps_first_and_last():
    runs = _spread(list(range(80)), 24)
    assert len(runs) == 24 and runs[0] == 0 and runs[-1] == 79 and runs == sorted(set(runs))
    assert _spread([1, 2, 3], 24) == [1, 2, 3]


def test_report_auto_draws_pages_for_the_representatives_only(twin, tmp_path):
    rec, seg, res, _ = twin
    out = tmp_path / "auto"
    before = sum(s.fft_frequency is not None for s in res.segments)
    write_spectrum_report(res, rec, seg, out, pages="auto")
    pages = sorted(p.name for p in out.glob("spectra_*.png"))
    assert pages == ["spectra_01.png", "spectra_02.png"]  # 12 segments, 8 a page
    text = (out / "report.md").read_text()
    assert "Pages for 12 of 28 segments" in text and "--pages all draws every one" in text
    assert "![summary](spectrum_summary.png)" in text and (out / "spectrum_summary.png").stat().st_size > 10_000
    # the spectra of the pages are computed where the pages are drawn (worker processes when the
    # machine has two CPUs: this process's result then holds none of them)
    held = sum(s.fft_frequency is not None for s in res.segments)
    assert held == before if parallel.worker_count() > 1 else held >= 12


def test_report_pages_none_and_a_bad_choice(twin, tmp_path):
    rec, seg, res, _ = twin
    out = tmp_path / "none"
    write_spectrum_report(res, rec, seg, out, pages="none")
    assert not list(out.glob("spectra_*.png"))
    assert "No page of spectra drawn (--pages none)" in (out / "report.md").read_text()
    with pytest.raises(InputError, match="--pages must be one of auto, all, none"):
        write_spectrum_report(res, rec, seg, tmp_path / "bad", pages="some")


def test_cli_prints_a_summary_per_speed_and_direction(twin, tmp_path, capsys):
    _, _, _, path = twin
    js = tmp_path / "s.json"
    assert main(["spectrum", str(path), "--gear", "silo4-joint3", "--json", str(js)]) == 0
    out = capsys.readouterr().out
    assert out.startswith("28 segments;")
    rows = [ln for ln in out.splitlines() if re.match(r"^ [+-]1 ", ln)]
    assert len(rows) == 14  # one line per speed and direction, not 28
    # the median motor-shaft amplitude of each group: 1 mNm within 3 % (the amplitude's se is
    # sqrt(2/n) 1e-4 ~ 4e-6 Nm for n ~ 1400 samples; 3 % is 7 se, and the print has 3 digits)
    amps = [float(re.search(r"motor shaft: ([0-9.e+-]+)", ln).group(1)) for ln in rows]
    assert amps == pytest.approx([MOTOR_AMPLITUDE] * 14, rel=0.03)
    assert all(("unexplained peak" in ln) == ln.startswith(" -1") for ln in rows)
    d = json.loads(js.read_text())  # every segment stays in the JSON
    assert len(d["segments"]) == 28 and {"direction", "speed", "n", "run", "peaks"} <= set(d["segments"][0])


def test_speed_groups_of_rows_split_at_the_tolerance():
    # 10 and 10.4 (4 % apart) are one speed; 11 (5.8 % above 10.4) starts the next; directions apart
    gid = speed_groups([10.0, 10.4, 11.0, -10.0, 10.2, np.nan], [1, 1, 1, -1, -1, 1])
    assert gid.tolist() == [0, 0, 1, 2, 2, -1]


def test_single_speed_panel_has_no_axis_offset_text(tmp_path, monkeypatch):
    """Issue 16: a line measured at one speed only (the twin's output shaft at 680.68 rad/s, speeds
    equal to 1e-10) drew the axis offset "1e-10+6.806834017e2" over the x label."""
    import gearspec.plots.spectrum as splots

    v = 680.6834017
    rec, _ = plateau_recording([v, -v, v * (1 + 1e-12), -v], ripples=[Ripple(1 / (2 * np.pi), 1e-3)], duration=1.0,
                               fs=2000, noise=1e-4, seed=2, gear=load_gear("silo4-joint3"), one_run_per_plateau=True)
    res = analyze(rec, progress=False)
    figs = []
    monkeypatch.setattr(splots, "_save", lambda fig, path, **kw: figs.append(fig) or path)
    splots.plot_amplitude_vs_speed(res, tmp_path / "a.png")
    (fig,) = figs
    fig.canvas.draw()
    ax = next(a for a in fig.axes if a.get_title() == "motor shaft")
    assert ax.xaxis.get_offset_text().get_text() == ""
    lo, hi = ax.get_xlim()
    assert lo < v < hi and hi - lo >= 0.09 * v  # the points inside a range that reads
