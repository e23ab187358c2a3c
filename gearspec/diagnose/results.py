"""What :func:`~gearspec.diagnose.diagnose` returns: every candidate as an :class:`Effect` (its
evidence, held-out numbers and decision) and the whole run as a :class:`Diagnosis`."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ..model import FrictionModel
from .data import DiagnoseData
from .design import FittedState

__all__ = ["Effect", "Diagnosis"]


@dataclass
class Effect:
    """One candidate of the loop with its evidence and held-out numbers (``CONTRACTS.md``
    section 4 ``effects`` entry, plus details)."""

    kind: str
    name: str
    accepted: bool
    evidence: str
    rmse_holdout_before: float
    rmse_holdout_after: float
    frequency: float | None = None
    label: str | None = None
    hint: str | None = None
    order: float | None = None
    z: float = float("nan")
    z_crit: float = float("nan")
    gain: float = float("nan")
    consistency: float = float("nan")
    n_params: int = 0
    round: int = 0
    decision: str = ""
    parameters: str = ""
    terms: list = field(default_factory=list)
    detail: dict = field(default_factory=dict, repr=False)
    validation: dict | None = None
    history: list = field(default_factory=list)
    value: float | None = None       # a scalar effect's estimate (lag: s)

    def to_dict(self) -> dict:
        f = lambda x: None if x is None or (isinstance(x, float) and not math.isfinite(x)) else x  # noqa: E731
        d = {"kind": self.kind, "accepted": bool(self.accepted), "frequency": f(self.frequency), "label": self.label,
             "evidence": self.evidence, "rmse_holdout_before": f(self.rmse_holdout_before),
             "rmse_holdout_after": f(self.rmse_holdout_after), "name": self.name, "hint": self.hint,
             "order": f(self.order), "z": f(self.z), "z_crit": f(self.z_crit), "gain": f(self.gain),
             "consistency": f(self.consistency), "parameters_added": self.n_params, "round": self.round,
             "decision": self.decision, "fitted": self.parameters, "terms": self.terms, "history": self.history,
             "value": f(self.value)}
        if self.validation is not None:
            d["validation"] = {k: f(v) if isinstance(v, float) else v for k, v in self.validation.items()}
        d["status"] = self.status
        return d

    @property
    def status(self) -> str:
        """``accepted`` (in the final model), ``removed`` (accepted once, then taken out again by
        backward elimination or the validation data) or ``rejected`` (never accepted)."""
        if self.accepted:
            return "accepted"
        return "removed" if self.detail.get("removed") else "rejected"


@dataclass
class Diagnosis:
    """What :func:`diagnose` finds: the baseline and final models (fitted), every candidate
    (``effects``, in the order they were last evaluated), the rounds, and per-group errors."""

    data: DiagnoseData
    baseline: FittedState
    final: FittedState
    baseline_model: FrictionModel
    final_model: FrictionModel
    effects: list
    rounds: list
    folds: np.ndarray
    baseline_holdout: dict
    final_holdout: dict
    analyses: dict = field(repr=False, default_factory=dict)     # of the baseline residual
    final_analyses: dict = field(repr=False, default_factory=dict)
    settings: dict = field(default_factory=dict)
    validation: dict | None = None
    notes: list = field(default_factory=list)
    trace: pd.DataFrame = field(repr=False, default=None)   # every evaluation of every round

    @property
    def accepted(self) -> list:
        return [e for e in self.effects if e.accepted]

    def summary_table(self) -> pd.DataFrame:
        """Before/after: rmse (in-sample) and held-out rmse, and on validation data when given."""
        rows = [{"model": "baseline", "name": self.baseline_model.name, "parameters": len(self.baseline.coef),
                 "rmse": self.baseline.rmse, "rmse_holdout": self.baseline_model.rmse_holdout},
                {"model": "final", "name": self.final_model.name, "parameters": len(self.final.coef),
                 "rmse": self.final.rmse, "rmse_holdout": self.final_model.rmse_holdout}]
        if self.validation:
            rows[0]["rmse_validation"] = self.validation["baseline_rmse"]
            rows[1]["rmse_validation"] = self.validation["final_rmse"]
        return pd.DataFrame(rows)

    def segment_table(self) -> pd.DataFrame:
        """Per held-out group: in-sample and held-out rmse of the baseline and the final model."""
        dd = self.data
        gt = dd.group_table()
        n = gt["n"].to_numpy()
        rb, rf = self.baseline.residual, self.final.residual
        gt["rmse_before"] = [float(np.sqrt(np.mean(rb[a:z] ** 2))) for a, z in zip(dd.starts, dd.stops)]
        gt["rmse_after"] = [float(np.sqrt(np.mean(rf[a:z] ** 2))) for a, z in zip(dd.starts, dd.stops)]
        gt["rmse_holdout_before"] = np.sqrt(self.baseline_holdout["sse"] / n)
        gt["rmse_holdout_after"] = np.sqrt(self.final_holdout["sse"] / n)
        gt["fold"] = self.folds
        return gt

    def to_dict(self) -> dict:
        """The ``gearspec diagnose --json`` form (CONTRACTS.md section 4) plus details."""
        f = lambda x: None if x is None or (isinstance(x, float) and not math.isfinite(x)) else float(x)  # noqa: E731
        out = {"baseline": {"model": self.baseline_model.name, "rmse": f(self.baseline.rmse),
                            "rmse_holdout": f(self.baseline_model.rmse_holdout),
                            "parameters": len(self.baseline.coef), "friction_model": self.baseline_model.to_dict()},
               "effects": [e.to_dict() for e in self.effects],
               "final": {"model": self.final_model.name, "rmse": f(self.final.rmse),
                         "rmse_holdout": f(self.final_model.rmse_holdout), "parameters": len(self.final.coef),
                         "friction_model": self.final_model.to_dict()},
               "settings": self.settings, "rounds": self.rounds, "notes": self.notes,
               "held_out": f"whole {'moves' if self.data.kind == 'trajectory' else self.data.by + 's'}, "
                           f"{int(self.folds.max()) + 1} folds",
               "unit": self.data.unit}
        if self.validation:
            out["validation"] = {k: (f(v) if isinstance(v, (float, np.floating)) else v)
                                 for k, v in self.validation.items() if k != "data"}
        return out
