"""The round's richest model takes only candidates whose held-out drop is above round-off
(``diagnose.loop.promising``): a candidate that repeats a column the model already has changes the
held-out error by 1e-14 of it, with either sign; the noise of every Z must not depend on that sign."""

from types import SimpleNamespace

import numpy as np

from gearspec.diagnose import loop, parallel_round


def _ev(drop_share, n, rmse=0.5, cons=1.0):
    sse = n * rmse ** 2
    return loop.Evaluation(z=1.0, z_crit=3.0, drop=drop_share * sse, fold_drops=np.zeros(5), consistency=cons,
                           rmse_holdout_before=rmse, rmse_holdout_after=rmse, gain=0.0, n_params=2,
                           passed=False, reason="", gate="")


def _richest(monkeypatch, shares):
    n = 1000
    rnd = SimpleNamespace(dd=np.zeros(n))
    cands = [SimpleNamespace(kind=f"kind {k}") for k in range(len(shares))]
    evs = {id(c): _ev(s, n) for c, s in zip(cands, shares)}
    runs = [SimpleNamespace(cand=c) for c in cands]
    joined = []
    monkeypatch.setattr(parallel_round, "run_candidates", lambda rnd, cands, fn: runs)
    monkeypatch.setattr(loop, "_decide", lambda rnd, fr, noise, **kw: evs[id(fr.cand)])
    monkeypatch.setattr(loop, "_full_residual", lambda rnd, frs: joined.append([fr.cand.kind for fr in frs]) or 0.0)
    loop._evaluate_round(rnd, cands, z_crit=3.0, min_gain=0.005)
    return joined


def test_a_drop_at_round_off_does_not_join_the_richest_model(monkeypatch):
    # a real effect (0.1 % of the held-out sse) and a repeated column (1e-14 of it, positive by chance)
    assert _richest(monkeypatch, [1e-3, 1e-14]) == []            # one promising kind: no richest model
    assert _richest(monkeypatch, [1e-3, 1e-6]) == [["kind 0", "kind 1"]]   # a small real drop joins
    assert loop.promising(_ev(2e-9, 100), 100) and not loop.promising(_ev(0.5e-9, 100), 100)   # ROUNDOFF_SHARE 1e-9
    assert not loop.promising(_ev(1e-3, 100, cons=0.8), 100)   # the consistency gate as before


def test_a_held_out_change_at_round_off_has_z_zero():
    from gearspec.core.crossval import z_statistic

    rng = np.random.default_rng(4)
    r0 = rng.normal(size=4000)
    starts, stops = np.arange(0, 4000, 400), np.arange(400, 4001, 400)
    # a duplicate column refitted: the prediction moves by ~1e-8 of the residual, correlated with it
    # by chance; its Z (here -2.9 or +2.9 by the sign of the round-off) would be pure arithmetic
    tiny = 1e-8 * (0.9 * r0 + 0.1 * rng.normal(size=4000))
    assert z_statistic(r0, tiny, r0 - tiny, starts, stops) == 0.0
    assert z_statistic(r0, -tiny, r0 + tiny, starts, stops) == 0.0
    # a real change of 1e-4 of the residual (above 1e-9 of its sum of squares) keeps its Z
    small = 1e-4 * (0.9 * r0 + 0.1 * rng.normal(size=4000))
    assert z_statistic(r0, small, r0 - small, starts, stops) > 3
