"""Detectors of effect ``hysteresis`` near reversals: presliding (``-s exp(-travel/L)``, terms kind
``hysteresis``) and backlash (friction missing over a gap after a reversal, ``backlash``)."""

from __future__ import annotations

import numpy as np

from ..candidates import Candidate, GridCandidate
from ..context import Round
from ..design import TermBlock
from ..nonlinear import travel_range
from .registry import register_detector


def _travel_grid(rnd: Round) -> np.ndarray:
    """Ten lengths (unit of position) from the shortest travel the data resolve to the 90th
    percentile of the travel since the last reversal (at least twice the shortest)."""
    dd = rnd.dd
    t_lo, _ = travel_range(dd)
    tr = dd.at("travel")
    fin = tr[np.isfinite(tr) & (tr > 0)]
    hi = float(np.quantile(fin, 0.9))
    return np.geomspace(t_lo, max(hi, 2 * t_lo), 10)


def _reversal_term(rnd: Round, analyses: dict, kind: str, name: str, param: str) -> list[Candidate]:
    """The terms kind ``kind`` with its length ``param`` searched on :func:`_travel_grid`, whenever
    the data have reversals (the held-out test decides) and the model has no such term yet."""
    rv = analyses.get("reversal")
    if rv is None or kind in rnd.keys:
        return []
    st = rv[1]
    ev = (f"residual against travel since the last reversal: presliding profile of length {st['length']:.3g} "
          f"(t {st['t']:.1f}, p {st['p']:.2g})")
    return [GridCandidate("hysteresis", name,
                          lambda x: ([TermBlock(key=kind, kind=kind, fixed=((param, float(x)),),
                                                effect_kind="hysteresis")], []),
                          _travel_grid(rnd), evidence=ev, detail={"analysis": "reversal"}, gate_p=st["p"],
                          describe_value=lambda x: f"{param} {x:.4g}")]


@register_detector("hysteresis", effect="hysteresis", order=120)
def hysteresis(rnd: Round, analyses: dict, *, gate: float) -> list[Candidate]:
    """Presliding after reversals, its length searched on a grid."""
    return _reversal_term(rnd, analyses, "hysteresis", "presliding hysteresis", "length")


@register_detector("backlash", effect="hysteresis", order=130)
def backlash(rnd: Round, analyses: dict, *, gate: float) -> list[Candidate]:
    """Backlash: friction missing over a gap after reversals, the gap searched on a grid."""
    return _reversal_term(rnd, analyses, "backlash", "backlash", "gap")
