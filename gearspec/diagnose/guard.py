"""A step of the closed loop is kept only when it leaves a better model (README, "The closed loop",
Acceptance): the model kept is the model the held-out test judged, its held-out rmse with the
candidate is below the one before, and no candidate is accepted twice.

The loop (:mod:`.loop`) calls :func:`accept_first` with the passing candidates of a round and
:func:`bar_repeat` on every evaluation before it records it.
"""

from __future__ import annotations

from .context import Round
from .data import DiagnoseData
from .design import State
from .nonlinear import polish, refine
from .results import Effect, Verdict

__all__ = ["settle_holding", "settle_step", "accept_first", "bar_repeat", "undone_in", "SETTLED_TEST"]

#: the name of the test that undoes a step (a :class:`~.results.Verdict`'s ``test``)
SETTLED_TEST = "settled model"


def settle_holding(state: State, dd: DiagnoseData, held) -> State:
    """The loop's settle (:func:`.polish`, then 8 steps of :func:`.refine`) with the nonlinear
    parameters of the blocks ``held`` (uids) kept as they are: those a candidate's own held-out
    search chose (an amplitude law and its decay).  Settled on all data they can return to the
    in-sample optimum the model had before (Kinova joint 7: a decay of 3.3 back to 69 per rad/s),
    and the model kept would not be the model the held-out test judged."""
    only = ({b.uid for b in state.blocks} - set(held)) if held else None
    return refine(polish(state, dd, only=only), dd, only=only, steps=8)


def accept_first(rnd, passing: list, effects: dict, k: int, *, z_crit: float, min_gain: float, held: set,
                 undone: dict, say):
    """Take the passing candidates of round ``k`` in order of their held-out SSE drop; keep the
    first whose step leaves a better model.  A step: its proposal added and the model settled
    (:func:`settle_step`); it is kept when that model's held-out rmse
    (:meth:`~.context.Round.baseline_holdout`, Nm, the same folds and refit as the baseline's) is
    below the one before the step: then ``held`` grows by the blocks the candidate holds, the effect
    is marked accepted and backward elimination runs (its removals are its own test's, as before).
    Otherwise the step is undone, the candidate recorded as rejected (:func:`mark_undone`) and
    ``undone[key] = (k, name)``; the next passing candidate is tried.

    Returns ``(round, evaluation, effect, names removed by backward elimination, held-out rmse)``,
    or None when no step is kept."""
    from .loop import _backward, _effect_key, _mark_accepted

    ho_before = rnd.baseline_holdout()["rmse"]
    for c, ev in sorted(passing, key=lambda x: x[1].drop, reverse=True):
        prop = c.propose(rnd, rnd.all_groups())
        if prop is None:
            continue
        new, hold = settle_step(rnd, prop, held, getattr(c, "holds_parameters", False))
        # the held-out rmse of the model with the candidate (its nonlinear parameters settled on all
        # data, refitted in every fold as the baseline's are): it must be below the one before
        ho_new = new.baseline_holdout()["rmse"]
        key = _effect_key(effects, c)
        if not ho_new < ho_before:
            line = mark_undone(effects[key], ev, k, ho_before, ho_new)
            undone[key] = (k, c.name)
            say(f"round {k}: {c.name} passes the held-out test but its step is undone: {line}")
            continue
        held |= hold
        e = _mark_accepted(effects[key], c, ev, prop, new.state, new, k)
        was_in = {x.name for x in effects.values() if x.accepted}
        new = _backward(new, effects, e, z_crit=z_crit, min_gain=min_gain, round_no=k) or new
        gone = sorted(was_in - {x.name for x in effects.values() if x.accepted})
        return new, ev, e, gone, (new.baseline_holdout()["rmse"] if gone else ho_new)
    return None


def settle_step(rnd, prop, held: set, holds: bool):
    """The round (:class:`~.context.Round`) of the model with the proposal ``prop`` settled, and the
    blocks held from now on.  Settled freely (but ``held``) as the loop always did; when the candidate
    ``holds`` its parameters (an amplitude law: its decay is what its held-out search chose) also with
    the proposal's blocks held, and that model is kept when it predicts the held-out groups better
    (:meth:`~.context.Round.baseline_holdout`): settling on all data must not turn the model the test
    judged into another one (Kinova joint 7: back to the law it replaced, 0.2297 Nm against 0.1521)."""
    dd = rnd.dd
    state = rnd.state.replaced(prop.drop, prop.add)
    free = Round(dd, settle_holding(state, dd, held), rnd.fold)
    if not holds:
        return free, held
    hold = held | {b.uid for b in prop.add}
    kept = Round(dd, settle_holding(state, dd, hold), rnd.fold)
    if kept.baseline_holdout()["rmse"] < free.baseline_holdout()["rmse"]:
        return kept, hold
    return free, held


def mark_undone(e: Effect, ev, k: int, ho_before: float, ho_after: float) -> str:
    """Record on ``e`` (as it was before round ``k``'s step; ``ev``: its held-out evaluation) that
    its step was undone: the settled model with it has held-out rmse ``ho_after`` (Nm), not below
    ``ho_before``.  Returns the reason."""
    reason = (f"the model with it settled has held-out rmse {ho_after:.4g}, not below {ho_before:.4g} before the "
              f"step (its own search in the folds gave {ev.rmse_holdout_after:.4g}): step undone")
    gain = (ho_before - ho_after) / ho_before if ho_before > 0 else 0.0
    e.accepted = False
    e.decision = "rejected: " + reason
    e.verdict = Verdict("rejected", SETTLED_TEST, reason, ev.z, ev.z_crit, gain, ev.min_gain, ho_before, ho_after, k)
    e.history.append(f"round {k}: passes the held-out test, but {reason}")
    return reason


def bar_repeat(prev: Effect | None, key: str, undone: dict, ev) -> None:
    """No candidate is accepted twice: one whose effect ``prev`` (under ``key``) is in the model
    already, or whose step was undone in an earlier round (``undone``, :func:`accept_first`), has its
    evaluation ``ev`` marked failing, with the reason."""
    if not ev.passed:
        return
    if prev is not None and prev.accepted:
        why = f"in the model already (accepted in round {prev.verdict.round if prev.verdict else prev.round})"
    elif key in undone:
        why = f"its step was undone in round {undone[key][0]} (the model with it was not better): not tried again"
    else:
        return
    ev.passed = False
    ev.reason = ev.gate = why
    ev.test = "re-entry" if prev is not None and prev.accepted else SETTLED_TEST


def undone_in(undone: dict, k: int) -> list:
    """Names of the candidates whose step was undone in round ``k``."""
    return sorted(name for r, name in undone.values() if r == k)
