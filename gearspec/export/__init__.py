"""A fitted friction model for a controller: C99 code, a per-joint parameter file (YAML), lookup
tables (CSV) or the model's own JSON (``gearspec export``, :meth:`FrictionModel.export`).

One function, :func:`export`, in front of one module per format (``c``, ``params`` for YAML, ``table``);
what every format accepts is checked once (:mod:`.check`): a file it accepts is computed as
:meth:`FrictionModel.evaluate` computes it, never silently less.
"""

from __future__ import annotations

import json
from pathlib import Path

from .. import __version__
from ..errors import InputError
from ..model import FrictionModel
from .check import check_exportable, read_model

__all__ = ["export", "FORMATS", "Written", "read_model", "check_exportable"]


class Written(list):
    """The paths written (a list of :class:`~pathlib.Path`), with ``notes``: what the files leave out or
    state (e.g. a table's interpolation error), one sentence each."""

    def __init__(self, paths=(), notes=()):
        super().__init__(paths)
        self.notes = list(notes)


def _write_json(model: FrictionModel, out: Path, **_) -> list[Path]:
    """``out/<name>.json``: the model's JSON, read back and written by this gearspec (its version in
    ``meta.gearspec_version``)."""
    d = model.to_dict()
    d["meta"] = {**d.get("meta", {}), "gearspec_version": __version__}
    out.mkdir(parents=True, exist_ok=True)
    path = out / "friction_model.json"
    path.write_text(json.dumps(d, indent=1))
    return [path]


def _notes(model: FrictionModel, raw: dict, name: str) -> list[str]:
    """What the files leave out or extrapolate, one sentence each."""
    out = [f"{name}: '{k}' = {raw[k]:.6g} ({'kg m^2' if k == 'inertia' else 's'}), found beside the model by the "
           f"fit, is not part of the friction model and is not exported"
           for k in ("inertia", "lag") if isinstance(raw.get(k), (int, float))]
    for dname, p in model.directions.items():
        for i, h in enumerate(p.harmonics):
            if h.amplitude is not None and h.speed_range is None and h.amplitude_law != "const":
                out.append(f"{dname} line {h.label or i + 1}: no speed range recorded, so its {h.amplitude_law} "
                           f"amplitude law is evaluated at every speed, as FrictionModel.evaluate does")
    return out


def _formats():
    from .c import write_c
    from .params import write_yaml
    from .table import write_tables

    return {"c": write_c, "yaml": write_yaml, "table": write_tables, "json": _write_json}


#: the formats, each ``writer(model, out, *, source, **options) -> list[Path]``
FORMATS = ("c", "yaml", "table", "json")


def export(model, format: str, out, **options) -> Written:
    """Write ``model`` in ``format`` into the folder ``out``.

    Parameters
    ----------
    model : a :class:`~gearspec.model.FrictionModel`, a model file's path (the ``gearspec fit --json``
        or ``gearspec diagnose --json`` form), or its JSON as a dict.
    format : ``"c"`` (``gearspec_model.h``/``.c``), ``"yaml"`` (``friction_params.yaml``), ``"table"``
        (``friction_grid.csv``, ``cogging_table.csv``) or ``"json"`` (``friction_model.json``).
    out : folder, created when missing.
    **options : of the format: ``smooth_velocity`` (c; rad/s or m/s), ``joint`` (yaml), ``entries``,
        ``speed``, ``positions``, ``speeds``, ``load``, ``temperature``, ``period`` (table).

    Returns
    -------
    :class:`Written`: the paths written, with ``notes``.

    Raises
    ------
    InputError
        A format gearspec does not know; a model file of another gearspec version or with a key this
        one does not know; a term the format cannot express without state (hysteresis, backlash,
        drift); a direction or parameter not identified.
    """
    if format not in FORMATS:
        raise InputError(f"unknown export format '{format}' (known: {', '.join(FORMATS)})")
    source = options.pop("source", None)
    raw: dict = {}
    if not isinstance(model, FrictionModel):
        if source is None and isinstance(model, (str, Path)):
            source = Path(model).name
        model, raw = read_model(model, source or "the model")
    name = source or f"model '{model.name}'"
    check_exportable(model, name, stateless=format != "json")
    notes = _notes(model, raw, name)
    try:
        paths = _formats()[format](model, Path(out), source=name, notes=notes, **options)
    except InputError as exc:   # a refusal of the writer (a line or term it cannot express): say which file
        text = str(exc)
        raise InputError(text if text.startswith(name) else f"{name}: {text}") from None
    return Written(paths, notes)
