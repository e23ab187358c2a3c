"""Detector ``lines`` (effect ``periodic``): lines of the residual spectrum that no line of the
model explains."""

from __future__ import annotations

from ..candidates import Candidate, PeriodicCandidate
from ..context import Round
from .registry import register_detector


@register_detector("lines", effect="periodic", order=10)
def line_candidates(rnd: Round, analyses: dict, *, gate: float | None = None, max_candidates: int = 6
                    ) -> list[Candidate]:
    """Lines in the pooled residual spectra (peaks at the false-alarm probability the analyses
    used; ``gate`` is not used) that no line of the model explains (within two resolution steps,
    or 0.5 %), merged across speed groups and directions (within two resolution steps), strongest
    first, at most ``max_candidates``."""
    dd = rnd.dd
    model_f = [b.frequency for b in rnd.lines()]
    peaks = []
    for sp in analyses["spectra"]["pooled"]:
        for _, p in sp.peaks.iterrows():
            peaks.append((float(p["z"]), float(p["frequency"]), float(p["resolution"]), float(p["fap"]), sp))
    peaks.sort(key=lambda x: -x[0])
    chosen: list = []
    for z, f, res, fp, sp in peaks:
        if any(abs(f - fm) <= max(2 * res, 5e-3 * fm) for fm in model_f):   # a line the model has
            continue
        hit = next((c for c in chosen if abs(c["f"] - f) <= 2 * max(res, c["res"])), None)
        if hit is not None:
            hit["seen"].append((sp, z, fp))
            continue
        chosen.append({"f": f, "res": res, "z": z, "fap": fp, "sp": sp, "seen": [(sp, z, fp)]})
        if len(chosen) >= max_candidates:
            break
    out = []
    for c in chosen:
        unit = "m" if dd.unit == "m" else "rad"
        seen = "; ".join(f"{sp.label}: {z:.1f} x noise, FAP {fp:.1e}" for sp, z, fp in c["seen"][:4])
        ev = f"residual spectrum peak at {c['f']:.6g} cycles/{unit} ({seen})"
        out.append(PeriodicCandidate(c["f"], c["res"], gear=dd.gear, evidence=ev, unit=unit,
                                     detail={"analysis": "spectrum", "spectrum": c["sp"], "frequency": c["f"]},
                                     gate_p=c["fap"]))
    return out
