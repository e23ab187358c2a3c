"""FrictionModel: a friction law with per-direction parameters, position-locked harmonics and
extra terms; evaluated, serialised, printed like the papers' tables, and scored on data.

    tau(theta, v, ...) = sign(v) * [ base_i(|v|, load) + sum_k H_k,i(theta, |v|, load) + magnitude terms ]
                         + signed terms (inertia, offset)

with ``i`` the direction of motion, ``base`` a law of :data:`LAWS`, ``H_k`` a position-locked
sinusoid with a speed-dependent amplitude (SILO4 eqs. 6, 8, 14) and the extra terms of
:mod:`gearspec.terms`.  At ``v = 0`` the model gives only its signed terms.  The JSON form
(``to_dict``, ``gearspec fit --json``) is CONTRACTS.md section 4; a model read back evaluates
identically.  Parameters the data could not identify are ``None`` (never invented), with the
reason in ``not_identified``; evaluating a direction with a missing parameter raises an error
that names it.
"""

from __future__ import annotations

import copy
import json
import math
import operator
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable

import numpy as np
import pandas as pd

from .errors import InputError
from .jsonsafe import finite_or_none, plain
from .terms import BASE_LAWS, TERMS, BaseLaw, evaluate_term
from .terms.lines import PARALLEL_MIN_SAMPLES, CompiledDirection, CompiledFriction, check_threads

__all__ = ["FrictionModel", "Direction", "Harmonic", "LAWS", "Law", "RPM", "DIRECTIONS"]

#: rad/s per rpm
RPM = 2.0 * math.pi / 60.0
DIRECTIONS = ("positive", "negative")


#: a base friction law: its parameters (SI units), magnitude ``f(speed, load, *params)``, linear
#: columns and degraded forms, declared once in the term registry (:mod:`gearspec.terms.registry`)
Law = BaseLaw
#: base laws by name (the registry's own objects); ``silo4`` is eq. 3 plus the harmonics of eq. 11
LAWS: dict[str, Law] = BASE_LAWS

#: the keys every harmonic has
HARMONIC_KEYS = ("frequency", "amplitude", "decay", "phase")
_ABSENT = object()


class _JsonView(Mapping):
    """Read access by JSON key (``p["tau_c"]``, ``p.get("tau_c_se")``, ``h["amplitude"]``) to a typed
    record; the record itself is changed through its attributes, never through the view.  ``_json(convert)``
    is the JSON form (``convert``: with nested records and lists converted, as :meth:`to_dict` gives it)."""

    def __getitem__(self, key):
        return self._json(convert=False)[key]

    def __iter__(self):
        return iter(self._json(convert=False))

    def __len__(self):
        return len(self._json(convert=False))

    def to_dict(self) -> dict:
        return self._json(convert=True)


@dataclass(eq=True)
class Harmonic(_JsonView):
    """A position-locked line of one direction (SILO4 eqs. 6, 8 and 14).

    ``frequency`` in cycles per unit of theta, ``amplitude`` in torque units (None: not measured),
    ``decay`` in s/rad (the amplitude law's parameter), ``phase`` in rad; ``law`` the amplitude law
    (None: exp, the default, not written to JSON), ``load_coefficient`` (eq. 14), ``speed_range``
    ``[min, max]`` of |v| the law was fitted on, ``segments`` the number of segments that measured
    the line; ``se`` the standard error of each parameter that has one; ``extra`` any other key a
    model file carries, kept as read.  An optional field that is None is absent from the JSON.
    """

    frequency: float
    amplitude: float | None
    decay: float = 0.0
    phase: float = 0.0
    label: str | None = None
    law: str | None = None
    load_coefficient: float | None = None
    speed_range: list | None = None
    segments: int | None = None
    se: dict = field(default_factory=dict)
    extra: dict = field(default_factory=dict)

    _OPTIONAL = ("label", "law", "load_coefficient", "speed_range", "segments")

    @classmethod
    def of(cls, h: Mapping) -> "Harmonic":
        """A harmonic from its JSON form (or a copy of another harmonic); InputError when it lacks
        ``frequency`` or ``amplitude`` or its ``speed_range`` is not ``[min, max]``."""
        if isinstance(h, Harmonic):
            return copy.deepcopy(h)
        missing = [k for k in ("frequency", "amplitude") if k not in h]
        if missing:
            raise InputError(f"a harmonic of the model lacks {', '.join(missing)}")
        out = cls(h["frequency"], h["amplitude"], h.get("decay", 0.0), h.get("phase", 0.0))
        for k, val in h.items():
            if k in HARMONIC_KEYS:
                continue
            if k.endswith("_se") and k[:-3] in HARMONIC_KEYS + cls._OPTIONAL:
                out.se[k[:-3]] = val
            elif k in cls._OPTIONAL and val is not None:
                setattr(out, k, _speed_range(val) if k == "speed_range" else copy.deepcopy(val))
            else:
                out.extra[k] = copy.deepcopy(val)
        return out

    @property
    def amplitude_law(self) -> str:
        return self.law or "exp"

    def term(self) -> dict:
        """The harmonic as a ``periodic`` term of :mod:`gearspec.terms` (how it is evaluated)."""
        return {"kind": "periodic", **self.to_dict()}

    def _json(self, convert: bool) -> dict:
        out = {}
        for k in HARMONIC_KEYS + self._OPTIONAL:
            if k in HARMONIC_KEYS or getattr(self, k) is not None:
                out[k] = list(self.speed_range) if k == "speed_range" and convert else getattr(self, k)
            if k in self.se:
                out[k + "_se"] = self.se[k]
        out.update(self.extra)
        return out


@dataclass(eq=True)
class Direction(_JsonView):
    """The parameters of one direction of motion.

    ``values``: every parameter of the base law by name (SI units; None where the data could not
    identify it), ``se``: their standard errors where known, ``harmonics``: the position-locked
    lines (:class:`Harmonic`), ``n_segments`` / ``n_samples``: the data behind the fit and
    ``se_method`` how the errors were computed when not by the covariance (None: not recorded),
    ``extra``: any other key a model file carries, kept as read.
    """

    values: dict
    se: dict = field(default_factory=dict)
    harmonics: list = field(default_factory=list)
    n_segments: int | None = None
    n_samples: int | None = None
    se_method: str | None = None
    extra: dict = field(default_factory=dict)

    _COUNTS = ("n_segments", "n_samples", "se_method")

    @classmethod
    def of(cls, law: "BaseLaw", p: Mapping) -> "Direction":
        """A direction from its JSON form (or a copy of another direction) for ``law``: every
        parameter of the law present (None where absent)."""
        if isinstance(p, Direction):
            out = copy.deepcopy(p)
        else:
            out = cls({})
            for k, val in p.items():
                if k == "harmonics":
                    out.harmonics = [Harmonic.of(h) for h in val]
                elif k.endswith("_se"):
                    out.se[k[:-3]] = val
                elif k in law.params:
                    out.values[k] = val
                elif k in cls._COUNTS and val is not None:
                    setattr(out, k, val)
                else:
                    out.extra[k] = copy.deepcopy(val)
        for k in law.params:
            out.values.setdefault(k, None)
        return out

    def set(self, name: str, value, se=_ABSENT) -> None:
        """Set a parameter (and its standard error, when given)."""
        self.values[name] = value
        if se is not _ABSENT:
            self.se[name] = se

    def _json(self, convert: bool) -> dict:
        out = {}
        for k, val in self.values.items():
            out[k] = val
            if k in self.se:
                out[k + "_se"] = self.se[k]
        out.update({k + "_se": s for k, s in self.se.items() if k not in self.values})
        out.update({k: getattr(self, k) for k in self._COUNTS if getattr(self, k) is not None})
        out.update(self.extra)
        out["harmonics"] = [h.to_dict() for h in self.harmonics] if convert else self.harmonics
        return out


class FrictionModel:
    """A friction model with direction-dependent parameters (scikit-learn-like: a fitted model
    carries what it learned; configuration and data checks happen in :mod:`gearspec.identify`).

    ``law``: base law, a key of :data:`LAWS`.  ``positive``, ``negative``: each direction's
    parameters of the base law (``x`` and optionally ``x_se``) and ``harmonics``, as a
    :class:`Direction` or its JSON form; ``negative`` defaults to a copy of ``positive`` (a
    symmetric model).  ``terms``: extra terms (:mod:`gearspec.terms`).  ``unit`` ("rad" or "m"):
    unit of theta; torques are Nm (N on a linear axis).  ``rmse``, ``rmse_holdout``: in-sample and
    held-out fit errors (torque units); ``rmse_holdout_reason``: why ``rmse_holdout`` is None or
    covers only part of the data (None: computed on every sample).  ``not_identified``:
    ``"direction.parameter" -> reason`` for parameters the data could not identify.
    """

    def __init__(self, law: str, positive: Mapping, negative: Mapping | None = None, *, terms: Iterable = (),
                 unit: str = "rad", rmse: float | None = None, rmse_holdout: float | None = None,
                 not_identified: Mapping | None = None, notes: Iterable[str] = (), name: str | None = None,
                 meta: Mapping | None = None, rmse_holdout_reason: str | None = None):
        if law not in LAWS:
            raise InputError(f"unknown friction law '{law}' (known: {', '.join(LAWS)})")
        if unit not in ("rad", "m"):
            raise InputError(f"unit must be 'rad' or 'm', got '{unit}'")
        self.law = law
        self.directions = {"positive": Direction.of(LAWS[law], positive),
                           "negative": Direction.of(LAWS[law], negative if negative is not None else positive)}
        self.terms = [dict(t) for t in terms]
        for t in self.terms:
            if t.get("kind") not in TERMS:
                raise InputError(f"unknown friction term kind '{t.get('kind')}'")
        self.unit = unit
        self.rmse = rmse
        self.rmse_holdout = rmse_holdout
        self.rmse_holdout_reason = rmse_holdout_reason
        self.not_identified = dict(not_identified or {})
        self.notes = list(notes)
        self.name = name or law
        self.meta = dict(meta or {})

    # ------------------------------------------------------------------ parameters
    @property
    def law_spec(self) -> Law:
        return LAWS[self.law]

    def params(self, direction) -> Direction:
        """Parameters of one direction (``"positive"``/``"negative"`` or +1/-1)."""
        return self.directions[_dir_name(direction)]

    def harmonics(self, direction) -> list[Harmonic]:
        return self.params(direction).harmonics

    @property
    def symmetric(self) -> bool:
        return self.directions["positive"] == self.directions["negative"]

    def copy(self) -> "FrictionModel":
        return FrictionModel.from_dict(self.to_dict())

    def with_terms(self, *terms: dict, name: str | None = None) -> "FrictionModel":
        """A copy with extra terms appended."""
        m = self.copy()
        m.terms += [dict(t) for t in terms]
        if name:
            m.name = name
        m.rmse = m.rmse_holdout = m.rmse_holdout_reason = None
        return m

    # ------------------------------------------------------------------ evaluation
    def evaluate(self, theta=None, v=None, *, load=None, temperature=None, t=None, acc=None, run=None,
                 threads: int | None = None) -> np.ndarray:
        """Torque the drive supplies according to the model, at each sample.

        Friction (base law + harmonics + magnitude terms) has the sign of ``v``; signed terms
        (inertia, offset) are added as they are.  Inputs are arrays of one length (scalars
        broadcast): ``theta`` (rad or m; needed by harmonics), ``v`` (rad/s or m/s), ``load``
        (Nm at the output), ``temperature`` (degC), ``t`` (s), ``acc`` (rad/s^2) and ``run``.

        No extrapolation: a harmonic with a ``speed_range`` ``[min, max]`` is evaluated with ``|v|``
        held within it (below ``min``, e.g. at standstill, and above ``max`` the amplitude is the
        law's value at that edge); a harmonic without one is not clamped.

        Speed: the base law and harmonics of both directions are compiled into parameter arrays
        once and kept until a parameter changes (:meth:`_compiled`); samples are evaluated in
        blocks, each direction on its own samples (``benchmarks/bench_evaluate.py``).

        ``threads``: inputs of at least ``gearspec.terms.lines.PARALLEL_MIN_SAMPLES`` (131072) samples
        have their blocks of base law and lines shared among this many threads; shorter ones (a
        scalar, a simulation's vector of runs) stay in the calling thread.  None: the environment
        variable ``GEARSPEC_THREADS`` when set, else the CPUs the process may use, at most 4; 1: one
        thread.  The values do not depend on it (the same blocks, bit for bit).  Extra terms are
        evaluated on the whole input in the calling thread.
        """
        return self._evaluate(self._compiled(), theta, v, load, temperature, t, acc, run, threads)

    def evaluator(self, threads: int | None = None):
        """:meth:`evaluate` with the parameters as they are now, for a loop that calls it thousands of
        times with the same model (a simulation): ``f(theta, v, load=..., ...)`` computes what
        ``evaluate`` does without checking, at each call, whether a parameter has changed; a change
        made to the model afterwards is not seen by ``f`` (take a new one).  ``threads``: as in
        :meth:`evaluate`, resolved once here (None: the default at this call)."""
        compiled, threads = self._compiled(), check_threads(threads)

        def f(theta=None, v=None, *, load=None, temperature=None, t=None, acc=None, run=None):
            return self._evaluate(compiled, theta, v, load, temperature, t, acc, run, threads)

        return f

    def _evaluate(self, compiled, theta, v, load, temperature, t, acc, run, threads=1) -> np.ndarray:
        if v is None:
            raise InputError("the model needs the velocity v")
        v = np.asarray(v, dtype=float)
        if v.ndim == 0:
            v = v.reshape(1)
        shape = v.shape
        if theta is not None:
            theta = _shaped(np.asarray(theta, dtype=float), shape)
        if load is not None:
            load = _shaped(np.asarray(load, dtype=float), shape)
        elif LAWS[self.law].needs_load:
            raise InputError(f"law {self.law} needs the output load torque ('load' channel), which the data does not have")
        # the default (environment, CPUs) is looked up only for inputs long enough to use it
        threads = check_threads(threads) if threads is not None or v.size >= PARALLEL_MIN_SAMPLES else 1
        if v.ndim == 1:
            out = compiled(theta, v, load, threads)
        else:
            flat = lambda x: None if x is None else x.reshape(-1)  # noqa: E731
            out = compiled(flat(theta), v.reshape(-1), flat(load), threads).reshape(shape)
        if self.terms:
            temperature, t, acc = (None if x is None else _shaped(np.asarray(x, dtype=float), shape)
                                   for x in (temperature, t, acc))
            run = None if run is None else _shaped(np.asarray(run), shape)
            sign = np.sign(v)
            inputs = dict(theta=theta, v=v, load=load, temperature=temperature, t=t, acc=acc, run=run)
            for term in self.terms:
                contrib, signed = evaluate_term(term, **inputs)
                out += contrib if signed else sign * contrib
        return out

    def _compiled(self) -> CompiledFriction:
        """The base law and harmonics of both directions as parameter arrays
        (:class:`~gearspec.terms.lines.CompiledFriction`), kept on the model and rebuilt when a value
        they are made of has changed.  Engines write parameters through ``Direction.set`` but also
        through a harmonic's attributes, ``p.harmonics.append`` or ``model.law``; so the cache is keyed
        on the values themselves (one tuple built and compared, a few microseconds), whoever wrote them."""
        key = self._compiled_key()
        cached = self.__dict__.get("_compiled_cache")
        if cached is not None and cached[0] == key:
            return cached[1]
        law = self.law_spec
        dirs = []
        for name in DIRECTIONS:
            p = self.directions[name]
            missing = [k for k in law.params if p.values.get(k) is None and k not in law.optional]
            error = None if not missing else (
                f"the model has no {name}-direction value for {', '.join(missing)} "
                f"(not identified: {self.not_identified.get(name + '.' + missing[0], 'no data')}); "
                f"it cannot predict motion in that direction")
            lines = [{"frequency": h.frequency, "amplitude": h.amplitude, "decay": h.decay, "phase": h.phase,
                      "law": h.law, "load_coefficient": h.load_coefficient, "speed_range": h.speed_range}
                     for h in p.harmonics if h.amplitude is not None]
            dirs.append(CompiledDirection(law, [p.values.get(k) for k in law.params], lines, error))
        compiled = CompiledFriction(*dirs)
        # kept with copies of the speed-range lists, so that one changed in place no longer compares equal
        snapshot = list(key)
        for i in (3, 5):        # the harmonics of each direction (see _compiled_key)
            snapshot[i] = tuple(h[:6] + (copy.copy(h[6]),) for h in key[i])
        self._compiled_cache = (tuple(snapshot), compiled)
        return compiled

    def _compiled_key(self) -> tuple:
        """Every value :meth:`_compiled` reads: law, not_identified, then per direction the parameter
        values and each harmonic's values (its speed range the list itself)."""
        params = self.law_spec.params
        key = [self.law, tuple(self.not_identified.items())]
        for name in DIRECTIONS:
            p = self.directions[name]
            key.append(tuple(map(p.values.get, params)))
            key.append(tuple(map(_LINE_KEY, p.harmonics)))
        return tuple(key)

    def __getstate__(self) -> dict:
        """Pickled (e.g. sent to a Dask worker) without the compiled cache, rebuilt on first use."""
        state = dict(self.__dict__)
        state.pop("_compiled_cache", None)
        return state

    def friction(self, theta=None, v=None, **inputs) -> np.ndarray:
        """Friction alone: :meth:`evaluate` without the signed terms (inertia, offset)."""
        if not any(TERMS[t["kind"]].signed for t in self.terms):
            return self.evaluate(theta, v, **inputs)
        m = self.copy()
        m.terms = [t for t in m.terms if not TERMS[t["kind"]].signed]
        return m.evaluate(theta, v, **inputs)

    def mean_level(self, speed, direction, load=None) -> np.ndarray:
        """Friction magnitude averaged over position (the base law and magnitude terms that do
        not depend on position): what a plateau average measures, for Stribeck-curve plots."""
        d = 1.0 if _dir_name(direction) == "positive" else -1.0
        s = np.atleast_1d(np.asarray(speed, dtype=float))
        m = self.copy()
        for p in m.directions.values():
            p.harmonics = []
        m.terms = [t for t in m.terms if t["kind"] not in ("periodic", "hysteresis") and not TERMS[t["kind"]].signed
                   and not set(TERMS[t["kind"]].needs) - {"load"}]
        return np.abs(m.evaluate(None, d * s, load=load))

    # ------------------------------------------------------------------ scoring
    def residual(self, data) -> np.ndarray:
        """``data.y - prediction`` on a :class:`~gearspec.fitdata.FitData` (torque units)."""
        return data.y - self.evaluate(**data.inputs())

    def rmse_on(self, data) -> float:
        r = self.residual(data)
        return float(np.sqrt(np.mean(r * r))) if len(r) else float("nan")

    # ------------------------------------------------------------------ serialisation
    def to_dict(self) -> dict:
        """The ``gearspec fit --json`` form (CONTRACTS.md section 4), JSON-ready; an identified
        inertia (one ``inertia`` term for both directions, with its ``inertia_se``) also as
        ``inertia``, ``inertia_se``."""
        d = {"law": self.law, "name": self.name, "unit": self.unit,
             "directions": {d: p.to_dict() for d, p in self.directions.items()}, "terms": self.terms,
             "rmse": self.rmse, "rmse_holdout": self.rmse_holdout, "rmse_holdout_reason": self.rmse_holdout_reason,
             "not_identified": self.not_identified, "notes": self.notes, "meta": self.meta}
        inertia = [t for t in self.terms if t.get("kind") == "inertia" and not t.get("direction") and "inertia_se" in t]
        if len(inertia) == 1:
            d["inertia"], d["inertia_se"] = inertia[0]["inertia"], inertia[0].get("inertia_se")
        return plain(d)

    @classmethod
    def from_dict(cls, d: Mapping) -> "FrictionModel":
        if "law" not in d or "directions" not in d:
            raise InputError("a friction model needs 'law' and 'directions' (the gearspec fit --json form)")
        dirs = d["directions"]
        return cls(d["law"], dirs["positive"], dirs.get("negative"), terms=d.get("terms", ()), unit=d.get("unit", "rad"),
                   rmse=d.get("rmse"), rmse_holdout=d.get("rmse_holdout"), not_identified=d.get("not_identified"),
                   notes=d.get("notes", ()), name=d.get("name"), meta=d.get("meta"),
                   rmse_holdout_reason=d.get("rmse_holdout_reason"))

    def to_json(self, path: str | Path) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(self.to_dict(), indent=1))
        return path

    @classmethod
    def from_json(cls, path: str | Path) -> "FrictionModel":
        path = Path(path)
        try:
            d = json.loads(path.read_text())
        except (OSError, json.JSONDecodeError) as exc:
            raise InputError(f"{path}: not a friction model JSON file ({exc})") from exc
        return cls.from_dict(d)

    # ------------------------------------------------------------------ tables
    def table(self) -> pd.DataFrame:
        """One row per parameter: SI value and standard error per direction, and on a rotary axis
        the papers' units beside (mNm, rpm, mNm/rpm, 1/rpm)."""
        law = self.law_spec
        rows = [_row(k, u, self.directions, lambda p, k=k: (p.get(k), p.get(k + "_se")), self.unit)
                for k, u in zip(law.params, law.units)]
        nh = max(len(p.harmonics) for p in self.directions.values())
        for i in range(nh):
            hs = {d: (p.harmonics[i] if i < len(p.harmonics) else {}) for d, p in self.directions.items()}
            lab = next((h.get("label") for h in hs.values() if h.get("label")), None) or f"harmonic {i + 1}"
            f = next((h.get("frequency") for h in hs.values() if h.get("frequency") is not None), float("nan"))
            for key, u in (("amplitude", "Nm"), ("decay", "s/rad"), ("phase", "rad")):
                r = _row(f"{lab} {key}", u, hs, lambda h, key=key: (h.get(key), h.get(key + "_se")), self.unit)
                if key == "phase":
                    r["unit"] = "rad"      # an angle of sin(2 pi f x + phi) on any axis, not a length
                rows.append({**r, "frequency": f})
            # the speeds the amplitude law was fitted on (held at the edges outside)
            if any(h.get("speed_range") for h in hs.values()):
                for j, key in ((0, "min"), (1, "max")):
                    r = _row(f"{lab} law fitted |v| {key}", "rad/s", hs,
                             lambda h, j=j: ((h.get("speed_range") or (None, None))[j], None), self.unit)
                    rows.append({**r, "frequency": f})
        rows += [{"parameter": TERMS[t["kind"]].describe(t), "unit": "", "positive": None, "negative": None}
                 for t in self.terms]
        return pd.DataFrame(rows)

    def __repr__(self) -> str:
        return f"FrictionModel(law={self.law!r}, name={self.name!r}, terms={len(self.terms)})"

    def __str__(self) -> str:
        return self.describe()

    def describe(self) -> str:
        """A plain-text table of the parameters."""
        df = self.table()
        lines = [f"{self.name} (law {self.law}: {self.law_spec.description})"]
        cols = [c for c in ("parameter", "unit", "positive", "positive_se", "negative", "negative_se",
                            "paper_unit", "positive_paper", "negative_paper") if c in df]
        lines.append(df[cols].to_string(index=False, float_format=lambda x: f"{x:.5g}"))
        if self.rmse is not None or self.rmse_holdout is not None:
            lines.append(f"rmse {_fmt(self.rmse)}, held-out rmse {_fmt(self.rmse_holdout)} "
                         f"({'Nm' if self.unit == 'rad' else 'N'})")
        if self.rmse_holdout_reason:
            lines.append(f"held-out rmse {'not computed' if self.rmse_holdout is None else 'partial'}: "
                         f"{self.rmse_holdout_reason}")
        lines += [n for n in self.notes if n.startswith("warning:")]
        su = "rad/s" if self.unit == "rad" else "m/s"
        for dname, p in self.directions.items():
            for h in p.harmonics:
                r = h.get("speed_range")
                lab = h.get("label") or f"line at {h['frequency']:.6g} cycles/{self.unit}"
                if r is not None:
                    lines.append(f"{lab} ({dname}): {h.get('law', 'exp')} amplitude law fitted on |v| "
                                 f"{r[0]:.4g}..{r[1]:.4g} {su}; held at the edge outside")
                elif h.get("amplitude") is not None and h.get("law", "exp") != "const":
                    lines.append(f"{lab} ({dname}): no speed range recorded; the amplitude law is "
                                 f"evaluated at every speed")
        lines += [f"not identified: {k}: {why}" for k, why in self.not_identified.items()]
        return "\n".join(lines)


    # ------------------------------------------------------------------ export
    def export(self, format: str, out, **options):
        """Write the model for a controller: ``format`` ``"c"``, ``"yaml"``, ``"table"`` or ``"json"``
        into the folder ``out`` (:func:`gearspec.export.export`; options there); returns the paths."""
        from .export import export

        return export(self, format, out, **options)

#: what a harmonic contributes to the key of a model's compiled evaluation
_LINE_KEY = operator.attrgetter("frequency", "amplitude", "decay", "phase", "law", "load_coefficient", "speed_range")


def _shaped(x: np.ndarray, shape: tuple) -> np.ndarray:
    """``x`` broadcast to ``shape`` (itself when it has that shape)."""
    return x if x.shape == shape else np.broadcast_to(x, shape)


def _speed_range(r) -> list:
    """``[min, max]`` of a harmonic's speed range, checked (InputError otherwise)."""
    try:
        lo, hi = (float(x) for x in r)
    except (TypeError, ValueError) as exc:
        raise InputError(f"a harmonic's speed_range must be [min, max] of |v|, got {r!r}") from exc
    if not (math.isfinite(lo) and math.isfinite(hi) and 0 <= lo <= hi):
        raise InputError(f"a harmonic's speed_range must be [min, max] with 0 <= min <= max, got {r!r}")
    return [lo, hi]


def _fmt(x):
    return "n/a" if x is None else f"{x:.4g}"


def _dir_name(direction) -> str:
    for name, aliases in (("positive", (1, "+", "+1")), ("negative", (-1, "-", "-1"))):
        if direction == name or direction in aliases:
            return name
    raise InputError(f"direction must be 'positive'/'negative' or +1/-1, got {direction!r}")


# conversion of SI units to the SILO4 paper's (mNm, rpm at the motor)
_PAPER = {"Nm": ("mNm", 1e3), "rad/s": ("rpm", 1 / RPM), "Nm s/rad": ("mNm/rpm", 1e3 * RPM),
          "s/rad": ("1/rpm", RPM), "rad": ("rad", 1.0), "-": ("-", 1.0)}


def _row(name, unit, directions, get, axis_unit) -> dict:
    r = {"parameter": name, "unit": unit if axis_unit == "rad" else unit.replace("Nm", "N").replace("rad", "m")}
    conv = _PAPER.get(unit) if axis_unit == "rad" else None
    if conv:
        r["paper_unit"] = conv[0]
    for d, p in directions.items():
        val, se = get(p)
        r[d] = finite_or_none(val)
        r[d + "_se"] = finite_or_none(se)
        if conv:
            r[d + "_paper"] = None if val is None else float(val) * conv[1]
    return r
