"""What :func:`~.explorer.discover` hands back: the candidate laws (:class:`Candidate`), the papers'
laws and published models beside them (:class:`Reference`), and the whole result
(:class:`DiscoveryResult`: Pareto front, selection, comparison table, JSON, summary)."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..jsonsafe import plain
from ..model import FrictionModel
from .law import LawFit
from .library import Library
from .moments import Moments

__all__ = ["Candidate", "Reference", "DiscoveryResult"]


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
    #: every ripple line offered (declared, found, given) with its line-screen Z (:mod:`.screen`)
    lines: list = field(default_factory=list)
    #: the acceptance rule's verdicts on the selected law's terms (:mod:`.accept`)
    acceptance: list = field(default_factory=list)

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
                       "notes": self.notes, "timings": self.timings, "line_screen": self.lines,
                       "acceptance": self.acceptance})

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

