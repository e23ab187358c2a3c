"""What the exporters accept: a model file of this gearspec's JSON form, every key known, every number
finite, both directions identified, and only terms a controller can evaluate without state.

A refusal is one sentence (:class:`~gearspec.errors.InputError`); an exporter never drops a key or a
term silently, so a file it accepts is computed in C (YAML, tables) exactly as
:meth:`FrictionModel.evaluate` computes it.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping
from pathlib import Path

from .. import __version__
from ..errors import InputError
from ..model import HARMONIC_KEYS, FrictionModel
from ..terms import TERMS

__all__ = ["read_model", "check_exportable", "STATEFUL", "MIN_VERSION", "model_version", "TOP_KEYS"]

#: the oldest model files read: 0.4.0 added ``speed_range`` to every line (no extrapolation of an
#: amplitude law) and ``rmse_holdout_reason``, which every model file written since carries
MIN_VERSION = (0, 4, 0)
#: keys of the model's JSON form (``FrictionModel.to_dict``)
TOP_KEYS = ("law", "name", "unit", "directions", "terms", "rmse", "rmse_holdout", "rmse_holdout_reason",
            "not_identified", "notes", "meta")
#: keys ``gearspec fit --json`` writes beside the model: results about the fit, not parts of the friction
FIT_KEYS = ("comparison", "models", "inertia", "inertia_se", "lag", "lag_se")
#: term kinds whose value depends on the history of the motion, not on the present inputs
STATEFUL = {
    "hysteresis": "it needs the travel since the last reversal, a state the exported function does not keep",
    "backlash": "it needs the travel since the last reversal, a state the exported function does not keep",
    "drift": "it needs the time since the model's reference instant, which a controller does not have",
}
#: keys of a harmonic and of a term that only describe it (never change what it computes)
DESCRIPTIVE = ("label", "segments", "evidence", "order", "fap", "source")
_HARMONIC = set(HARMONIC_KEYS) | {"law", "load_coefficient", "speed_range"} | set(DESCRIPTIVE)


def model_version(d: Mapping) -> tuple | None:
    """The gearspec version that wrote a model file, from ``meta.gearspec_version`` (written by
    ``gearspec export --format json``); None when the file does not say."""
    text = (d.get("meta") or {}).get("gearspec_version") if isinstance(d.get("meta"), Mapping) else None
    if text is None:
        return None
    m = re.match(r"^(\d+)\.(\d+)\.(\d+)", str(text))
    if not m:
        raise InputError(f"the model's meta.gearspec_version '{text}' is not a version number such as 0.4.3")
    return tuple(int(x) for x in m.groups())


def _version_tuple(text: str) -> tuple:
    return tuple(int(x) for x in re.findall(r"\d+", text)[:3])


def read_model(source, name: str = "the model") -> tuple[FrictionModel, dict]:
    """A model file (a path, or its JSON as a dict) checked for export: ``(model, raw dict)``.

    Accepts the ``gearspec fit --json`` form and a ``gearspec diagnose --json`` file (its
    ``final.friction_model``).  Refused with one sentence: a file that is not JSON or not a model, one
    written before gearspec 0.4.0 (no ``rmse_holdout_reason`` key: its lines carry no speed range) or
    by a newer gearspec than this one, and one with a key this gearspec does not know.
    """
    if isinstance(source, (str, Path)):
        path = Path(source)
        name = path.name
        try:
            d = json.loads(path.read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise InputError(f"{path}: not a friction model JSON file ({exc})") from None
    else:
        d = source
    if isinstance(d, Mapping) and "final" in d and isinstance(d["final"], Mapping) and "friction_model" in d["final"]:
        d = d["final"]["friction_model"]      # a gearspec diagnose --json file: its final model
    if not isinstance(d, Mapping) or "law" not in d or "directions" not in d:
        raise InputError(f"{name}: not a friction model (a model file has 'law' and 'directions', "
                         f"as gearspec fit --json writes it)")
    version = model_version(d)
    if version is not None and version > _version_tuple(__version__):
        raise InputError(f"{name}: written by gearspec {'.'.join(map(str, version))}, newer than this gearspec "
                         f"{__version__}; export it with that version")
    if (version is not None and version < MIN_VERSION) or (version is None and "rmse_holdout_reason" not in d):
        raise InputError(f"{name}: written by a gearspec older than 0.4.0 (it lacks 'rmse_holdout_reason', which "
                         f"every model file since carries), whose lines have no speed range; refit the recording "
                         f"with this gearspec before exporting")
    unknown = [k for k in d if k not in TOP_KEYS + FIT_KEYS]
    if unknown:
        raise InputError(f"{name}: unknown key '{unknown[0]}' at the top level; this gearspec would ignore it, "
                         f"so the export could compute something else than the file means")
    _check_shape(d, name)
    try:
        return FrictionModel.from_dict(d), dict(d)
    except InputError as exc:       # the model's own sentence, with the file it is about
        raise InputError(f"{name}: {exc}") from None


def _check_shape(d: Mapping, name: str) -> None:
    """Refuse (one sentence naming the file and the key) a model whose directions, lines or terms are
    not the JSON objects and lists a model file holds, before they are read."""
    dirs = d["directions"]
    if not isinstance(dirs, Mapping) or not dirs or not all(isinstance(p, Mapping) for p in dirs.values()):
        raise InputError(f"{name}: 'directions' must be an object of directions ('positive', 'negative'), each an "
                         f"object of parameters")
    for dname, p in dirs.items():
        lines = p.get("harmonics", [])
        if not isinstance(lines, list) or not all(isinstance(h, Mapping) for h in lines):
            raise InputError(f"{name}: the {dname} direction's 'harmonics' must be a list of objects (one per line)")
    terms = d.get("terms", [])
    if not isinstance(terms, list) or not all(isinstance(t, Mapping) for t in terms):
        raise InputError(f"{name}: 'terms' must be a list of objects (one per term, each with its 'kind')")


def check_exportable(model: FrictionModel, name: str = "the model", *, stateless: bool = True) -> None:
    """Refuse (InputError, one sentence) what an exporter cannot express: an unknown key in a
    direction, a line or a term (it would be ignored), a parameter that is not a finite number, a
    direction with a parameter not identified, and with ``stateless`` a term of :data:`STATEFUL`."""
    law = model.law_spec
    for dname, p in model.directions.items():
        if p.extra:
            raise InputError(f"{name}: unknown key '{next(iter(p.extra))}' in the {dname} direction; this gearspec "
                             f"would ignore it, so the export could compute something else than the file means")
        missing = [k for k in law.params if p.values[k] is None and k not in law.optional]
        if missing:
            raise InputError(f"{name}: the {dname} direction has no value for {', '.join(missing)} (not identified), "
                             f"so no friction can be exported for that direction; refit with data moving that way")
        for k, val in p.values.items():
            _finite(val, f"{name}: {dname} {k}", allow_none=True)
        for i, h in enumerate(p.harmonics):
            where = f"{name}: {dname} line {h.label or i + 1}"
            bad = [k for k in h.extra if k not in _HARMONIC]
            if bad:
                raise InputError(f"{where}: unknown key '{bad[0]}'; this gearspec would ignore it, so the export "
                                 f"could compute something else than the file means")
            if h.amplitude is None:
                continue
            for k in ("frequency", "amplitude", "decay", "phase", "load_coefficient"):
                _finite(getattr(h, k), f"{where} {k}", allow_none=k == "load_coefficient")
    for i, t in enumerate(model.terms):
        kind = t.get("kind")
        where = f"{name}: term {i + 1} ({kind})"
        if stateless and kind in STATEFUL:
            raise InputError(f"{where}: cannot be exported: {STATEFUL[kind]}")
        tk = TERMS[kind]
        allowed = {"kind", "direction", *tk.params, *DESCRIPTIVE}
        allowed |= {"law", "speed_range"} if kind == "periodic" else set()
        bad = [k for k in t if k not in allowed and not (k.endswith("_se") and k[:-3] in allowed)]
        if bad:
            raise InputError(f"{where}: unknown key '{bad[0]}'; this gearspec would ignore it, so the export "
                             f"could compute something else than the file means")
        if t.get("direction", 0) not in (0, 1, -1, None):
            raise InputError(f"{where}: direction must be 1, -1 or absent, got {t.get('direction')!r}")
        for k in tk.params:
            if k in t and k != "shape":
                _finite(t[k], f"{where} {k}", allow_none=False)


def _finite(x, what: str, allow_none: bool) -> None:
    if x is None and allow_none:
        return
    if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(float(x)):
        raise InputError(f"{what} is {x!r}, not a finite number; the export needs every parameter as a number")
