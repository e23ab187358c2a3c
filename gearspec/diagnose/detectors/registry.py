"""The registry of detectors.

A detector is a function ``detector(rnd, analyses, *, gate) -> list[Candidate]``: ``rnd`` is the
round's context (:class:`~gearspec.diagnose.context.Round`, read-only), ``analyses`` what
:func:`~gearspec.diagnose.detectors.analyses.analyse` computed on the round's residual, ``gate``
the p-value below which a detector that needs evidence proposes its candidates.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from ...errors import InputError

__all__ = ["Detector", "register_detector", "unregister_detector", "detectors", "propose", "LAST"]


@dataclass(frozen=True)
class Detector:
    """A registered detector: its ``name`` (the term kind it proposes, or its family), the effect
    kind of ``CONTRACTS.md`` section 4 of every candidate it proposes (``effect``), its place in
    the order the loop asks detectors (``order``) and the function."""

    name: str
    effect: str
    order: float
    function: Callable


#: the default place of a detector: after those of this package (their ``order`` is 10 to 150)
LAST = 1000.0

_REGISTRY: dict[str, Detector] = {}


def register_detector(name: str, *, effect: str, order: float | None = None):
    """Register a detector (decorator; it returns the function unchanged).

    ``name``: unique, the term kind (:mod:`gearspec.terms`) it proposes or the name of their family;
    ``effect``: the effect kind (``CONTRACTS.md`` section 4) of every candidate it proposes
    (``diagnose(kinds=...)`` selects by it); ``order``: the loop asks detectors by increasing
    ``order``, which decides ties between equally good candidates (default :data:`LAST`, after
    this package's; several at ``LAST``: in the order they were registered).
    """
    def decorate(fn: Callable) -> Callable:
        if name in _REGISTRY:
            raise InputError(f"a detector named '{name}' is registered already")
        _REGISTRY[name] = Detector(name, effect, float(LAST if order is None else order), fn)
        return fn
    return decorate


def unregister_detector(name: str) -> None:
    """Remove the detector ``name`` (a test's, or one to replace)."""
    if name not in _REGISTRY:
        raise InputError(f"no detector named '{name}' is registered")
    del _REGISTRY[name]


def detectors() -> list[Detector]:
    """The registered detectors in the order the loop asks them (equal orders: as registered, the
    registry's order, which the stable sort keeps)."""
    return sorted(_REGISTRY.values(), key=lambda d: d.order)


def propose(rnd, analyses: dict, *, gate: float, kinds=None, skip=()) -> list:
    """The candidates of every registered detector (but those named in ``skip``) for the round
    ``rnd``, in the detectors' order; with ``kinds``, only detectors and candidates of those
    effect kinds."""
    out = []
    for det in detectors():
        if det.name in skip or (kinds is not None and det.effect not in kinds):
            continue
        out += [c for c in det.function(rnd, analyses, gate=gate) if kinds is None or c.kind in kinds]
    return out
