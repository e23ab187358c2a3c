"""The final judge: every accepted term of a :class:`~gearspec.diagnose.results.Diagnosis` checked
on an independent recording (e.g. the EMPS cross-test), by the loop's Z test on its groups and the
same margin; a term that does not help there is removed again, the weakest first."""

from __future__ import annotations

import numpy as np

from ..core.crossval import critical_z, z_statistic
from .baseline import relative_error
from .context import Round
from .data import DiagnoseData
from .design import fit_state
from .results import Diagnosis, Verdict

__all__ = ["validate"]


def validate(diag: Diagnosis, rnd: Round, vd: DiagnoseData, *, alpha: float, min_gain: float, say=None) -> None:
    """Check every accepted term on independent data; remove those that do not help there (each
    removal is the effect's :class:`~.results.Verdict`, test ``validation``; ``say``: called with
    one line per removal)."""
    dd = diag.data
    accepted = [e for e in diag.effects if e.accepted]
    state = rnd.state
    removed = []

    def pred(st):
        f = fit_state(st, dd)
        return f, st.design(vd) @ f.coef

    while True:
        full_fit, p_full = pred(state)
        worst = None
        for e in accepted:
            if e in removed:
                continue
            # without the effect: its blocks out, the blocks it replaced (an old amplitude law) back
            st_wo = state.replaced(e.detail.get("blocks", []), e.detail.get("dropped", []))
            _, p_wo = pred(st_wo)
            r0 = vd.y - p_wo
            r1 = vd.y - p_full
            zv = z_statistic(r0, p_full - p_wo, r1, vd.starts, vd.stops)
            rm0 = float(np.sqrt(np.mean(r0 ** 2)))
            rm1 = float(np.sqrt(np.mean(r1 ** 2)))
            gain = (rm0 - rm1) / rm0 if rm0 > 0 else 0.0
            zc = critical_z(alpha, len(accepted), vd.n_groups)
            ok = zv >= zc and gain >= min_gain
            e.validation = {"z": zv, "z_crit": zc, "rmse_without": rm0, "rmse_with": rm1, "gain": gain,
                            "relative_error_without": relative_error(vd.y, p_wo),
                            "relative_error_with": relative_error(vd.y, p_full), "confirmed": bool(ok)}
            if not ok and (worst is None or zv < worst[0]):
                worst = (zv, e, st_wo)
        if worst is None:
            break
        _, e, st_wo = worst
        e.accepted = False
        v = e.validation
        e.decision = (f"rejected by the validation data: helps on the estimation data (held-out rmse "
                      f"{e.rmse_holdout_before:.4g} -> {e.rmse_holdout_after:.4g}) but not on the independent "
                      f"recording (rmse {v['rmse_without']:.4g} -> {v['rmse_with']:.4g}, relative error "
                      f"{v['relative_error_without']:.3f} % -> {v['relative_error_with']:.3f} %, Z {v['z']:.2f} "
                      f"< {v['z_crit']:.2f} or gain below {100 * min_gain:.2g} %)")
        e.history.append(e.decision)
        e.detail.setdefault("removed", []).append("validation")
        why = (f"Z {v['z']:.2f} below {v['z_crit']:.2f}" if not v["z"] >= v["z_crit"] else
               f"rmse changes by {-100 * v['gain']:+.2f} % (needs a fall of {100 * min_gain:.2g} %)")
        e.verdict = Verdict("removed", "validation", f"does not help on the independent recording: {why}", v["z"],
                            v["z_crit"], v["gain"], min_gain, v["rmse_without"], v["rmse_with"], None,
                            f"on the estimation data it passed the held-out test (Z {e.z:.2f}, needs {e.z_crit:.2f})")
        if say is not None:
            say(f"validation: removed {e.name} ({e.verdict.reason})")
        removed.append(e)
        state = st_wo
    if removed:
        rnd2 = Round(dd, state, diag.folds)
        h = rnd2.baseline_holdout()
        ho = h["rmse"]
        name = "final: " + diag.baseline_model.name.replace("baseline: ", "") + "".join(
            f" + {e.name}" for e in diag.effects if e.accepted)
        diag.final = rnd2.fitted
        diag.final_model = rnd2.fitted.model(name=name, rmse_holdout=ho)
        diag.final_holdout = h
        diag.notes.append(f"held-out rmse: {diag.baseline_model.rmse_holdout:.5g} (baseline) -> {ho:.5g} (final "
                          f"model): the validation data removed {', '.join(e.name for e in removed)} after the "
                          f"loop, and the final model is the one without "
                          f"{'them' if len(removed) > 1 else 'it'} (same folds as every step)")
    for e in accepted:
        if e.accepted and e.verdict is not None and e.validation:
            v = e.validation
            e.verdict.note = (f"confirmed on the independent recording (Z {v['z']:.2f}, needs {v['z_crit']:.2f}; rmse "
                              f"{v['rmse_without']:.4g} -> {v['rmse_with']:.4g})")
    # numbers on the validation data, baseline and final (both fitted on the estimation data)
    pb = diag.baseline.state.design(vd) @ diag.baseline.coef
    pf = diag.final.state.design(vd) @ diag.final.coef
    diag.validation = {"name": vd.name, "baseline_rmse": float(np.sqrt(np.mean((vd.y - pb) ** 2))),
                       "final_rmse": float(np.sqrt(np.mean((vd.y - pf) ** 2))),
                       "baseline_relative_error": relative_error(vd.y, pb),
                       "final_relative_error": relative_error(vd.y, pf),
                       "removed": [e.name for e in removed], "groups": vd.n_groups, "data": vd}
