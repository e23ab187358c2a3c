"""Repetition scatter of a twin: the friction levels and line amplitudes of a bench vary by a few
percent from one run (repetition) to the next, each on its own (:func:`run_scatter`).

Every linear parameter of the base law (``tau_c``, ``tau_s``, ``viscous`` of SILO4 eq. 3; the
linear parameters of any law, :func:`gearspec.terms.registry.basis`) and every line's amplitude is
multiplied in run ``r`` by its own factor ``1 + fraction * N(0, 1)``, drawn independently per run,
per parameter and per direction.  The nonlinear parameters (Stribeck velocity, decays, phases) are
the same in every run.  The law is linear in these parameters, so the friction of run ``r`` is the
nominal model's plus ``sum_j (factor_rj - 1) * part_j``, where ``part_j`` is the model with only
parameter ``j`` (:meth:`RunScatter.extra`): the nominal model is evaluated once, as without scatter.

What a fit of all runs estimates is the *run mean* (:meth:`RunScatter.run_mean`: each parameter
times the mean of its factors over the runs of its direction); the nominal model is what the runs
scatter about.  Units: torques Nm (N), speeds rad/s (m/s), ``fraction`` relative (0.03 = 3 %).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..model import DIRECTIONS, FrictionModel
from ..terms.registry import basis

__all__ = ["RunScatter", "run_scatter"]


@dataclass
class RunScatter:
    """Per-run factors of a model's scattering parameters (see the module docstring).

    ``fraction``: relative standard deviation; ``names``: one name per scattering parameter,
    ``"direction.parameter"`` or ``"direction.line label.amplitude"``; ``factors`` ``(runs, J)``;
    ``parts``: per parameter the model holding only it (the others zero); ``run_direction``
    ``(runs,)`` +1 / -1 / 0 (unknown: every run counts for both directions in :meth:`run_mean`)."""

    fraction: float
    names: list
    factors: np.ndarray
    parts: list
    run_direction: np.ndarray

    def __post_init__(self):
        self._eval = [p.evaluator() for p in self.parts]

    def extra(self, theta, v, run, **inputs) -> np.ndarray:
        """Signed friction (Nm) that run ``run`` (per sample) has beyond the nominal model at
        ``theta`` (rad), ``v`` (rad/s); ``inputs``: the model's channels (load, temperature, ...)."""
        run = np.asarray(run, dtype=int)
        out = np.zeros(np.shape(v), dtype=float)
        for j, f in enumerate(self._eval):
            g = self.factors[run, j] - 1.0
            if np.any(g):
                out = out + g * f(theta, v, **inputs)
        return out

    def run_mean(self, model: FrictionModel) -> FrictionModel:
        """``model`` with each scattering parameter times the mean of its factors over the runs of
        its direction: what a fit of all runs estimates."""
        m = model.copy()
        for j, name in enumerate(self.names):
            dname, rest = name.split(".", 1)
            d = 1 if dname == "positive" else -1
            runs = (self.run_direction == d) | (self.run_direction == 0)
            mean = float(np.mean(self.factors[runs, j])) if runs.any() else 1.0
            P = m.directions[dname]
            if rest.endswith(".amplitude"):
                k = int(rest.split("#", 1)[1].split(".", 1)[0])
                P.harmonics[k].amplitude = P.harmonics[k].amplitude * mean
            else:
                P.values[rest] = P.values[rest] * mean
        m.name = f"{model.name} (run mean)"
        return m

    def truth(self, model: FrictionModel) -> dict:
        """The record for a twin's truth JSON: ``fraction``, the ``parameters`` that scatter, the
        ``run_mean`` model (:meth:`run_mean`, the ``gearspec fit --json`` form) and the factors of
        every run (``factors``: one list per run, in the order of ``parameters``)."""
        return {"fraction": self.fraction, "parameters": list(self.names),
                "run_mean": self.run_mean(model).to_dict(), "factors": self.factors.tolist()}


def _zeroed(model: FrictionModel) -> FrictionModel:
    """A copy without terms, its base law's linear parameters 0 and no lines."""
    m = model.copy()
    m.terms, m.meta, m.notes = [], {}, []
    lin = basis(m.law).lin
    for P in m.directions.values():
        for k in lin:
            if P.values.get(k) is not None:
                P.values[k] = 0.0
        P.harmonics = []
    return m


def run_scatter(model: FrictionModel, fraction: float, n_runs: int, rng: np.random.Generator,
                run_direction=None) -> RunScatter | None:
    """Draw the per-run factors of ``model``'s base-law linear parameters and line amplitudes (each
    direction its own): ``1 + fraction * N(0, 1)`` per run and parameter.  None for ``fraction`` 0
    (no draw: a twin without scatter keeps its random stream).  ``run_direction``: +1 / -1 per run
    (for :meth:`RunScatter.run_mean`; default unknown)."""
    fraction = float(fraction)
    if not np.isfinite(fraction) or not 0.0 <= fraction < 0.5:
        raise InputError(f"scatter must be a fraction between 0 and 0.5 (e.g. 0.03 for 3 %), got {fraction}")
    if fraction == 0.0:
        return None
    lin = basis(model.law).lin
    names, parts = [], []
    for dname in DIRECTIONS:
        src = model.directions[dname]
        for k in lin:
            if src.values.get(k):
                part = _zeroed(model)
                for dd in DIRECTIONS:  # the parameter in its own direction only
                    part.directions[dd].values[k] = src.values[k] if dd == dname else 0.0
                names.append(f"{dname}.{k}")
                parts.append(part)
        for i, h in enumerate(src.harmonics):
            if h.amplitude:
                part = _zeroed(model)
                part.directions[dname].harmonics = [type(h).of(h)]
                names.append(f"{dname}.{h.label or h.frequency}#{i}.amplitude")
                parts.append(part)
    factors = 1.0 + fraction * rng.standard_normal((int(n_runs), len(names)))
    rd = np.zeros(int(n_runs), int) if run_direction is None else np.sign(np.asarray(run_direction)).astype(int)
    return RunScatter(fraction, names, factors, parts, rd)
