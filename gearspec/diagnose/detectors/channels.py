"""Detectors of friction linear in a recorded channel: ``temperature`` (the temperature channel,
degC) and ``drift`` (the recording's clock, s)."""

from __future__ import annotations

import numpy as np

from ..candidates import Candidate, GridCandidate
from ..context import Round
from ..design import TermBlock
from .registry import register_detector


def _channel_term(rnd: Round, analyses: dict, ch: str, kind: str) -> list[Candidate]:
    """The terms kind ``kind`` (linear in the channel ``ch`` about its mean), whenever the channel
    varies (the held-out test decides) and the model has no such term yet."""
    res = analyses.get(ch)
    if res is None or kind in rnd.keys:
        return []
    st = res[1]
    ref = float(np.mean(rnd.dd.at(ch)))
    ev = (f"residual means against {'temperature' if ch == 'temperature' else 'time'}: slope "
          f"{st.get('both', {}).get('slope', float('nan')):.3g} per {'degC' if ch == 'temperature' else 's'} "
          f"(p {st['p']:.2g})")
    return [GridCandidate(kind, kind, lambda _: (
        [TermBlock(key=kind, kind=kind, fixed=(("reference", ref),), effect_kind=kind)], []), [None],
        evidence=ev, detail={"analysis": ch}, gate_p=st["p"])]


@register_detector("temperature", effect="temperature", order=80)
def temperature(rnd: Round, analyses: dict, *, gate: float) -> list[Candidate]:
    """Friction linear in temperature."""
    return _channel_term(rnd, analyses, "temperature", "temperature")


@register_detector("drift", effect="drift", order=90)
def drift(rnd: Round, analyses: dict, *, gate: float) -> list[Candidate]:
    """Friction linear in time (on the recording's clock)."""
    return _channel_term(rnd, analyses, "t", "drift")
