"""Detectors of effect ``load``: Coulomb and viscous friction growing with |load| (Lola law (8)),
and a line whose amplitude grows with load^2 (SILO4 eq. 14)."""

from __future__ import annotations

from dataclasses import replace

from ..candidates import DIRECTION_NAMES, Candidate, GridCandidate, per_direction
from ..context import Round
from .registry import register_detector


def _load_term(rnd: Round, analyses: dict, kind: str, name: str) -> list[Candidate]:
    """One candidate of the terms kind ``kind`` per direction, whenever the load varies (the
    held-out test decides) and the model has no such term yet."""
    ld = analyses.get("load")
    if ld is None or any(k.startswith(kind) for k in rnd.keys):
        return []
    st = ld[1]
    ev = "residual means against |load|: " + "; ".join(
        f"{DIRECTION_NAMES[k]}: slope {v['slope']:.3g} per Nm (p {v['p']:.2g})" for k, v in st.items() if k in (1, -1))
    return [GridCandidate("load", name, lambda _: (per_direction(rnd, kind, [], kind, "load"), []), [None],
                          evidence=ev, detail={"analysis": "load"}, gate_p=st["p"])]


@register_detector("load_coulomb", effect="load", order=50)
def load_coulomb(rnd: Round, analyses: dict, *, gate: float) -> list[Candidate]:
    """Coulomb friction growing with |load|: ``mu |load| sign(v)``."""
    return _load_term(rnd, analyses, "load_coulomb", "load-dependent Coulomb mu|load|")


@register_detector("load_viscous", effect="load", order=60)
def load_viscous(rnd: Round, analyses: dict, *, gate: float) -> list[Candidate]:
    """Viscous friction growing with |load|: ``gamma |load| v``."""
    return _load_term(rnd, analyses, "load_viscous", "load-speed coupling gamma|load||v|")


@register_detector("load_line", effect="load", order=70)
def load_line(rnd: Round, analyses: dict, *, gate: float) -> list[Candidate]:
    """A line of the model whose amplitude grows with load^2 (SILO4 eq. 14), for every line the
    load-line analysis could measure (the held-out test decides)."""
    lm = analyses.get("load_lines", {})
    out = []
    for blk in [b for b in rnd.lines() if not b.load_phase]:
        res = lm.get(blk.key)
        if res is None:
            continue
        phases = rnd.line_phases(blk)
        lab = blk.label or f"{blk.frequency:.6g}"
        out.append(GridCandidate(
            "load", f"amplitude of {lab} growing with load^2 (SILO4 eq. 14)",
            lambda _, blk=blk, phases=phases: ([replace(blk, load_phase=phases)], [blk]), [None],
            evidence=(f"the in-phase residual at {lab} grows with load^2 across segments (t {res['t']:.1f}, "
                      f"p {res['p']:.2g})"), detail={"analysis": "load_line", "key": blk.key}, gate_p=res["p"]))
    return out
