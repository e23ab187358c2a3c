"""What :func:`~gearspec.diagnose.diagnose` returns: every candidate as an :class:`Effect` (its
evidence, held-out numbers and decision) and the whole run as a :class:`Diagnosis`."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ..jsonsafe import finite_or_none
from ..model import FrictionModel
from .data import DiagnoseData
from .design import FittedState

__all__ = ["Effect", "Diagnosis", "Verdict", "verdict_line"]

#: the tests that decide a candidate's fate, in the order the loop applies them
TESTS = ("held-out", "settled model", "re-entry", "backward elimination", "validation")


@dataclass
class Verdict:
    """The one decision record of a candidate, made once by the loop and shown identically on the
    console, in the report and in the JSON (:func:`verdict_line`).

    ``status``: ``accepted`` (in the final model), ``removed`` (accepted once, then taken out) or
    ``rejected`` (never accepted); ``test``: the test that decided (:data:`TESTS`); ``reason``:
    the one gate that decided, one sentence; ``z``, ``z_crit``: that test's Z and the value it
    needed; ``gain``: the relative rmse fall it measured (``min_gain``: needed); ``rmse_before``,
    ``rmse_after``: that test's rmse without and with the term (torque units); ``round``: the
    loop's round (None for the validation); ``note``: what a later check added (e.g. confirmed on
    the independent recording)."""

    status: str
    test: str
    reason: str
    z: float
    z_crit: float
    gain: float
    min_gain: float
    rmse_before: float
    rmse_after: float
    round: int | None = None
    note: str = ""

    def to_dict(self) -> dict:
        num = finite_or_none
        return {"status": self.status, "test": self.test, "reason": self.reason, "z": num(self.z),
                "z_crit": num(self.z_crit), "gain": num(self.gain), "min_gain": num(self.min_gain),
                "rmse_before": num(self.rmse_before), "rmse_after": num(self.rmse_after), "round": self.round,
                "note": self.note}


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
    verdict: Verdict | None = None   # the decision record (:func:`verdict_line` renders it)

    def to_dict(self, unit: str | None = None, torque_unit: str = "") -> dict:
        """The JSON entry (``unit``, ``torque_unit``: of the data, for the decision line as printed)."""
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
        if self.verdict is not None:
            d["verdict"] = {**self.verdict.to_dict(), "status": self.status,
                            "line": verdict_line(self, unit, torque_unit)}
        return d

    @property
    def status(self) -> str:
        """``accepted`` (in the final model), ``removed`` (accepted once, then taken out again by
        backward elimination or the validation data) or ``rejected`` (never accepted)."""
        if self.accepted:
            return "accepted"
        return "removed" if self.detail.get("removed") else "rejected"


def _fmt(x: float, spec: str) -> str:
    return "n/a" if x is None or not math.isfinite(x) else format(x, spec)


def verdict_line(e: Effect, unit: str | None = None, torque_unit: str = "") -> str:
    """One line for an effect's decision (its :class:`Verdict`): status, kind, name, label, the one
    reason, and the deciding test's Z (needed), gain and rmse before -> after.  The console, the
    report and the JSON (``verdict.line``) all show this line."""
    v = e.verdict
    mark = {"accepted": "ACCEPTED", "removed": "removed", "rejected": "rejected"}[e.status]
    f = "" if (e.frequency is None or e.kind == "periodic" or unit is None) else f" at {e.frequency:.6g} cycles/{unit}"
    lab = f" ({e.label})" if e.label else (f" (unknown order; {e.hint})" if e.hint else "")
    head = f"{mark:8s} {e.kind:11s} {e.name}{f}{lab}"
    if v is None:
        return head
    tu = f" {torque_unit}" if torque_unit else ""
    where = "on the independent recording" if v.test == "validation" else "held-out"
    nums = (f"{v.test} test: Z {_fmt(v.z, '.2f')} (needs {_fmt(v.z_crit, '.2f')}), {where} rmse "
            f"{_fmt(v.rmse_before, '.4g')} -> {_fmt(v.rmse_after, '.4g')}{tu} ({_fmt(-100 * v.gain, '+.2f')} %, "
            f"needs a fall of {_fmt(100 * v.min_gain, '.2g')} %)")
    if (v.rmse_before is not None and v.rmse_after is not None and math.isfinite(v.rmse_after)
            and v.rmse_before > 0 and v.rmse_after > DIVERGED * v.rmse_before):
        # a term that makes the held-out error many times the model's is no weak effect: its fold
        # fits ran away (a shape the training groups do not pin down); said, so the number is not
        # read as a measured size of the effect
        nums += (f"; its fold fits diverge ({v.rmse_after / v.rmse_before:.0f}x the model's held-out rmse): the "
                 f"data do not identify its shape")
    return f"{head}: {v.reason} [{nums}]" + (f"; {v.note}" if v.note else "")


#: a candidate whose held-out rmse is more than this many times the model's is said to diverge
#: (:func:`verdict_line`): an effect the loop tests is a small part of the error, so a ratio of 10
#: is no effect of the data but fold fits that ran away
DIVERGED = 10.0


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
               "effects": [e.to_dict(self.data.unit, self.data.torque_unit) for e in self.effects],
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
