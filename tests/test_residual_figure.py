"""Issue 10 item 8 / issue 16: the residual-spectrum figure of ``diagnose`` was cut below the
frequency of the line the loop accepted (the all-speed pool stops below the Nyquist frequency of
its fastest segment; the line had been found in the slow pool), and drew no marker for it."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

import gearspec.plots.diagnose as dplots
from gearspec.diagnose.residual import ResidualSpectrum


def _pool(direction, speeds, n_seg, f_hi, peak=None):
    f = np.linspace(0.005, f_hi, 400)
    amp = np.full(f.size, 4e-6)
    if peak is not None:
        amp[np.argmin(abs(f - peak))] = 3e-5
    return ResidualSpectrum(direction, speeds[0], speeds[1], list(range(n_seg)), 1000, 300.0, f, amp,
                            np.full(f.size, 4e-6))


def test_residual_spectra_extend_past_and_mark_every_candidate(tmp_path, monkeypatch):
    spectra = [_pool(1, (31.4, 157.1), 6, 0.65),                 # all speeds: stops at 0.65
               _pool(1, (31.4, 31.4), 2, 3.2, peak=1.114),        # the slow pool reaches 3.2
               _pool(-1, (31.4, 157.1), 6, 0.65)]                  # negative: no slow pool at all
    effects = [SimpleNamespace(kind="periodic", frequency=1.114, accepted=True, label=None, hint="7x motor shaft"),
               SimpleNamespace(kind="periodic", frequency=0.4775, accepted=False, label="3x motor shaft", hint=None),
               SimpleNamespace(kind="speed_law", frequency=None, accepted=False, label=None, hint=None)]
    figs = []
    monkeypatch.setattr(dplots, "save", lambda fig, path: figs.append(fig) or path)
    dplots.plot_spectra(spectra, effects, tmp_path / "r.png")
    (fig,) = figs
    axes = fig.axes
    assert len(axes) == 2
    for ax in axes:
        lo, hi = ax.get_xlim()
        assert lo < 0.4775 and hi > 1.114 * 1.2                   # past every candidate line
        xs = sorted(round(float(ln.get_xdata()[0]), 4) for ln in ax.lines if len(set(ln.get_xdata())) == 1)
        assert xs == [0.4775, 1.114]                               # a marker for each candidate
        tags = sorted(t.get_text().split(" ")[0] for t in ax.texts)
        assert tags == ["1", "2"]                                  # a numbered tag on each line
    # the key below the axes names each tag: 1 = 0.4775 (3x motor shaft), 2 = 1.114 (7x motor shaft)
    key = " | ".join(t.get_text() for t in fig.texts)
    assert "1: 0.4775 cycles/rad, 3x motor shaft (rejected)" in key
    assert "2: 1.114 cycles/rad, 7x motor shaft (accepted)" in key
    # the positive panel draws the slow pool that reaches the accepted line; the negative has none
    # and says the line is beyond its spectra
    assert any("31.4-31.4" in (ln.get_label() or "") for ln in axes[0].lines)
    assert "beyond the spectra" in " ".join(t.get_text() for t in axes[1].texts)
    assert "beyond the spectra" not in " ".join(t.get_text() for t in axes[0].texts if t.get_text().startswith("2"))


def test_fit_residuals_draw_repetitions_as_markers_and_join_only_medians(tmp_path, monkeypatch):
    """Issue 16: the fit's residual figure joined the repetitions of a speed with lines (a tangle).
    3 speeds x 3 repetitions per direction: each segment a marker, one line through the 3 medians;
    errors of 0.1-0.3 mNm drawn in mNm."""
    import pandas as pd

    import gearspec.plots.fit as fplots

    speeds = np.repeat([10.0, 20.0, 40.0], 3) * (1 + np.tile([-0.01, 0.0, 0.01], 3))
    rows = [{"direction": d, "speed": v, "e": d * 1e-4 * (1 + k % 3), "rmse": 3e-4 + 1e-5 * k}
            for d in (1, -1) for k, v in enumerate(speeds)]
    figs = []
    monkeypatch.setattr(fplots, "save", lambda fig, path: figs.append(fig) or path)
    fplots.plot_residuals({"joint": pd.DataFrame(rows)}, tmp_path / "r.png")
    (fig,) = figs
    for ax in fig.axes:
        joined = [ln for ln in ax.lines if ln.get_linestyle() not in ("None", "") and not ln.get_label().startswith("_")]
        markers = [ln for ln in ax.lines if ln.get_linestyle() in ("None", "")]
        assert len(joined) == 2 and all(len(ln.get_xdata()) == 3 for ln in joined)   # one median per speed
        assert sorted(len(ln.get_xdata()) for ln in markers) == [9, 9]              # every segment, unjoined
        assert "mNm" in ax.get_ylabel()
    rm = [ln for ln in fig.axes[1].lines if len(ln.get_xdata()) == 3][0]
    # the median rmse of the first speed's three repetitions (k = 0, 1, 2 on the positive side): 0.31 mNm
    assert float(rm.get_ydata()[0]) == pytest.approx(0.31, rel=1e-9)


def test_diagnose_segment_errors_join_only_medians_and_draw_present_directions(tmp_path, monkeypatch):
    """Issue 16: diagnose's segment_errors.png joined every held-out group in speed order (a vertical
    tangle at a repeated speed) and drew an empty panel for a direction never driven.  3 speeds x 3
    repetitions in one direction: one panel; the lines go through the 3 medians only."""
    import pandas as pd

    speeds = np.repeat([0.04, 0.08, 0.12], 3) * (1 + np.tile([-0.01, 0.0, 0.01], 3))
    t = pd.DataFrame({"direction": 1, "speed": speeds, "rmse_holdout_before": np.linspace(1, 2, 9),
                      "rmse_holdout_after": np.linspace(0.5, 1, 9), "rmse_after": np.linspace(0.4, 0.9, 9)})
    figs = []
    monkeypatch.setattr(dplots, "save", lambda fig, path: figs.append(fig) or path)
    dplots.plot_segment_errors(t, tmp_path / "s.png", torque_unit="N", unit="m")
    (fig,) = figs
    assert len(fig.axes) == 1 and "positive direction only" in fig._suptitle.get_text()
    joined = [ln for ln in fig.axes[0].lines if ln.get_linestyle() in ("-", "--")]
    assert len(joined) == 2 and all(len(ln.get_xdata()) == 3 for ln in joined)
