"""Effects a declared model lacks, injected into the truth of a twin (or of any synthetic recording).

An effect is a small frozen dataclass that changes a truth :class:`~gearspec.model.FrictionModel`
(:meth:`Effect.apply`: adds a :mod:`gearspec.terms` term, or changes a harmonic or a base-law
parameter), may supply channels the model then needs (:meth:`Effect.channels`: a warming
temperature, the load of each run) and reports its ground truth (:meth:`Effect.truth`: one dict per
component with a ``kind`` of ``CONTRACTS.md`` section 4, ``frequency`` in cycles per unit of theta
or None, ``direction`` +1, -1 or 0 for both) -- what a detector should find.

>>> rec, truth = silo4_twin(effects=[cogging(count=7, amplitude=2e-4), drift(-2e-7)])  # doctest: +SKIP

Channels are functions of the *experiment clock* (the twins' ``t``, running on from one run to the
next) and of the run id, so drift and warming accumulate over the whole experiment, as on a bench.
On the command line an effect is ``NAME:key=value,...`` (:func:`parse_effect`), e.g.
``cogging:count=7,amplitude=2e-4``.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Callable, ClassVar, Iterable, Mapping

import numpy as np

from ..errors import InputError
from ..jsonsafe import plain
from ..model import DIRECTIONS, FrictionModel, Harmonic
from ..terms import AMPLITUDE_LAWS

__all__ = ["Effect", "EFFECTS", "Cogging", "ExtraOrder", "Sideband", "LoadMeshing", "Warming", "Drift",
           "DecayShape", "NonlinearViscous", "Asymmetry", "Hysteresis", "Backlash", "ExtraInertia",
           "cogging", "extra_order", "sideband", "load_meshing", "warming", "drift", "decay_shape",
           "nonlinear_viscous", "asymmetry", "hysteresis", "backlash", "extra_inertia",
           "apply_effects", "effects_truth", "effect_channels", "channel_function", "parse_effect",
           "effect_from_dict", "KINDS"]

#: the effect kinds of CONTRACTS.md section 4
KINDS = ("periodic", "speed_law", "load", "temperature", "drift", "asymmetry", "inertia", "hysteresis", "other")

#: every effect class by its name (as used by parse_effect and the CLI)
EFFECTS: dict[str, type] = {}

_TWO_PI = 2.0 * math.pi


def _dirs(direction) -> tuple[str, ...]:
    """Direction names an effect acts in: 0/None -> both."""
    if direction in (0, None, "both"):
        return DIRECTIONS
    if direction in (1, "positive", "+"):
        return ("positive",)
    if direction in (-1, "negative", "-"):
        return ("negative",)
    raise InputError(f"direction must be 1, -1 or 0 (both), got {direction!r}")


def _dir_int(direction) -> int:
    d = _dirs(direction)
    return 0 if len(d) == 2 else (1 if d[0] == "positive" else -1)


def _check_law(effect: str, law: str) -> None:
    if law not in AMPLITUDE_LAWS:
        raise InputError(f"{effect}: unknown amplitude law '{law}' ({', '.join(AMPLITUDE_LAWS)})")


def _with_direction(term: dict, direction) -> dict:
    """``term`` with a ``direction`` key when the effect acts in one direction only."""
    d = _dir_int(direction)
    return {**term, "direction": d} if d else term


def _matches(h: Harmonic, target, rel: float = 1e-6) -> bool:
    """Does harmonic ``h`` match ``target`` (a label, one of a ' = '-joined label, or a frequency)?"""
    if isinstance(target, str):
        lab = h.label or ""
        return target == lab or target in lab.split(" = ")
    f = float(target)
    return abs(float(h.frequency) - f) <= rel * max(abs(f), 1e-300)


@dataclass(frozen=True)
class Effect:
    """Base class of the effects: does nothing; subclasses override what they need.

    Attributes of the class: ``name`` (how :func:`parse_effect` and the CLI call it) and ``kind``
    (the ground-truth kind of CONTRACTS.md section 4).
    """

    name: ClassVar[str] = "effect"
    kind: ClassVar[str] = "other"
    #: channels the effect's term needs from the twin (e.g. "load")
    needs: ClassVar[tuple[str, ...]] = ()

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if "name" in cls.__dict__:  # a concrete effect: register it under its name
            EFFECTS[cls.name] = cls

    def apply(self, model: FrictionModel) -> FrictionModel:
        """A copy of ``model`` with the effect in it."""
        return model.copy()

    def channels(self, t: np.ndarray, run: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """Channels the effect supplies at experiment times ``t`` (s) of runs ``run``."""
        return {}

    @property
    def recorded(self) -> tuple[str, ...]:
        """Names of the supplied channels that go into the recording (the others stay hidden)."""
        return tuple(self.channels(np.zeros(1), np.zeros(1, int)))

    def frequencies(self) -> list[float | None]:
        return [None]

    def describe(self) -> str:
        return f"{self.name}: " + ", ".join(f"{k}={v!r}" for k, v in self.params().items())

    def params(self) -> dict:
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}

    def truth(self) -> list[dict]:
        """Ground truth: one dict per component a detector should find."""
        d = _dir_int(getattr(self, "direction", 0))
        return [{"effect": self.name, "kind": self.kind, "frequency": f, "label": None, "direction": d,
                 "description": self.describe(), "params": plain(self.params())} for f in self.frequencies()]

    def to_dict(self) -> dict:
        return {"effect": self.name, **plain(self.params())}


# ---------------------------------------------------------------------- position-locked
@dataclass(frozen=True)
class Cogging(Effect):
    """Motor cogging: ``amplitude * sin(count * motor angle + phase)``, the same torque in both
    directions (a ``cogging`` term, signed: it does not reverse with the motion).  ``count``: cycles
    per motor revolution (poles, slots or commutator segments, or their least common multiple);
    ``amplitude``: Nm at theta's shaft (SILO4: cogging "less than 1 % of the meshing friction");
    ``phase``: rad at theta = 0; ``motor_turns_per_theta_turn``: 1 when theta is the motor angle (all
    the twins), the gear ratio when theta is at the output."""

    count: int = 7
    amplitude: float = 2e-4
    phase: float = 0.0
    motor_turns_per_theta_turn: float = 1.0
    name: ClassVar[str] = "cogging"
    kind: ClassVar[str] = "periodic"

    @property
    def frequency(self) -> float:
        return self.count * self.motor_turns_per_theta_turn / _TWO_PI

    def frequencies(self):
        return [self.frequency]

    def apply(self, model):
        return model.with_terms({"kind": "cogging", "frequency": self.frequency, "amplitude": float(self.amplitude),
                                 "phase": float(self.phase), "label": f"cogging {self.count}x motor"})


@dataclass(frozen=True)
class ExtraOrder(Effect):
    """An extra position-locked friction component the gear spec does not declare.

    ``amplitude * g(|v|) * sin(2 pi frequency theta + phase)`` in the friction magnitude (a
    ``periodic`` term), with ``g`` the amplitude law ``law`` (exp, const, rational, power; see
    :mod:`gearspec.terms`) and its ``decay``.  ``direction``: 1 or -1 to act in one direction
    only, 0 for both.  ``frequency`` in cycles per unit of theta.
    """

    frequency: float = 1.0
    amplitude: float = 2e-4
    decay: float = 0.0
    law: str = "exp"
    phase: float = 0.0
    direction: int = 0
    name: ClassVar[str] = "extra_order"
    kind: ClassVar[str] = "periodic"

    def __post_init__(self):
        _check_law("extra_order", self.law)
        if not self.frequency > 0:
            raise InputError(f"extra_order: frequency must be positive (cycles per unit of theta), got {self.frequency}")

    def frequencies(self):
        return [float(self.frequency)]

    def _term(self, frequency, amplitude, label):
        return _with_direction({"kind": "periodic", "frequency": float(frequency), "amplitude": float(amplitude),
                                "decay": float(self.decay), "law": self.law, "phase": float(self.phase),
                                "label": label}, self.direction)

    def apply(self, model):
        return model.with_terms(self._term(self.frequency, self.amplitude, f"extra order {self.frequency:.6g}"))


@dataclass(frozen=True)
class Sideband(ExtraOrder):
    """Sidebands of two lines ``f1`` and ``f2`` (cycles per unit of theta): components at
    ``f1 + f2`` and/or ``|f1 - f2|`` (``which`` = "both", "sum" or "difference"), each of
    ``amplitude`` (as an amplitude modulation of one shaft's ripple by another's would make).
    The other parameters as :class:`ExtraOrder`."""

    f1: float = 0.15915494309189535
    f2: float = 0.011368210220849667
    which: str = "both"
    frequency: float = 1.0  # unused: the components are at f1 +- f2
    name: ClassVar[str] = "sideband"

    def __post_init__(self):
        if self.which not in ("both", "sum", "difference"):
            raise InputError(f"sideband: which must be both, sum or difference, got '{self.which}'")
        _check_law("sideband", self.law)
        if not (self.f1 > 0 and self.f2 > 0) or math.isclose(self.f1, self.f2):
            raise InputError("sideband: f1 and f2 must be positive and different")

    def frequencies(self):
        out = []
        if self.which in ("both", "sum"):
            out.append(float(self.f1 + self.f2))
        if self.which in ("both", "difference"):
            out.append(float(abs(self.f1 - self.f2)))
        return out

    def params(self):
        p = super().params()
        p.pop("frequency", None)
        return p

    def apply(self, model):
        return model.with_terms(*[self._term(f, self.amplitude, f"sideband {f:.6g}") for f in self.frequencies()])


# ---------------------------------------------------------------------- load
class _Targeted(Effect):
    """An effect on the model's harmonics matching ``target``: a label, or a frequency in cycles per
    unit of theta (a number given as text is read as a frequency)."""

    def __post_init__(self):
        if isinstance(self.target, str):
            try:
                object.__setattr__(self, "target", float(self.target))
            except ValueError:
                pass

    def frequencies(self):
        return [None if isinstance(self.target, str) else float(self.target)]

    def truth(self):
        label = self.target if isinstance(self.target, str) else None
        return [{**o, "label": label} for o in super().truth()]


@dataclass(frozen=True)
class LoadMeshing(_Targeted):
    """Meshing amplitude growing with the square of the load (SILO4 eq. 14, "future work").

    The harmonics matching ``target`` (a label or a frequency) get ``A = A0 + coefficient * load^2``
    (:func:`gearspec.laws.load_dependent_amplitude`); a frequency no harmonic has becomes a new
    component ``coefficient * load^2 * sin(2 pi f theta)``.  ``loads``: output loads (Nm) the effect
    supplies as the ``load`` channel, ``loads[run % len(loads)]``, for twins without a load of their
    own (SILO4); leave it empty on the Lola testbed, whose brake is the load.  The drive supplies
    ``load / N`` more torque.
    """

    target: str | float = "planetary output shaft"
    coefficient: float = 2e-5
    loads: tuple = ()
    name: ClassVar[str] = "load_meshing"
    kind: ClassVar[str] = "load"
    needs: ClassVar[tuple[str, ...]] = ("load",)

    def __post_init__(self):
        super().__post_init__()
        loads = (self.loads,) if isinstance(self.loads, (int, float)) else self.loads
        object.__setattr__(self, "loads", tuple(float(x) for x in loads))

    def apply(self, model):
        m = model.copy()
        hit = False
        for p in m.directions.values():
            for h in p.harmonics:
                if _matches(h, self.target):
                    h.load_coefficient = float(h.load_coefficient or 0.0) + float(self.coefficient)
                    hit = True
        if hit:
            m.rmse = m.rmse_holdout = None
            return m
        if isinstance(self.target, str):
            labels = sorted({h.label or f"{h.frequency:.6g}" for p in m.directions.values() for h in p.harmonics})
            raise InputError(f"load_meshing: the model has no harmonic labelled '{self.target}' "
                             f"(it has: {', '.join(labels) or 'none'}); give a label or a frequency")
        return m.with_terms({"kind": "periodic", "frequency": float(self.target), "amplitude": 0.0,
                             "load_coefficient": float(self.coefficient), "law": "const",
                             "label": f"load meshing {float(self.target):.6g}"})

    def channels(self, t, run=None):
        if not self.loads:
            return {}
        run = np.zeros(np.shape(t), int) if run is None else np.asarray(run)
        levels = np.asarray(self.loads, dtype=float)
        return {"load": levels[np.asarray(run, dtype=np.int64) % len(levels)] * np.ones(np.shape(t))}


# ---------------------------------------------------------------------- temperature, time
@dataclass(frozen=True)
class Warming(Effect):
    """The drive warms up over the experiment and its friction changes with temperature.

    Temperature (degC) on the experiment clock: ``ambient + rise * (1 - exp(-t / time_constant))``
    (a first-order thermal model of housing and lubricant).  Friction magnitude changes by
    ``coefficient * (T - ambient)`` (a ``temperature`` term; negative: warm oil is thinner).
    ``record``: put the temperature channel into the recording (True), or keep it hidden -- then
    the effect is, for the analysis, a drift (kind ``drift``).
    """

    coefficient: float = -4e-5
    rise: float = 20.0
    time_constant: float = 900.0
    ambient: float = 25.0
    record: bool = True
    name: ClassVar[str] = "warming"
    needs: ClassVar[tuple[str, ...]] = ("temperature",)

    @property
    def kind(self):  # type: ignore[override]
        return "temperature" if self.record else "drift"

    def channels(self, t, run=None):
        t = np.asarray(t, dtype=float)
        return {"temperature": self.ambient + self.rise * (1.0 - np.exp(-np.maximum(t, 0.0) / self.time_constant))}

    @property
    def recorded(self):
        return ("temperature",) if self.record else ()

    def apply(self, model):
        return model.with_terms({"kind": "temperature", "coefficient": float(self.coefficient),
                                 "reference": float(self.ambient)})


@dataclass(frozen=True)
class Drift(Effect):
    """Slow linear change of the friction level over the experiment clock:
    ``coefficient * (t - reference)`` (Nm per s; a ``drift`` term: running-in, lubricant
    redistribution -- not explained by any recorded channel)."""

    coefficient: float = -2e-7
    reference: float = 0.0
    name: ClassVar[str] = "drift"
    kind: ClassVar[str] = "drift"

    def apply(self, model):
        return model.with_terms({"kind": "drift", "coefficient": float(self.coefficient),
                                 "reference": float(self.reference)})


# ---------------------------------------------------------------------- speed laws, asymmetry
@dataclass(frozen=True)
class DecayShape(_Targeted):
    """The meshing amplitude of a harmonic decays with speed by another law than SILO4's
    exponential: the harmonics matching ``target`` (label or frequency) get amplitude law ``law``
    (const, rational ``1/(1+(b|v|)^2)``, power ``(1+|v|)^-b``, exp) with decay ``decay`` (in the
    law's own unit), in ``direction`` (1, -1, or 0 for both)."""

    target: str | float = "planetary output shaft"
    law: str = "rational"
    decay: float = 0.05
    direction: int = 1
    name: ClassVar[str] = "decay_shape"
    kind: ClassVar[str] = "speed_law"

    def __post_init__(self):
        _check_law("decay_shape", self.law)
        super().__post_init__()

    def apply(self, model):
        m = model.copy()
        hit = False
        for d in _dirs(self.direction):
            for h in m.directions[d].harmonics:
                if _matches(h, self.target):
                    h.law = self.law
                    h.decay = float(self.decay)
                    hit = True
        if not hit:
            raise InputError(f"decay_shape: the model has no harmonic matching {self.target!r} in the "
                             f"{' and '.join(_dirs(self.direction))} direction")
        m.rmse = m.rmse_holdout = None
        return m


@dataclass(frozen=True)
class NonlinearViscous(Effect):
    """Viscous friction that is not linear in speed: ``coefficient * |v|^exponent`` added to the
    magnitude (a ``viscous_power`` term), in ``direction`` (1, -1, 0 for both)."""

    coefficient: float = 1e-4
    exponent: float = 0.5
    direction: int = 0
    name: ClassVar[str] = "nonlinear_viscous"
    kind: ClassVar[str] = "speed_law"

    def apply(self, model):
        return model.with_terms(_with_direction({"kind": "viscous_power", "coefficient": float(self.coefficient),
                                                 "exponent": float(self.exponent)}, self.direction))


@dataclass(frozen=True)
class Asymmetry(Effect):
    """One direction's base-law parameter differs: ``parameter`` (e.g. tau_c, t_f0, viscous) is
    multiplied by ``factor`` in ``direction`` (1 or -1)."""

    parameter: str = "tau_c"
    factor: float = 1.2
    direction: int = -1
    name: ClassVar[str] = "asymmetry"
    kind: ClassVar[str] = "asymmetry"

    def apply(self, model):
        if _dir_int(self.direction) == 0:
            raise InputError("asymmetry: give direction 1 or -1 (an asymmetry acts in one direction)")
        m = model.copy()
        if self.parameter not in m.law_spec.params:
            raise InputError(f"asymmetry: law {m.law} has no parameter '{self.parameter}' "
                             f"(it has {', '.join(m.law_spec.params)})")
        p = m.directions[_dirs(self.direction)[0]]
        p.set(self.parameter, float(p.values[self.parameter]) * float(self.factor))
        m.rmse = m.rmse_holdout = None
        return m


# ---------------------------------------------------------------------- reversals, inertia
@dataclass(frozen=True)
class Hysteresis(Effect):
    """Presliding after reversals: friction builds up over a travel ``length`` instead of jumping
    (a ``hysteresis`` term, ``-scale * exp(-|theta - theta_turn| / length)``).  Visible only where
    the motion reverses within a run."""

    scale: float = 2e-3
    length: float = 0.5
    name: ClassVar[str] = "hysteresis"
    kind: ClassVar[str] = "hysteresis"

    def apply(self, model):
        return model.with_terms({"kind": "hysteresis", "scale": float(self.scale), "length": float(self.length)})


@dataclass(frozen=True)
class Backlash(Effect):
    """Backlash: for a travel ``gap`` (unit of theta) after every reversal the friction behind
    the gap (``scale``, Nm) is missing (a ``backlash`` term).  Visible only where the motion
    reverses within a run."""

    gap: float = 0.5
    scale: float = 2e-3
    name: ClassVar[str] = "backlash"
    kind: ClassVar[str] = "hysteresis"

    def apply(self, model):
        return model.with_terms({"kind": "backlash", "scale": float(self.scale), "gap": float(self.gap)})


@dataclass(frozen=True)
class ExtraInertia(Effect):
    """More inertia than the gear spec declares (kg m^2 at theta's shaft): an ``inertia`` term
    ``J_extra * thetadd``.  The twins add it to the rotor's inertia (it changes the closed-loop
    dynamics); :func:`~gearspec.simulate.model_recording` evaluates it as a drive torque."""

    inertia: float = 1e-6
    name: ClassVar[str] = "extra_inertia"
    kind: ClassVar[str] = "inertia"

    def apply(self, model):
        return model.with_terms({"kind": "inertia", "inertia": float(self.inertia)})


# lower-case names, as in the issue ("cogging(order, amplitude)", ...)
cogging = Cogging
extra_order = ExtraOrder
sideband = Sideband
load_meshing = LoadMeshing
warming = Warming
drift = Drift
decay_shape = DecayShape
nonlinear_viscous = NonlinearViscous
asymmetry = Asymmetry
hysteresis = Hysteresis
backlash = Backlash
extra_inertia = ExtraInertia


# ---------------------------------------------------------------------- helpers
def apply_effects(model: FrictionModel, effects: Iterable[Effect] = ()) -> FrictionModel:
    """A copy of ``model`` with every effect applied in order; the effects' ground truth is kept
    in ``model.meta["effects"]`` (so it survives the JSON round trip)."""
    effects = list(effects or ())
    m = model.copy()
    for e in effects:
        if not isinstance(e, Effect):
            raise InputError(f"not an effect: {e!r} (use the classes of gearspec.simulate.effects)")
        m = e.apply(m)
    if effects:
        m.meta = {**m.meta, "effects": [t for e in effects for t in e.truth()]}
        m.notes = list(m.notes) + [f"effect injected: {e.describe()}" for e in effects]
        m.name = f"{model.name} + {len(effects)} effect(s)"
    return m


def effects_truth(effects: Iterable[Effect], gear=None) -> list[dict]:
    """Ground truth of the effects, one dict per component (see :meth:`Effect.truth`).

    With ``gear`` (a :class:`~gearspec.gears.GearTrain`), a periodic component whose frequency a
    harmonic or sideband of the gear's lines explains gets that ``label`` (what
    ``gearspec spectrum`` would call it); ``label`` None means nothing declared explains it.
    """
    out = []
    for e in effects or ():
        for t in e.truth():  # fresh dicts
            if gear is not None and t["frequency"] is not None and t["label"] is None:
                ln = gear.label(t["frequency"], 1e-6 * t["frequency"])
                t["label"] = None if ln is None else ln.label
            out.append(t)
    return out


def effect_channels(effects: Iterable[Effect], t, run=None) -> tuple[dict[str, np.ndarray], set[str]]:
    """Channels the effects supply at experiment times ``t`` of runs ``run``, and the names of
    those that are recorded.  Two effects supplying one channel is refused."""
    chans: dict[str, np.ndarray] = {}
    recorded: set[str] = set()
    for e in effects or ():
        for k, v in e.channels(t, run).items():
            if k in chans:
                raise InputError(f"two effects supply the '{k}' channel; give it once")
            chans[k] = np.asarray(v, dtype=float)
        recorded |= set(e.recorded)
    return chans, recorded


def channel_function(effects: Iterable[Effect], name: str) -> Callable | None:
    """``f(t) -> array`` of one channel the effects supply (run 0), for the ``load`` and
    ``temperature`` arguments of :func:`~gearspec.simulate.model_recording`; None if none does."""
    effects = list(effects or ())
    if not any(name in e.channels(np.zeros(1), np.zeros(1, int)) for e in effects):
        return None

    def f(t):
        return effect_channels(effects, np.asarray(t, dtype=float), np.zeros(np.shape(t), int))[0][name]

    return f


def _convert(text: str, ftype: str):
    """``text`` as a value of a field annotated ``ftype`` (int, bool, tuple, float; else a number or text)."""
    if ftype == "int":
        return int(float(text))
    if ftype == "bool":
        return {"1": True, "true": True, "yes": True, "on": True,
                "0": False, "false": False, "no": False, "off": False}[text.lower()]
    if ftype == "tuple":
        return tuple(float(x) for x in text.replace(";", " ").replace("/", " ").split())
    try:
        return float(text)
    except ValueError:
        if ftype == "float":
            raise
        return text


def parse_effect(text: str) -> Effect:
    """An effect from ``NAME`` or ``NAME:key=value,key=value`` (the CLI's ``--effect``).

    Tuples (``loads``) are written with ``/`` or ``;`` between values: ``loads=0/2/4``.
    """
    name, _, rest = str(text).strip().partition(":")
    name = name.strip().replace("-", "_")
    if name not in EFFECTS:
        raise InputError(f"--effect: unknown effect '{name}' (known: {', '.join(sorted(EFFECTS))})")
    cls = EFFECTS[name]
    ftypes = {f.name: f.type for f in dataclasses.fields(cls)}
    kwargs = {}
    for part in rest.split(","):
        if not part.strip():
            continue
        if "=" not in part:
            raise InputError(f"--effect {name}: '{part}' is not of the form key=value")
        k, v = (s.strip() for s in part.split("=", 1))
        if k not in ftypes:
            raise InputError(f"--effect {name}: no parameter '{k}' (parameters: {', '.join(ftypes)})")
        ft = ftypes[k].split("|")[0].strip()  # the annotation's text (from __future__ import annotations)
        try:
            kwargs[k] = _convert(v, ft)
        except (ValueError, KeyError):
            raise InputError(f"--effect {name}: {k}={v} is not a valid {ft}") from None
    try:
        return cls(**kwargs)
    except TypeError as exc:
        raise InputError(f"--effect {name}: {exc}") from None


def effect_from_dict(d: Mapping) -> Effect:
    """Inverse of :meth:`Effect.to_dict`."""
    d = dict(d)
    name = d.pop("effect", None)
    if name not in EFFECTS:
        raise InputError(f"unknown effect '{name}' (known: {', '.join(sorted(EFFECTS))})")
    cls = EFFECTS[name]
    fields_ = {f.name for f in dataclasses.fields(cls)}
    return cls(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in d.items() if k in fields_})
