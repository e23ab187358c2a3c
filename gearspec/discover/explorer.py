"""The explorer: library -> sparse-regression path -> candidate laws -> refinement -> held-out
selection -> inclusion probabilities -> comparison with the papers' laws.

See :func:`discover` and the package docstring for the procedure; the search pool and its moves
are in :mod:`.pool`, the result classes in :mod:`.results`, the papers' laws in :mod:`.references`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np
import pandas as pd

from ..errors import InputError
from ..fitdata import FitData
from ..model import FrictionModel
from .law import LawFit, Part, _design, _multipliers, equation, fit_law, fold_ids, to_model
from .library import Library, default_library
from .moments import Moments, moments
from .pool import _addable, _front, _group_of, _path_structures, _Pool, _signature, climb, finalize
from .references import PAPER_LAWS, _paper_law, _published, _segment_mean
from .results import Candidate, DiscoveryResult, Reference
from .screen import screen_lines
from .search import OPTIMIZERS, Scaled, bootstrap_inclusion, path
from .accept import backward, validate_law
from .blocks import SegmentDesign

__all__ = ["discover", "DiscoveryResult", "Candidate", "Reference", "spectrum_lines", "PAPER_LAWS"]


# ---------------------------------------------------------------------- frequencies
def spectrum_lines(result, *, max_fap: float = 1e-3, min_segments: int = 2, rel_tol: float = 0.01) -> list[dict]:
    """Frequencies a spectrum analysis found that the gear spec does not declare (harmonics,
    sidebands, unlabelled lines) with ``fap <= max_fap`` in at least ``min_segments`` segments
    (all segments if there are fewer): ``[{"frequency", "label"}]``, each the median of a cluster of
    peaks closer than ``rel_tol`` or than the frequency resolution of a typical segment (one cycle
    over its travel) -- two lines a segment cannot resolve are one line to a regression."""
    t = result.peaks_table()
    if t.empty:
        return []
    t = t[(~t["declared"].astype(bool)) & (t["fap"] <= max_fap)].sort_values("frequency")
    need = min(min_segments, len(result.segments))
    spans = [s.span for s in result.segments if s.span and s.span > 0]
    resolution = 1.0 / float(np.median(spans)) if spans else 0.0
    declared = [float(ln.frequency) for ln in (result.gear.declared_lines() if result.gear is not None else [])]
    out = []
    f = t["frequency"].to_numpy()
    i = 0
    while i < len(f):
        j = i + 1
        while j < len(f) and f[j] - f[j - 1] <= max(f[j - 1] * rel_tol, resolution):
            j += 1
        grp = t.iloc[i:j]
        fc = float(np.median(grp["frequency"]))
        near_declared = any(abs(fc - fd) <= max(fd * rel_tol, resolution) for fd in declared)
        if grp["segment"].nunique() >= need and not near_declared:
            lab = grp["label"].dropna()
            hint = grp["hint"].dropna() if "hint" in grp else pd.Series([], dtype=object)
            label = (lab.mode().iloc[0] if len(lab) else (hint.mode().iloc[0] if len(hint) else None))
            out.append({"frequency": fc, "source": "found",
                        "label": f"found: {label}" if label else f"found in {grp['segment'].nunique()} segments"})
        i = j
    return out


def _frequency_specs(frequencies, gear, spectrum) -> list[dict]:
    specs: list[dict] = []
    if gear is not None:
        from ..identify import harmonic_specs

        specs += [{**h, "source": "declared"} for h in harmonic_specs(None, gear)]
    if spectrum is not None:
        specs += spectrum_lines(spectrum)
    for f in frequencies or ():
        specs.append({"source": "given", **dict(f)} if isinstance(f, Mapping)
                     else {"frequency": float(f), "label": None, "source": "given"})
    out: list[dict] = []
    for s in specs:
        f = float(s["frequency"])
        if not (math.isfinite(f) and f > 0):
            raise InputError(f"ripple frequency must be a positive number (cycles per unit of theta), got {f}")
        if any(abs(f - o["frequency"]) <= 1e-6 * f for o in out):
            continue
        out.append({"frequency": f, "label": s.get("label"), "source": s.get("source", "given")})
    return out


# ---------------------------------------------------------------------- the explorer
def discover(data: FitData, *, frequencies=None, gear=None, spectrum=None, library: Library | None = None,
             library_options: Mapping | None = None, optimizer: str = "stlsq", alpha: float = 1e-4,
             thresholds: int | Sequence[float] = 24, folds: int = 5, by: str = "segment", n_models: int = 50,
             max_parts: int = 12, se_rule: float = 4.0, local_search: bool = True,
             references: Sequence[str] = PAPER_LAWS, published: Mapping[str, FrictionModel] | None = None,
             inertia: bool | str = "auto", seed: int = 0, test_alpha: float = 0.01, min_gain: float = 0.005,
             validation: FitData | None = None, progress=None) -> DiscoveryResult:
    """Search a library of friction terms for the laws the data support.

    Parameters
    ----------
    data : FitData
        Samples in constant-speed segments (``velocity="segment"``), or quasi-static points.
    frequencies : sequence of float or dict, optional
        Ripple frequencies (cycles per unit of theta; dicts with ``frequency`` and ``label``).
    gear : GearTrain, preset name or path, optional
        Its declared lines are added to the ripple frequencies.
    spectrum : SpectrumResult, optional
        Lines it found that the gear does not declare are added (:func:`spectrum_lines`).
    library : Library, optional
        Default: :func:`~gearspec.discover.library.default_library` with ``library_options``.
    optimizer : {"stlsq", "sr3"}
        pysindy optimiser of the threshold path.
    alpha : float
        Ridge weight of STLSQ relative to a standardised column's squared norm.
    thresholds : int or sequence
        Number of thresholds (log-spaced from 1 to 1e-5 of the friction RMS), or the thresholds.
    folds, by
        Held-out error: ``folds``-fold cross-validation over whole ``"segment"``s or ``"run"``s.
    n_models : int
        Bootstrap replicates (over segments or runs) for the inclusion probabilities (0: none).
    max_parts : int
        Structures with more terms are not refined (the path's densest end).
    se_rule : float
        Selection: the simplest law whose held-out error exceeds the best one's by at most
        ``se_rule`` standard errors of the noise in that difference (see ``_excess``); 0 selects
        the best held-out error.
    local_search : bool
        Search around the sparse-regression proposals: hill climbing on held-out error (a term
        added, dropped, made direction-dependent or symmetric, given another shape), then the
        selected law's simplifications.
    references : sequence of str
        Papers' laws (:func:`gearspec.identify.fit` names) refitted on the same folds for comparison.
    published : mapping of str to FrictionModel, optional
        Fixed models (e.g. published parameters) scored on the data as they are.
    inertia : bool or "auto"
        Offer a signed acceleration (residual inertia) column.
    seed : int
        Of the bootstrap.
    test_alpha, min_gain
        The acceptance rule of the closed loop (:func:`gearspec.diagnose.diagnose`'s ``alpha`` and
        ``min_gain``, same defaults): a ripple line enters the library only if its held-out Z
        reaches the critical value at ``test_alpha`` over the lines tried (:mod:`.screen`), and every
        term of the selected law must pass the held-out test against the law without it
        (:mod:`.accept`): the selection rule above proposes, this rule decides.
    validation : FitData, optional
        An independent recording (same preparation): every term of the selected law must also
        lower the error there (the closed loop's validation check), or it is simplified away.
    progress : callable, optional
        Called with one line of text as each stage ends.

    Returns
    -------
    DiscoveryResult
    """
    from ..core.reduction import one_blas_thread

    # the work is many small dense problems: BLAS threads only add overhead (and contend); the
    # controller made here is inherited by the forked workers (forked_map), which then need not make one
    with one_blas_thread():
        t_start = time.perf_counter()
        say = progress or (lambda text: None)
        run = _prepare(data, t_start, frequencies=frequencies, gear=gear, spectrum=spectrum, library=library,
                       library_options=library_options, optimizer=optimizer, alpha=alpha, thresholds=thresholds,
                       folds=folds, by=by, n_models=n_models, max_parts=max_parts, se_rule=se_rule,
                       local_search=local_search, inertia=inertia, seed=seed, test_alpha=test_alpha, say=say)
        run.min_gain = min_gain
        pool, _, sel, stages = _search(run, say)
        sel = _accept(run, pool, sel, validation, inertia, say)
        say("acceptance: every term of the selected law tested on held-out data")
        cand_list, front, selected = _finish(run, pool, sel)
        inclusion = _inclusion(run, cand_list[selected].parts, *stages, say=say)
        if run.n_models:
            say(f"inclusion probabilities: {run.n_models} bootstrap replicates")
        refs, levels = _compare(data, run, cand_list[selected], references, published, say)
        if references or published:
            say(f"{len(refs)} reference laws scored on the same folds")
        run.timings["total"] = time.perf_counter() - t_start
        run.settings["level_law"] = "+".join(p.label(run.M.frequencies) for p in run.level)
        return DiscoveryResult(cand_list, front, selected, refs, inclusion, run.lib, run.M, run.fold, run.settings,
                               run.notes, run.timings, levels, run.lines, run.verdicts)


def _search(run: "_Run", say) -> tuple:
    """The proposal: the level stage, the ripple stage, the hill climb and the selection rule.
    Returns the pool of whole laws, the level stage's pool, the proposed signature and each
    stage's (moments, library, path, design, held columns) for the bootstrap."""
    M, lib = run.M, run.lib
    lib1 = Library([t for t in lib.terms if t.fam.basis != "ripple"], lib.frequencies, lib.t_ref)
    lib2 = Library([t for t in lib.terms if t.fam.basis == "ripple"], lib.frequencies, lib.t_ref)
    M1 = (M.profile([b for b in M.basis if not b.startswith(("sin", "cos"))], min_cycles=run.min_cycles)
          if len(lib2) else M)
    pool1, path1, level, z_level = _level_stage(run, M1, lib1)
    run.level = level
    say(f"level law searched: {len(pool1.cands)} laws")
    t0 = time.perf_counter()
    pool, path2, X2, nf = _ripple_stage(run, pool1, level, z_level, lib1, lib2)
    pool.say = say
    if not pool.fits:
        raise InputError("the sparse regression selected no term at any threshold: the friction signal is "
                         "zero or the library does not fit the data")
    run.timings["ripple path"] = time.perf_counter() - t0
    say(f"ripple terms searched: {len(pool.cands)} laws")
    t0 = time.perf_counter()
    if run.local_search:
        climb(pool)
    sel = finalize(pool, run.local_search)
    run.settings["selection_rounds"], run.settings["selection_settled"] = pool.rounds, pool.settled
    run.timings["selection"] = time.perf_counter() - t0
    say(f"search: {len(pool.cands) + len(pool1.cands)} laws screened")
    run.settings["n_screened"] = len(pool.cands) + len(pool1.cands)
    return pool, pool1, sel, ((M1, lib1, path1, None, 0), (M, lib2, path2, X2, nf))


@dataclass
class _Run:
    """One exploration's data and settings, read by each of its steps."""

    M: Moments
    lib: Library
    specs: list
    fold: np.ndarray
    ths: np.ndarray
    optimizer: str
    alpha: float
    by: str
    max_parts: int
    se_rule: float
    local_search: bool
    n_models: int
    seed: int
    min_cycles: float
    settings: dict
    notes: list
    timings: dict
    test_alpha: float = 0.01
    min_gain: float = 0.005
    lines: list = field(default_factory=list)
    verdicts: list = field(default_factory=list)
    level: tuple = ()

    def pool(self, M: Moments, lib: Library) -> _Pool:
        return _Pool(M, self.fold, self.by, self.max_parts, self.se_rule, addable=_addable(lib))

    def path(self, M: Moments, lib: Library, fixed: np.ndarray | None = None) -> tuple:
        """``(threshold, structure)`` along the sparse-regression path over ``lib``'s columns on the
        pseudo rows of ``M`` with the columns ``fixed`` (S*K, nf) held in (never thresholded); and
        the design it ran on (``fixed`` first), a :class:`~.blocks.SegmentDesign`: the path runs on
        its normal equations, reduced a block of segments at a time."""
        design = SegmentDesign.of(lib, M, fixed)
        nf = design.nf
        coefs = path(Scaled(*design.reduce()), self.ths, self.optimizer, self.alpha,
                     free=_free(design.shape[1], nf), max_columns=nf + 2 * self.max_parts)
        return _path_structures(lib, coefs, self.ths, offset=nf), design


def _prepare(data, t_start, *, frequencies, gear, spectrum, library, library_options, optimizer, alpha, thresholds,
             folds, by, n_models, max_parts, se_rule, local_search, inertia, seed, test_alpha, say) -> _Run:
    """The inputs checked, the lines screened, the moments of the data, the library, the
    thresholds and the folds."""
    if optimizer not in OPTIMIZERS:
        raise InputError(f"optimizer must be one of {', '.join(OPTIMIZERS)}, got '{optimizer}'")
    if by not in ("segment", "run"):
        raise InputError(f"held-out groups must be 'segment' or 'run', got '{by}'")
    specs = _frequency_specs(frequencies, gear, spectrum)
    if specs and data.theta is None:
        raise InputError("ripple frequencies were given but the fit data has no positions (theta)")
    if not 0 < test_alpha < 1:
        raise InputError(f"test_alpha must be a probability between 0 and 1, got {test_alpha}")
    lib_opts = dict(library_options or {})
    min_cycles = lib_opts.get("min_cycles", 1.0)
    M0 = moments(data, [], inertia=inertia)          # the level bases alone: groups, folds
    ngroups = len(np.unique(M0.groups(by)))
    if ngroups < 3:
        raise InputError(f"the data has {ngroups} {by}(s): held-out errors need at least 3 (whole {by}s are held "
                         "out); record more constant-speed plateaus")
    say(f"{M0.N} samples in {M0.S} segments reduced")
    t0 = time.perf_counter()
    screen = screen_lines(data, [s["frequency"] for s in specs], fold_ids(M0, by, folds), M0.groups(by),
                          alpha=test_alpha, inertia=inertia, min_cycles=min_cycles, max_lines=max_parts,
                          progress=say) if specs else []
    notes: list = []
    lines = []
    for s, r in zip(specs, screen):
        lines.append({**s, **r})
        if not r["passed"] and r["cycles"] >= min_cycles:
            notes.append(f"ripple line {s['frequency']:.6g} cycles/{data.unit}" + (f" ({s['label']})" if s.get("label")
                         else "") + f": held-out Z {r['z']:.2f} below {r['z_crit']:.2f} (line screen, "
                         f"{'alone' if r['round'] == 0 else 'beside the stronger lines'}): left out")
    kept = [s for s, r in zip(specs, screen) if r["passed"]]
    if len(kept) > max_parts:   # a law holds at most max_parts terms: the strongest lines are searched
        # the lines that entered the screen's rounds first (each the strongest beside those before it)
        z = {id(s): (not r.get("inside", False), -r["z"]) for s, r in zip(specs, screen)}
        cut = sorted(kept, key=lambda s: z[id(s)])[max_parts:]
        notes.append(f"{len(kept)} ripple lines passed the screen; the {max_parts} that entered its rounds first "
                     f"(each the strongest beside those before it) are searched (a law holds at most {max_parts} "
                     "terms), not "
                     + ", ".join(f"{s['frequency']:.6g}" for s in cut) + f" cycles/{data.unit}")
        kept = [s for s in kept if s not in cut]
    if specs:
        say(f"{len(specs)} ripple lines screened on held-out data, {len(kept)} kept")
    t_screen = time.perf_counter() - t0
    M = moments(data, [s["frequency"] for s in kept], [s.get("label") for s in kept], inertia=inertia,
                min_cycles=min_cycles)
    if kept:
        say(f"{M.S} segments reduced with their {len(kept)} ripple lines")
    timings = {"moments": time.perf_counter() - t_start - t_screen, "line screen": t_screen}
    notes = list(M.notes) + notes
    lib = library if library is not None else default_library(M, **lib_opts)
    if len(lib) == 0:
        raise InputError("the candidate library is empty")
    used = {b for _, _, b in lib.columns} | {"1"}
    for i, f in enumerate(M.frequencies):
        if f"sin{i}" not in used:
            lab = M.labels[i]
            notes.append(f"ripple line {f:.6g} cycles/{M.unit}" + (f" ({lab})" if lab else "")
                         + " completes a cycle in too few segments to be told from the friction level: left out")
    M = M.restrict(used)
    ths = (np.geomspace(1.0, 1e-5, int(thresholds)) if np.ndim(thresholds) == 0
           else np.sort(np.asarray(thresholds, dtype=float))[::-1])
    fold = fold_ids(M, by, folds)
    settings = {"optimizer": optimizer, "alpha": alpha, "thresholds": [float(t) for t in ths], "folds": int(
        len(np.unique(fold))), "by": by, "n_models": n_models, "max_parts": max_parts, "se_rule": se_rule,
        "local_search": local_search, "library": lib.describe()}
    settings.update(test_alpha=test_alpha)
    return _Run(M, lib, specs, fold, ths, optimizer, alpha, by, max_parts, se_rule, local_search, n_models, seed,
                min_cycles, settings, notes, timings, test_alpha, lines=lines)


def _level_stage(run: _Run, M1: Moments, lib1: Library) -> tuple:
    """Stage 1: the friction level (speed, load, temperature, inertia), every segment's ripple
    profiled out by its own free sin/cos coefficients (``M1``): its path, then a hill climb from
    the best law on it.  Returns the pool, the path, and the level law's parts and nonlinear
    parameters (empty and None when the path selected nothing)."""
    t0 = time.perf_counter()
    pool1 = run.pool(M1, lib1)
    path1 = []
    if len(lib1):
        path1, _ = run.path(M1, lib1)
        pool1.consider_all([(parts, f"level path t={t:.3g}", t) for t, parts in path1])
    run.timings["level path"] = time.perf_counter() - t0
    level, z = (), None
    if pool1.fits:
        best1 = climb(pool1) if run.local_search else (pool1.screen() or pool1.best())
        level, z = pool1.cands[best1].parts, pool1.cands[best1].fit.z
    run.timings["level selection"] = time.perf_counter() - t0 - run.timings["level path"]
    return pool1, path1, level, z


def _ripple_stage(run: _Run, pool1: _Pool, level, z_level, lib1: Library, lib2: Library) -> tuple:
    """Stage 2: the ripple terms with the level law's columns held in; then the level law again
    with the ripple's columns held in (the level is then seen without the ripple that partial
    cycles leave in slow segments); alternated until the best law stops changing (two rounds at
    most).  Returns the pool of whole laws (stage 1's laws in it), and the last ripple path with
    its design and its number of held columns (for the bootstrap)."""
    M = run.M
    pool = run.pool(M, run.lib)
    pool.consider_all([(c.parts, c.origin, c.threshold) for c in pool1.cands.values()])
    path2, X2, nf = [], None, 0
    if not len(lib2):
        return pool, path2, X2, nf
    current, z_cur = tuple(level), z_level
    seen: set = set()
    for rnd in range(2):
        lvl = tuple(p for p in current if p.fam.basis != "ripple")
        if ("level", _signature(lvl)) in seen:
            break
        seen.add(("level", _signature(lvl)))
        Xf = _fixed_columns(M, lvl, current, z_cur)      # ripple path given the level law
        nf = Xf.shape[1]
        path2, X2 = run.path(M, lib2, Xf)
        pool.consider_all([(lvl + tuple(rparts), f"ripple path t={t:.3g} (round {rnd + 1})", t)
                           for t, rparts in path2])
        pool.screen()
        best = pool.cands[pool.best()]
        rip = tuple(p for p in best.parts if p.fam.basis == "ripple")
        if len(lib1) and rip and ("ripple", _signature(rip)) not in seen:    # level path given the ripple
            seen.add(("ripple", _signature(rip)))
            path1, _ = run.path(M, lib1, _fixed_columns(M, rip, best.parts, best.fit.z))
            pool.consider_all([(tuple(lparts) + rip, f"level path t={t:.3g} given the ripple (round {rnd + 1})", t)
                               for t, lparts in path1])
            pool.screen()
        nxt = pool.cands[pool.best()]
        if nxt.parts == current:
            break
        current, z_cur = nxt.parts, nxt.fit.z
    return pool, path2, X2, nf


def _accept(run: _Run, pool: _Pool, sel, validation, inertia, say=None):
    """The closed loop's acceptance rule on the law the search selected (:mod:`.accept`): backward
    elimination by the held-out test, then the independent recording's check; the signature of
    the law that stands (added to the pool with its full held-out refit when it is new)."""
    t0 = time.perf_counter()
    M = run.M
    cand = pool.cands[sel]
    fams = {t.family for t in run.lib.terms}
    splittable = sum(1 for p in cand.parts if not p.split and p.fam.basis != "acc") if len(M.directions) == 2 else 0
    n_cand = max(len(_addable(run.lib)) + splittable, 1)
    final, verdicts = backward(M, run.fold, M.groups(run.by), cand.parts, alpha=run.test_alpha,
                               min_gain=run.min_gain, n_candidates=n_cand, families=fams, progress=say,
                               holdout=pool.holdout, prefetch=pool.holdout_all)
    if validation is not None:
        Mv = _validation_moments(validation, M, inertia)
        final, more = validate_law(M, Mv, final, alpha=run.test_alpha, min_gain=run.min_gain, families=fams)
        verdicts += more
        run.settings["validation_segments"] = Mv.S
    run.verdicts = [v.to_dict() for v in verdicts]
    run.settings["acceptance_candidates"] = n_cand
    before = "+".join(p.label(M.frequencies) for p in cand.parts)
    if _signature(final) != _signature(cand.parts):
        gone = [v.reason() for v in verdicts if not v.passed]
        run.notes.append(f"the search proposed {before}; the acceptance test simplified it: " + "; ".join(gone))
        pool.consider(final, "the search's law simplified by the acceptance test", cand.threshold)
        sel = _signature(final)
        pool.screen()
        pool.refit_holdout([sel])
    run.timings["acceptance"] = time.perf_counter() - t0
    return sel


def _validation_moments(validation: FitData, M: Moments, inertia) -> Moments:
    """The independent recording reduced on the estimation moments' bases and lines."""
    Mv = moments(validation, M.frequencies, M.labels, inertia=inertia)
    missing = [b for b in M.basis if b not in Mv.basis]
    if missing:
        raise InputError(f"the validation recording lacks the channel(s) {', '.join(missing)} that the estimation "
                         "recording's law uses (acc: acceleration; load; temperature)")
    return Mv.restrict(M.basis)


def _finish(run: _Run, pool: _Pool, sel) -> tuple[list, list, int]:
    """The laws with full held-out refits ordered by complexity then held-out error, the indices
    of the Pareto front and of the selected law; the front's laws refitted with standard errors,
    AIC, BIC and their FrictionModels; every law's equation."""
    t0 = time.perf_counter()
    M = run.M
    cands = {s: pool.cands[s] for s in pool.full}
    order = sorted(cands, key=lambda s: (cands[s].complexity, cands[s].rmse_holdout))
    cand_list = [cands[s] for s in order]
    selected = order.index(sel)
    front = [order.index(s) for s in _front(cands)]
    if selected not in front:
        # the acceptance test simplified the proposal off the front: the front shown runs through the
        # selected law (laws simpler and better on held-out error hold a term that failed the test)
        sel_c = cand_list[selected]
        hidden = [i for i in front if cand_list[i].complexity <= sel_c.complexity
                  and cand_list[i].rmse_holdout <= sel_c.rmse_holdout]
        keep, best = [], math.inf
        for i in sorted((set(front) - set(hidden)) | {selected}):    # (by complexity, then held-out error)
            if i == selected or cand_list[i].rmse_holdout < best:
                keep.append(i)
                best = cand_list[i].rmse_holdout
        front = keep
        if hidden:
            run.notes.append(f"{len(hidden)} law(s) simpler than the selected one predicted the held-out data "
                             "better but hold a term that failed the acceptance test; not shown on the front")
    for i in front:
        c = cand_list[i]
        c.fit = fit_law(M, c.parts, z0=c.fit.z, se=True)
        k = c.complexity
        sse = float(np.sum(c.fit.sse))
        c.aic = M.N * math.log(max(sse, 1e-300) / M.N) + 2 * k
        c.bic = M.N * math.log(max(sse, 1e-300) / M.N) + k * math.log(M.N)
        c.model = to_model(c.fit, M.frequencies, M.labels, M.t_ref, M.unit, name=f"discovered (complexity {k})",
                           rmse=c.rmse, rmse_holdout=c.rmse_holdout)
    for c in cand_list:
        c.equation = equation(c.fit, M.frequencies, M.t_ref, M.unit)
    aic_best = min(front, key=lambda i: cand_list[i].aic)
    bic_best = min(front, key=lambda i: cand_list[i].bic)
    run.notes.append(f"on the Pareto front, AIC would choose complexity {cand_list[aic_best].complexity} and BIC "
                     f"complexity {cand_list[bic_best].complexity} (both assume independent samples, which friction "
                     f"residuals are not; the selection uses held-out error)")
    run.timings["finish"] = time.perf_counter() - t0
    return cand_list, front, selected


def _inclusion(run: _Run, final, level_path: tuple, ripple_path: tuple, say=None) -> pd.DataFrame:
    """Inclusion probabilities of the terms of the selected law ``final``: the fraction of
    bootstrap replicates over segments (or runs) in which each stage's sparse regression
    (``(moments, library, path, design or None, held columns)``), at the largest threshold of its
    path that selects as many terms as the law has in that stage, selects a column of the term's
    slot (any of its shapes, either direction variant).  Only the selected law's terms are shown:
    a term the law does not hold was rejected by the held-out rule, whatever a path picks."""
    t0 = time.perf_counter()
    inclusion = pd.DataFrame()
    if run.n_models:
        rows = []
        n_rip = sum(1 for p in final if p.fam.basis == "ripple")
        for stage, n, (Ms, lib, structs, X, nf) in (("level", len(final) - n_rip, level_path),
                                                   ("ripple", n_rip, ripple_path)):
            mine = [p for p in final if (p.fam.basis == "ripple") == (stage == "ripple")]
            if not (structs and n and mine):
                continue
            t = _threshold_for(structs, n)
            X = SegmentDesign.of(lib, Ms) if X is None else X
            slots = [_group_of(p) for p in mine]
            ct = lib.column_terms()
            cg = np.full(X.shape[1], -1)
            for j in range(len(ct)):
                tm = lib.terms[ct[j]]
                slot = _group_of(Part(tm.family, tm.freq))
                cg[nf + j] = slots.index(slot) if slot in slots else -1
            if not np.any(cg >= 0):
                continue
            prob = bootstrap_inclusion(X, Ms, t, by=run.by, n_models=run.n_models, method=run.optimizer,
                                       alpha=run.alpha, seed=run.seed, free=_free(X.shape[1], nf), column_groups=cg,
                                       progress=None if say is None else
                                       (lambda text, st=stage: say(f"inclusion probabilities of the {st} terms: "
                                                                   + text)))
            for k, p in enumerate(mine):
                rows.append({"term": p.label(run.M.frequencies), "family": p.family,
                             "variant": "direction-dependent" if p.split else "both directions",
                             "frequency": None if p.freq is None else float(run.M.frequencies[p.freq]),
                             "probability": float(prob[k]) if k < len(prob) else 0.0, "stage": stage,
                             "threshold": t})
            run.settings[f"bootstrap_threshold_{stage}"] = t
            if say is not None:
                say(f"inclusion probabilities of the {stage} terms: {run.n_models} bootstrap replicates")
        if rows:
            inclusion = pd.DataFrame(rows).sort_values("probability", ascending=False).reset_index(drop=True)
    run.timings["bootstrap"] = time.perf_counter() - t0
    return inclusion


def _compare(data: FitData, run: _Run, selected: Candidate, references, published, say=None) -> tuple[list, dict]:
    """The papers' laws refitted on the same folds and the published models scored as they are;
    the mean friction of every segment (data, the selected law, each reference) for the plots."""
    t0 = time.perf_counter()
    M = run.M
    # the laws in turn, not in forked workers: a paper law's fit reads per-segment statistics of the
    # samples cached on ``data`` (identify.stats.segment_stats), which the laws share in one process,
    # while each worker would make (rows x columns at once, 1 GB more at 10^7 rows) and throw away its
    # own; a law's held-out folds, which read those its fit on all data left, run in forked workers
    refs: list[Reference] = []
    for law in references or ():
        refs.append(_paper_law(data, M, law, run.specs, run.fold))
        if say is not None and refs[-1].model is not None:      # as each ends (a long recording: a minute each)
            say(f"reference law {refs[-1].name} fitted on the same folds")
    refs += [_published(data, M, name, model) for name, model in (published or {}).items()]
    run.timings["references"] = time.perf_counter() - t0
    levels = {"data": M.b[:, 0] / M.n, "selected": _mean_prediction(selected.fit, M)}
    for r in refs:
        if r.model is not None:
            try:
                levels[r.name] = _segment_mean(data, r.model, M)
            except InputError:
                pass
    return refs, levels


def _mean_prediction(fit: LawFit, M: Moments) -> np.ndarray:
    """Mean of a fitted law's prediction over each segment's samples (exact: the first row of
    each segment's Gram matrix holds the sums of the bases)."""
    A = _multipliers(fit.parts, fit.layout, M, fit.z)
    k = np.array([M.index(b) for _, _, b in fit.layout.cols], dtype=int)
    sums = M.G[:, 0, :][:, k]
    return np.sum(A * sums * fit.w[None, :], axis=1) / M.n


def _free(p: int, nf: int) -> np.ndarray:
    """Which of a design's ``p`` columns a path may threshold: all but the ``nf`` held-in columns
    first (all of them, to the optimisers, is the same as no mask)."""
    return np.arange(p) >= nf


def _fixed_columns(M: Moments, keep, parts, z) -> np.ndarray:
    """The design columns of the parts ``keep`` of the law ``parts`` (fitted with nonlinear
    parameters ``z``), on the pseudo rows of ``M``: terms held in while a path searches the rest."""
    if not keep:
        return np.zeros((M.S * M.K, 0))
    fit = fit_law(M, parts, z0=z, refine=False)
    X = _design(fit.parts, fit.layout, M, fit.z)
    idx = [j for j, (i, _, _) in enumerate(fit.layout.cols) if fit.parts[i] in keep]
    return X[:, idx]


def _threshold_for(path_structs, n_parts: int) -> float:
    """The largest threshold of a path whose structure has at least ``n_parts`` terms."""
    return next((t for t, parts in path_structs if len(parts) >= n_parts), path_structs[-1][0])
