"""Detector ``lag`` (effect ``lag``): the torque channel logged behind position, seen as phases of
the model's lines that drift with speed across plateaus (:mod:`gearspec.lag`)."""

from __future__ import annotations

import numpy as np

from ...lag import lag_from_phases
from ...spectrum.harmonic import harmonic_fit
from ..candidates import Candidate, LagCandidate, LaggedHarmonicBlock
from ..context import Round
from ..coverage import resolved
from .registry import register_detector

__all__ = ["segment_phases", "lag_candidates"]


def segment_phases(dd, frequencies, *, min_snr: float = 5.0) -> dict:
    """Per held-out group (a plateau) and line of ``frequencies``: the phase of the line in the
    friction magnitude (``sin(2 pi f theta + phase)``, all lines and a straight line fitted
    jointly, :func:`gearspec.spectrum.harmonic.harmonic_fit`) with its standard error, where
    the line is resolved and stands ``min_snr`` standard errors above the noise.  Cached on the
    data.  Returns arrays ``group, frequency, velocity, phase, phase_se, series``."""
    key = ("segment_phases", tuple(np.round(frequencies, 12)), float(min_snr))
    hit = dd.cache.get(key)
    if hit is not None:
        return hit
    th = dd.at("theta")
    d = dd.at("direction")
    v = dd.at("v")
    rows = []
    for g, (a, z) in enumerate(zip(dd.starts, dd.stops)):
        x = int(d[a])
        fr = [f for f in frequencies if resolved(dd, f)[dd.index[a]] and f * np.ptp(th[a:z]) >= 1.0]
        if not fr or z - a < 4 * len(fr) + 16:
            continue
        hf = harmonic_fit(th[a:z], x * dd.y[a:z], fr, degree=1)
        for f, A, Ase, ph, phse in zip(fr, hf.amplitude, hf.amplitude_se, hf.phase, hf.phase_se):
            if Ase > 0 and A >= min_snr * Ase:
                rows.append((g, f, float(np.mean(v[a:z])), ph, phse, f"{f:.6g} ({'+' if x > 0 else '-'})"))
    cols = list(zip(*rows)) if rows else [[]] * 6
    out = {k: np.asarray(c) for k, c in zip(("group", "frequency", "velocity", "phase", "phase_se", "series"), cols)}
    dd.cache[key] = out
    return out


@register_detector("lag", effect="lag", order=140)
def lag_candidates(rnd: Round, analyses: dict | None = None, *, gate: float = 0.01) -> list[Candidate]:
    """The lag candidate, when the data can show a lag: plateau data (not reduced), no lag in the
    model yet, a line of the model seen strongly at :data:`gearspec.lag.MIN_SPEEDS` speeds or more
    of one direction, and a lag estimated on all data nonzero at p < ``gate`` (``analyses``: unused)."""
    dd = rnd.dd
    if "lag" in rnd.keys:
        return []
    if dd.kind != "plateaus" or dd.reduce is not None or dd.at("theta") is None or dd.at("t") is None:
        return []
    blocks = rnd.lines()
    if not blocks or any(isinstance(b, LaggedHarmonicBlock) for b in blocks):
        return []
    table = segment_phases(dd, sorted({b.frequency for b in blocks}))
    if not len(table["group"]):
        return []
    dt = np.diff(dd.at("t"))
    dt = dt[dt > 0]
    max_lag = max(20 * float(np.median(dt)), 0.05) if len(dt) else 0.05
    est = lag_from_phases(table["frequency"], table["velocity"], table["phase"], table["phase_se"], table["series"],
                          max_lag=max_lag)
    if est is None or not est.p < gate:   # phases consistent with no lag: nothing to test
        return []
    ev = (f"the phases of the model's lines drift with speed across plateaus: {est.describe()}, z {est.z:.1f} "
          f"(p {est.p:.2g})")
    return [LagCandidate(table, est, max_lag, evidence=ev)]
