"""The closed loop in bounded memory on long recordings (issue 13: "memory stays bounded", helper
"diagmem"): caches bounded in bytes (:mod:`gearspec.diagnose.budget`), designs stacked block by
block (:func:`gearspec.diagnose.gram.stack`), a round's design let go while a candidate's extended
round holds its own (:meth:`Round.release_design`) and channels read without a copy.

Known answers: the same numbers, bit for bit, with every budget at 0 (everything built again when
asked for) as with the default budgets; peaks of tracemalloc on N and 4N rows, whose growth per row
is bounded by what the design itself needs.
"""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

import gearspec.diagnose as dg
from gearspec.diagnose import budget, gram, loop
from gearspec.diagnose.candidates import FixedCandidate, per_direction
from gearspec.diagnose.context import Round
from gearspec.diagnose.frommodel import state_from_model
from gearspec.model import FrictionModel
from gearspec.simulate import model_recording

#: a Stribeck law with a decaying line: a nonlinear Stribeck velocity and a decay, so the round's
#: design carries Taylor columns and a candidate's test refines them (extended round)
MODEL = FrictionModel("stribeck", {"tau_c": 0.05, "tau_s": 0.08, "v_s": 1.5, "viscous": 2e-3,
                                   "harmonics": [{"frequency": 0.5, "amplitude": 4e-3, "phase": 0.3,
                                                  "law": "exp", "decay": 0.05}]})


#: four decaying lines: a design of 16 columns (base law, lines, Taylor columns), wide enough that
#: copies of it, not the few per-row arrays of a held-out test, set the memory per row
MODEL4 = FrictionModel("stribeck", {"tau_c": 0.05, "tau_s": 0.08, "v_s": 1.5, "viscous": 2e-3,
                                    "harmonics": [{"frequency": f, "amplitude": 4e-3, "phase": 0.3, "law": "exp",
                                                   "decay": 0.05} for f in (0.5, 0.9, 1.7, 2.3)]})


def _data(duration=1.0, n_speeds=4, model=MODEL):
    speeds = [x for s in np.geomspace(0.5, 16, n_speeds) for x in (s, -s)]
    rec, _ = model_recording(model, speeds, noise=1e-3, seed=0, duration=duration, fs=500.0)
    return dg.DiagnoseData.from_recording(rec)


def _zero_budgets(monkeypatch):
    for name in ("CACHE_BYTES", "TRIG_BYTES", "DESIGN_BYTES"):
        monkeypatch.setattr(budget, name, 0)


def test_stack_is_column_stack_bit_for_bit_and_holds_one_block_at_a_time():
    rng = np.random.default_rng(1)
    n = 40000
    widths = [3, 1, 4, 2, 5]
    blocks = [rng.normal(size=(n, k)) for k in widths]
    got = gram.stack(iter(blocks), n, sum(widths))
    assert np.array_equal(got, np.column_stack(blocks))
    with pytest.raises(ValueError):
        gram.stack(iter(blocks[:2]), n, sum(widths))
    # blocks made as they are asked for: the peak is the result and about one block, not all of them
    del blocks
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        tracemalloc.reset_peak()
        gram.stack((np.full((n, k), 1.0) for k in widths), n, sum(widths))
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    result, largest = 8 * n * sum(widths), 8 * n * max(widths)
    assert peak <= result + 2 * largest + 1e5          # a list of the blocks first: 2 x result
    assert peak >= result


def test_at_gives_a_read_only_view_of_the_samples_and_a_copy_of_reduced_data():
    dd = _data()
    v = dd.at("v")
    assert np.shares_memory(v, dd.fit.v) and np.array_equal(v, dd.fit.v)
    assert not v.flags.writeable and dd.fit.v.flags.writeable      # the data's own array stays writable
    sub = dg.DiagnoseData(dd.fit, index=np.arange(0, len(dd.fit), 2), reduce=lambda a: np.asarray(a)[::2])
    assert np.array_equal(sub.at("v"), dd.fit.v[::2])


def test_budgets_at_zero_give_the_same_numbers_bit_for_bit(monkeypatch):
    """With every budget at 0 nothing is kept (columns, sines, the round's design while a candidate's
    extended round lives): every array is built again when asked for.  The candidate's held-out
    test and the settled round are the same, bit for bit, as with the default budgets."""
    def run():
        dd = _data()
        fold = loop.folds_of(dd, 4)
        rnd = Round(dd, loop._settle(state_from_model(MODEL, dd), dd), fold)
        cand = FixedCandidate("other", "offset", per_direction(rnd, "offset", key="offset"))
        fr = loop._run_folds(rnd, cand)
        released = rnd._design[0] is None
        ev = loop._decide(rnd, fr, None, z_crit=2.0, min_gain=0.005)
        return rnd, fr, ev, released

    rnd0, fr0, ev0, released0 = run()
    _zero_budgets(monkeypatch)
    rnd1, fr1, ev1, released1 = run()
    assert not released0 and released1                     # the default keeps a small design, 0 lets it go
    assert rnd1._design[0] is None
    assert np.array_equal(rnd1.X, rnd0.X)                  # built again: the same array
    assert np.array_equal(rnd1.fitted.coef, rnd0.fitted.coef)
    assert list(rnd1.fitted.nonlinear_se.values()) == list(rnd0.fitted.nonlinear_se.values())   # uids differ
    for a, b in ((fr1.p1, fr0.p1), (fr1.r0, fr0.r0), (fr1.contribution, fr0.contribution)):
        assert np.array_equal(a, b)
    assert (ev1.z, ev1.gain, ev1.passed) == (ev0.z, ev0.gain, ev0.passed)


def _peak_per_run(duration: float, monkeypatch) -> tuple[float, int, int]:
    """tracemalloc peak (bytes above the prepared data) of a round and one candidate's held-out
    test, the rows and the round's design width."""
    dd = _data(duration=duration, model=MODEL4)
    fold = loop.folds_of(dd, 4)
    state = state_from_model(MODEL4, dd)
    _zero_budgets(monkeypatch)
    monkeypatch.setattr(gram, "CHUNK_ROWS", 1024)    # chunks of a long recording: far shorter than the data
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        tracemalloc.reset_peak()
        rnd = Round(dd, state, fold)
        cand = FixedCandidate("other", "offset", per_direction(rnd, "offset", key="offset"))
        loop._run_folds(rnd, cand)
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    return peak, len(dd), rnd.width


def test_memory_of_a_round_and_a_candidate_test_grows_by_a_bounded_amount_per_row(monkeypatch):
    """On N and 4N rows, with the budgets at 0 (a recording too long for any cache) and chunks of
    1024 rows: the peak of a round and one candidate's held-out test grows per row by at most 2.1
    times the round's design (8 bytes x 16 columns x 2.1 = 269 bytes; measured 242: the blocks'
    columns of the round, then of the extended round built after the round's are let go, the
    Taylor columns a design computes, the held-out predictions and residuals).  A round's design
    stacked into one array takes 326 (294 in 0.10), the refinement's designs stacked 326 too, the
    round's and the extended round's held at once 416 (0.10)."""
    p1, n1, w = _peak_per_run(1.0, monkeypatch)
    p4, n4, w4 = _peak_per_run(4.0, monkeypatch)
    assert w == w4 == 16 and n4 > 3.5 * n1
    per_row = (p4 - p1) / (n4 - n1)
    bound = 8 * 2.1 * w
    assert per_row <= bound, f"{per_row:.0f} bytes per row (design width {w}), bound {bound:.0f}"


class _Stop(Exception):
    pass


def test_the_loop_alone_holds_the_data_so_untrimmed_data_are_freed_once_trimmed():
    """``diagnose`` (the function and the command) keeps no reference of its own to the data it is
    given: once :meth:`DiagnoseData.without_edges` has made the trimmed copy the loop works on, the
    untrimmed data (a long recording's 0.9 GB at 10^7 rows) are freed.  Known answer: a weak
    reference to them is dead at the loop's first progress line; it was alive when ``diagnose`` held
    its argument through the loop."""
    import weakref

    dd = _data()
    ref = weakref.ref(dd)
    seen = []
    box, dd = [dd], None
    dg.diagnose(box.pop(), law="stribeck", max_rounds=1, progress=lambda line: seen.append(ref() is None))
    assert seen and all(seen)


def test_the_command_lets_the_recording_and_the_data_go_before_the_loop(tmp_path, monkeypatch):
    """``gearspec diagnose`` hands the loop data it holds no reference to (the recording's samples and
    the untrimmed data are not kept through the loop): a weak reference to what the loop is given
    dies when the loop lets it go."""
    import weakref

    from gearspec.cli import main
    from gearspec.simulate import model_recording

    speeds = [x for s in np.geomspace(0.5, 16, 4) for x in (s, -s)]
    rec, _ = model_recording(MODEL, speeds, noise=1e-3, seed=0, duration=1.0, fs=500.0)
    csv = tmp_path / "rec.csv"
    rec.save(csv)
    alive = []

    def loop_stand_in(data, *args, **kwargs):
        ref = weakref.ref(data)
        del data
        alive.append(ref() is not None)
        raise _Stop

    monkeypatch.setattr(dg, "diagnose", loop_stand_in)
    main(["diagnose", str(csv), "--law", "stribeck", "--quiet"])    # stopped by the stand-in
    assert alive == [False]
