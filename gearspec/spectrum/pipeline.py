"""The spectral analysis of a whole recording (``gearspec spectrum``): segment it, analyse every
segment (:func:`~gearspec.spectrum.analysis.analyze_segment`, in threads when segments are long),
and label the peaks of one segment that are aliases of lines measured in another."""

from __future__ import annotations

import sys
from collections import Counter
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace

from threadpoolctl import threadpool_limits

from ..errors import InputError
from ..gears import GearTrain, alias_of, load_gear
from ..recording import Recording
from ..segment import FrictionTorque, Segment, Segmentation, find_segments
from .analysis import _local, analyze_segment
from .results import SegmentSpectrum, SpectrumResult

__all__ = ["analyze", "relabel_aliases", "attach_spectra", "can_hold_spectra"]


def analyze(rec: Recording, gear=None, *, segmentation: Segmentation | None = None,
            window: float | str = "auto", rel_tol: float = 0.15, min_speed: float | None = None,
            min_duration: float | None = None, inertia: bool = True, progress: bool | None = None,
            workers: int | str = "auto", **options) -> SpectrumResult:
    """Segment a recording and analyse every segment (``gearspec spectrum``).

    ``gear``: a GearTrain, preset name or path (default the recording's own).  ``segmentation``:
    precomputed segments, else :func:`~gearspec.segment.find_segments` runs with ``window``,
    ``rel_tol``, ``min_speed`` and ``min_duration``.  ``inertia``: subtract ``J * thetadd`` when
    the gear spec gives J.  ``progress``: a progress bar (default: when stderr is a terminal and
    there are many segments).  ``workers``: segments analysed at once, in threads, with the same
    results whatever the number; ``"auto"``: two when the process may use two or more CPUs and
    there are at least two segments, else one.
    ``options`` go to :func:`analyze_segment`.
    """
    gear = load_gear(gear) if gear is not None else rec.gear
    if gear is not None and gear.unit != rec.unit:
        raise InputError(f"gear spec '{gear.name}' is for theta in {gear.unit}, the recording's theta is in {rec.unit}")
    # `is None`, not `or`: an empty Segmentation is falsy, and is refused below, never replaced
    seg = segmentation if segmentation is not None else find_segments(
        rec, window=window, rel_tol=rel_tol, min_speed=min_speed, min_duration=min_duration)
    if len(seg) == 0:
        raise InputError(f"{', '.join(rec.sources)}: no constant-speed segment found "
                         f"(rows: {dict(seg.excluded)}); try a larger --rel-tol or a fixed --window")
    J = gear.inertia if (inertia and gear is not None) else None
    # the friction torque segment by segment (tau - J thetadd), never the whole recording at once
    tau = FrictionTorque(rec, inertia=J) if J else rec.tau
    theta = rec.theta
    notes = list(rec.notes)
    if J:
        notes.append(f"inertia removed: tau - {J:g} x thetadd (Savitzky-Golay derivative)")
    if progress is None:
        progress = sys.stderr.isatty() and len(seg) > 5
    n_workers = _n_workers(workers, seg)

    def one(s: Segment) -> SegmentSpectrum:
        return analyze_segment(theta[s.rows], _magnitude(rec, tau, s), gear, segment=s, **options)

    def one_in_pool(s: Segment) -> SegmentSpectrum:
        _local.in_pool = True
        try:
            return one(s)
        finally:
            _local.in_pool = False

    # small matrices (tens of columns): OpenBLAS's threads only contend there, 16 ms instead of 0.04 ms
    # for one 40-column solve on a busy 2-core machine; the segments run in threads of their own
    with threadpool_limits(limits=1, user_api="blas"), \
            ThreadPoolExecutor(max_workers=n_workers, thread_name_prefix="gearspec-segment") as pool:
        it = pool.map(one_in_pool, seg.segments) if n_workers > 1 else map(one, seg.segments)
        if progress:
            from tqdm import tqdm

            it = tqdm(it, total=len(seg), desc="segments", unit="seg", file=sys.stderr)
        results = list(it)
    relabel_aliases(results, gear, unit=rec.unit)
    excluded = Counter(rec.excluded) + Counter(seg.excluded)
    return SpectrumResult(results, excluded, rec.n_read, rec.unit, gear, notes,
                          settings={**seg.settings, **options, "inertia": inertia},
                          options={**options, "inertia": J})


def _magnitude(rec: Recording, tau, s: Segment):
    """The friction magnitude of segment ``s``: direction x (torque - J thetadd), a quasi-static
    sweep's torque as measured (it was taken at rest: no J thetadd)."""
    y = (rec.tau if s.kind == "quasi_static" else tau)[s.rows]
    return -y if s.direction < 0 else y  # a view of the torque when it is the torque


def attach_spectra(result: SpectrumResult, rec: Recording, indices) -> list[int]:
    """Compute the figures' spectra (``keep_spectra``) of the segments ``indices`` of ``result``
    after an analysis run without them, so that a report draws a few segments without holding
    every segment's spectra (memory of the order of the samples) for a long recording.

    The segment is analysed again with the options of ``result`` (the analysis is deterministic:
    the same peaks); only the spectra are taken from it, the peaks of ``result`` (relabelled
    across segments by :func:`relabel_aliases`) are kept.  Segments that hold spectra already are
    left alone.  ``rec``: the recording ``result`` was computed from.  Returns the indices computed.
    """
    opts = dict(result.options)
    J = opts.pop("inertia", None)
    opts["keep_spectra"] = True
    tau = FrictionTorque(rec, inertia=J) if J else rec.tau
    done = []
    with threadpool_limits(limits=1, user_api="blas"):  # small matrices: as in analyze
        for i in indices:
            if _attach_one(result, rec, tau, opts, i):
                done.append(i)
    return done


def can_hold_spectra(s: SegmentSpectrum) -> bool:
    """Whether segment ``s`` holds the figures' spectra or :func:`attach_spectra` gives them to it
    (a segment not fitted has none): a report numbers its pages of spectra from this before it
    draws them."""
    return s.fft_frequency is not None or s.fit is not None


def _attach_one(result: SpectrumResult, rec: Recording, tau, opts: dict, i: int) -> bool:
    """The figures' spectra of segment ``i`` into ``result`` (:func:`attach_spectra`); False when
    it holds them already or was not fitted."""
    s = result.segments[i]
    if s.fft_frequency is not None or not can_hold_spectra(s):
        return False
    g = s.segment
    again = analyze_segment(rec.theta[g.rows], _magnitude(rec, tau, g), result.gear, segment=g, **opts)
    for name in ("fft_frequency", "fft_amplitude", "ls_frequency", "ls_amplitude", "ls_residual_amplitude",
                 "noise_amplitude"):
        setattr(s, name, getattr(again, name))
    return True


def relabel_aliases(segments: list[SegmentSpectrum], gear: GearTrain | None = None, unit: str = "rad") -> int:
    """Label ``alias of <line>`` the unexplained peaks of a segment that sit where a line measured
    in *another* segment aliases in this one (:func:`gearspec.gears.alias_of`).  Changes the peaks
    in place; returns how many were relabelled."""
    known: list[tuple[float, str]] = []
    for s in segments:
        for p in s.peaks:
            # the encoder's own count-rate lines move with the speed: not a position-locked line
            # another segment could alias
            if p.declared or p.aliased_from is not None or p.fap >= 0.01 or p.quantisation_harmonic is not None:
                continue
            name = (p.label.split(" = ")[0] if p.label else p.hint) or f"line at {p.frequency:.6g} cycles/{unit}"
            if not any(abs(f - p.frequency) <= 1e-4 * p.frequency for f, _ in known):
                known.append((p.frequency, name))
    changed = 0
    for s in segments:
        n = s.segment.n
        if not s.peaks or n < 2 or not (s.span > 0):
            continue
        spacing = s.span / (n - 1)
        for i, p in enumerate(s.peaks):
            if p.declared or p.label is not None:
                continue
            others = [(f, lab) for f, lab in known if f > s.nyquist]  # only lines this segment cannot measure
            if not others:
                continue
            ln = alias_of(None, p.frequency, max(0.5 / s.span, 3 * p.frequency_se), spacing, nyquist=s.nyquist,
                          known=others, max_harmonic=1)
            if ln is not None:
                s.peaks[i] = replace(p, label=ln.label, hint=None, frequency_exact=None, order_exact=None,
                                     aliased_from={"label": ln.parents[0], "frequency": ln.frequency,
                                                   "order": None if gear is None else gear.order(ln.frequency)})
                changed += 1
    return changed


def _n_workers(workers, seg: Segmentation) -> int:
    """Segments analysed at once: ``workers``, or for ``"auto"`` two when this process may use two
    CPUs and there are two segments or more, else one.

    Two threads with one finufft thread each, rather than one thread whose periodograms use
    finufft's OpenMP threads: the same numbers, the same CPU time, and on a busy machine a fraction
    of the wall time (80 segments of a SILO4 twin at load average 6 on 2 cores: 3.8 s instead of
    5.5-6.3 s; OpenMP's threads wait for each other on every small transform).  Short segments
    need little memory each; before, only recordings with two segments of more than
    ``LS_MAX_SAMPLES`` samples got two threads."""
    if workers == "auto":
        import os

        cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
        return 2 if cpus >= 2 and len(seg) >= 2 else 1
    try:
        n = int(workers)
    except (TypeError, ValueError):
        raise InputError(f"workers must be a positive integer or 'auto', got {workers!r}") from None
    if n < 1:
        raise InputError(f"workers must be a positive integer or 'auto', got {workers!r}")
    return min(n, max(1, len(seg)))
