"""The explorer: library -> sparse-regression path -> candidate laws -> refinement -> held-out
selection -> inclusion probabilities -> comparison with the papers' laws.

See :func:`discover` and the package docstring for the procedure.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
import pandas as pd

from ..core.crossval import n_params as _n_params
from ..errors import InputError
from ..jsonsafe import plain
from ..fitdata import FitData
from ..model import FrictionModel
from .law import (LawFit, Part, canonical, cross_validate, cross_validate_linear, equation, fit_law, fold_ids,
                  to_model)
from .library import FAMILIES, GROUPS, Library, default_library
from .moments import Moments, moments
from .search import OPTIMIZERS, Scaled, bootstrap_inclusion, path

__all__ = ["discover", "DiscoveryResult", "Candidate", "Reference", "spectrum_lines", "PAPER_LAWS"]

#: the papers' laws the explorer compares with (names of :func:`gearspec.identify.fit`)
PAPER_LAWS = ("coulomb_viscous", "stribeck", "silo4", "lola8", "lola11")


# ---------------------------------------------------------------------- results
@dataclass
class Candidate:
    """A candidate law: structure, fit on all data, held-out error."""

    fit: LawFit
    cv_sse: np.ndarray             # held-out residual sum of squares per segment
    rmse_holdout: float
    origin: str
    threshold: float | None
    cv_pred: np.ndarray | None = None   # held-out predictions as coefficients of the sample bases (S, K)
    equation: str = ""
    model: FrictionModel | None = None
    aic: float = float("nan")
    bic: float = float("nan")

    @property
    def parts(self) -> tuple:
        return self.fit.parts

    @property
    def complexity(self) -> int:
        return self.fit.complexity

    @property
    def rmse(self) -> float:
        return self.fit.rmse

    def terms(self, frequencies=None) -> list[str]:
        return [p.label(frequencies) for p in self.parts]

    @property
    def direction_dependent(self) -> list[str]:
        return [p.family for p in self.parts if p.split]


@dataclass
class Reference:
    """A law of the papers (fitted on the same folds) or a published model (not fitted here)."""

    name: str
    kind: str                      # "paper law" | "published"
    rmse: float | None
    rmse_holdout: float | None
    complexity: int | None
    cv_sse: np.ndarray | None
    model: FrictionModel | None = None
    note: str = ""


@dataclass
class DiscoveryResult:
    """What :func:`discover` found.  ``candidates``: every law evaluated, sorted by complexity
    then held-out error; ``front``: indices of the Pareto front (complexity vs held-out error);
    ``selected``: index (into ``candidates``) of the chosen law."""

    candidates: list[Candidate]
    front: list[int]
    selected: int
    references: list[Reference]
    inclusion: pd.DataFrame
    library: Library
    moments: Moments
    fold: np.ndarray
    settings: dict
    notes: list = field(default_factory=list)
    timings: dict = field(default_factory=dict)
    #: mean friction of every segment (data, the selected law and each reference), for plots
    levels: dict = field(default_factory=dict)

    @property
    def best(self) -> Candidate:
        return self.candidates[self.selected]

    @property
    def unit(self) -> str:
        return self.moments.unit

    @property
    def torque_unit(self) -> str:
        return "Nm" if self.unit == "rad" else "N"

    @property
    def frequencies(self) -> np.ndarray:
        return self.moments.frequencies

    def front_candidates(self) -> list[Candidate]:
        return [self.candidates[i] for i in self.front]

    def comparison(self) -> pd.DataFrame:
        """Selected law, the rest of the Pareto front, the papers' laws and published models on the
        same held-out folds; ``vs_selected`` is the held-out MSE difference to the selected law
        with its standard error (paired over held-out groups)."""
        sel = self.best
        g = self.moments.groups(self.settings["by"])
        rows = []
        for i in self.front:
            c = self.candidates[i]
            rows.append({"law": ("selected: " if i == self.selected else "") + c.equation, "kind": "discovered",
                         "complexity": c.complexity, "rmse": c.rmse, "rmse_holdout": c.rmse_holdout,
                         **_paired(c.cv_sse, sel.cv_sse, g, self.moments.N)})
        for r in self.references:
            rows.append({"law": r.name, "kind": r.kind, "complexity": r.complexity, "rmse": r.rmse,
                         "rmse_holdout": r.rmse_holdout,
                         **(_paired(r.cv_sse, sel.cv_sse, g, self.moments.N) if r.cv_sse is not None
                            else {"delta_mse": None, "delta_mse_se": None})})
        return pd.DataFrame(rows)

    def to_dict(self) -> dict:
        """The ``gearspec discover --json`` form (CONTRACTS.md section 4) plus details:
        ``candidates`` is the Pareto front (by complexity), ``selected`` an index into it."""
        freqs = self.frequencies
        cands = []
        for i in self.front:
            c = self.candidates[i]
            coefs = []
            for v in c.fit.values():
                p = c.parts[v["part"]]
                coefs.append({"term": p.label(freqs), "direction": {0: "both", 1: "positive", -1: "negative"}[v["slot"]],
                              "name": v["name"], "value": v["value"], "se": v["se"], "at_bound": v["at_bound"]})
            cands.append({"equation": c.equation, "terms": c.terms(freqs), "complexity": c.complexity,
                          "rmse_holdout": c.rmse_holdout, "rmse": c.rmse, "aic": c.aic, "bic": c.bic,
                          "direction_dependent": c.direction_dependent, "origin": c.origin,
                          "threshold": c.threshold, "coefficients": coefs, "se_method": c.fit.se_method,
                          "model": c.model.to_dict() if c.model is not None else None})
        refs = [{"name": r.name, "kind": r.kind, "complexity": r.complexity, "rmse": r.rmse,
                 "rmse_holdout": r.rmse_holdout, "note": r.note,
                 "model": r.model.to_dict() if r.model is not None else None} for r in self.references]
        inc = self.inclusion.to_dict(orient="records") if len(self.inclusion) else []
        return plain({"candidates": cands, "selected": self.front.index(self.selected),
                       "unit": self.unit, "torque_unit": self.torque_unit,
                       "n_samples": self.moments.N, "n_segments": self.moments.S,
                       "frequencies": [{"frequency": float(f), "label": lab}
                                       for f, lab in zip(freqs, self.moments.labels)],
                       "library": {"columns": self.library.names, "size": len(self.library)},
                       "n_candidates_evaluated": len(self.candidates),
                       "references": refs, "inclusion_probabilities": inc, "settings": self.settings,
                       "notes": self.notes, "timings": self.timings})

    def to_json(self, path) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(self.to_dict(), indent=1))
        return path

    def summary(self) -> str:
        tu = self.torque_unit
        lines = [f"{len(self.library)} library columns, {len(self.candidates)} candidate laws evaluated on "
                 f"{self.moments.N} samples in {self.moments.S} segments; held-out: {self.settings['folds']}-fold "
                 f"by {self.settings['by']}"]
        lines.append(f"{'':2}{'cplx':>4} {'held-out rmse':>14} {'rmse':>11}  law")
        for i in self.front:
            c = self.candidates[i]
            lines.append(f"{'->' if i == self.selected else '':2}{c.complexity:>4} {c.rmse_holdout:>14.5g} "
                         f"{c.rmse:>11.5g}  {c.equation}")
        for r in self.references:
            ho = "n/a" if r.rmse_holdout is None else f"{r.rmse_holdout:.5g}"
            rm = "n/a" if r.rmse is None else f"{r.rmse:.5g}"
            lines.append(f"{'':2}{'' if r.complexity is None else r.complexity:>4} {ho:>14} {rm:>11}  [{r.kind}] {r.name}"
                         + (f" ({r.note})" if r.note else ""))
        lines.append(f"({tu}; '(a | b)': positive | negative direction)")
        return "\n".join(lines)


def _paired(a, b, groups, N):
    """Held-out MSE difference a - b and its standard error, paired over groups."""
    if a is None or b is None:
        return {"delta_mse": None, "delta_mse_se": None}
    ug = np.unique(groups)
    d = np.array([np.sum(a[groups == u]) - np.sum(b[groups == u]) for u in ug])
    se = math.sqrt(len(d)) * float(np.std(d, ddof=1)) / N if len(d) > 1 else float("nan")
    return {"delta_mse": float(np.sum(d)) / N, "delta_mse_se": se}


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
    fam = p.family
    for g, members in GROUPS.items():
        if fam in members:
            return (g, p.freq)
    return (fam, p.freq)


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


def _compound(parts, M: Moments, addable) -> list[tuple]:
    """Two moves at once: a term dropped and another made direction-dependent -- to leave a local
    optimum where one term stands in for the direction dependence of another."""
    out = []
    both = len(M.directions) == 2
    for i in range(len(parts)):
        rest = list(parts[:i]) + list(parts[i + 1:])
        if not rest:
            continue
        for j, p in enumerate(rest):
            if both and not p.split and p.fam.basis != "acc":
                out.append(canonical(rest[:j] + rest[j + 1:] + [Part(p.family, p.freq, True, p.param0)]))
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


def discover(data: FitData, *, frequencies=None, gear=None, spectrum=None, library: Library | None = None,
             library_options: Mapping | None = None, optimizer: str = "stlsq", alpha: float = 1e-4,
             thresholds: int | Sequence[float] = 24, folds: int = 5, by: str = "segment", n_models: int = 50,
             max_parts: int = 12, se_rule: float = 4.0, local_search: bool = True,
             references: Sequence[str] = PAPER_LAWS, published: Mapping[str, FrictionModel] | None = None,
             inertia: bool | str = "auto", seed: int = 0) -> DiscoveryResult:
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

    Returns
    -------
    DiscoveryResult
    """
    from threadpoolctl import threadpool_limits

    # the work is many small dense problems: BLAS threads only add overhead (and contend)
    with threadpool_limits(limits=1, user_api="blas"):
        return _discover(data, frequencies=frequencies, gear=gear, spectrum=spectrum, library=library,
                         library_options=library_options, optimizer=optimizer, alpha=alpha, thresholds=thresholds,
                         folds=folds, by=by, n_models=n_models, max_parts=max_parts, se_rule=se_rule,
                         local_search=local_search, references=references, published=published, inertia=inertia,
                         seed=seed)


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
        self.addable = list(addable)
        self.screen_nfev = 12          # a few refinement steps while screening; full refinement later
        self.refine_top = 4

    def consider(self, parts, origin, thr, refine: bool = True):
        parts = canonical(parts)
        if not parts or parts in self.tried or len(parts) > self.max_parts:
            return None
        self.tried.add(parts)
        fit = fit_law(self.M, parts, max_nfev=self.screen_nfev, refine=refine)
        sig = _signature(parts)
        old = self.fits.get(sig)
        if old is None or np.sum(fit.sse) < np.sum(old[0].sse) * (1 - 1e-9):
            self.fits[sig] = (fit, origin if old is None else old[1], thr if old is None else old[2])
            self.cands.pop(sig, None)
            self.full.discard(sig)
        return sig

    def screen(self):
        for sig, (fit, origin, thr) in self.fits.items():
            if sig not in self.cands:
                cv, pred = cross_validate_linear(self.M, fit, self.fold)
                self.cands[sig] = Candidate(fit, cv, math.sqrt(float(np.sum(cv)) / self.M.N), origin, thr, pred)

    def refine(self, sigs):
        """A few refinement steps for structures screened with their start values."""
        for sig in sigs:
            fit, origin, thr = self.fits[sig]
            if any(p.free for p in fit.parts):
                self.fits[sig] = (fit_law(self.M, fit.parts, z0=fit.z, max_nfev=self.screen_nfev), origin, thr)
                self.cands.pop(sig, None)
        self.screen()

    def refit_holdout(self, sigs):
        for sig in sigs:
            if sig in self.full:
                continue
            c = self.cands[sig]
            if any(p.free for p in c.parts):
                c.fit = fit_law(self.M, c.parts, z0=c.fit.z)
                c.cv_sse, c.cv_pred = cross_validate(self.M, c.parts, self.fold, z0=c.fit.z)
                c.rmse_holdout = math.sqrt(float(np.sum(c.cv_sse)) / self.M.N)
            self.full.add(sig)

    def best(self, among=None):
        keys = list(among if among is not None else self.cands)
        return min(keys, key=lambda s: self.cands[s].rmse_holdout)

    def climb(self, rounds: int = 12, moves=None):
        """Hill climbing on the screened held-out error from the best structure found: every
        neighbour (a term added, dropped, made direction-dependent or symmetric, reshaped)
        evaluated, the best taken, until nothing improves."""
        self.screen()
        cur = self.best()
        compound = False
        for _ in range(rounds):
            base = self.cands[cur]
            start = _inherit(base.fit)
            moves_ = _compound(start, self.M, self.addable) if compound else _neighbours(start, self.M, self.addable)
            new = []
            for parts in moves_:
                if moves is None or moves(parts):
                    sig = self.consider(parts, f"neighbour of {_short(base, self.M)}", base.threshold, refine=False)
                    if sig is not None:
                        new.append(sig)
            self.screen()
            # neighbours start from the parent's refined values (new terms from the grid): refine
            # the most promising few
            new = sorted(set(new), key=lambda s_: self.cands[s_].rmse_holdout)[:self.refine_top]
            self.refine(new)
            nxt = self.best()
            if nxt == cur and not compound:
                compound = True          # a local optimum of single moves: try pairs once
                continue
            compound = False
            if nxt == cur:
                break
            cur = nxt
        return cur

    def finalize(self, local_search: bool = True):
        """Full held-out refits of the screened Pareto front and of every law within reach of the
        best; the selection rule on those; the selected law's simplifications checked too."""
        self.screen()
        for _ in range(4):
            near = sorted((s for s in self.cands if self._near(s, max(self.se_rule, 1.0))),
                          key=lambda s: self.cands[s].rmse_holdout)[:10]
            todo = set(_front(self.cands)) | set(near)
            self.refit_holdout(todo)
            sel = _select({s: self.cands[s] for s in self.full}, self.M, self.groups, self.se_rule)
            if not local_search:
                return sel
            base = self.cands[sel]
            nb = set()
            for parts in _neighbours(_inherit(base.fit), self.M, self.addable, adds=False):
                self.consider(parts, f"neighbour of {_short(base, self.M)}", base.threshold)
                sig = _signature(parts)
                if sig in self.fits:
                    nb.add(sig)
            self.screen()
            self.refit_holdout(nb)
            nsel = _select({s: self.cands[s] for s in self.full}, self.M, self.groups, self.se_rule)
            if nsel == sel:
                return sel
        return nsel

    def _near(self, sig, n_se):
        b = self.best()
        if sig == b:
            return True
        return _excess(self.cands[sig], self.cands[b], self.M, self.groups) <= n_se


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
    out = []
    for t, w in zip(ths, coefs):
        w = w[offset:]
        if np.any(w):
            out.append((float(t), _structure(lib, w)))
    return out


def _discover(data, *, frequencies, gear, spectrum, library, library_options, optimizer, alpha, thresholds, folds,
              by, n_models, max_parts, se_rule, local_search, references, published, inertia, seed):
    t_start = time.perf_counter()
    timings: dict = {}
    if optimizer not in OPTIMIZERS:
        raise InputError(f"optimizer must be one of {', '.join(OPTIMIZERS)}, got '{optimizer}'")
    if by not in ("segment", "run"):
        raise InputError(f"held-out groups must be 'segment' or 'run', got '{by}'")
    specs = _frequency_specs(frequencies, gear, spectrum)
    if specs and data.theta is None:
        raise InputError("ripple frequencies were given but the fit data has no positions (theta)")
    lib_opts = dict(library_options or {})
    M = moments(data, [s["frequency"] for s in specs], [s.get("label") for s in specs], inertia=inertia,
                min_cycles=lib_opts.get("min_cycles", 1.0))
    timings["moments"] = time.perf_counter() - t_start
    notes = list(M.notes)
    ngroups = len(np.unique(M.groups(by)))
    if ngroups < 3:
        raise InputError(f"the data has {ngroups} {by}(s): held-out errors need at least 3 (whole {by}s are held "
                         "out); record more constant-speed plateaus")
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
    max_cols = 2 * max_parts

    # ---- stage 1: the friction level (speed, load, temperature, inertia), every segment's ripple
    # profiled out by its own free sin/cos coefficients
    t0 = time.perf_counter()
    lib1 = Library([t for t in lib.terms if t.fam.basis != "ripple"], lib.frequencies, lib.t_ref)
    lib2 = Library([t for t in lib.terms if t.fam.basis == "ripple"], lib.frequencies, lib.t_ref)
    M1 = (M.profile([b for b in M.basis if not b.startswith(("sin", "cos"))], min_cycles=lib_opts.get("min_cycles", 1.0))
          if len(lib2) else M)
    pool1 = _Pool(M1, fold, by, max_parts, se_rule, addable=_addable(lib1))
    path1 = []
    if len(lib1):
        X1 = lib1.design(M1)
        sc1 = Scaled(X1, M1.q.reshape(-1), M1.N, float(np.sum(M1.yy)))
        path1 = _path_structures(lib1, path(sc1, ths, optimizer, alpha, max_columns=max_cols), ths)
        for t, parts in path1:
            pool1.consider(parts, f"level path t={t:.3g}", t)
    timings["level path"] = time.perf_counter() - t0
    level = ()
    if pool1.fits:
        best1 = pool1.climb() if local_search else (pool1.screen() or pool1.best())
        level = pool1.cands[best1].parts
    timings["level selection"] = time.perf_counter() - t0 - timings["level path"]

    # ---- stage 2: ripple terms with the level law's columns always in; then the level law again
    # with the ripple's columns always in (the level is then seen without the ripple that partial
    # cycles leave in slow segments); alternated until the best law stops changing
    t0 = time.perf_counter()
    pool = _Pool(M, fold, by, max_parts, se_rule, addable=_addable(lib))
    for sig, c in pool1.cands.items():
        pool.consider(c.parts, c.origin, c.threshold)
    path2 = []
    nf = 0
    X2 = None
    if len(lib2):
        X2lib = lib2.design(M)
        X1full = lib1.design(M) if len(lib1) else None
        q = M.q.reshape(-1)
        yy = float(np.sum(M.yy))
        current = tuple(level)
        z_cur = pool1.cands[best1].fit.z if level else None
        seen_fixed: set = set()
        for rnd in range(2):
            lvl = tuple(p for p in current if p.fam.basis != "ripple")
            rip = tuple(p for p in current if p.fam.basis == "ripple")
            if ("level", _signature(lvl)) in seen_fixed:
                break
            seen_fixed.add(("level", _signature(lvl)))
            # ripple path given the level law
            Xf = _fixed_columns(M, lvl, current, z_cur)
            nf = Xf.shape[1]
            X2 = np.hstack([Xf, X2lib])
            free = np.r_[np.zeros(nf, bool), np.ones(X2lib.shape[1], bool)]
            coefs2 = path(Scaled(X2, q, M.N, yy), ths, optimizer, alpha, free=free, max_columns=nf + max_cols)
            path2 = _path_structures(lib2, coefs2, ths, offset=nf)
            for t, rparts in path2:
                pool.consider(lvl + tuple(rparts), f"ripple path t={t:.3g} (round {rnd + 1})", t)
            pool.screen()
            best = pool.cands[pool.best()]
            rip = tuple(p for p in best.parts if p.fam.basis == "ripple")
            # level path given the ripple law
            if X1full is not None and rip and ("ripple", _signature(rip)) not in seen_fixed:
                seen_fixed.add(("ripple", _signature(rip)))
                Xf = _fixed_columns(M, rip, best.parts, best.fit.z)
                nr = Xf.shape[1]
                coefs1 = path(Scaled(np.hstack([Xf, X1full]), q, M.N, yy), ths, optimizer, alpha,
                              free=np.r_[np.zeros(nr, bool), np.ones(X1full.shape[1], bool)],
                              max_columns=nr + max_cols)
                for t, lparts in _path_structures(lib1, coefs1, ths, offset=nr):
                    pool.consider(tuple(lparts) + rip, f"level path t={t:.3g} given the ripple (round {rnd + 1})", t)
                pool.screen()
            nxt = pool.cands[pool.best()]
            if nxt.parts == current:
                break
            current, z_cur = nxt.parts, nxt.fit.z
    if not pool.fits:
        raise InputError("the sparse regression selected no term at any threshold: the friction signal is zero "
                         "or the library does not fit the data")
    timings["ripple path"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    if local_search:
        pool.climb()
    sel = pool.finalize(local_search)
    timings["selection"] = time.perf_counter() - t0
    settings["n_screened"] = len(pool.cands) + len(pool1.cands)

    # ---- finish: order, front, SEs, equations, models
    t0 = time.perf_counter()
    cands = {s: pool.cands[s] for s in pool.full}
    order = sorted(cands, key=lambda s: (cands[s].complexity, cands[s].rmse_holdout))
    cand_list = [cands[s] for s in order]
    selected = order.index(sel)
    front, best = [], math.inf
    for i, c in enumerate(cand_list):
        if c.rmse_holdout < best * (1 - 1e-12):
            front.append(i)
            best = c.rmse_holdout
    if selected not in front:   # (cannot happen with the selection rule; kept for safety)
        front = sorted(set(front) | {selected})
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
    notes.append(f"on the Pareto front, AIC would choose complexity {cand_list[aic_best].complexity} and BIC "
                 f"complexity {cand_list[bic_best].complexity} (both assume independent samples, which friction "
                 f"residuals are not; the selection uses held-out error)")
    timings["finish"] = time.perf_counter() - t0

    # ---- inclusion probabilities: bootstrap over segments (or runs) of each stage's path, at the
    # largest threshold that selects as many terms as the chosen law has in that stage
    t0 = time.perf_counter()
    inclusion = pd.DataFrame()
    final = cand_list[selected].parts
    if n_models:
        tables = []
        n_level = sum(1 for p in final if p.fam.basis != "ripple")
        n_rip = len(final) - n_level
        if path1 and n_level:
            t1 = _threshold_for(path1, n_level)
            prob = bootstrap_inclusion(lib1.design(M1), M1, t1, by=by, n_models=n_models, method=optimizer,
                                       alpha=alpha, seed=seed)
            tables.append(_inclusion_table(lib1, prob, M, "level", t1))
            settings["bootstrap_threshold_level"] = t1
        if path2 and n_rip:
            t2 = _threshold_for(path2, n_rip)
            prob = bootstrap_inclusion(X2, M, t2, by=by, n_models=n_models, method=optimizer, alpha=alpha, seed=seed,
                                       free=np.r_[np.zeros(nf, bool), np.ones(X2.shape[1] - nf, bool)])
            tables.append(_inclusion_table(lib2, prob[nf:], M, "ripple", t2))
            settings["bootstrap_threshold_ripple"] = t2
        tables = [t for t in tables if len(t)]
        if tables:
            inclusion = pd.concat(tables, ignore_index=True)
    timings["bootstrap"] = time.perf_counter() - t0

    # ---- the papers' laws and published models on the same folds
    t0 = time.perf_counter()
    refs: list[Reference] = []
    for law in references or ():
        refs.append(_paper_law(data, M, law, specs, fold, by))
    for name, model in (published or {}).items():
        refs.append(_published(data, M, name, model))
    timings["references"] = time.perf_counter() - t0
    levels = {"data": M.c[:, 0] / M.n, "selected": _mean_prediction(cand_list[selected].fit, M)}
    for r in refs:
        if r.model is not None:
            try:
                levels[r.name] = _segment_mean(data, r.model, M)
            except InputError:
                pass
    timings["total"] = time.perf_counter() - t_start
    settings["level_law"] = "+".join(p.label(M.frequencies) for p in level)
    return DiscoveryResult(cand_list, front, selected, refs, inclusion, lib, M, fold, settings, notes, timings, levels)


def _mean_prediction(fit: LawFit, M: Moments) -> np.ndarray:
    """Mean of a fitted law's prediction over each segment's samples (exact: the first row of
    each segment's Gram matrix holds the sums of the bases)."""
    from .law import _multipliers

    A = _multipliers(fit.parts, fit.layout, M, fit.z)
    k = np.array([M.index(b) for _, _, b in fit.layout.cols], dtype=int)
    sums = M.B[:, 0, :][:, k]
    return np.sum(A * sums * fit.w[None, :], axis=1) / M.n


def _segment_mean(data: FitData, model: FrictionModel, M: Moments) -> np.ndarray:
    pred = model.evaluate(**data.inputs())
    pos = {int(s): i for i, s in enumerate(M.segment)}
    idx = np.array([pos[int(s)] for s in data.segment], dtype=int)
    return np.bincount(idx, weights=np.nan_to_num(pred), minlength=M.S) / M.n


def _fixed_columns(M: Moments, keep, parts, z) -> np.ndarray:
    """The design columns of the parts ``keep`` of the law ``parts`` (fitted with nonlinear
    parameters ``z``), on the pseudo rows of ``M``: terms held in while a path searches the rest."""
    from .law import _design

    if not keep:
        return np.zeros((M.S * M.K, 0))
    fit = fit_law(M, parts, z0=z, refine=False)
    X = _design(fit.parts, fit.layout, M, fit.z)
    idx = [j for j, (i, _, _) in enumerate(fit.layout.cols) if fit.parts[i] in keep]
    return X[:, idx]


def _threshold_for(path_structs, n_parts: int) -> float:
    """The largest threshold of a path whose structure has at least ``n_parts`` terms."""
    for t, parts in path_structs:
        if len(parts) >= n_parts:
            return t
    return path_structs[-1][0]


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
        d2 = np.einsum("sk,skl,sl->s", d, M.B, d)
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


def _inclusion_table(lib: Library, prob: np.ndarray, M, stage: str = "", threshold=None) -> pd.DataFrame:
    """Inclusion probability per library term (its columns merged: the larger of sin/cos)."""
    ct = lib.column_terms()
    rows = []
    for i, t in enumerate(lib.terms):
        pr = float(np.max(prob[ct == i]))
        if pr <= 0:
            continue
        name = t.names(M.frequencies, M.t_ref)[0]
        rows.append({"term": name, "family": t.family, "variant": t.variant,
                     "frequency": None if t.freq is None else float(M.frequencies[t.freq]),
                     "probability": pr, "stage": stage, "threshold": threshold})
    df = pd.DataFrame(rows)
    if len(df):
        df = df.sort_values("probability", ascending=False).reset_index(drop=True)
    return df


# ---------------------------------------------------------------------- references
def _segment_sse(data: FitData, model: FrictionModel, M: Moments, mask=None) -> np.ndarray:
    sub = data if mask is None else data.subset(mask)
    r = model.residual(sub)
    out = np.zeros(M.S)
    pos = {int(s): i for i, s in enumerate(M.segment)}
    np.add.at(out, np.array([pos[int(s)] for s in sub.segment], dtype=int), np.nan_to_num(r * r, nan=0.0))
    return out


def _paper_law(data: FitData, M: Moments, law: str, specs, fold, by) -> Reference:
    """A law of the papers, fitted by :func:`gearspec.identify.fit` (ordinary least squares,
    ``weights="uniform"``, like the candidates) on the same folds."""
    from .. import identify

    label = {"coulomb_viscous": "Coulomb + viscous (IDIM-LS structure, per direction)",
             "stribeck": "SILO4 eq. 3 (per direction)", "silo4": "SILO4 eq. 11 (per direction, declared lines)",
             "lola8": "Lola law (8)", "lola11": "Lola law (11)"}.get(law, law)
    if law in ("lola8", "lola11") and data.load is None:
        return Reference(label, "paper law", None, None, None, None, note="needs the load channel; not fitted")
    # SILO4 eq. 11 with the lines the user declared or gave (not those the spectrum found: the
    # paper's law is about the gear train's own lines)
    harmonics = ([{"frequency": s["frequency"], "label": s.get("label")} for s in specs
                  if s.get("source") != "found"] if law == "silo4" else None)
    if law == "silo4" and not harmonics:
        return Reference(label, "paper law", None, None, None, None, note="no ripple line declared; same as eq. 3")
    kw = {"harmonics": harmonics, "weights": "uniform", "holdout": None}
    try:
        model = identify.fit(data, law, **kw)
    except InputError as exc:
        return Reference(label, "paper law", None, None, None, None, note=f"not fitted: {exc}")
    except (np.linalg.LinAlgError, ValueError, FloatingPointError) as exc:   # a comparison is never worth a crash
        return Reference(label, "paper law", None, None, None, None,
                         note=f"identify.fit failed ({type(exc).__name__}: {exc})")
    seg_fold = dict(zip(M.segment.tolist(), fold.tolist()))
    sample_fold = np.array([seg_fold[int(s)] for s in data.segment])
    cv = np.zeros(M.S)
    failed = 0
    for f in np.unique(fold):
        test = sample_fold == f
        try:
            mf = identify.fit(data.subset(~test), law, **kw)
            cv += _segment_sse(data, mf, M, test)
        except (InputError, np.linalg.LinAlgError, ValueError, FloatingPointError):
            failed += 1
            cv[fold == f] = np.nan
    ok = np.isfinite(cv)
    note = ""
    if failed:
        note = f"fit failed in {failed} fold(s): held-out error over the other folds"
    n_ok = float(np.sum(M.n[ok]))
    ho = math.sqrt(float(np.sum(cv[ok])) / n_ok) if n_ok else None
    return Reference(label, "paper law", _rmse_all(data, model), ho, _n_params(model),
                     np.where(ok, cv, np.nan) if not failed else None, model, note)


def _rmse_all(data, model) -> float | None:
    try:
        r = model.residual(data)
    except InputError:
        return None
    r = r[np.isfinite(r)]
    return float(np.sqrt(np.mean(r * r))) if len(r) else None


def _published(data: FitData, M: Moments, name: str, model: FrictionModel) -> Reference:
    try:
        sse = _segment_sse(data, model, M)
    except InputError as exc:
        return Reference(name, "published", None, None, None, None, model, note=f"cannot be evaluated: {exc}")
    rm = math.sqrt(float(np.sum(sse)) / M.N)
    return Reference(name, "published", rm, rm, _n_params(model), sse, model,
                     note="parameters as published; not fitted here, so its held-out error is its error on all data")
