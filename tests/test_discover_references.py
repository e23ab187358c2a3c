"""The papers' laws beside the explorer's (:mod:`gearspec.discover.references`): every held-out
fold refitted with the settings of the fit on all data, for its predictions only -- the same
held-out numbers as a full fit per fold, without the fold's in-sample rmse and checks (on a
10^7-row recording each fold's in-sample rmse evaluated the law at 8 million samples, and a
check's warning was said once per fold)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from gearspec import identify
from gearspec.core import parallel
from gearspec.core.crossval import held_out
from gearspec.discover.law import fold_ids
from gearspec.discover.moments import moments
from gearspec.discover import references
from gearspec.discover.references import _paper_law, _segment_sse
from gearspec.errors import GearspecWarning
from gearspec.fitdata import FitData


def _falling(seed=3):
    """12 plateaus per direction, 300 samples each: friction 0.3 - 0.002 |v| (a viscous coefficient
    falling with speed, which the Coulomb + viscous law's check flags) + white noise 0.01."""
    rng = np.random.default_rng(seed)
    th, vv, yy, ss = [], [], [], []
    t0 = 0.0
    for i, v in enumerate(np.concatenate([np.geomspace(0.5, 40, 12), -np.geomspace(0.5, 40, 12)])):
        n = 300
        vv.append(np.full(n, v))
        yy.append(np.sign(v) * (0.3 - 0.002 * abs(v)) + 0.01 * rng.standard_normal(n))
        th.append(t0 + v * np.arange(n) * 1e-3)
        t0 = th[-1][-1]
        ss.append(np.full(n, i))
    return FitData(theta=np.concatenate(th), v=np.concatenate(vv), y=np.concatenate(yy), segment=np.concatenate(ss))


fork_only = pytest.mark.skipif(parallel.can_fork() is False, reason="no fork on this system")


@pytest.mark.parametrize("threads", ["1", "2"])
def test_a_paper_laws_folds_give_a_full_fits_numbers_and_warn_once(threads, monkeypatch):
    # the folds run in forked workers with 2 (the fit on all data, and its warnings, in this process)
    monkeypatch.setenv("GEARSPEC_THREADS", threads)
    fd = _falling()
    M = moments(fd)
    fold = fold_ids(M, "segment", 5)
    with warnings.catch_warnings(record=True) as got:
        warnings.simplefilter("always")
        ref = _paper_law(fd, M, "coulomb_viscous", [], fold)
    said = [str(w.message) for w in got if issubclass(w.category, GearspecWarning)]
    # the fit on all data flags each direction's negative viscous coefficient once; its five
    # folds say nothing (a full fit per fold: 12 warnings)
    assert len(said) == 2 and all("viscous coefficient" in s for s in said), said
    # the held-out numbers of a full identify.fit per fold, exactly (the same fits)
    seg = M.rows(fd.segment)
    kw = {"harmonics": None, "weights": "uniform", "holdout": None, "inertia": "none"}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        full = held_out(fold, lambda train: identify.fit(fd.subset(train[seg]), "coulomb_viscous", **kw),
                        lambda mf, test: _segment_sse(fd, mf, M, test[seg])[test], weight=M.n, catch=())
    assert np.array_equal(ref.cv_sse, full.sse)
    assert ref.rmse_holdout == full.rmse
    # the law falls with speed: the coefficient the check flags is negative, many errors below 0
    assert ref.model.directions["positive"].values["viscous"] < -0.001


@fork_only
def test_a_fold_that_fails_in_a_worker_is_skipped_and_counted(monkeypatch):
    # a fold's error raised in a forked worker reaches held_out as it would in this process: that
    # fold skipped (its segments without a held-out error), counted in the note
    monkeypatch.setenv("GEARSPEC_THREADS", "2")
    fd = _falling()
    M = moments(fd)
    fold = fold_ids(M, "segment", 5)
    real = references.fold_fit

    def flaky(model, data):
        if 1 not in set(np.unique(data.segment).tolist()):      # the fold that holds segment 1 out
            raise ValueError("a singular fold")
        return real(model, data)

    monkeypatch.setattr(references, "fold_fit", flaky)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = _paper_law(fd, M, "coulomb_viscous", [], fold)
    out = fold[M.rows(np.array([1]))[0]]
    assert ref.note.startswith("fit failed in 1 fold(s)")
    assert ref.cv_sse is None and ref.rmse_holdout is not None
    monkeypatch.setattr(references, "fold_fit", real)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        whole = _paper_law(fd, M, "coulomb_viscous", [], fold)
    kept = fold != out
    # the other folds' held-out error, as with every fold fitted
    n = M.n
    assert ref.rmse_holdout == pytest.approx(np.sqrt(np.sum(whole.cv_sse[kept]) / np.sum(n[kept])), rel=1e-12)


def test_a_long_recordings_folds_run_in_turn(monkeypatch):
    # above FORK_MAX_ROWS the folds are fitted here in turn (each worker would gather and reduce its
    # own copy of the training samples); below, in a map; the same numbers either way
    fd = _falling()
    M = moments(fd)
    fold = fold_ids(M, "segment", 5)
    maps = []

    def spy(fn, items, *a, **k):
        maps.append(len(items))
        return [fn(x) for x in items]

    monkeypatch.setattr(references, "fits_map", spy)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        short = _paper_law(fd, M, "coulomb_viscous", [], fold)
        assert maps == [5]
        monkeypatch.setattr(references, "FORK_MAX_ROWS", len(fd) - 1)
        long = _paper_law(fd, M, "coulomb_viscous", [], fold)
    assert maps == [5]
    assert np.array_equal(short.cv_sse, long.cv_sse)
