"""Gear trains (TOML specs, ``CONTRACTS.md`` section 2, or presets) and their *lines*: the
frequencies, in cycles per unit of ``theta``, at which the drive can ripple.  Declared lines (fitted
in every segment): ``shaft`` (each shaft's revolution), ``mesh`` (tooth mesh of a stage with
``teeth``), ``wave`` (2x / 4x wave generator of a strain-wave stage); lines that only label a found
peak: ``harmonic`` (integer multiples) and ``sideband`` (sums and differences).

``ratio`` is input turns per output turn of a stage.  Frequencies of a rotary train are per radian
of the reference shaft: with ``reference = "motor"`` the motor shaft is at 1/(2 pi) cycles/rad and
the output at 1/(2 pi N); with ``reference = "output"`` the output is at 1/(2 pi) and the motor at
N/(2 pi).  A linear axis (``unit = "m"``) ends in a ``ballscrew`` or ``belt`` stage with ``lead``
(m of travel per turn); its screw turns 1/lead times per metre.  ``teeth`` counts the teeth of the
stage's input member; the mesh frequency is ``teeth`` times the input member's speed relative to
the carrier (planetary, harmonic, cycloidal: input minus output) or to the housing (all others).
``order`` is cycles per revolution of the output shaft (of the screw on a linear axis).
"""

from __future__ import annotations

import functools
import math
import operator
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from itertools import accumulate
from pathlib import Path
from typing import Iterable

from .errors import InputError, warn

__all__ = ["Stage", "Line", "GearTrain", "KINDS", "presets", "load_gear", "integer_hint", "integer_order",
           "IntegerOrder", "alias_frequency", "alias_of", "HINT_COINCIDENCE", "MAX_SLOW_SHAFT_MULTIPLE"]

KINDS = ("planetary", "worm", "spur", "helical", "harmonic", "cycloidal", "ballscrew", "belt", "other")
_CARRIER_KINDS = ("planetary", "harmonic", "cycloidal")
_LINEAR_KINDS = ("ballscrew", "belt")
_WAVE_MULTIPLES = (1, 2, 4)
_KIND_RANK = {"shaft": 0, "wave": 1, "mesh": 2, "harmonic": 3, "sideband": 4, "found": 5, "alias": 6}
_TOP_KEYS = {"name", "reference", "unit", "torque_constant", "inertia", "stages", "description"}
_STAGE_KEYS = {"name", "kind", "ratio", "teeth", "lead"}
#: most stages of a gear train (robot drives have one to four; more is a spec mistake)
MAX_STAGES = 8
#: largest total ratio (motor turns per output turn) and its inverse the smallest; beyond it the output
#: shaft's lines lie below any recording's resolution and the line fits become singular
MAX_TOTAL_RATIO = 1e6


@dataclass(frozen=True)
class Stage:
    """One gear stage, listed from the motor towards the output."""

    name: str
    kind: str
    ratio: float = 1.0
    teeth: int | None = None
    lead: float | None = None

    def __post_init__(self) -> None:
        where = f"stage '{self.name}'"
        if self.kind not in KINDS:
            raise InputError(f"{where}: unknown kind '{self.kind}' (expected one of {', '.join(KINDS)})")
        if not (_is_number(self.ratio) and math.isfinite(self.ratio) and self.ratio > 0):
            raise InputError(f"{where}: ratio must be a positive number (input turns per output turn), got {self.ratio!r}")
        if self.teeth is not None and (not _is_number(self.teeth) or not math.isfinite(self.teeth)
                                       or int(self.teeth) != self.teeth or self.teeth < 1):
            raise InputError(f"{where}: teeth must be a positive integer, got {self.teeth!r}")
        if self.lead is not None:
            if self.kind not in _LINEAR_KINDS:
                raise InputError(f"{where}: 'lead' is only meaningful for a ballscrew or belt stage, not '{self.kind}'")
            if not (_is_number(self.lead) and math.isfinite(self.lead) and self.lead > 0):
                raise InputError(f"{where}: lead must be a positive length in m per turn, got {self.lead!r}")


@dataclass(frozen=True)
class Line:
    """A frequency the gear train explains, in cycles per unit of theta."""

    frequency: float
    label: str
    kind: str
    order: float | None = None
    parents: tuple[str, ...] = ()

    def to_dict(self) -> dict:
        return {"frequency": self.frequency, "label": self.label, "kind": self.kind, "order": self.order}


@dataclass(frozen=True)
class GearTrain:
    """A drive.  ``reference`` {"motor", "output"}: the shaft ``theta`` measures; ``unit`` {"rad",
    "m"}: rotary or linear; ``torque_constant`` Nm/A (to use ``current``); ``inertia`` at the reference
    shaft, kg m^2 (kg), for inertia removal; ``stages`` from the motor on, may be empty."""

    name: str
    reference: str = "motor"
    unit: str = "rad"
    torque_constant: float | None = None
    inertia: float | None = None
    stages: tuple[Stage, ...] = ()
    description: str = ""
    source: str = field(default="", compare=False)

    def __post_init__(self) -> None:
        where = f"gear spec {self.source}" if self.source else f"gear spec '{self.name}'"
        if self.reference not in ("motor", "output"):
            raise InputError(f"{where}: reference must be 'motor' or 'output', got '{self.reference}'")
        if self.unit not in ("rad", "m"):
            raise InputError(f"{where}: unit must be 'rad' (rotary) or 'm' (linear), got '{self.unit}'")
        for key in ("torque_constant", "inertia"):
            value = getattr(self, key)
            if value is not None and not (_is_number(value) and math.isfinite(value) and value > 0):
                raise InputError(f"{where}: {key} must be a positive number, got {value!r}")
        names = [s.name for s in self.stages]
        if len(set(names)) != len(names):
            raise InputError(f"{where}: stage names must be unique, got {names}")
        linear = [i for i, s in enumerate(self.stages) if s.lead is not None]
        if self.unit == "m":
            if self.stages and linear != [len(self.stages) - 1]:
                raise InputError(
                    f"{where}: a linear axis (unit = 'm') with stages must end in one ballscrew or belt "
                    "stage with 'lead' (m per turn), so that shaft frequencies per metre are known")
        elif linear:
            raise InputError(f"{where}: 'lead' given on a rotary axis (unit = 'rad'); use unit = 'm' for a linear axis")
        if len(self.stages) > MAX_STAGES:
            raise InputError(f"{where}: {len(self.stages)} stages; a gear train has at most {MAX_STAGES}")
        total = math.prod(s.ratio for s in self.stages if s.lead is None)
        if not (1 / MAX_TOTAL_RATIO <= total <= MAX_TOTAL_RATIO):
            raise InputError(f"{where}: the stages' ratios multiply to {total:.3g}, outside 1e-6 to 1e6 turns per "
                             "output turn; check the ratios (input turns per output turn of each stage)")

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_dict(cls, spec: dict, source: str = "") -> "GearTrain":
        where = f"gear spec {source or spec.get('name', '')}".strip()
        if not isinstance(spec, dict):
            raise InputError(f"{where}: must be a table of keys (name, reference, unit, stages, ...)")
        unknown = set(spec) - _TOP_KEYS
        if unknown:
            warn(f"{where}: ignoring unknown keys {sorted(unknown)}")
        stages = []
        raw_stages = spec.get("stages", [])
        if not isinstance(raw_stages, list):
            raise InputError(f"{where}: 'stages' must be a list of [[stages]] tables")
        if len(raw_stages) > MAX_STAGES:
            raise InputError(f"{where}: {len(raw_stages)} stages; a gear train has at most {MAX_STAGES} "
                             "(list the stages that put lines into friction, or use a total 'other' stage)")
        for i, st in enumerate(raw_stages):
            if not isinstance(st, dict):
                raise InputError(f"{where}: stage {i + 1} must be a [[stages]] table, got {st!r}")
            extra = set(st) - _STAGE_KEYS
            if extra:
                warn(f"{where}: stage {i + 1} ignores unknown keys {sorted(extra)}")
            if "kind" not in st:
                raise InputError(f"{where}: stage {i + 1} has no 'kind'")
            kind = st["kind"]
            label = f"stage {i + 1} ('{st.get('name', kind)}')"
            if not isinstance(kind, str):
                raise InputError(f"{where}: {label}: 'kind' must be a name such as \"planetary\", got {kind!r}")
            if "ratio" not in st and kind not in _LINEAR_KINDS:
                raise InputError(f"{where}: {label} has no 'ratio'")
            ratio = _spec_number(where, label, "ratio", st.get("ratio", 1.0))
            teeth = _spec_number(where, label, "teeth", st.get("teeth"), integer=True)
            lead = _spec_number(where, label, "lead", st.get("lead"))
            try:
                stages.append(Stage(name=str(st.get("name", f"{kind}{i + 1}")), kind=kind, ratio=ratio,
                                    teeth=teeth, lead=lead))
            except InputError as exc:
                raise InputError(f"{where}: {exc}") from None
        for key in ("reference", "unit", "name", "description"):
            if key in spec and not isinstance(spec[key], str):
                raise InputError(f"{where}: '{key}' must be a text, got {spec[key]!r}")
        return cls(name=str(spec.get("name", Path(source).stem if source else "unnamed")),
                   reference=spec.get("reference", "motor"), unit=spec.get("unit", "rad"),
                   torque_constant=_spec_number(where, "", "torque_constant", spec.get("torque_constant")),
                   inertia=_spec_number(where, "", "inertia", spec.get("inertia")), stages=tuple(stages),
                   description=str(spec.get("description", "")), source=source)

    @classmethod
    def from_toml(cls, path: str | Path) -> "GearTrain":
        path = Path(path)
        try:
            raw = path.read_bytes()
        except OSError as exc:
            raise InputError(f"gear spec {path}: cannot be read ({exc.strerror})") from None
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise InputError(f"gear spec {path}: is not UTF-8 text (byte {exc.start}); TOML files are UTF-8") from None
        try:
            spec = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise InputError(f"gear spec {path}: not valid TOML ({exc})") from None
        return cls.from_dict(spec, source=str(path))

    def to_dict(self) -> dict:
        out = {"name": self.name, "reference": self.reference, "unit": self.unit}
        if self.torque_constant is not None:
            out["torque_constant"] = self.torque_constant
        if self.inertia is not None:
            out["inertia"] = self.inertia
        out["stages"] = [{k: v for k, v in vars(s).items() if v is not None} for s in self.stages]
        return out

    def to_toml(self, path: str | Path | None = None) -> str:
        """The spec as TOML (``CONTRACTS.md`` section 2), which :meth:`from_toml` reads back; also
        written to ``path`` when given (e.g. beside a twin recording, to read it with)."""

        def q(s):
            return '"' + str(s).replace("\\", "\\\\").replace('"', '\\"') + '"'

        lines = [f"name = {q(self.name)}"]
        if self.description:
            lines.append(f"description = {q(self.description)}")
        lines += [f"reference = {q(self.reference)}", f"unit = {q(self.unit)}"]
        if self.torque_constant is not None:
            lines.append(f"torque_constant = {float(self.torque_constant)!r}")
        if self.inertia is not None:
            lines.append(f"inertia = {float(self.inertia)!r}")
        for s in self.stages:
            lines += ["", "[[stages]]", f"name = {q(s.name)}", f"kind = {q(s.kind)}", f"ratio = {float(s.ratio)!r}"]
            if s.teeth is not None:
                lines.append(f"teeth = {int(s.teeth)}")
            if s.lead is not None:
                lines.append(f"lead = {float(s.lead)!r}")
        text = "\n".join(lines) + "\n"
        if path is not None:
            Path(path).write_text(text)
        return text

    # ------------------------------------------------------------------ kinematics
    @property
    def total_ratio(self) -> float:
        """Motor turns per output turn (rotary stages only)."""
        return math.prod(s.ratio for s in self.stages if s.lead is None)

    def _shaft_turns_per_unit(self) -> list[float]:
        """Turns of each shaft (motor, after stage 1, ..., output) per unit of theta."""
        ratios = [s.ratio for s in self.stages]
        if self.unit == "m":
            if not self.stages:
                return []
            # the screw shaft (input of the last stage) turns 1/lead times per metre; none turns after it
            return list(accumulate(ratios[:-1][::-1], operator.mul, initial=1.0 / self.stages[-1].lead))[::-1]
        if self.reference == "motor":
            return [a / (2 * math.pi) for a in accumulate(ratios, operator.truediv, initial=1.0)]
        return [a / (2 * math.pi) for a in accumulate(ratios[::-1], operator.mul, initial=1.0)][::-1]

    def shaft_names(self) -> list[str]:
        """Names of the shafts, in the order of :meth:`_shaft_turns_per_unit`."""
        n = len(self.stages)
        inner = [f"{s.name} output shaft" for s in self.stages[:-1]]
        if self.unit == "m":  # shaft j is the input of stage j+1; the last one is the screw (or pulley) shaft
            if not n:
                return []
            screw = f"{self.stages[-1].name} shaft" + (" (= motor shaft)" if n == 1 else "")
            return (["motor shaft"] + inner)[:n - 1] + [screw]
        return ["motor shaft" if n else "shaft"] + inner + ["output shaft"] * (n > 0)

    @property
    def output_frequency(self) -> float | None:
        """Frequency of one output (or screw) revolution, cycles per unit of theta."""
        turns = self._shaft_turns_per_unit()
        return turns[-1] if turns else (1 / (2 * math.pi) if self.unit == "rad" else None)

    def order(self, frequency: float) -> float | None:
        """Cycles per revolution of the output shaft (of the screw on a linear axis)."""
        fo = self.output_frequency
        return None if fo is None else frequency / fo

    def declared_lines(self, max_harmonic: int = 1) -> list[Line]:
        """Shaft, mesh and wave-generator lines and their harmonics up to ``max_harmonic``; lines at
        one frequency (1e-9 relative) are merged, labels joined by ' = ' (no two identical columns)."""
        turns = self._shaft_turns_per_unit()
        names = self.shaft_names()
        base = [Line(f, nm, "shaft") for f, nm in zip(turns, names)]
        for j, s in enumerate(self.stages):
            if j >= len(turns):
                break
            f_in = turns[j]
            f_out = turns[j + 1] if j + 1 < len(turns) else 0.0
            if s.kind == "harmonic":
                for m in _WAVE_MULTIPLES[1:]:  # 1x is the input shaft itself (its label says so below)
                    base.append(Line(m * f_in, f"{s.name} {m}x wave generator", "wave"))
            if s.teeth:
                rel = (f_in - f_out) if s.kind in _CARRIER_KINDS else f_in
                base.append(Line(s.teeth * abs(rel), f"{s.name} tooth mesh", "mesh"))
        # the 1x wave generator is the input shaft of the harmonic stage: say so in its label
        for j, s in enumerate(self.stages):
            if s.kind == "harmonic" and j < len(turns):
                base = [Line(b.frequency, f"{b.label} (= {s.name} 1x wave generator)", b.kind)
                        if b.kind == "shaft" and math.isclose(b.frequency, turns[j], rel_tol=1e-12) else b
                        for b in base]
        return self._finish(base + _harmonics(base, max_harmonic))

    def candidate_lines(self, max_harmonic: int = 4, sidebands: bool = True) -> list[Line]:
        """Every line that may explain a peak: declared lines, harmonics and sidebands."""
        base = self.declared_lines(1)
        lines = base + _harmonics(base, max_harmonic)
        if sidebands:
            for i, a in enumerate(base):
                for b in base[i + 1:]:
                    hi, lo = (a, b) if a.frequency >= b.frequency else (b, a)
                    lines.append(Line(hi.frequency + lo.frequency, f"{hi.label} + {lo.label}", "sideband",
                                      parents=(hi.label, lo.label)))
                    if hi.frequency - lo.frequency > 1e-12 * hi.frequency:
                        lines.append(Line(hi.frequency - lo.frequency, f"{hi.label} - {lo.label}", "sideband",
                                          parents=(hi.label, lo.label)))
        return self._finish(lines, join=False)

    def _finish(self, lines: Iterable[Line], join: bool = True) -> list[Line]:
        """Sort, attach orders, and merge lines at the same frequency: labels joined with ' = '
        (``join``), or only the simplest kept."""
        merged: list[Line] = []
        for ln in sorted(lines, key=lambda x: (x.frequency, _KIND_RANK[x.kind])):
            if merged and math.isclose(merged[-1].frequency, ln.frequency, rel_tol=1e-9):
                prev = merged[-1]
                if join and ln.label not in prev.label.split(" = "):
                    merged[-1] = Line(prev.frequency, f"{prev.label} = {ln.label}", prev.kind, prev.order, prev.parents)
                continue
            merged.append(Line(ln.frequency, ln.label, ln.kind, self.order(ln.frequency), ln.parents))
        return merged

    def label(self, frequency: float, tolerance: float, max_harmonic: int = 4, *, spacing: float | None = None,
              nyquist: float | None = None, known: Iterable[tuple[float, str]] = ()) -> Line | None:
        """The simplest line (shaft, wave generator, mesh, harmonic, sideband; then the closest)
        within ``tolerance`` (cycles per unit) of ``frequency``, or None.  With ``spacing`` (mean
        position spacing of the samples) and no line there: the line whose alias falls there
        (:func:`alias_of`, with ``nyquist`` and ``known``)."""
        best = _simplest(_candidates(self, max_harmonic), lambda ln: abs(ln.frequency - frequency), tolerance)
        if best is None and spacing is not None:
            return alias_of(self, frequency, tolerance, spacing, nyquist=nyquist, known=known,
                            max_harmonic=max_harmonic)
        return best

    def torque_from_current(self, current):
        """Drive torque at the reference shaft from motor current: k_t * I (times the ideal ratio N,
        gear efficiency ignored, at the output)."""
        if self.torque_constant is None:
            raise InputError(f"gear spec '{self.name}' has no torque_constant (Nm/A): it is needed to turn "
                             "motor current into torque; add it to the spec, or record torque")
        factor = self.torque_constant * (self.total_ratio if self.reference == "output" else 1.0)
        return current * factor

    def describe(self) -> str:
        """A short human-readable table of the train and its declared lines."""
        lines = [f"{self.name}  (reference: {self.reference}, theta in {self.unit})"]
        if self.description:
            lines.append(f"  {self.description}")
        for s in self.stages:
            extra = "".join(f", {k} {v}" for k, v in (("teeth", s.teeth), ("lead", s.lead)) if v is not None)
            lines.append(f"  stage {s.name:<14} {s.kind:<10} ratio {s.ratio:g}{extra}")
        if self.stages:
            lines.append(f"  total ratio {self.total_ratio:g}")
        per = "cycles/rad" if self.unit == "rad" else "cycles/m"
        for ln in self.declared_lines():
            o = "" if ln.order is None else f"   order {ln.order:.4g}"
            lines.append(f"  {ln.frequency:12.6g} {per}{o}   {ln.label}")
        return "\n".join(lines)


def _harmonics(base: list[Line], max_harmonic: int) -> list[Line]:
    return [Line(h * b.frequency, f"{h}x {b.label}", "harmonic", parents=(b.label,))
            for h in range(2, max_harmonic + 1) for b in base]


def _simplest(lines: Iterable[Line], distance, tol: float) -> Line | None:
    """The line of the simplest kind within ``tol`` (``distance(line)``), the closest among equals."""
    near = [((_KIND_RANK[ln.kind], d), ln) for ln in lines for d in [distance(ln)] if d <= tol]
    return min(near, key=lambda x: x[0])[1] if near else None


@functools.lru_cache(maxsize=64)
def _candidates(gear: "GearTrain", max_harmonic: int) -> tuple[Line, ...]:
    return tuple(gear.candidate_lines(max_harmonic))


def _is_number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _spec_number(where: str, label: str, key: str, value, integer: bool = False):
    """A number from a spec (None stays None); a text, a list or true/false is refused naming the field."""
    if value is None:
        return None
    field_ = f"{label}: '{key}'" if label else f"'{key}'"
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        kind = "a whole number" if integer else "a number"
        got = {str: "a text", list: "a list", dict: "a table", bool: "true/false"}.get(type(value), type(value).__name__)
        raise InputError(f"{where}: {field_} must be {kind}, got {value!r} ({got})")
    if integer:
        if value != int(value) if math.isfinite(value) else True:
            raise InputError(f"{where}: {field_} must be a whole number, got {value!r}")
        return int(value)
    return float(value)


# ---------------------------------------------------------------------- presets
def presets() -> dict[str, GearTrain]:
    """Built-in gear trains by name (``gearspec gears`` lists them)."""
    out = {}
    for res in sorted(resources.files("gearspec.presets").iterdir(), key=lambda r: r.name):
        if res.name.endswith(".toml"):
            spec = tomllib.loads(res.read_text())
            out[res.name[:-5]] = GearTrain.from_dict(spec, source=f"preset:{res.name[:-5]}")
    return out


def load_gear(spec: "str | Path | GearTrain | dict | None") -> GearTrain | None:
    """A GearTrain from a preset name, a TOML path, a dict, or a GearTrain (returned as is)."""
    if spec is None or isinstance(spec, GearTrain):
        return spec
    if isinstance(spec, dict):
        return GearTrain.from_dict(spec)
    text = str(spec)
    known = presets()
    if text in known:
        return known[text]
    path = Path(text)
    if path.exists():
        return GearTrain.from_toml(path)
    raise InputError(f"gear spec '{text}': no such file and no such preset (presets: {', '.join(known)})")


#: the largest chance that a frequency unrelated to a shaft falls within the tolerance of one of
#: its integer multiples, for an integer-order hint (or an alias of one) to be given at all
HINT_COINCIDENCE = 0.1

#: the highest multiple of a shaft other than the fastest (the motor's) that a hint may name: a
#: shaft's run-out, eccentricity and misalignment make its 1x and a few low harmonics; a tooth
#: mesh makes a declared line (labelled as such, not hinted).  Only the motor shaft makes high
#: integer orders of its own (pole pairs, slots, commutator segments: cogging, torque ripple), so
#: "53x planetary output shaft" is no hint but a coincidence
MAX_SLOW_SHAFT_MULTIPLE = 4


@dataclass(frozen=True)
class IntegerOrder:
    """An integer multiple of a shaft that a measured frequency sits on (:func:`integer_order`)."""

    multiple: int
    shaft: str               # the shaft's label
    frequency: float         # the exact frequency, multiple x shaft frequency (cycles per unit)
    order: float | None      # the exact order (cycles per output turn)

    @property
    def hint(self) -> str:
        return f"{self.multiple}x {self.shaft}"


def integer_order(gear: GearTrain | None, frequency: float, tol: float, *, max_multiple: int | None = None,
                  coincidence: float = HINT_COINCIDENCE) -> IntegerOrder | None:
    """The integer multiple (>= 2, at most ``max_multiple``) of a shaft of ``gear`` within ``tol`` of
    ``frequency``, or None.

    Any multiple that ``tol`` tells from its neighbours is tried: an unrelated frequency lands
    within ``tol`` of a multiple of a shaft at ``f_s`` with probability ``2 tol / f_s``.  Shafts
    are tried fastest first while the summed chance stays at most ``coincidence`` (a union bound
    on a false hint); a slow shaft thus needs a sharper frequency.  And a multiple is named only
    where a gear can plausibly make it: any of the fastest shaft (the motor: pole pairs, slots),
    at most :data:`MAX_SLOW_SHAFT_MULTIPLE` of any other shaft (run-out and its low harmonics),
    which keeps hints such as "53x planetary output shaft" out however sharp the frequency.
    """
    if gear is None or not (frequency > 0) or not (tol >= 0):
        return None
    shafts = sorted((ln for ln in gear.declared_lines() if ln.kind == "shaft"), key=lambda x: -x.frequency)
    chance = 0.0
    for ln in shafts:
        chance += 2.0 * tol / ln.frequency
        if chance > coincidence:  # neighbouring multiples of this shaft (or slower) cannot be told apart reliably
            break
        m = round(frequency / ln.frequency)
        if ln is not shafts[0] and m > MAX_SLOW_SHAFT_MULTIPLE:  # no high orders but the motor's
            continue
        if m >= 2 and (max_multiple is None or m <= max_multiple) and abs(frequency - m * ln.frequency) <= tol:
            exact = m * ln.frequency
            return IntegerOrder(m, ln.label, exact, gear.order(exact))
    return None


def integer_hint(gear: GearTrain | None, frequency: float, tol: float, max_multiple: int | None = None,
                 coincidence: float = HINT_COINCIDENCE) -> str | None:
    """'7x motor shaft' when :func:`integer_order` finds one, else None: a hint, not a label (a motor
    pole-pair, slot or commutator count, or a cogging order shows up this way)."""
    io = integer_order(gear, frequency, tol, max_multiple=max_multiple, coincidence=coincidence)
    return None if io is None else io.hint


# ---------------------------------------------------------------------- aliasing
def alias_frequency(frequency: float, spacing: float) -> float:
    """Where a line at ``frequency`` (cycles per unit) shows up in samples every ``spacing`` units of
    position: ``|f - m / spacing|``, m the nearest integer (exact for uniform spacing)."""
    fs = 1.0 / spacing
    return abs(frequency - round(frequency / fs) * fs)


def alias_of(gear: GearTrain | None, frequency: float, tol: float, spacing: float, *,
             nyquist: float | None = None, known: Iterable[tuple[float, str]] = (), max_harmonic: int = 4,
             coincidence: float = HINT_COINCIDENCE) -> Line | None:
    """The line above the position Nyquist frequency ``nyquist`` (default ``0.5 / spacing``) whose
    alias (:func:`alias_frequency`, ``spacing`` the mean position spacing of the samples) is within
    ``tol`` of ``frequency``: a :class:`Line` ``alias of <label>`` of kind ``"alias"`` with the true
    line's frequency and order, or None.  Tried, simplest first: the lines :meth:`GearTrain.label`
    knows, the ``(frequency, label)`` pairs in ``known`` with their harmonics, then integer multiples
    of a shaft in the first fold (``1/spacing -+ frequency``, as :func:`integer_order` bounds them)."""
    if not (spacing > 0) or not (frequency >= 0) or not (tol >= 0):
        return None
    fs = 1.0 / spacing
    fn = 0.5 * fs if nyquist is None else float(nyquist)
    lines: list[Line] = list(_candidates(gear, max_harmonic)) if gear is not None else []
    for f0, lab in known:
        lines.append(Line(float(f0), str(lab), "found"))
        lines += [Line(h * float(f0), f"{h}x {lab}", "found") for h in range(2, max_harmonic + 1)]
    # a line measurable at its own frequency (below fn) is not an alias
    ln = _simplest((x for x in lines if x.frequency > fn),
                   lambda x: abs(alias_frequency(x.frequency, spacing) - frequency), tol)
    if ln is not None:
        order = gear.order(ln.frequency) if gear is not None else None
        return Line(ln.frequency, f"alias of {ln.label}", "alias", order, (ln.label,))
    for f_true in (fs - frequency, fs + frequency):
        if f_true > fn:
            io = integer_order(gear, f_true, tol, coincidence=coincidence)
            if io is not None:
                return Line(io.frequency, f"alias of {io.hint}", "alias", io.order, (io.hint,))
    return None
