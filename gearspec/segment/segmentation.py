"""What a segmentation returns: :class:`Segment` (a constant-speed stretch or a quasi-static sweep)
and :class:`Segmentation` (the segments and the ledger of the rows outside them)."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

__all__ = ["Segment", "Segmentation"]


@dataclass(frozen=True)
class Segment:
    """A constant-speed stretch of one run in one direction, a quasi-static sweep, or a block of free
    motion (``kind``; :mod:`gearspec.segment.freemotion`).

    ``start``/``stop`` index rows of ``Recording.data`` (stop exclusive); ``speed``: travel over
    duration (>= 0, unit/s; nominal for a sweep at rest); ``direction``: +1 or -1.
    """

    run: int
    start: int
    stop: int
    direction: int
    speed: float
    speed_ripple: float = 0.0  # relative std of the window speed inside the segment
    window: float = 0.0        # the speed window (s) used to find it
    kind: str = "plateau"      # "plateau" (constant speed), "quasi_static" (a sweep at rest) or "free"
    unit: int = -1             # held-out unit of a free-motion block (its stretch of motion); -1: itself

    @property
    def n(self) -> int:
        return self.stop - self.start

    @property
    def rows(self) -> slice:
        return slice(self.start, self.stop)

    @property
    def velocity(self) -> float:
        """Signed mean velocity (unit/s)."""
        return self.direction * self.speed

    def to_dict(self) -> dict:
        return {"run": self.run, "start": self.start, "stop": self.stop, "direction": self.direction,
                "speed": self.speed, "n": self.n, "speed_ripple": self.speed_ripple, "window": self.window,
                "kind": self.kind, "unit": self.unit}


@dataclass
class Segmentation:
    """The segments of a recording and the ledger of rows outside them."""

    segments: list[Segment]
    excluded: Counter
    n_rows: int
    settings: dict = field(default_factory=dict)

    def __iter__(self):
        return iter(self.segments)

    def __len__(self) -> int:
        return len(self.segments)

    def check_ledger(self) -> None:
        """Assert that every row is in one segment or counted once (an internal invariant)."""
        covered = sum(s.n for s in self.segments) + sum(self.excluded.values())
        if covered != self.n_rows:
            raise AssertionError(f"row ledger broken: {covered} accounted for, {self.n_rows} rows")
