"""The closed loop: residual -> detectors -> candidate terms -> held-out acceptance -> refit,
until nothing more is accepted (the rule and its reasons: README, "The closed loop", Acceptance).

In every fold of whole held-out groups the model as it stands is fitted on the other folds
(prediction ``p0``), the candidate's procedure runs there too and the extended model is fitted
(``p1``).  With ``r0 = y - p0`` and ``Delta = p1 - p0`` on the held-out fold,
``Z = sum_g <r0_g, Delta_g> / sqrt(sum_g V_g)`` (:func:`gearspec.core.crossval.z_statistic`,
``V_g`` cluster-robust); a candidate passes when ``Z`` exceeds the one-sided t quantile at
``alpha / candidates`` (:func:`~gearspec.core.crossval.critical_z`), the improving folds carry 90 %
of the change and the held-out rmse falls by ``min_gain``.  The best passing candidate is added,
the model refitted, and the loop repeats; every candidate is kept with its evidence and decision.
An independent recording (``validation``) is the final judge (:mod:`.validate`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from scipy import stats
from threadpoolctl import threadpool_limits

from ..core.crossval import ROUNDOFF_SHARE, critical_z, deal_folds, group_summary, splits, z_statistic
from ..errors import InputError
from ..model import FrictionModel
from .baseline import _as_data, baseline_model, idim_model, relative_error, residual_analysis
from .candidates import Candidate, FixedCandidate, PeriodicCandidate, train_fit
from .context import Round
from .data import DiagnoseData
from .design import FittedState, HarmonicBlock, State, TermBlock
from .foldfits import full_residual as _full_residual, predict_groups as _predict
from .frommodel import state_from_model
from .nonlinear import polish, refine
from .nuisance import admit_partial_lines
from .detectors import analyse, propose
from .guard import accept_first, bar_repeat, undone_in
from .results import Diagnosis, Effect, Verdict
from .validate import validate

__all__ = ["diagnose", "Diagnosis", "Effect", "Round", "evaluate_candidate", "folds_of", "baseline_model",
           "idim_model", "residual_analysis", "KINDS", "relative_error"]

#: effect kinds of CONTRACTS.md section 4
KINDS = ("periodic", "speed_law", "load", "temperature", "drift", "asymmetry", "inertia", "hysteresis", "lag", "other")


def folds_of(dd: DiagnoseData, folds: int) -> np.ndarray:
    """Fold of every held-out group (``dd``'s group order) by THE rule of
    :mod:`gearspec.core.crossval` (:func:`~gearspec.core.crossval.deal_folds`)."""
    gid = dd.fit.groups(dd.by)[dd.index]
    ids, sign, speed = group_summary(gid, dd.at("direction"), dd.at("v"))
    return deal_folds(sign, speed, ids, folds)[np.searchsorted(ids, gid[dd.starts])]


# ---------------------------------------------------------------------- one round
@dataclass
class Evaluation:
    """What the held-out test measured for one candidate in one round."""

    z: float
    z_crit: float
    drop: float                  # held-out SSE drop, all folds
    fold_drops: np.ndarray
    consistency: float           # share of the absolute change carried by improving folds
    rmse_holdout_before: float
    rmse_holdout_after: float
    gain: float                  # relative held-out rmse drop
    n_params: int
    passed: bool
    reason: str
    contribution: np.ndarray = field(repr=False, default=None)   # all-data fit with the candidate minus without
    gate: str = ""               # the one reason: the first gate failed (or that every gate passed)
    min_gain: float = 0.0
    test: str = "held-out"       # the test that decided ("re-entry" when the re-entry rule barred it)

    def verdict(self, status: str, test: str | None, round_no: int | None, reason: str | None = None) -> Verdict:
        """The decision record of this evaluation (``test``: default :attr:`test`; ``reason``:
        default the gate that decided)."""
        return Verdict(status, self.test if test is None else test, self.gate if reason is None else reason, self.z,
                       self.z_crit, self.gain, self.min_gain, self.rmse_holdout_before, self.rmse_holdout_after,
                       round_no)


@dataclass
class _Folds:
    """What one candidate did in every fold (pass 1 of a round)."""

    r0: np.ndarray              # held-out residual without the candidate, every observation
    p1: np.ndarray              # held-out prediction with it
    proposals: list             # per fold: (keep mask over the round's columns, Proposal) or None
    contribution: np.ndarray | None
    n_par: int


def _run_folds(rnd: Round, cand: Candidate, *, repolish: bool = True) -> _Folds:
    """Run a candidate's procedure in every fold: held-out predictions with and without it.
    With ``repolish`` (all but periodic candidates) the model it extends has its nonlinear
    parameters refined together with the candidate on all data (README: "Nonlinear parameters
    stay where the data want them")."""
    dd, ext = rnd.dd, rnd
    prop_all = cand.propose(rnd, rnd.all_groups())
    contribution = None
    if prop_all is not None:
        if repolish and not isinstance(cand, PeriodicCandidate):
            rnd.release_design()    # a long recording: one round's design held at a time, not two
            movable = [b.uid for b, (a, z) in zip(rnd.state.blocks, rnd.taylor_spans()) if z - a > len(b.names)]
            movable += [b.uid for b in prop_all.add]     # and those with Taylor columns in the round's design
            st = refine(rnd.state.replaced(prop_all.drop, prop_all.add), dd, only=set(movable))
            st_base = st.replaced([b.uid for b in prop_all.add], prop_all.drop)
            ext = Round(dd, st_base, rnd.fold, standard_errors=False)
        # what the candidate adds when fitted on all data (for the report's figure)
        p_ext = prop_all if ext is rnd else cand.propose(ext, ext.all_groups())
        if p_ext is not None:
            keep = ext.keep_mask(p_ext.drop)
            beta, _ = train_fit(ext, keep, p_ext, ext.all_groups())
            nk = int(keep.sum())
            full = np.zeros(ext.width)
            full[keep] = beta[:nk]      # no copy of the kept columns (rows x terms) of a long recording
            contribution = ext.X @ full + p_ext.columns(dd) @ beta[nk:] - rnd.fitted.prediction
    p0 = rnd.held_out_prediction()      # the same for every candidate of the round
    p1 = np.zeros(len(dd))
    props = []
    n_par = 0
    for _, test in splits(rnd.fold):
        train = ~test
        prop = cand.propose(ext, train) if (train.any() and not train.all()) else None
        if prop is None:
            p1[rnd.rows(test)] = p0[rnd.rows(test)]
            props.append(None)
            continue
        keep = ext.keep_mask(prop.drop)
        beta1, _ = train_fit(ext, keep, prop, train)
        n_par = prop.n_params(ext)
        full = np.zeros(ext.width)
        full[keep] = beta1[:int(keep.sum())]
        _predict(p1, test, dd, ext.X, full, prop.column_blocks(dd), beta1[int(keep.sum()):])
        props.append((rnd.keep_mask(prop.drop), prop))
    if ext is not rnd and cand._cache.get("round") is ext:
        cand._cache = {}    # its memo holds the extended round's design (rows x terms), never asked again
    return _Folds(rnd.held_out_residual(), p1, props, contribution, n_par)


def _decide(rnd: Round, fr: _Folds, noise: np.ndarray | None, *, z_crit: float, min_gain: float,
            consistency: float = 0.9) -> Evaluation:
    """The three conditions of the module docstring.  ``noise``: the held-out residual the
    variance of Z is estimated from (default: the candidate's own, ``y - p1``)."""
    dd = rnd.dd
    y = dd.y
    r0 = fr.r0
    r1 = y - fr.p1
    delta = fr.p1 - (y - r0)
    rn = r1 if noise is None else noise
    ng = dd.n_groups
    sse0 = np.zeros(ng)
    sse1 = np.zeros(ng)
    fold_d = np.zeros(rnd.K)
    for g, (a, z) in enumerate(zip(dd.starts, dd.stops)):
        sse0[g] = float(r0[a:z] @ r0[a:z])
        sse1[g] = float(r1[a:z] @ r1[a:z])
        fold_d[rnd.fold[g]] += sse0[g] - sse1[g]
    N = len(dd)
    drop = float(sse0.sum() - sse1.sum())
    z = z_statistic(r0, delta, rn, dd.starts, dd.stops)
    tot = float(np.abs(fold_d).sum())
    cons = float(np.clip(fold_d, 0, None).sum() / tot) if tot > 0 else 0.0
    hb = math.sqrt(sse0.sum() / N)
    ha = math.sqrt(sse1.sum() / N)
    gain = (hb - ha) / hb if hb > 0 else 0.0
    reasons = []
    if not z >= z_crit:
        reasons.append(f"held-out Z {z:.2f} below {z_crit:.2f} (what noise alone gives at this level)"
                       + low_power_note(z_crit, ng))
    if not cons >= consistency:
        reasons.append(f"improves in folds carrying only {100 * cons:.0f} % of the change (needs {100 * consistency:.0f} %)")
    if not gain >= min_gain:
        reasons.append(f"held-out rmse changes by {-100 * gain:+.2f} % (needs a fall of {100 * min_gain:.2g} %)")
    passed = not reasons
    reason = (f"accepted: held-out Z {z:.1f} >= {z_crit:.2f}, rmse -{100 * gain:.2f} %" if passed
              else "; ".join(reasons))
    # the one reason: the first gate failed, in the order Z, consistency, gain
    first = (f"passes every gate (Z, {100 * consistency:.0f} % of the change in improving folds, rmse fall of "
             f"{100 * min_gain:.2g} %)" if passed else reasons[0])
    return Evaluation(z, z_crit, drop, fold_d, cons, hb, ha, gain, fr.n_par, passed, reason, fr.contribution,
                      first, min_gain)


#: the Z test is called low-power when its t quantile exceeds the normal quantile of the same level by this factor
LOW_POWER_RATIO = 1.5


def low_power_note(z_crit: float, groups: int) -> str:
    """A clause for a rejection by the Z gate when the held-out groups are too few: its t quantile
    (``groups - 1`` degrees of freedom) above :data:`LOW_POWER_RATIO` times the normal one."""
    if groups < 2 or not math.isfinite(z_crit):
        return ""
    level = float(stats.t.sf(z_crit, groups - 1))
    z_many = float(stats.norm.isf(level))
    ratio = z_crit / z_many
    if ratio <= LOW_POWER_RATIO:
        return ""
    verdict = ("the test cannot reach significance in practice" if ratio > 2 * LOW_POWER_RATIO
               else "the test has little power")
    return (f"; with {groups} held-out groups {verdict}: it needs Z above {z_crit:.1f} (a t quantile with "
            f"{groups - 1} degrees of freedom) where many groups would need {z_many:.1f}; hold out by segment "
            f"or record more runs")


def evaluate_candidate(rnd: Round, cand: Candidate, *, z_crit: float, min_gain: float,
                       consistency: float = 0.9, repolish: bool = True) -> Evaluation:
    """The held-out test of the module docstring for one candidate on its own (its own held-out
    residual estimates the noise)."""
    fr = _run_folds(rnd, cand, repolish=repolish)
    return _decide(rnd, fr, None, z_crit=z_crit, min_gain=min_gain, consistency=consistency)


# ---------------------------------------------------------------------- the loop
def _contribution(rnd_dd: DiagnoseData, state: State, fitted: FittedState, uids) -> np.ndarray:
    """What the blocks ``uids`` add to the prediction (torque, at the observations)."""
    out = np.zeros(len(rnd_dd))
    for blk, (a, z) in zip(state.blocks, state.spans()):
        if blk.uid in set(uids):
            out += blk.columns(rnd_dd) @ fitted.coef[a:z]
    return out


def diagnose(data, model: FrictionModel | None = None, *, law: str = "silo4", gear=None, harmonics=None,
             symmetric: bool | None = None, folds: int = 5, by: str | None = None, alpha: float = 0.01,
             min_gain: float = 0.005, max_rounds: int = 8, gate: float = 0.01, fap: float = 0.01,
             kinds=None, validation=None, per_segment_spectra: bool = True, progress=None) -> Diagnosis:
    """Run the closed loop on ``data`` from ``model`` (or from ``law`` fitted to it).

    Parameters
    ----------
    data : Recording, FitData or DiagnoseData
        Recordings are cut into constant-speed segments (:meth:`DiagnoseData.from_recording`);
        whole trajectories come from :func:`~gearspec.diagnose.trajectory_data`.
    model : FrictionModel, optional
        The model the user believes in (its law, lines and terms; nonlinear parameters kept,
        linear ones refitted).  Default: :func:`baseline_model` with ``law``, ``gear``,
        ``harmonics``, ``symmetric``.
    symmetric : bool, optional
        One parameter set for both directions (the asymmetry candidates then test whether the
        data want two); default: as ``model`` is (its two directions equal), else per direction.
    folds, by
        Held-out folds over whole groups (``by``: "segment" or "run"; trajectories: moves).
    alpha : float
        Family-wise level of the held-out test per round (Bonferroni over the round's candidates).
    min_gain : float
        Smallest relative fall of the held-out rmse worth a term.
    max_rounds : int
        At most this many terms are added.
    gate : float
        A detector proposes its candidates only when its evidence reaches p < gate (periodic: a
        residual-spectrum peak with false-alarm probability below ``fap``).
    kinds : iterable of str, optional
        Only these effect kinds (default: all).
    validation : Recording, FitData or DiagnoseData, optional
        Independent data (the same preparation): every accepted term must also lower the error
        there, or it is removed again.
    progress : callable, optional
        Called with one line of text per round.

    Notes
    -----
    BLAS on one thread (small matrices); untrimmed ``data`` are freed once trimmed if the caller keeps none.
    """
    with threadpool_limits(limits=1, user_api="blas"):
        box, data = [data], None
        return _diagnose(box, model, law=law, gear=gear, harmonics=harmonics, symmetric=symmetric, folds=folds,
                         by=by, alpha=alpha, min_gain=min_gain, max_rounds=max_rounds, gate=gate, fap=fap,
                         kinds=kinds, validation=validation, per_segment_spectra=per_segment_spectra,
                         progress=progress)


def _diagnose(box, model, *, law, gear, harmonics, symmetric, folds, by, alpha, min_gain, max_rounds, gate, fap,
              kinds, validation, per_segment_spectra, progress) -> Diagnosis:
    dd = _as_data(box.pop(), by, gear).without_edges()
    if gear is not None and dd.gear is None:
        from ..gears import load_gear
        dd.gear = load_gear(gear)
    if model is None:
        model = baseline_model(dd, law, gear=gear if gear is not None else dd.gear, harmonics=harmonics,
                               symmetric=bool(symmetric))
    if symmetric is None:
        symmetric = model.symmetric
    kinds = set(KINDS if kinds is None else kinds)
    bad = kinds - set(KINDS)
    if bad:
        raise InputError(f"unknown effect kind(s) {sorted(bad)} (known: {', '.join(KINDS)})")
    if dd.n_groups < 3:
        raise InputError(f"the data hold {dd.n_groups} held-out group(s) ({dd.by}s); the loop needs at least 3 "
                         "to hold whole groups out")
    fold = folds_of(dd, folds)
    state = _settle(state_from_model(model, dd, symmetric=bool(symmetric) and len(dd.directions()) == 2), dd)
    state, partial_notes = admit_partial_lines(state, model, dd, fold, _settle, evaluate_candidate, alpha=alpha,
                                               min_gain=min_gain, harmonics=harmonics,
                                               gear=gear if gear is not None else dd.gear)
    rnd = Round(dd, state, fold)
    base_fit = rnd.fitted
    base_h = rnd.baseline_holdout()
    base_ho = base_h["rmse"]
    say = progress or (lambda s: None)
    say(f"baseline: {model.name}, rmse {base_fit.rmse:.4g}, held-out rmse {base_ho:.4g} ({dd.n_groups} held-out "
        f"groups, {int(fold.max()) + 1} folds)")
    baseline = base_fit.model(name=f"baseline: {model.name}", rmse_holdout=base_ho)
    effects: dict[str, Effect] = {}
    rounds = []
    trace = []
    first_analyses = None
    held: set = set()        # blocks whose nonlinear parameters a candidate's own search chose (never re-settled)
    undone: dict = {}        # effect key -> (round, name): steps undone (the model with them was not better)
    for k in range(1, max_rounds + 1):
        analyses = analyse(rnd, fap=fap, per_segment=per_segment_spectra and k == 1)
        if first_analyses is None:
            first_analyses = analyses
        cands = propose(rnd, analyses, gate=gate, kinds=kinds)
        if cands:
            say(f"round {k}: residual analysed, testing {len(cands)} candidate(s) on held-out groups")
        if not cands:
            rounds.append({"round": k, "candidates": 0, "accepted": None})
            break
        z_crit = critical_z(alpha, len(cands), dd.n_groups)
        evals = _evaluate_round(rnd, cands, z_crit=z_crit, min_gain=min_gain)
        for c, ev in evals:
            _bar_reentry(effects, c, ev)
            bar_repeat(effects.get(_effect_key(effects, c)), _effect_key(effects, c), undone, ev)
            _record(effects, c, ev, k, rnd)
            trace.append({"round": k, "candidate": c.name, "kind": c.kind, "z": ev.z, "z_crit": z_crit,
                          "gain": ev.gain, "consistency": ev.consistency, "passed": ev.passed})
        passing = [(c, ev) for c, ev in evals if ev.passed]
        step = accept_first(rnd, passing, effects, k, z_crit=z_crit, min_gain=min_gain, held=held, undone=undone,
                            say=say) if passing else None
        if step is None:   # nothing passed, or every passing step was undone (accept_first said which)
            rounds.append({"round": k, "candidates": len(cands), "accepted": None, "z_crit": z_crit}
                          | ({"undone": undone_in(undone, k)} if passing else {}))
            say(f"round {k}: {len(cands)} candidates, " + ("none kept" if passing else "none accepted"))
            break
        rnd, ev, e, gone, ho_now = step
        rounds.append({"round": k, "candidates": len(cands), "accepted": e.name, "z_crit": z_crit,
                       "rmse": rnd.fitted.rmse, "rmse_holdout_step": ev.rmse_holdout_after,
                       "rmse_holdout_model": ho_now, "removed": gone, "undone": undone_in(undone, k)})
        say(f"round {k}: {len(cands)} candidates, accepted {e.name} (held-out rmse {ev.rmse_holdout_before:.4g} -> "
            f"{ev.rmse_holdout_after:.4g}; the model with it refitted: {ho_now:.4g})"
            + (f"; removed again: {', '.join(gone)}" if gone else ""))
    final_fit = rnd.fitted
    final_h = rnd.baseline_holdout()
    final_ho = final_h["rmse"]
    name = "final: " + model.name + "".join(f" + {e.name}" for e in effects.values() if e.accepted)
    final = final_fit.model(name=name, rmse_holdout=final_ho)
    diag = Diagnosis(dd, base_fit, final_fit, baseline, final, list(effects.values()), rounds, fold, base_h, final_h,
                     first_analyses or {}, {},
                     {"alpha": alpha, "min_gain": min_gain, "folds": int(fold.max()) + 1, "gate": gate, "fap": fap,
                      "max_rounds": max_rounds, "kinds": sorted(kinds), "symmetric": bool(state.symmetric)})
    diag.trace = pd.DataFrame(trace)
    if validation is not None:
        validate(diag, rnd, _as_data(validation, by, gear).without_edges(), alpha=alpha, min_gain=min_gain, say=say)
    if not (diag.validation or {}).get("removed"):
        diag.notes += _holdout_notes(rounds, base_ho, final_ho)
    diag.notes += partial_notes
    # what each accepted term wrote, from the final model (after backward elimination, validation)
    for e in diag.effects:
        if e.accepted:
            e.terms = _written_terms(e, diag.final)
            blocks = [diag.final.state.block(u) for u in e.detail.get("blocks", [])]
            e.parameters = "; ".join(b.describe() for b in blocks if b is not None)
    # what each accepted term explains in the final model: its contribution, and the partial
    # residual (data minus the rest of the final model) it is fitted to
    for e in diag.effects:
        if e.accepted:
            con = _contribution(dd, diag.final.state, diag.final, e.detail.get("blocks", []))
            e.detail["contribution"] = con
            e.detail["residual"] = diag.final.residual + con
            e.detail["partial"] = True
    diag.final_analyses = analyse(Round(dd, diag.final.state, fold), fap=fap, per_segment=False)
    return diag


def _mark_accepted(e: Effect, c: Candidate, ev: Evaluation, prop, new_state: State, rnd: Round, k: int) -> Effect:
    """Record on ``e`` that its candidate ``c`` was accepted in round ``k`` (proposal ``prop``,
    settled in ``new_state``; ``rnd``: the round with it)."""
    dd = rnd.dd
    e.accepted = True
    e.decision = ev.reason
    e.verdict = ev.verdict("accepted", "held-out", k)
    e.detail.setdefault("accepted_z", []).append(float(ev.z))
    e.history.append(f"round {k}: accepted")
    e.detail["blocks"] = [b.uid for b in prop.add]
    e.detail["dropped"] = [b for b in prop.drop]
    added = [new_state.block(u) for u in e.detail["blocks"]]
    e.parameters = "; ".join(b.describe() for b in added if b is not None)
    if isinstance(c, PeriodicCandidate):
        f_fit = added[0].frequency
        f_se = rnd.fitted.nonlinear_se.get(added[0].uid, {}).get(("frequency",))
        c.relabel(f_fit, f_se)
        e.detail["frequency_se"] = f_se
        e.frequency, e.label, e.hint = f_fit, c.label, c.hint
        e.name = f"line at {f_fit:.6g} cycles/{dd.unit}"
        e.order = dd.gear.order(f_fit) if dd.gear is not None else None
    e.detail["contribution"] = _contribution(dd, rnd.state, rnd.fitted, e.detail["blocks"])
    return e


def _holdout_notes(rounds: list, base_ho: float, final_ho: float) -> list:
    """Why the final held-out rmse is not the last accepted step's number, when it is not."""
    acc = [r for r in rounds if r.get("accepted")]
    if not acc:
        return []
    last = acc[-1]
    step, model_ho = last["rmse_holdout_step"], last["rmse_holdout_model"]
    if math.isclose(step, final_ho, rel_tol=1e-9):
        return []
    out = (f"held-out rmse: {base_ho:.5g} (baseline) -> {final_ho:.5g} (final model). The last accepted step "
           f"(round {last['round']}) reported {step:.5g}: there the candidate's own search (frequency, amplitude "
           f"law, shape) ran again in every fold, the honest figure for choosing it; the final model, like the "
           f"baseline, has its nonlinear parameters settled on all data and refits them in every fold (same folds)")
    if last.get("removed"):
        out += f", and backward elimination removed {', '.join(last['removed'])}"
    if not math.isclose(model_ho, final_ho, rel_tol=1e-9):
        out += "; later rounds changed the model"
    return [out + "."]


def promising(ev: Evaluation, n: int) -> bool:
    """A candidate that may join the round's richest model: its held-out drop above round-off
    (:data:`~gearspec.core.crossval.ROUNDOFF_SHARE` of the held-out sum of squares), in folds
    carrying 90 % of the change."""
    return ev.drop > ROUNDOFF_SHARE * n * ev.rmse_holdout_before ** 2 and ev.consistency >= 0.9


def _evaluate_round(rnd: Round, cands: list, *, z_crit: float, min_gain: float) -> list:
    """Every candidate of a round through the held-out test (in forked workers where they pay), the noise of Z
    from the held-out residual of the richest model the round supports (README, Acceptance)."""
    from .parallel_round import run_candidates
    runs = run_candidates(rnd, cands, _run_folds)
    first = [_decide(rnd, fr, None, z_crit=z_crit, min_gain=min_gain) for fr in runs]
    # the richest model: the best promising candidate of every kind (members of one family, e.g.
    # three shapes of Stribeck term, would only fit each other's noise)
    best: dict = {}
    for c, fr, ev in zip(cands, runs, first):
        if promising(ev, len(rnd.dd)) and (c.kind not in best or ev.drop > best[c.kind][1].drop):
            best[c.kind] = (fr, ev)
    if len(best) < 2:
        return list(zip(cands, first))
    noise = _full_residual(rnd, [fr for fr, _ in best.values()])
    out = []
    for c, fr, ev in zip(cands, runs, first):
        ev2 = _decide(rnd, fr, noise, z_crit=z_crit, min_gain=min_gain)
        # the noise estimate is the smaller of the two: the richest model can extrapolate worse
        # than the candidate alone on a few groups
        out.append((c, ev2 if ev2.z > ev.z else ev))
    return out


def _backward(rnd: Round, effects: dict, newest: Effect, *, z_crit: float, min_gain: float, round_no: int):
    """Backward elimination: every term accepted before ``newest`` must still pass the held-out test
    against the model without it; the weakest that fails is removed, and the check repeats.
    Returns the new round, or None when nothing was removed."""
    dd = rnd.dd
    changed = None
    while True:
        weakest = None
        for e in [x for x in effects.values() if x.accepted and x is not newest]:
            uids = e.detail.get("blocks", [])
            blocks = [rnd.state.block(u) for u in uids]
            if not blocks or any(b is None for b in blocks):
                continue
            st_wo = _settle(rnd.state.replaced(uids, e.detail.get("dropped", [])), dd)
            rnd_wo = Round(dd, st_wo, rnd.fold)
            cand = FixedCandidate(e.kind, e.name, blocks, [b for b in e.detail.get("dropped", [])])
            ev = evaluate_candidate(rnd_wo, cand, z_crit=z_crit, min_gain=min_gain, repolish=False)
            if not ev.passed and (weakest is None or ev.z < weakest[1].z):
                weakest = (e, ev, rnd_wo)
        if weakest is None:
            return changed
        e, ev, rnd_wo = weakest
        e.accepted = False
        e.detail.setdefault("removed", []).append(round_no)
        e.decision = (f"removed in round {round_no}: once '{newest.name}' was added it no longer lowers the held-out "
                      f"error enough ({ev.reason})")
        e.history.append(e.decision)
        e.z, e.gain = ev.z, ev.gain
        e.verdict = ev.verdict("removed", "backward elimination", round_no,
                               f"once '{newest.name}' was in, it no longer passes: {ev.gate}")
        rnd = changed = rnd_wo


def _settle(state: State, dd: DiagnoseData) -> State:
    """Nonlinear parameters of a state where all data want them: :func:`.polish`, then
    :func:`.refine` (a candidate's held-out gain is then its own, not a better-tuned base law's)."""
    return refine(polish(state, dd), dd, steps=8)


def _effect_key(effects: dict, c: Candidate) -> str:
    """The key of ``c``'s effect: a line seen again in a later round (within two resolution steps)
    is the same effect."""
    if not isinstance(c, PeriodicCandidate):
        return f"{c.kind}: {c.name}"
    return next((kk for kk, e in effects.items() if e.kind == "periodic" and e.frequency
                 and abs(e.frequency - c.f0) <= max(2 * c.resolution, 5e-3 * e.frequency)), f"periodic {c.f0:.4g}")


#: a term removed by backward elimination is accepted again at most this many times
MAX_REENTRIES = 1


def _bar_reentry(effects: dict, c: Candidate, ev: Evaluation) -> None:
    """The re-entry rule: a term that backward elimination removed is accepted again only with a
    held-out Z above the largest it was accepted with, and at most :data:`MAX_REENTRIES` times (the
    same evidence would accept and remove it round after round).  Marks ``ev`` failing when barred."""
    prev = effects.get(_effect_key(effects, c))
    if prev is None or prev.accepted or not prev.detail.get("removed") or not ev.passed:
        return
    z_before = max(prev.detail.get("accepted_z", [float("-inf")]))
    removed = prev.detail["removed"]
    if len(removed) > MAX_REENTRIES:
        why = f"removed {len(removed)} times already (rounds {', '.join(map(str, removed))}): not accepted again"
    elif not ev.z > z_before:
        why = (f"removed in round {removed[-1]}; passes again with Z {ev.z:.1f}, not above the Z {z_before:.1f} it "
               f"was accepted with: the same evidence, not accepted again")
    else:
        return
    ev.passed = False
    ev.reason = ev.gate = why
    ev.test = "re-entry"


def _record(effects: dict, c: Candidate, ev: Evaluation, k: int, rnd: Round) -> None:
    key = _effect_key(effects, c)
    prev = effects.get(key)
    if prev is not None and prev.accepted:
        return
    history = list(prev.history) if prev is not None else []
    dd = rnd.dd
    e = Effect(kind=c.kind, name=c.name, accepted=False, evidence=c.evidence,
               rmse_holdout_before=ev.rmse_holdout_before, rmse_holdout_after=ev.rmse_holdout_after,
               frequency=c.frequency, label=c.label, hint=c.hint,
               order=(dd.gear.order(c.frequency) if (dd.gear is not None and c.frequency) else None),
               z=ev.z, z_crit=ev.z_crit, gain=ev.gain, consistency=ev.consistency, n_params=ev.n_params, round=k,
               decision=("passes the test (another candidate went first this round)" if ev.passed else
                         "rejected: " + ev.reason), detail=dict(c.detail), history=history,
               value=getattr(c, "value", None))
    barred = prev is not None and bool(prev.detail.get("removed"))
    e.verdict = ev.verdict("removed" if barred else "rejected", None,
                           k, f"passes every gate, but another candidate went first in round {k} and it was not "
                              "tested again" if ev.passed else None)
    e.detail["residual"] = rnd.fitted.residual
    e.detail["contribution"] = ev.contribution
    e.history.append(f"round {k}: Z {ev.z:.2f} (needs {ev.z_crit:.2f}), held-out rmse {ev.rmse_holdout_before:.4g} -> "
                     f"{ev.rmse_holdout_after:.4g}: " + ("passes" if ev.passed else "fails"))
    if prev is not None:  # what the loop did with it before: acceptances and removals
        for kk in ("accepted_z", "removed"):
            if kk in prev.detail:
                e.detail[kk] = list(prev.detail[kk])
    effects[key] = e


def _written_terms(e: Effect, fitted: FittedState) -> list:
    """The model entries an accepted effect added (terms and harmonics, with standard errors), as
    the fitted state ``fitted`` (the final model) has them."""
    blocks = [fitted.state.block(u) for u in e.detail.get("blocks", [])]
    m = fitted.model()
    out = []
    for blk in [b for b in blocks if b is not None]:
        if isinstance(blk, HarmonicBlock):
            out += [{"direction": dname, "harmonic": h.to_dict()} for dname, p in m.directions.items()
                    for h in p.harmonics if math.isclose(h.frequency, blk.frequency, rel_tol=1e-12)]
        elif isinstance(blk, TermBlock):
            out += [{"term": t} for t in m.terms if blk.matches(t)]
        else:
            out.append({"note": blk.describe()})
    return out
