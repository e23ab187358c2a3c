"""Detector ``inertia``: a missing inertia, torque ``J thetadd``."""

from __future__ import annotations

from ..candidates import Candidate, GridCandidate
from ..context import Round
from ..design import TermBlock
from .registry import register_detector


@register_detector("inertia", effect="inertia", order=110)
def inertia(rnd: Round, analyses: dict, *, gate: float) -> list[Candidate]:
    """An inertia term whenever the data have accelerations (the held-out test decides) and the
    model has none."""
    ac = analyses.get("acc")
    if ac is None or ac[1].get("roundoff") or "inertia" in rnd.keys:   # round-off accelerations: nothing to fit
        return []
    st = ac[1]
    return [GridCandidate("inertia", "inertia J thetadd",
                          lambda _: ([TermBlock(key="inertia", kind="inertia", effect_kind="inertia")], []), [None],
                          evidence=(f"residual against acceleration: slope {st['slope']:.3g} "
                                    f"(t {st['t']:.1f}, p {st['p']:.2g}): an inertia the model misses"),
                          detail={"analysis": "acc"}, gate_p=st["p"])]
