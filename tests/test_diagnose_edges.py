"""Plateau edges the loop leaves out (gearspec.segment.trim, DiagnoseData.without_edges) and
accelerations that are round-off.

Test data: the SILO4 twin's truth (``table2_model``) on plateaus at 500 Hz joined by linear ramps,
the twin's inertia in the drive torque and removed again as the gear declares it, without noise:
inside a plateau the position is a straight line, so the Savitzky-Golay acceleration is 0 up to
round-off and ``y`` is the friction exactly; only the first and last half filter window (11 samples
at 500 Hz: 5 rows) see the ramp.  Known answers: 5 rows cut at each end, and ``y`` equal to the
truth to 1e-9 Nm in what is kept (round-off of ``J * acc`` with ``acc`` ~ 1e-9 rad/s^2 and
``J`` ~ 1e-6 kg m^2 is far below); the rows cut carry inertia-torque errors of 0.1 mNm and more.
"""

from __future__ import annotations

import numpy as np

import gearspec.diagnose as dg
from gearspec.diagnose.residual import acceleration_analysis
from gearspec.segment import find_segments
from gearspec.segment.trim import edge_rows, trim_edges
from gearspec.simulate import model_recording, table2_model, twin_gear

SPEEDS = [3.0, -30.0, 300.0, -600.0]


def _twin(noise=0.0, seed=0):
    gear = twin_gear()
    rec, _ = model_recording(table2_model(), SPEEDS, noise=noise, gear=gear, seed=seed, duration=0.8, fs=500.0,
                             one_run_per_plateau=True, inertia=gear.inertia)
    return rec


def _edge_error(dd):
    """Largest |y - truth| (Nm) over the first and last 6 rows of every segment, and elsewhere."""
    truth = table2_model().evaluate(dd.at("theta"), dd.at("v"))
    err = np.abs(dd.y - truth)
    edge = np.zeros(len(err), bool)
    for a, z in zip(dd.starts, dd.stops):
        edge[a:a + 6] = edge[z - 6:z] = True
    return float(err[edge].max()), float(err[~edge].max())


def test_plateau_edges_whose_acceleration_sees_the_ramp_are_cut():
    rec = _twin()
    seg = find_segments(rec)
    h = edge_rows(rec.t[seg.segments[0].rows])
    assert h == 5    # SG window max(7, round(0.02 s * 500 Hz) | 1) = 11 samples: 5 on each side of a row
    cut = trim_edges(rec, seg)
    assert [s.n for s in cut.segments] == [s.n - 10 for s in seg.segments]
    assert cut.excluded["edge"] == 10 * len(seg)
    cut.check_ledger()
    whole = dg.DiagnoseData.from_recording(rec)
    kept = whole.without_edges()        # what diagnose works on
    assert len(whole) - len(kept) == 10 * len(seg)
    e_edge, e_mid = _edge_error(kept)
    assert e_edge < 1e-9 and e_mid < 1e-9     # what is kept is the friction (noise-free data)
    e_edge_whole, _ = _edge_error(whole)
    assert e_edge_whole > 1e-4                 # the rows cut carried the ramp's inertia torque


def test_accelerations_at_round_off_make_no_inertia_evidence():
    """On trimmed exact plateaus the accelerations are round-off (~1e-9 rad/s^2): a residual with a
    trend in time would otherwise give a 'slope against acceleration' of 1e6 kg m^2 at high t."""
    rec = _twin()
    dd = dg.DiagnoseData.from_recording(rec).without_edges()
    assert np.max(np.abs(dd.at("acc"))) < 1e-6
    r = 1e-4 * dd.at("t") + np.random.default_rng(1).normal(0, 1e-5, len(dd))   # a drift in time
    table, st = acceleration_analysis(dd, r)
    assert st["roundoff"] and st["p"] == 1.0 and len(table) == 0
    # with the ramps' rows the accelerations are data again and the analysis tests them
    whole = dg.DiagnoseData.from_recording(rec)
    _, st2 = acceleration_analysis(whole, 1e-4 * whole.at("t"))
    assert "roundoff" not in st2 and np.isfinite(st2["slope"])


def test_segment_edge_transients_are_not_discovered():
    """Seed 16 of the false-discovery test: with the ramp rows in the data the loop accepted an
    extra Stribeck term (Z 4.0, needs 3.5); they are cut, and nothing is accepted.  What is left of
    the accelerations is round-off: no inertia candidate is tested on it."""
    from test_false_discoveries import complete_twin

    rec, gear = complete_twin(16)
    d = dg.diagnose(rec, law="silo4", gear=gear, per_segment_spectra=False)
    assert [e.name for e in d.accepted] == []
    assert not [e.name for e in d.effects if e.kind == "inertia"]
