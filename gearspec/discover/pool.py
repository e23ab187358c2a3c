"""The search pool of the explorer: structures refined and scored on one set of moments, the moves
of its hill climb (a term added, dropped, made direction-dependent or symmetric, reshaped) and the
selection rule (the simplest law within ``se_rule`` standard errors of noise of the best)."""

from __future__ import annotations

import math

import numpy as np

from .forked import MIN_QUICK, fits_map
from .law import LawFit, Part, canonical, complexity, cross_validate, cross_validate_linear, fit_law
from .library import FAMILIES, Library
from .moments import Moments
from .results import Candidate, _paired


def _structure(lib: Library, w: np.ndarray) -> tuple:
    """Library columns selected (nonzero standardised coefficients ``w``) -> a structure: one part
    per slot of equivalent shapes (Stribeck of any shape and velocity, one power law, one
    amplitude law per ripple line; the member with the largest coefficient), direction-dependent
    where an asym column of the slot is selected.  Keeping one Stribeck term and one amplitude law
    per line keeps the laws readable and the refinement well posed: a second Stribeck term at a
    neighbouring velocity is how plain least squares spends collinearity, not physics."""
    ct = lib.column_terms()
    weight: dict = {}
    split: dict = {}
    for j in np.flatnonzero(w):
        t = lib.terms[ct[j]]
        slot = _group_of(Part(t.family, t.freq))
        weight.setdefault(slot, {}).setdefault(t.key, 0.0)
        weight[slot][t.key] += abs(float(w[j]))
        split[slot] = split.get(slot, False) or t.variant == "asym"
    parts = []
    for slot, members in weight.items():
        fam, param, freq = max(members, key=members.get)
        parts.append(Part(fam, freq, split[slot], param))
    return canonical(parts)


def _signature(parts) -> tuple:
    """What distinguishes structures after refinement (refined parameters' start values do not)."""
    return tuple(sorted((p.family, -1 if p.freq is None else p.freq, p.split, 0.0 if p.free else (p.param0 or 0.0))
                        for p in parts))


def _group_of(p: Part) -> tuple:
    """The slot of a part: its family's slot of equivalent shapes and its ripple line."""
    return (p.fam.slot, p.freq)


def _addable(lib: Library) -> list[Part]:
    """One symmetric part per family (and ripple line, and fixed exponent) of the library, its
    parameter started at the middle of the library's grid: what the search may add."""
    grid: dict = {}
    for t in lib.terms:
        key = (t.family, t.freq, t.param if (t.fam.param and not t.fam.refine) else None)
        grid.setdefault(key, []).append(t.param)
    out = []
    for (fam, freq, fixed), params in grid.items():
        if fixed is not None:
            p0 = fixed
        elif FAMILIES[fam].param:
            vals = sorted(set(params))
            p0 = vals[len(vals) // 2]
        else:
            p0 = None
        out.append(Part(fam, freq, False, p0))
    return out


def _inherit(fit: LawFit) -> tuple:
    """The law's parts with their start values set to the refined ones (geometric mean over the
    directions), so that its neighbours start their refinement where it ended."""
    vals: dict = {}
    for (i, _), zv in zip(fit.layout.nl, fit.z):
        vals.setdefault(i, []).append(zv)
    return tuple(Part(p.family, p.freq, p.split, math.exp(float(np.mean(vals[i]))) if i in vals else p.param0)
                 for i, p in enumerate(fit.parts))


def _compound(parts, M: Moments) -> list[tuple]:
    """Two moves at once: a term dropped and another made direction-dependent -- to leave a local
    optimum where one term stands in for the direction dependence of another."""
    out = []
    for i in range(len(parts) if len(M.directions) == 2 else 0):
        rest = list(parts[:i]) + list(parts[i + 1:])
        out += [canonical(rest[:j] + rest[j + 1:] + [Part(p.family, p.freq, True, p.param0)])
                for j, p in enumerate(rest) if not p.split and p.fam.basis != "acc"]
    return out


def _neighbours(parts, M: Moments, addable=(), adds: bool = True) -> list[tuple]:
    """Structures around one: each part dropped, made symmetric or direction-dependent, or given
    the other shapes of its slot; each of ``addable`` added (if its family and line are absent)."""
    out = []
    both = len(M.directions) == 2
    if both:   # direction dependence wholesale: every term split, or none
        out.append(canonical([Part(p.family, p.freq, p.fam.basis != "acc", p.param0) for p in parts]))
        out.append(canonical([Part(p.family, p.freq, False, p.param0) for p in parts]))
    have = {_group_of(p) for p in parts}
    for a in (addable if adds else ()):
        if _group_of(a) not in have:
            out.append(canonical(list(parts) + [a]))
    for i, p in enumerate(parts):
        rest = list(parts[:i]) + list(parts[i + 1:])
        if rest:
            out.append(canonical(rest))
        if p.split:
            out.append(canonical(rest + [Part(p.family, p.freq, False, p.param0)]))
        elif both and p.fam.basis != "acc":
            out.append(canonical(rest + [Part(p.family, p.freq, True, p.param0)]))
        slot = _group_of(p)
        for a in addable:
            if _group_of(a) == slot and (a.family != p.family or (not a.free and a.param0 != p.param0)):
                p0 = a.param0 if not a.free else (p.param0 if (p.param0 is not None and p.free
                                                               and a.fam.param == p.fam.param) else a.param0)
                out.append(canonical(rest + [Part(a.family, p.freq, p.split, p0)]))
    return out


def _better(fit: LawFit, old: LawFit) -> bool:
    """Whether a new fit of a signature replaces the pool's: a lower in-sample error (beyond round-off)."""
    return bool(np.sum(fit.sse) < np.sum(old.sse) * (1 - 1e-9))


def _full_holdout(M: Moments, fold, fit: LawFit):
    """A law's full held-out refit: its all-data fit run to convergence from ``fit``'s optimum and
    every fold refitted from there (:func:`~.law.cross_validate`): ``(fit, cv_sse, cv_pred)``; None
    for a law without nonlinear parameters (its screen is exact)."""
    if not any(p.free for p in fit.parts):
        return None
    f = fit_law(M, fit.parts, z0=fit.z)
    return (f,) + tuple(cross_validate(M, fit.parts, fold, z0=f.z))


#: laws per progress line within a step of the selection (on the default twin: 10 full held-out
#: refits of a 40-parameter law take about 7 s)
TICK = 10


class _Pool:
    """Structures refined and scored on one set of moments: one per signature (the best in-sample
    fit among those that share it).  Held-out errors: a fast screen while searching (nonlinear
    parameters held, :func:`~.law.cross_validate_linear`), then full refits per fold for the laws
    that can end up on the front or be selected (:func:`~.law.cross_validate`)."""

    def __init__(self, M: Moments, fold, by, max_parts, se_rule, addable=()):
        self.M, self.fold, self.max_parts, self.se_rule = M, fold, max_parts, se_rule
        self.groups = M.groups(by)
        self.fits: dict = {}          # signature -> (fit, origin, threshold)
        self.tried: set = set()
        self.cands: dict = {}         # signature -> Candidate (screened)
        self.full: set = set()        # signatures with full held-out refits
        self.screened: dict = {}      # signature -> (fit, its screen) computed with the fit, not yet in cands
        self.prefit: dict = {}        # signature -> (fit, its full held-out refit) computed with the fit (consider_all)
        self.addable = list(addable)
        self.screen_nfev = 12          # a few refinement steps while screening; full refinement later
        self.refine_top = 4
        self.rounds, self.settled = 0, False   # of the selection (:func:`finalize`)
        self.say = lambda text: None   # progress: called with one line of text as a step of the search ends

    def consider(self, parts, origin, thr, refine: bool = True):
        """The structure ``parts`` fitted (a few refinement steps) and kept under its signature when
        it fits better than the law held there; its signature (None: empty, tried before or over
        ``max_parts`` terms)."""
        return self.consider_all([(parts, origin, thr)], refine)[0]

    def consider_all(self, items, refine: bool = True, what: str = "", holdout: bool = False) -> list:
        """:meth:`consider` of every ``(parts, origin, threshold)`` of ``items`` in turn, the new
        structures fitted at once (:func:`~gearspec.core.parallel.forked_map`: a fit depends on its
        structure and the moments only) and the pool's bookkeeping done in the order of ``items``,
        as one call after another would; with ``what``, :meth:`tick` after every item.  With
        ``holdout``: the full held-out refits (:meth:`refit_holdout`) of the signatures of ``items``
        the pool will hold without one are computed in the same map, each in the task of its
        signature's fits (a task fits a signature's new structures, takes the fit the bookkeeping
        will keep and refits it: the same numbers as a map of fits then a map of refits), kept for
        the :meth:`refit_holdout` that follows; a fit refitted so is not screened (the screen
        would be replaced), unless its law has no nonlinear parameter (its screen is its held-out
        error)."""
        plan = []
        for parts, origin, thr in items:
            parts = canonical(parts)
            if not parts or parts in self.tried or len(parts) > self.max_parts:
                plan.append(None)
                continue
            self.tried.add(parts)
            sig = _signature(parts)
            # a law with a held-out error keeps it (its all-data fit converged from the best start
            # the screen had): an error that changed between rounds could make the selection cycle
            plan.append((parts, sig, origin, thr, sig not in self.full))
        M, nfev, fold = self.M, self.screen_nfev, self.fold

        def fit(ps, screen=True):        # a new fit and its screen (every fit kept is screened next)
            f = fit_law(M, ps, max_nfev=nfev, refine=refine)
            return f, (cross_validate_linear(M, f, fold) if screen else None)

        new = [p for p in plan if p is not None and p[4]]
        if holdout:
            got = self._fit_refit(new, [canonical(it[0]) for it in items], fit)
        else:
            got = fits_map(fit, [p[0] for p in new], min_items=MIN_QUICK, cost=complexity)
        fits = iter(got)
        out = []
        for k, p in enumerate(plan):
            if p is not None and p[4]:
                _, sig, origin, thr, _ = p
                fit, screen = next(fits)
                old = self.fits.get(sig)
                if old is None or _better(fit, old[0]):
                    self.fits[sig] = (fit, origin if old is None else old[1], thr if old is None else old[2])
                    self.cands.pop(sig, None)
                    self.full.discard(sig)
                    self.screened[sig] = (fit, screen)
            out.append(None if p is None else p[1])
            self.tick(k, len(plan), what)
        for sig, (start, _) in list(self.prefit.items()):
            if sig not in self.fits or self.fits[sig][0] is not start:    # (cannot happen: the task's rule is ours)
                del self.prefit[sig]
        return out

    def _fit_refit(self, new, sigs_of_items, fit) -> list:
        """The fits of the planned structures ``new`` (in their order, as :meth:`consider_all`
        wants them) and, in the same tasks, the full held-out refits of the fits the pool will
        hold under their signatures and under the other signatures of ``sigs_of_items`` it holds
        without one: one task per signature, the refits kept in :attr:`prefit` (signature ->
        (the fit refitted, :meth:`refit_holdout`'s result))."""
        groups: dict = {}
        for p in new:
            groups.setdefault(p[1], []).append(p[0])
        tasks = [(sig, ps) for sig, ps in groups.items()]
        for parts in sigs_of_items:
            sig = _signature(parts)
            if sig in self.cands and sig not in self.full and sig not in groups:
                groups[sig] = []
                tasks.append((sig, []))
        M, fold, fits, cands = self.M, self.fold, self.fits, self.cands

        def task(t):
            sig, group = t
            linear = not any(p.free for p in (group[0] if group else cands[sig].parts))
            got = [fit(ps, screen=linear) for ps in group]
            keep, start = -1, (fits[sig][0] if sig in fits else None)
            if not group:
                start = cands[sig].fit
            for i, (f, _) in enumerate(got):      # the rule of consider_all's bookkeeping
                if start is None or _better(f, start):
                    keep, start = i, f
            return got, keep, _full_holdout(M, fold, start)

        res = fits_map(task, tasks, cost=lambda t: complexity(t[1][0] if t[1] else
                                                                                   cands[t[0]].parts))
        self.prefit = {}
        out: dict = {}
        for (sig, group), (got, keep, full) in zip(tasks, res):
            out[sig] = iter(got)
            start = got[keep][0] if keep >= 0 else (fits[sig][0] if group else cands[sig].fit)
            self.prefit[sig] = (start, full)
        return [next(out[p[1]]) for p in new]

    def screen(self):
        """The fast held-out screen (:func:`~.law.cross_validate_linear`) of every fit not screened
        yet, in the order of the fits: computed with the fit (:meth:`consider_all`, :meth:`refine`),
        here for a fit put in the pool otherwise; for a fit whose full held-out refit is at hand
        (:attr:`prefit`), that refit's numbers until :meth:`refit_holdout` applies it."""
        M, done = self.M, self.screened
        for sig, (fit, origin, thr) in self.fits.items():
            if sig not in self.cands:
                # a screen computed with a fit serves only that fit (the same object, not a later one)
                mine = sig in done and done[sig][0] is fit and done[sig][1] is not None
                pre = self.prefit.get(sig, (None, None))
                if mine:
                    cv, pred = done[sig][1]
                elif pre[0] is fit and pre[1] is not None:
                    _, cv, pred = pre[1]
                else:
                    cv, pred = cross_validate_linear(M, fit, self.fold)
                self.cands[sig] = Candidate(fit, cv, math.sqrt(float(np.sum(cv)) / M.N), origin, thr, pred)
        self.screened = {}

    def refine(self, sigs):
        """A few refinement steps for structures screened with their start values."""
        todo = [s for s in dict.fromkeys(sigs) if any(p.free for p in self.fits[s][0].parts)]
        M, nfev, fits, fold = self.M, self.screen_nfev, self.fits, self.fold

        def fit(sig):
            f = fit_law(M, fits[sig][0].parts, z0=fits[sig][0].z, max_nfev=nfev)
            return f, cross_validate_linear(M, f, fold)

        res = fits_map(fit, todo, min_items=MIN_QUICK, cost=lambda s: complexity(fits[s][0].parts))
        for sig, (f, screen) in zip(todo, res):
            self.fits[sig] = (f, self.fits[sig][1], self.fits[sig][2])
            self.cands.pop(sig, None)
            self.screened[sig] = (f, screen)
        self.screen()

    def refit_holdout(self, sigs, what: str = ""):
        """Full held-out refits of the laws ``sigs`` (those without one yet), computed at once (or
        taken from :attr:`prefit` where :meth:`consider_all` computed them from the same fit);
        with ``what``, a progress line every :data:`TICK` laws (``what``: the laws, as the line
        names them)."""
        todo = [s for s in dict.fromkeys(sigs) if s not in self.full]
        M, fold, cands = self.M, self.fold, self.cands
        pre = {s: self.prefit[s][1] for s in todo if s in self.prefit and self.prefit[s][0] is cands[s].fit}
        self.prefit = {}
        rest = [s for s in todo if s not in pre]
        res = dict(zip(rest, fits_map(lambda s: _full_holdout(M, fold, cands[s].fit), rest,
                                      cost=lambda s: cands[s].complexity)))
        for k, sig in enumerate(todo):
            got = pre[sig] if sig in pre else res[sig]
            if got is not None:
                c = self.cands[sig]
                c.fit, c.cv_sse, c.cv_pred = got
                c.rmse_holdout = math.sqrt(float(np.sum(c.cv_sse)) / M.N)
            self.full.add(sig)
            self.tick(k, len(todo), what)

    def holdout(self, parts, origin: str = "the acceptance test") -> tuple | None:
        """The held-out sse per segment and predictions of the law ``parts`` as the pool scores it
        (fitted, screened and refitted on the folds when it is new; the pool's own numbers when
        it has them): what the acceptance test judges by, so that one law has one held-out error.
        None for a law the pool does not hold (none, or more than ``max_parts`` terms)."""
        parts = canonical(parts)
        sig = _signature(parts)
        if sig not in self.full:
            if not parts or len(parts) > self.max_parts:
                return None
            self.holdout_all([parts], origin)
        c = self.cands[sig]
        return c.cv_sse, c.cv_pred

    def holdout_all(self, laws, origin: str = "the acceptance test") -> None:
        """:meth:`holdout` of every law of ``laws`` in turn (their results kept in the pool), the
        new laws' fits and held-out refits computed at once: what the acceptance test asks of one
        round, before it asks."""
        new, seen = [], set()
        for parts in laws:
            parts = canonical(parts)
            sig = _signature(parts)
            if parts and len(parts) <= self.max_parts and sig not in self.full and sig not in seen:
                seen.add(sig)
                new.append((parts, sig))
        M, fold = self.M, self.fold

        def score(item):
            # what refit_holdout does, without the screen's few steps first: the all-data fit from
            # the parts' start values (scanned), the folds from its optimum
            fit = fit_law(M, item[0])
            return (fit,) + tuple(cross_validate(M, item[0], fold, z0=fit.z))

        for (parts, sig), (fit, cv, pred) in zip(new, fits_map(score, new, cost=lambda it: complexity(it[0]))):
            self.tried.add(parts)
            self.fits[sig] = (fit, origin, None)
            self.cands[sig] = Candidate(fit, cv, math.sqrt(float(np.sum(cv)) / M.N), origin, None, pred)
            self.full.add(sig)

    def tick(self, k: int, n: int, what: str) -> None:
        """Progress within a long step: a line after every :data:`TICK` of its ``n`` laws but the last."""
        if what and (k + 1) % TICK == 0 and k + 1 < n:
            self.say(f"{what}: {k + 1} of {n}")

    def best(self):
        """The structure with the lowest held-out error so far."""
        return min(self.cands, key=lambda s: self.cands[s].rmse_holdout)

    def select(self):
        """The selection rule (:func:`_select`) over the laws with full held-out refits."""
        return _select({s: self.cands[s] for s in self.full}, self.M, self.groups, self.se_rule)


def climb(pool: _Pool, rounds: int = 12):
    """Hill climbing on the screened held-out error from the best structure of ``pool``: every
    neighbour (a term added, dropped, made direction-dependent or symmetric, reshaped) evaluated,
    the best taken, until nothing improves (at a local optimum of single moves, pairs of moves are
    tried once).  Returns the signature it ends at."""
    pool.screen()
    cur = pool.best()
    compound = False
    for rnd in range(rounds):
        nxt = _climb_step(pool, cur, compound)
        pool.say(f"hill climb round {rnd + 1}{' (pairs of moves)' if compound else ''}: {len(pool.cands)} laws "
                 f"screened, the best of complexity {pool.cands[nxt].complexity}")
        if nxt == cur and not compound:
            compound = True          # a local optimum of single moves: try pairs once
            continue
        compound = False
        if nxt == cur:
            break
        cur = nxt
    return cur


def _climb_step(pool: _Pool, cur, compound: bool):
    """One round of moves (or pairs of moves) from the structure ``cur``; the best structure after it."""
    base = pool.cands[cur]
    start = _inherit(base.fit)
    moves = _compound(start, pool.M) if compound else _neighbours(start, pool.M, pool.addable)
    origin = f"neighbour of {_short(base, pool.M)}"
    new = [s for s in pool.consider_all([(parts, origin, base.threshold) for parts in moves], refine=False)
           if s is not None]
    pool.screen()
    # neighbours start from the parent's refined values (new terms from the grid): refine the most
    # promising few
    pool.refine(sorted(set(new), key=lambda s_: pool.cands[s_].rmse_holdout)[:pool.refine_top])
    return pool.best()


#: rounds of :func:`finalize` after which it stops unsettled (a guard: every round that does not
#: settle adds laws to the refitted set, whose errors never change, so the rounds end by themselves)
MAX_ROUNDS = 25


def finalize(pool: _Pool, local_search: bool = True):
    """Full held-out refits of the screened Pareto front and of every law within reach of the
    best; the selection rule on those; the selected law's simplifications checked too, until the
    selection stands: a fixed point, where the selected law's simplifications are all refitted and
    the rule selects it again.  It cannot cycle: a law's held-out error, once computed, does not
    change (:meth:`_Pool.consider`), the rule is a function of the refitted set, and a round that
    does not settle has added to that set.  Returns the selected signature; ``pool.rounds``: the
    rounds it took, ``pool.settled``: whether it reached the fixed point within :data:`MAX_ROUNDS`."""
    pool.screen()
    pool.rounds, pool.settled = 0, False
    nsel = None
    for rnd in range(MAX_ROUNDS):
        pool.rounds = rnd + 1
        reach = _reachable(pool)
        n_new = len(reach - pool.full)
        pool.refit_holdout(reach, f"selection round {rnd + 1}: laws on or near the front refitted on held-out folds")
        sel = pool.select()
        pool.say(f"selection round {rnd + 1}: {n_new} laws on or near the front refitted on held-out folds, "
                 f"selected complexity {pool.cands[sel].complexity}")
        if not local_search:
            pool.settled = True
            return sel
        simple = _simplifications(pool, sel, f"selection round {rnd + 1}: simplifications of the selected law fitted")
        n_new = len(simple - pool.full)
        pool.say(f"selection round {rnd + 1}: {len(simple)} simplifications of the selected law fitted")
        pool.refit_holdout(simple, f"selection round {rnd + 1}: simplifications refitted on held-out folds")
        nsel = pool.select()
        pool.say(f"selection round {rnd + 1}: {n_new} simplifications refitted on held-out folds, "
                 + ("the selection stands" if nsel == sel else f"selected complexity {pool.cands[nsel].complexity}"))
        if nsel == sel:
            pool.settled = True
            return sel
    pool.say(f"selection: not settled after {MAX_ROUNDS} rounds")
    return nsel


def _reachable(pool: _Pool) -> set:
    """The screened Pareto front and the five best laws within ``max(se_rule, 1)`` standard errors
    of noise (:func:`_excess`) of the best."""
    b = pool.best()
    n_se = max(pool.se_rule, 1.0)
    near = sorted((s for s in pool.cands
                   if s == b or _excess(pool.cands[s], pool.cands[b], pool.M, pool.groups) <= n_se),
                  key=lambda s: pool.cands[s].rmse_holdout)[:5]
    return set(_front(pool.cands)) | set(near)


def _simplifications(pool: _Pool, sel, what: str = "") -> set:
    """The selected law's neighbours that add nothing (a term dropped, made symmetric or
    direction-dependent, reshaped), fitted and screened, their full held-out refits computed in
    the same map for the :meth:`_Pool.refit_holdout` that follows (``what``: progress, as in
    :meth:`_Pool.refit_holdout`)."""
    base = pool.cands[sel]
    nb = set()
    moves = _neighbours(_inherit(base.fit), pool.M, pool.addable, adds=False)
    origin = f"neighbour of {_short(base, pool.M)}"
    pool.consider_all([(parts, origin, base.threshold) for parts in moves], what=what, holdout=True)
    for parts in moves:
        # (a move's signature is in the pool after its turn or never: fits are only added, and a
        # later move of the same signature has as many terms)
        sig = _signature(parts)
        if sig in pool.fits:
            nb.add(sig)
    pool.screen()
    return nb


def _front(cands: dict) -> list:
    """Signatures on the Pareto front (complexity vs held-out error)."""
    out, best = [], math.inf
    for s in sorted(cands, key=lambda s: (cands[s].complexity, cands[s].rmse_holdout)):
        if cands[s].rmse_holdout < best * (1 - 1e-12):
            out.append(s)
            best = cands[s].rmse_holdout
    return out


def _path_structures(lib: Library, coefs, ths, offset: int = 0):
    """(threshold, structure) along a path, ``offset`` leading fixed columns skipped."""
    return [(float(t), _structure(lib, w[offset:])) for t, w in zip(ths, coefs) if np.any(w[offset:])]


def _short(c: Candidate, M) -> str:
    return "+".join(c.terms(M.frequencies))


def _excess(c: Candidate, best: Candidate, M: Moments, groups) -> float:
    """How much worse ``c`` predicts held-out data than ``best``, in standard errors of that
    difference when it is noise: for held-out predictions p_c, p_b and data y,
    ``D = |y - p_c|^2 - |y - p_b|^2 = |d|^2 - 2 d.(y - p_b)`` with ``d = p_c - p_b``, whose noise
    part has variance ``4 sum_s sigma_s^2 |d_s|^2`` (sigma_s^2: the segment's noise variance,
    :attr:`Moments.noise`).  Where no noise variance is known (one point per segment), the
    spread of the per-group differences is used instead."""
    D = float(np.sum(c.cv_sse) - np.sum(best.cv_sse))
    if D <= 0:
        return D
    if M.noise is not None and np.all(np.isfinite(M.noise)) and c.cv_pred is not None and best.cv_pred is not None:
        d = c.cv_pred - best.cv_pred               # held-out prediction difference, as basis coefficients
        d2 = np.einsum("sk,skl,sl->s", d, M.G, d)
        se = 2.0 * math.sqrt(float(np.sum(M.noise * d2)))
    else:
        p = _paired(c.cv_sse, best.cv_sse, groups, M.N)
        se = (p["delta_mse_se"] or float("nan")) * M.N
    if not (se > 0 and math.isfinite(se)):
        return math.inf
    return D / se


#: when two laws of equal complexity predict held-out data equally well (within one standard
#: error), the more conventional shape is preferred: SILO4's exponential Stribeck and decay
#: laws, then Lola's rational form, then the Gaussian
_PREFERENCE = {"stribeck_exp": 0, "stribeck_rational": 1, "stribeck_gauss": 2,
               "ripple_const": 0, "ripple_exp": 0, "ripple_rational": 1}


def _select(cands: dict, M: Moments, groups, se_rule) -> tuple:
    """The simplest candidate whose held-out error exceeds the best one's by at most ``se_rule``
    standard errors of noise (:func:`_excess`).  Among the laws of that complexity, those within
    one standard error of the best of them are ties, broken by :data:`_PREFERENCE` and then by
    held-out error."""
    best = min(cands, key=lambda s: cands[s].rmse_holdout)
    ok = [s for s in cands if s == best or _excess(cands[s], cands[best], M, groups) <= se_rule]
    k = min(cands[s].complexity for s in ok)
    same = [s for s in ok if cands[s].complexity == k]
    top = min(same, key=lambda s: cands[s].rmse_holdout)
    ties = [s for s in same if s == top or _excess(cands[s], cands[top], M, groups) <= 1.0]
    return min(ties, key=lambda s: (sum(_PREFERENCE.get(p.family, 0) for p in cands[s].parts),
                                    cands[s].rmse_holdout))


