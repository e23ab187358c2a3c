"""Detector ``sidebands`` (effect ``periodic``): declared sidebands of a line of the model,
amplitude-modulated by a slower shaft (:class:`~gearspec.diagnose.candidates.SidebandCandidate`);
they compete, in the same round, with another amplitude law of the carrier."""

from __future__ import annotations

import math

import numpy as np

from ..candidates import Candidate, SidebandCandidate, travel_ok
from ..context import Round
from .registry import register_detector

__all__ = ["SIDEBAND_CYCLES", "sideband_candidates"]

#: a sideband pair f_c +- f_m is fitted only on plateaus whose travel covers this many periods
#: of the modulating line (1/f_m): shorter ones cannot tell the sidebands from the carrier
SIDEBAND_CYCLES = 2.0


def _declared_pairs(rnd: Round) -> list:
    """``[(carrier line of the model, carrier label, shaft line, [sideband lines])]``: the
    sidebands the gear declares whose carrier (the higher parent) the model has, modulated by a
    shaft (the lower parent), without those where the model has a line already (declared, or
    found in the residual: within 0.2 %)."""
    gear = rnd.dd.gear
    lines = rnd.lines()
    have = [b.frequency for b in lines]
    shafts = {ln.label: ln for ln in gear.declared_lines(1) if ln.kind == "shaft"}
    pairs: dict = {}
    for ln in gear.candidate_lines(sidebands=True):
        if ln.kind != "sideband" or len(ln.parents) != 2 or ln.parents[1] not in shafts:
            continue
        pairs.setdefault(ln.parents, []).append(ln)
    out = []
    for (hi_lab, lo_lab), sb in pairs.items():
        carrier = next((b for b in lines if b.label and (b.label == hi_lab or hi_lab in b.label.split(" = "))), None)
        if carrier is None:
            continue
        sb = [x for x in sb if not any(math.isclose(x.frequency, f, rel_tol=2e-3) for f in have)]
        if sb:
            out.append((carrier, hi_lab, shafts[lo_lab], sb))
    return out


@register_detector("sidebands", effect="periodic", order=150)
def sideband_candidates(rnd: Round, analyses: dict, *, gate: float) -> list[Candidate]:
    """Sidebands the gear declares around a line of the model (the carrier: the higher of the two
    parents) modulated by a slower shaft (the lower, a shaft line), proposed when at least three
    plateaus resolve them (travel of :data:`SIDEBAND_CYCLES` modulation periods or more) and one
    of them stands out in the pooled residual spectrum at p < ``gate``.  They compete, in the
    same round, with another amplitude law of the carrier; the held-out test prefers one."""
    dd = rnd.dd
    if dd.gear is None or dd.reduce is not None or dd.at("theta") is None:
        return []
    spectra = analyses.get("spectra", {}).get("pooled", [])
    out = []
    for carrier, hi_lab, shaft, sb in _declared_pairs(rnd):
        min_travel = SIDEBAND_CYCLES / shaft.frequency
        ok = travel_ok(dd, min_travel)[dd.index]
        n_groups = len(np.unique(dd.group[ok]))
        if n_groups < 3:
            continue
        zs = [(s.power_z(x.frequency), x) for s in spectra for x in sb
              if len(s.frequency) and s.frequency[0] <= x.frequency <= s.frequency[-1]]
        if not zs:
            continue
        zmax = max(z for z, _ in zs)
        p_line = min(1.0, len(zs) * math.exp(-zmax))
        if not p_line < gate:
            continue
        out.append(SidebandCandidate(
            carrier, sb, min_travel, unit=dd.unit, gate_p=p_line,
            evidence=(f"declared sidebands of {hi_lab} modulated by the {shaft.label} stand out in the residual "
                      f"spectrum (power {zmax:.1f} x local noise, p {p_line:.2g}); fitted on the {n_groups} plateaus "
                      f"that travel {SIDEBAND_CYCLES:g} modulation periods or more"),
            detail={"analysis": "spectrum", "frequency": sb[0].frequency, "min_travel": min_travel,
                    "groups": n_groups}))
    return out
