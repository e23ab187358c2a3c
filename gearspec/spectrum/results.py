"""What the spectral analysis returns: the peaks of a segment (:class:`Peak`), the analysis of one
segment (:class:`SegmentSpectrum`) and of a recording (:class:`SpectrumResult`, with its JSON form,
``CONTRACTS.md`` section 4, and its tables)."""

from __future__ import annotations

import json
from collections import Counter
import copy
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np
import pandas as pd

from ..gears import GearTrain
from ..jsonsafe import plain
from ..segment import Segment
from .harmonic import HarmonicFit

__all__ = ["Peak", "SegmentSpectrum", "SpectrumResult", "speed_groups", "SPEED_GROUP_TOL", "REPRESENTATIVES"]

#: relative speed difference within which segments of one direction are repetitions of one speed
SPEED_GROUP_TOL = 0.05
#: segments :meth:`SpectrumResult.representatives` picks by default (the report's ``--pages auto``)
REPRESENTATIVES = 12


@dataclass(frozen=True)
class Peak:
    """A sinusoidal component of one segment (``CONTRACTS.md`` section 4, ``peaks``)."""

    frequency: float
    amplitude: float
    amplitude_se: float
    phase: float
    phase_se: float
    fap: float
    order: float | None
    label: str | None
    declared: bool
    snr: float  # power over local noise power at the frequency
    hint: str | None = None  # for an unlabelled peak: an integer multiple of a shaft it sits on
    frequency_se: float = 0.0  # standard error of a found peak's frequency (0: declared, fixed)
    frequency_exact: float | None = None  # with a hint: the exact frequency of that multiple
    order_exact: float | None = None      # ... and its exact order
    aliased_from: dict | None = None  # a peak labelled 'alias of X': X's label, frequency and order
    #: a peak where the encoder's staircase has a line of its own (spectrum.quantisation_lines): the
    #: harmonic m of the count rate; not a position-locked line (it moves with the speed)
    quantisation_harmonic: int | None = None

    def to_dict(self) -> dict:
        """:func:`dataclasses.asdict` of the peak, the same dict (``aliased_from`` a copy), without a
        deep copy of every number: a report builds the table of thousands of peaks more than once."""
        d = {name: getattr(self, name) for name in _PEAK_FIELDS}
        for k, v in d.items():
            if not isinstance(v, _ATOMS):
                d[k] = copy.deepcopy(v)
        return d


_PEAK_FIELDS = tuple(f.name for f in fields(Peak))
#: values :func:`copy.deepcopy` returns unchanged (or as an equal scalar): no copy needed
_ATOMS = (int, float, str, bool, type(None), np.generic)


@dataclass
class SegmentSpectrum:
    """Spectral analysis of one segment."""

    segment: Segment
    peaks: list[Peak]
    level: float            # mean friction magnitude over the segment (Nm or N)
    sigma: float            # residual standard deviation after the fit
    span: float             # travel, rad or m
    nyquist: float          # highest frequency the sampling resolves, cycles per unit
    degree: int             # nuisance polynomial degree
    skipped: list[dict]     # declared lines not fitted, with the reason
    fit: HarmonicFit | None
    fft_frequency: np.ndarray | None = None
    fft_amplitude: np.ndarray | None = None
    ls_frequency: np.ndarray | None = None
    ls_amplitude: np.ndarray | None = None
    ls_residual_amplitude: np.ndarray | None = None
    noise_amplitude: np.ndarray | None = None
    note: str = ""
    #: encoder step of the positions (unit of theta; 0: not quantised) and the highest frequency it
    #: lets the analysis measure (cycles per unit; inf: no limit), see spectrum.quantisation_limit
    quantisation_step: float = 0.0
    quantisation_limit: float = float("inf")

    @property
    def direction(self) -> int:
        return self.segment.direction

    @property
    def speed(self) -> float:
        return self.segment.speed

    def peak(self, label: str) -> Peak | None:
        """The peak labelled ``label`` (or with ``label`` among its ' = '-joined names), or None."""
        return next((p for p in self.peaks
                     if p.label is not None and (p.label == label or label in p.label.split(" = "))), None)

    def to_dict(self) -> dict:
        s = self.segment
        return {"direction": s.direction, "speed": s.speed, "n": s.n, "run": s.run, "kind": s.kind,
                "start": s.start, "stop": s.stop, "level": self.level, "sigma": self.sigma,
                "span": self.span, "nyquist": self.nyquist, "nuisance_degree": self.degree,
                "peaks": [p.to_dict() for p in self.peaks], "skipped_lines": self.skipped,
                "above_nyquist": [d["label"] for d in self.skipped if d.get("kind") == "above_nyquist"],
                "quantisation_step": self.quantisation_step,
                "quantisation_limit": self.quantisation_limit if np.isfinite(self.quantisation_limit) else None,
                "above_quantisation_limit": [d["label"] for d in self.skipped
                                             if d.get("kind") == "above_quantisation_limit"],
                **({"note": self.note} if self.note else {})}


@dataclass
class SpectrumResult:
    """All segments of a recording with their spectra, and the ledger of excluded rows."""

    segments: list[SegmentSpectrum]
    excluded: Counter
    n_rows: int
    unit: str
    gear: GearTrain | None
    notes: list[str] = field(default_factory=list)
    settings: dict = field(default_factory=dict)
    #: the options the segments were analysed with (to compute spectra again: ``attach_spectra``)
    options: dict = field(default_factory=dict, repr=False)

    def to_dict(self) -> dict:
        return {"unit": self.unit, "torque_unit": "Nm" if self.unit == "rad" else "N",
                "frequency_unit": f"cycles/{self.unit}", "n_rows": self.n_rows,
                "gear": None if self.gear is None else self.gear.to_dict(),
                "segments": [s.to_dict() for s in self.segments],
                "excluded": dict(sorted(self.excluded.items())), "notes": self.notes,
                "settings": {k: v for k, v in self.settings.items() if _jsonable(v)}}

    def to_json(self, path: str | Path) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(plain(self.to_dict()), indent=1))
        return path

    def peaks_table(self) -> pd.DataFrame:
        """One row per (segment, peak)."""
        return pd.DataFrame([{"segment": i, "run": s.segment.run, "direction": s.direction, "speed": s.speed,
                              "level": s.level, **p.to_dict()} for i, s in enumerate(self.segments) for p in s.peaks])

    def amplitude_vs_speed(self, label: str) -> pd.DataFrame:
        """Amplitude of the peak labelled ``label`` in every segment where it was fitted."""
        return pd.DataFrame([{"segment": i, "direction": s.direction, "speed": s.speed, "level": s.level,
                              "amplitude": p.amplitude, "amplitude_se": p.amplitude_se, "phase": p.phase,
                              "frequency": p.frequency}
                             for i, s in enumerate(self.segments) if (p := s.peak(label)) is not None])

    def unexplained(self, max_fap: float = 0.01) -> pd.DataFrame:
        """Peaks found that no declared line, harmonic or sideband explains."""
        t = self.peaks_table()
        if t.empty:
            return t
        return t[(~t["declared"]) & t["label"].isna() & (t["fap"] <= max_fap)].reset_index(drop=True)

    def chance_peaks(self, max_fap: float = 0.01) -> float:
        """How many peaks no declared line explains noise alone would give at a false-alarm
        probability of at most ``max_fap`` each: ``max_fap`` per segment searched.  A peak's
        false-alarm probability counts every frequency searched in its own segment, not the other
        segments, so a recording of many segments shows up to about this many by chance (the
        false-alarm probabilities are conservative: on 10 twins of 120 segments of white noise
        around the declared lines, 0.4 on average for 1.2; on the 400-segment 10^7-row benchmark
        recording 4 for 4)."""
        return max_fap * len(self.segments)

    def unexplained_sentence(self, max_fap: float = 0.01) -> str:
        """One sentence on :meth:`unexplained`: how many, at what false-alarm probability, and how
        many of them chance alone would give (:meth:`chance_peaks`): what the console and the
        report say."""
        n, S = len(self.unexplained(max_fap)), len(self.segments)
        return (f"{n} peak(s) no declared line explains (false-alarm probability <= {max_fap:g} each, "
                f"{S} segment(s) searched: up to about {self.chance_peaks(max_fap):.2g} expected from noise alone)")


    def speed_groups(self, rel_tol: float = SPEED_GROUP_TOL) -> list[tuple[int, float, list[int]]]:
        """Segments of one direction at the same nominal speed (:func:`speed_groups`): ``(direction,
        median speed, segment indices)``, positive direction first, then by speed."""
        gid = speed_groups([s.speed for s in self.segments], [s.direction for s in self.segments], rel_tol)
        groups = [list(np.flatnonzero(gid == k)) for k in range(int(gid.max()) + 1)] if len(gid) else []
        return [(self.segments[g[0]].direction, float(np.median([self.segments[i].speed for i in g])),
                 [int(i) for i in g]) for g in groups]

    def information(self, i: int, max_fap: float = 0.01) -> tuple[int, float, int]:
        """How much segment ``i``'s spectrum shows, to rank segments for figures: (significant
        peaks no declared line fits, highest signal-to-noise ratio of a significant peak, samples)."""
        s = self.segments[i]
        sig = [p for p in s.peaks if p.fap <= max_fap]
        return (sum(not p.declared for p in sig), max((p.snr for p in sig), default=0.0), s.segment.n)

    def representatives(self, limit: int = REPRESENTATIVES) -> list[int]:
        """At most ``limit`` segments whose spectra stand for the rest: in each group of
        :meth:`speed_groups` the one of most :meth:`information`; when there are more groups than
        ``limit``, the groups whose representative shows the most.  Sorted by segment index."""
        reps = [max(g, key=self.information) for _, _, g in self.speed_groups()]
        if len(reps) > limit:
            reps = sorted(reps, key=self.information, reverse=True)[:limit]
        return sorted(reps)


def speed_groups(speed, direction, rel_tol: float = SPEED_GROUP_TOL) -> np.ndarray:
    """Group ids of segments (or any rows) of one direction at one nominal speed: numbered from 0,
    positive direction first, then by |speed|; sorted by |speed|, a row more than ``rel_tol``
    (relative) faster than the previous one of its direction starts a new group.  -1 for a row
    without a finite speed or a direction of 0."""
    speed = np.abs(np.asarray(speed, dtype=float))
    direction = np.asarray(direction)
    gid = np.full(len(speed), -1, dtype=int)
    k = -1
    for d in (1, -1):
        idx = np.flatnonzero((direction == d) & np.isfinite(speed))
        idx = idx[np.argsort(speed[idx], kind="stable")]
        prev = None
        for i in idx:
            if prev is None or speed[i] > (1 + rel_tol) * prev:
                k += 1
            gid[i] = k
            prev = speed[i]
    return gid


def _jsonable(v) -> bool:
    try:
        json.dumps(plain(v))
        return True
    except TypeError:
        return False
