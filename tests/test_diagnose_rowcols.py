"""A block's columns a range of rows at a time on long data (issue 13: "memory stays bounded:
reductions, never a dense rows x terms matrix of a long recording"; helper "diaglazy").

Above :data:`gearspec.diagnose.budget.LAZY_BYTES` a base law's, a line's and an elementwise term's
columns (plain and with their Taylor columns) are :class:`~gearspec.diagnose.rowcols.Columns`: rows computed on demand from
facts of the whole data.  Known answer: the whole arrays the blocks build below the threshold --
equal bit for bit, for every kind, both directions and a symmetric model, a line above its position
Nyquist limit in part of the segments, a sideband pooled over long plateaus, a load-dependent line,
any row range (one row alone included); and a whole ``diagnose`` with every block lazy gives the
same final model, verdicts and numbers as with arrays.  Memory: a round on lazy columns holds no
rows x columns array.
"""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

import gearspec.diagnose as dg
from gearspec.diagnose import budget, design, gram, rowcols
from gearspec.diagnose.candidates import LaggedHarmonicBlock, SidebandBlock, lagged
from gearspec.diagnose.context import Round
from gearspec.diagnose.coverage import resolved, segment_span
from gearspec.diagnose.frommodel import state_from_model
from gearspec.model import FrictionModel
from gearspec.simulate import model_recording

F_MOTOR = 1 / (2 * np.pi)
#: cycles per rad above 0.8 of the position Nyquist limit at the faster plateaus (500 Hz, > 10 rad/s)
F_HIGH = 20.0
#: cycles per rad measured (a whole cycle in a plateau) only from 2 rad/s up
F_SLOW = 0.05


def _model(load: bool = False) -> FrictionModel:
    def lines(a, ph):
        out = [{"frequency": F_MOTOR, "amplitude": a, "decay": 0.05, "phase": ph, "label": "motor shaft"},
               {"frequency": 17 * F_MOTOR, "amplitude": 0.6 * a, "decay": 0.15, "phase": ph + 1, "law": "rational",
                "label": "mesh"},
               {"frequency": F_HIGH, "amplitude": 0.3 * a, "decay": 0.02, "phase": ph - 1, "label": "high"},
               # a cycle within a plateau only from 2 rad/s: its amplitude law held below (the data's range)
               {"frequency": F_SLOW, "amplitude": 0.5 * a, "decay": 0.3, "phase": ph + 2, "label": "slow"}]
        if load:
            out[0]["load_coefficient"] = 2e-3
        return out
    pos = {"tau_c": 0.05, "tau_s": 0.08, "v_s": 1.5, "viscous": 2e-3, "harmonics": lines(5e-3, 0.3)}
    neg = {"tau_c": 0.055, "tau_s": 0.085, "v_s": 1.2, "viscous": 2.2e-3, "harmonics": lines(4e-3, 1.0)}
    return FrictionModel("silo4", pos, neg, name="truth")


def _data(load: bool = False, n_speeds: int = 6, duration: float = 1.5):
    speeds = [x for s in np.geomspace(0.5, 16, n_speeds) for x in (s, -1.1 * s)]
    rec, _ = model_recording(_model(load), speeds, noise=1e-3, seed=3, duration=duration, fs=500.0,
                             load=list(np.linspace(1.0, 3.0, len(speeds))) if load else None)
    return dg.DiagnoseData.from_recording(rec)


def _blocks(dd, symmetric=False, load=False):
    st = state_from_model(_model(load), dd, symmetric=symmetric)
    st = st.refreshed(np.linspace(0.5, 1.5, len(st.names)))     # coefficients for the Taylor columns
    blocks = list(st.blocks)
    line = next(b for b in blocks if isinstance(b, design.HarmonicBlock))
    # a sideband pooled over the plateaus with travel >= the median (zero on the others)
    span = np.median(segment_span(dd))
    blocks.append(SidebandBlock(key="sb", frequency=3 * F_MOTOR, dirs=line.dirs, symmetric=line.symmetric,
                                law=line.law, decay=line.decay, min_travel=float(span),
                                coef=tuple(np.linspace(0.7, 1.3, 2 * (1 if line.symmetric else len(line.dirs))))))
    dirs = [0] if symmetric else [1, -1]
    terms = [("viscous_power", (("exponent", 1.7),)), ("stribeck_extra", (("v_s", 2.0), ("shape", "gauss"))),
             ("drift", (("reference", 0.0),)), ("offset", ()), ("cogging", (("frequency", 3.0),)), ("inertia", ())]
    terms += [("load_viscous", ())] if load else []
    for kind, fixed in terms:
        for d in (dirs if kind not in ("offset", "inertia", "cogging") else [0]):
            k = 2 if kind == "cogging" else 1
            blocks.append(design.TermBlock(key=kind, kind=kind, fixed=fixed, direction=d,
                                           coef=tuple(np.linspace(0.9, 1.1, k))))
    return blocks


def _whole_and_lazy(blk, dd, taylor, monkeypatch):
    dd.cache.clear()
    with monkeypatch.context() as m:
        m.setattr(budget, "LAZY_BYTES", 1 << 62)
        whole = blk.columns(dd, taylor)
    dd.cache.clear()
    with monkeypatch.context() as m:
        m.setattr(budget, "LAZY_BYTES", 0)
        lazy = blk.columns(dd, taylor)
    dd.cache.clear()
    return whole, lazy


@pytest.mark.parametrize("symmetric,load", [(False, False), (True, False), (False, True)])
def test_lazy_rows_are_the_whole_arrays_rows_bit_for_bit(symmetric, load, monkeypatch):
    dd = _data(load=load)
    ok = resolved(dd, F_HIGH)
    assert 0 < ok.mean() < 1            # the high line is above its Nyquist limit in part of the segments
    slow = next(b for b in _blocks(dd, symmetric, load) if getattr(b, "frequency", 0) == F_SLOW)
    assert all(lo > 1.5 for lo, _ in slow.ranges(dd).values())     # its law held below 2 rad/s (of 0.5)
    blocks = _blocks(dd, symmetric, load)
    n = len(dd)
    ranges = [(0, n), (0, 1), (n - 1, n), (7, 8), (3, 777), (1234, 5678), (n - 2, n)]
    kinds = set()
    for blk in blocks:
        for taylor in (False, True):
            whole, lazy = _whole_and_lazy(blk, dd, taylor, monkeypatch)
            if isinstance(blk, design.BaseBlock) and load:
                assert isinstance(lazy, np.ndarray)     # a base law with load: elementwise in two channels, kept whole
                continue
            assert isinstance(lazy, rowcols.Columns), type(blk)
            assert lazy.shape == whole.shape and lazy.nbytes == 0
            assert whole.shape[1] == len(blk.names) + (blk.n_taylor(dd) if taylor else 0)
            for a, z in ranges:
                assert np.array_equal(lazy[a:z], whole[a:z]), (type(blk).__name__, taylor, a, z)
            assert np.array_equal(np.asarray(lazy), whole)
            beta = np.linspace(-1, 2, whole.shape[1])
            assert np.array_equal(lazy @ beta, whole @ beta)
            mask = (np.arange(n) % 7) == 2
            assert np.array_equal(lazy[mask], whole[mask])
            kinds.add(type(blk).__name__)
    assert kinds == ({"HarmonicBlock", "SidebandBlock", "TermBlock"} | ({"BaseBlock"} if not load else set()))
    # the Taylor columns of the terms' own nonlinear parameters (exponent, Stribeck velocity) among them
    assert sum(b.n_taylor(dd) for b in blocks if isinstance(b, design.TermBlock)) >= 2
    # the load-dependent column is among them
    if load:
        assert any(b.load_phase for b in blocks if isinstance(b, design.HarmonicBlock))


def test_blocks_that_cannot_compute_rows_keep_whole_arrays(monkeypatch):
    dd = _data()
    line = next(b for b in _blocks(dd) if isinstance(b, design.HarmonicBlock))
    monkeypatch.setattr(budget, "LAZY_BYTES", 0)
    hyst = design.TermBlock(key="h", kind="hysteresis", fixed=(("length", 0.1),), coef=(1.0,))
    assert isinstance(hyst.columns(dd), np.ndarray)     # the travel since the last reversal: whole
    lag = lagged(line, 2e-3)
    assert isinstance(lag, LaggedHarmonicBlock)
    assert isinstance(lag.columns(dd), np.ndarray)      # a shifted view of positions: whole
    monkeypatch.setattr(budget, "LAZY_BYTES", 8 * len(dd) * len(line.names))
    assert isinstance(line.columns(dd), np.ndarray)     # at the threshold: whole
    dd.cache.clear()
    monkeypatch.setattr(budget, "LAZY_BYTES", 8 * len(dd) * len(line.names) - 1)
    assert isinstance(line.columns(dd), rowcols.Columns)


def test_columns_side_by_side_and_their_norm(monkeypatch):
    from gearspec.diagnose.candidates import side_by_side
    dd = _data()
    blocks = _blocks(dd)[:2]
    whole = [_whole_and_lazy(b, dd, False, monkeypatch)[0] for b in blocks]
    monkeypatch.setattr(budget, "LAZY_BYTES", 0)
    lazy = [b.columns(dd) for b in blocks]
    C = side_by_side(lazy)
    assert isinstance(C, rowcols.Columns)
    W = np.column_stack(whole)
    assert np.array_equal(np.asarray(C), W) and np.array_equal(C[10:20], W[10:20])
    assert C.sum_of_squares() == pytest.approx(float(np.sum(W ** 2)), rel=1e-12)
    assert rowcols.chunk_ranges(2 * 16384 + 1) == [(0, 16384), (16384, 2 * 16384 + 1)]   # no chunk of one row


def _diagnose(dd, lazy_bytes, monkeypatch):
    dd.cache.clear()
    with monkeypatch.context() as m:
        m.setattr(budget, "LAZY_BYTES", lazy_bytes)
        m.setenv("GEARSPEC_THREADS", "1")
        return dg.diagnose(dd, gear=None, max_rounds=3, per_segment_spectra=False)


def test_diagnose_with_every_block_lazy_gives_the_same_model(monkeypatch):
    dd = _data(n_speeds=5, duration=1.2)
    arr = _diagnose(dd, 1 << 62, monkeypatch)
    lazy = _diagnose(dd, 0, monkeypatch)
    assert arr.final_model.to_dict() == lazy.final_model.to_dict()
    assert arr.baseline_model.to_dict() == lazy.baseline_model.to_dict()
    assert [e.to_dict() for e in arr.effects] == [e.to_dict() for e in lazy.effects]
    assert len(arr.effects) >= 3
    assert np.array_equal(arr.final.coef, lazy.final.coef)


def test_a_round_on_lazy_columns_holds_no_rows_x_columns_array(monkeypatch):
    """tracemalloc peak of a round (fit, Taylor design, group normals, standard errors) on 90 000
    rows in 48 plateaus (chunks of 2048 rows): with lazy columns below a quarter of the design's rows x columns x 8 bytes; with arrays,
    above the whole design (the known answer the rule is read against)."""
    dd = _data(n_speeds=24, duration=3.75)     # 48 plateaus: a group's rows small beside the data's
    st = state_from_model(_model(), dd)
    fold = np.arange(dd.n_groups) % 5
    peaks = {}
    monkeypatch.setattr(gram, "CHUNK_ROWS", 2048)     # a chunk's rows small beside the data's
    for name, lazy_bytes in (("lazy", 0), ("whole", 1 << 62)):
        dd.cache.clear()
        monkeypatch.setattr(budget, "LAZY_BYTES", lazy_bytes)
        Round(dd, st, fold)     # warm: the whole-data facts (speed keys, resolved segments, ranges)
        for k in [k for k in dd.cache if k == "columns"]:
            del dd.cache[k]
        tracemalloc.start()
        rnd = Round(dd, st, fold)
        peaks[name] = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    design_bytes = 8 * len(dd) * rnd.width
    assert len(dd) > 80_000 and rnd.width >= 20, (len(dd), rnd.width)
    assert peaks["lazy"] < design_bytes / 4, (peaks, design_bytes)
    assert peaks["whole"] > design_bytes, (peaks, design_bytes)


def test_a_round_on_lazy_columns_may_fork_its_candidates(monkeypatch):
    """The fork rule reads the bytes the design's arrays hold: none for lazy columns, the whole
    rows x columns for arrays (:func:`~gearspec.diagnose.parallel_round.fork_allowed`)."""
    from gearspec.diagnose import parallel_round
    dd = _data()
    st = state_from_model(_model(), dd)
    fold = np.arange(dd.n_groups) % 5
    monkeypatch.setattr(parallel_round, "FORK_DESIGN_BYTES", 8 * len(dd))     # one column's worth
    monkeypatch.setattr(budget, "LAZY_BYTES", 1 << 62)
    whole = Round(dd, st, fold)
    assert whole.design_bytes() == 8 * len(dd) * whole.width and not parallel_round.fork_allowed(whole)
    dd.cache.clear()
    monkeypatch.setattr(budget, "LAZY_BYTES", 0)
    lazy = Round(dd, st, fold)
    assert lazy.width == whole.width and lazy.design_bytes() == 0 and parallel_round.fork_allowed(lazy)
