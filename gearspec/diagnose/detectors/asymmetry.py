"""Detector ``asymmetry``: a base-law parameter of a symmetric model that differs between the
directions (its column, :class:`AsymmetryBlock`, lives here with it)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...model import LAWS
from ..candidates import Candidate, GridCandidate
from ..context import Round
from ..design import LINEAR, BaseBlock, Block
from .registry import register_detector

__all__ = ["AsymmetryBlock", "asymmetry"]


@dataclass(frozen=True, eq=False)
class AsymmetryBlock(Block):
    """The difference of one base-law parameter in the negative direction from the shared value
    of a symmetric model: column ``sign(v) [v < 0] m_param(|v|)``."""

    law: str = "coulomb_viscous"
    param: str = "tau_c"
    nonlin: tuple = ()

    @property
    def names(self):
        return [f"{self.param}[neg - pos]"]

    def _raw(self, dd):
        f = dd.fit
        law = LAWS[self.law]
        speed = np.abs(f.v)
        params = {k: 0.0 for k in law.params}
        params.update({k: None for k in law.optional})
        params.update(dict(self.nonlin))
        if all(v is not None for v in dict(self.nonlin).values()):
            params.update({k: 0.0 for k in LINEAR[self.law][0]})
        params[self.param] = 1.0
        load = f.load if f.load is not None else (np.zeros(len(f)) if law.needs_load else None)
        mag = np.broadcast_to(np.asarray(law.magnitude(speed, load, *[params[k] for k in law.params]), float),
                              speed.shape)
        return np.where(f.direction < 0, np.sign(f.v) * mag, 0.0)[:, None]

    def write(self, model, coef, se):
        p = model.directions["negative"]
        if p.values.get(self.param) is not None:
            p.set(self.param, float(p.values[self.param]) + float(coef[0]), float(se[0]))
        model.notes.append(f"asymmetry: {self.param} differs in the negative direction by {coef[0]:.4g} "
                           f"(+- {se[0]:.2g})")

    def describe(self):
        return f"{self.param} different in the negative direction"


@register_detector("asymmetry", effect="asymmetry", order=100)
def asymmetry(rnd: Round, analyses: dict, *, gate: float) -> list[Candidate]:
    """For a symmetric model of data in both directions: every linear parameter of the base law
    (one candidate each) differing in the negative direction, whenever the speed analysis measured
    the mean residual's difference between directions (the held-out test decides)."""
    sp = analyses.get("speed")
    base = next((b for b in rnd.state.blocks if isinstance(b, BaseBlock)), None)
    if not rnd.state.symmetric or base is None or len(rnd.dd.directions()) != 2 or sp is None:
        return []
    asy = sp[1].get("asymmetry")
    if asy is None:
        return []
    nl = dict(base.nonlin).get(0, {})
    out = []
    for p in dict(base.lin)[0]:
        if f"asym {p}" in rnd.keys:
            continue
        out.append(GridCandidate(
            "asymmetry", f"{p} different by direction",
            lambda _, p=p: ([AsymmetryBlock(key=f"asym {p}", law=base.law, param=p, nonlin=tuple(nl.items()))], []),
            [None],
            evidence=(f"mean residual differs between directions by {asy['difference']:.3g} "
                      f"(Welch t {asy['t']:.1f}, p {asy['p']:.2g})"),
            detail={"analysis": "speed"}, gate_p=asy["p"]))
    return out
