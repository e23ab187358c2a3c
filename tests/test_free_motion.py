"""Identification from free motion (issue 12 item 2): bell-shaped moves with no plateau and no
declared inertia give the friction law, a decaying line and the inertia; the blocks, the ledger,
the held-out units and the vectorised per-block statistics.

The recordings are open loop: torque = the model's own evaluate at the true velocity + J x the
true acceleration + white noise (sd NOISE), positions exact; the fit sees only t, theta, torque.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from gearspec import identify
from gearspec.cli import main
from gearspec.core.reduction import group_normal_equations, normal_equations
from gearspec.fitdata import FitData
from gearspec.identify.stats import segment_stats, speed_ranges
from gearspec.model import FrictionModel
from gearspec.recording import Recording
from gearspec.segment import find_segments, free_motion
from gearspec.segment import freemotion as fm
from gearspec.simulate.synthetic import model_recording
from gearspec.spectrum import position_nyquist
from gearspec.spectrum.analysis import group_position_nyquist

NOISE = 2e-3     # Nm, white
J = 2e-3         # kg m^2
LINE = {"frequency": 3.0, "label": "line 3"}
H = {"frequency": 3.0, "amplitude": 0.02, "decay": 0.05, "phase": 0.7}
POS = {"tau_c": 0.3, "tau_s": 0.4, "v_s": 1.0, "viscous": 0.01, "harmonics": [H]}
NEG = {"tau_c": 0.25, "tau_s": 0.4, "v_s": 1.0, "viscous": 0.012, "harmonics": [dict(H, amplitude=0.015)]}
TRUTH = FrictionModel("silo4", POS, NEG)


def bell_moves(n_moves=12, top=20.0, fs=1000.0, seed=0):
    """Minimum-jerk moves there and back (velocity 30 A/T s^2 (1-s)^2), 1-3 s each, peak speeds
    30-100 % of ``top`` rad/s, 0.2 s at rest between them: no plateau anywhere."""
    rng = np.random.default_rng(seed)
    parts = []
    for i in range(n_moves):
        T = rng.uniform(1.0, 3.0)
        peak = rng.uniform(0.3, 1.0) * top
        s = np.arange(int(T * fs)) / (T * fs)
        parts += [(1 if i % 2 == 0 else -1) * peak / 1.875 * 30 * s ** 2 * (1 - s) ** 2, np.zeros(int(0.2 * fs))]
    return np.concatenate(parts)


def recording(v, fs=1000.0, seed=1, model=TRUTH, inertia=J, noise=NOISE):
    dt = 1.0 / fs
    theta = np.concatenate(([0.0], np.cumsum(0.5 * (v[1:] + v[:-1])) * dt))
    acc = np.gradient(v, dt)
    tau = model.evaluate(theta, v) + inertia * acc + np.random.default_rng(seed).normal(0, noise, len(v))
    return Recording.from_arrays(t=np.arange(len(v)) * dt, theta=theta, torque=tau, source="bell moves")


@pytest.fixture(scope="module")
def bells():
    rec = recording(bell_moves())
    data = FitData.from_recording(rec, motion="auto")
    return rec, data


@pytest.fixture(scope="module")
def fitted(bells):
    _, data = bells
    return identify.fit(data, "silo4", harmonics=[LINE], holdout="segment", folds=4)


# ---------------------------------------------------------------------- the known answer
def test_bell_moves_give_the_law_the_line_and_the_inertia(fitted):
    m = fitted
    d = m.to_dict()
    # the tolerances: Coulomb and viscous 5 %, amplitude 10 %, decay 30 %, inertia 5 %,
    # held-out rmse 1.5x the noise (measured: within 0.1 %, 0.2 %, 2 %, 4 %, 0.2 % and 1.08x)
    assert d["inertia"] == pytest.approx(J, rel=0.05)
    assert 0 < d["inertia_se"] < 0.01 * J
    for name, truth in (("positive", POS), ("negative", NEG)):
        P = m.params(name)
        assert P["tau_c"] == pytest.approx(truth["tau_c"], rel=0.05)
        assert P["viscous"] == pytest.approx(truth["viscous"], rel=0.05)
        # Coulomb and viscous also within four of their standard errors (no bias the errors hide)
        for k in ("tau_c", "viscous"):
            assert abs(P[k] - truth[k]) < 4 * P.se[k], (name, k)
        h = P.harmonics[0]
        assert h.amplitude == pytest.approx(truth["harmonics"][0]["amplitude"], rel=0.10)
        assert h.decay == pytest.approx(0.05, rel=0.30)
        # the amplitude law was fitted over the speeds the moves cover, from near rest
        assert h.speed_range[0] < 2.0 and h.speed_range[1] > 10.0
    assert m.rmse_holdout < 1.5 * NOISE
    # judged at each sample's own speed the model leaves the noise (measured 1.004x; the rms of 24,000
    # samples scatters by 0.5 %); at each block's mean speed it would leave viscous x the change of
    # speed within the block too (1.08x)
    assert m.rmse < 1.05 * NOISE
    assert any("inertia identified with the friction" in n for n in m.notes)


def test_the_same_law_from_plateaus_agrees_within_the_standard_errors(fitted):
    """The same friction driven by plateaus (inertia irrelevant there): Coulomb and viscous agree
    with the bell-move estimates within three standard errors of their difference."""
    rec, _ = model_recording(TRUTH, [1.5, 3, 6, 10, 15, 20, -1.5, -3, -6, -10, -15, -20], duration=3.0,
                             noise=NOISE, seed=5)
    plate = identify.fit(FitData.from_recording(rec), "silo4", harmonics=[LINE], holdout=None)
    for name in ("positive", "negative"):
        a, b = fitted.params(name), plate.params(name)
        for k in ("tau_c", "viscous"):
            assert abs(a[k] - b[k]) < 3 * np.hypot(a.se[k], b.se[k]), (name, k, a[k], b[k])


# ---------------------------------------------------------------------- decision rules
def test_auto_uses_free_motion_only_where_it_is_most_of_the_motion(bells):
    rec, data = bells
    assert data.free_motion and data.inertia is None
    kinds = set(data.segments["kind"])
    assert "free" in kinds
    # a plateau experiment: its ramps are a small share of the moving rows, left out as before
    prec, _ = model_recording(TRUTH, [2, 5, 10, -2, -5, -10], duration=3.0, noise=NOISE, seed=2)
    seg = find_segments(prec)
    auto = free_motion(prec, seg, motion="auto")
    assert auto.settings["free_share"] < fm.FREE_SHARE
    assert [s.kind for s in auto.segments] == [s.kind for s in seg.segments]
    forced = free_motion(prec, seg, motion="free")
    assert {s.kind for s in forced.segments} == {"free"}
    assert free_motion(prec, seg, motion="plateaus") is seg


def test_blocks_keep_the_speed_band_the_ledger_and_whole_stretches(bells):
    rec, _ = bells
    seg = free_motion(rec, find_segments(rec), motion="free")
    seg.check_ledger()
    vel = np.gradient(np.interp(rec.t, rec.t, rec.theta), rec.t)
    blocks = [s for s in seg.segments if s.kind == "free"]
    assert len(blocks) > 100
    wide = [s for s in blocks if s.n > 2 and np.ptp(np.abs(vel[s.start:s.stop])) > 0.1 * s.speed + 0.05]
    assert len(wide) < 0.01 * len(blocks)       # a few rows at a block's edge move the numerical derivative
    # held-out units: every stretch of motion whole and contiguous, one direction each
    data = FitData.from_recording(rec, seg)
    g = data.groups("segment")
    change = np.flatnonzero(np.diff(g) != 0)
    assert len(np.unique(g)) == len(change) + 1
    for u in np.unique(g):
        assert len(np.unique(data.direction[g == u])) == 1
    # one stretch per move (each move one direction, at rest between them)
    assert len(np.unique(g)) == 12
    # standstill between moves is never a block: every block above the floor
    floor = fm.FREE_FLOOR * np.nanmax(np.abs(vel))
    assert min(s.speed for s in blocks) > 0.5 * floor


def test_inertia_is_identified_only_when_free_motion_has_none_removed(bells):
    rec, data = bells
    est = identify.JointFit("coulomb_viscous", holdout=None)
    assert est._identifies_inertia(data)
    assert not est.set_params(inertia="none")._identifies_inertia(data)
    plateau = FitData.from_recording(model_recording(TRUTH, [2, -2, 5, -5], duration=2.0, seed=3)[0])
    assert not identify.JointFit()._identifies_inertia(plateau)
    # without it the bell moves are explained far worse (the inertia torque is most of the signal)
    without = identify.fit(data, "silo4", harmonics=[LINE], holdout=None, inertia="none")
    assert without.rmse > 3 * NOISE
    with pytest.raises(Exception, match="inertia must be"):
        identify.fit(data, "coulomb_viscous", holdout=None, inertia="maybe")


def test_the_speed_range_of_free_motion_is_pooled_over_blocks(bells):
    """No block of a move covers a cycle of the line at low speed; together they do, so the
    amplitude law reaches down there (without the pooled rule it starts where single blocks hold
    a tenth of a cycle, several rad/s higher)."""
    _, data = bells
    sub = data.direction_subset(1)
    st = segment_stats(sub, [3.0], min_cycles=0.1)
    lo_pooled = speed_ranges(st)[0, 0]
    lo_single = float(np.min(st.speed[st.active[:, 0]]))
    assert lo_pooled < 0.6 * lo_single
    # at the pooled edge the blocks below hold one cycle together
    f = st.free & st.sampled[:, 0]
    assert np.sum(st.cycles[f & (st.speed < lo_pooled), 0]) < 1.0 <= np.sum(st.cycles[f & (st.speed <= lo_pooled), 0])


# ---------------------------------------------------------------------- vectorised statistics
def test_group_statistics_equal_the_group_by_group_ones():
    rng = np.random.default_rng(0)
    sizes = [1, 2, 3, 17, 5000, 4, 9000, 1, 60]
    n = sum(sizes)
    X, y = rng.normal(size=(n, 5)), rng.normal(size=n)
    starts = np.concatenate(([0], np.cumsum(sizes)[:-1]))
    stops = starts + sizes
    G, b, yy = group_normal_equations(X, y, starts, stops)
    for g, (a, z) in enumerate(zip(starts, stops)):
        G1, b1, yy1 = normal_equations(X[a:z], y[a:z])
        np.testing.assert_allclose(G[g], G1, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(b[g], b1, rtol=1e-12, atol=1e-12)
        assert yy[g] == pytest.approx(yy1, rel=1e-12)
    theta = np.round(np.cumsum(rng.uniform(0, 1, n)), 2)
    nyq = group_position_nyquist(theta, starts, stops)
    assert list(nyq) == [position_nyquist(theta[a:z]) if z - a > 1 else 0.0 for a, z in zip(starts, stops)]


# ---------------------------------------------------------------------- the command
def test_fit_cli_on_bell_moves_reports_the_inertia_and_what_each_kind_gave(tmp_path, capsys):
    rec = recording(bell_moves(n_moves=6, seed=4), seed=6)
    path = tmp_path / "moves.csv"
    rec.data[["t", "theta", "torque"]].to_csv(path, index=False)
    rc = main(["fit", str(path), "--law", "coulomb_viscous", "--json", str(tmp_path / "m.json"),
               "--out", str(tmp_path / "out"), "--folds", "3"])
    out = capsys.readouterr().out
    assert rc == 0
    d = json.loads((tmp_path / "m.json").read_text())
    assert d["inertia"] == pytest.approx(J, rel=0.05) and d["inertia_se"] > 0
    assert "free-motion blocks" in out and "free motion is" in out
    report = (tmp_path / "out" / "report.md").read_text()
    assert "blocks of free motion" in report
    # --motion plateaus: only the near-constant tops of the moves, no inertia identified
    rc = main(["fit", str(path), "--law", "coulomb_viscous", "--motion", "plateaus", "--quiet",
               "--json", str(tmp_path / "p.json")])
    assert rc == 0
    d = json.loads((tmp_path / "p.json").read_text())
    assert "inertia" not in d and not any(t["kind"] == "inertia" for t in d["terms"])


def test_free_motion_is_weighted_uniformly(bells):
    """Blocks of free motion are too short for their own residual variance to weight them: the
    default segment weights give the same fit as uniform weights (blocks of 8 rows or more here,
    so that no undefined variance forces it)."""
    _, data = bells
    counts = np.bincount(data.segment)
    long = data.subset(counts[data.segment] >= 8)
    a = identify.fit(long, "coulomb_viscous", holdout=None, weights="segment")
    b = identify.fit(long, "coulomb_viscous", holdout=None, weights="uniform")
    for name in ("positive", "negative"):
        assert a.params(name).values == b.params(name).values


# ---------------------------------------------------------------------- twins driven by each profile
def _silo4_without_output_line():
    """SILO4 Table 2 (law 11 per direction) without the output-shaft line: one cycle of it is
    1803 rad of motor travel, more than these short profiles cover, so it could not be identified
    by any of them (a plateau experiment's long runs do)."""
    from gearspec.simulate.silo4 import table2_model

    m = table2_model()
    for p in m.directions.values():
        p.harmonics = [h for h in p.harmonics if h.label != "output shaft"]
    return m


@pytest.mark.slow
@pytest.mark.parametrize("profile", ["ramp", "chirp", "bell", "sine"])
def test_each_profile_gives_the_silo4_law_its_mesh_line_and_the_inertia(profile):
    """The SILO4 friction driven open loop by each profile (120 s at 250 Hz, as the bench logs, up to
    3000 rpm, inertia 2e-6 kg m^2 not declared, noise 0.2 mNm): the issue's tolerances.  The decay of
    the planetary line has a standard error of 7-10 % here, so 30 % is three or more of them."""
    from gearspec.simulate.synthetic import motion_recording

    truth = _silo4_without_output_line()
    lines = [{"frequency": h.frequency, "label": h.label} for h in truth.harmonics("positive")]
    rec, _ = motion_recording(truth, profile, top_speed=314.0, duration=120.0, fs=250.0, inertia=2e-6,
                              noise=2e-4, seed=3)
    m = identify.fit(FitData.from_recording(rec, motion="auto"), "silo4", harmonics=lines, folds=3)
    assert m.to_dict()["inertia"] == pytest.approx(2e-6, rel=0.05)
    for name in ("positive", "negative"):
        P, T = m.params(name), truth.params(name)
        assert P["tau_c"] == pytest.approx(T["tau_c"], rel=0.05)
        assert P["viscous"] == pytest.approx(T["viscous"], rel=0.05)
        h = next(x for x in P.harmonics if x.label == "planetary output shaft")
        t = next(x for x in T.harmonics if x.label == "planetary output shaft")
        assert h.amplitude == pytest.approx(t.amplitude, rel=0.10)
        assert h.decay == pytest.approx(t.decay, rel=0.30)
    assert m.rmse_holdout < 1.5 * 2e-4


@pytest.mark.slow
def test_plateaus_and_moves_of_one_drive_agree_within_their_standard_errors():
    """The same friction from plateaus and from bell moves: Coulomb, viscous and the planetary line's
    amplitude at 150 rad/s agree within three standard errors of their difference (the amplitude's
    error from those of A and b taken independent)."""
    from gearspec.simulate.synthetic import motion_recording

    truth = _silo4_without_output_line()
    lines = [{"frequency": h.frequency, "label": h.label} for h in truth.harmonics("positive")]
    speeds = [20, 40, 80, 120, 160, 200, 250, 300]
    prec, _ = model_recording(truth, speeds + [-s for s in speeds], duration=4.0, fs=250.0, noise=2e-4, seed=7)
    plate = identify.fit(FitData.from_recording(prec), "silo4", harmonics=lines, holdout=None)
    mrec, _ = motion_recording(truth, "bell", top_speed=314.0, duration=120.0, fs=250.0, inertia=2e-6,
                               noise=2e-4, seed=8)
    moves = identify.fit(FitData.from_recording(mrec, motion="auto"), "silo4", harmonics=lines, holdout=None)

    def amp(h, v=150.0):
        f = np.exp(-h.decay * v)
        return h.amplitude * f, np.hypot(f * h.se["amplitude"], h.amplitude * v * f * h.se["decay"])

    for name in ("positive", "negative"):
        a, b = plate.params(name), moves.params(name)
        for k in ("tau_c", "viscous"):
            assert abs(a[k] - b[k]) < 3 * np.hypot(a.se[k], b.se[k]), (name, k, a[k], b[k])
        (x, sx), (y, sy) = (amp(next(h for h in P.harmonics if h.label == "planetary output shaft")) for P in (a, b))
        assert abs(x - y) < 3 * np.hypot(sx, sy), (name, x, y)
