"""``gearspec export``: a fitted model for a controller (C99, YAML parameters, lookup tables, JSON)."""

from __future__ import annotations

import argparse

from ..errors import InputError
from . import COMMAND_HELP, number

_EXAMPLES = """examples:
  gearspec export model.json --format c --out ctrl/ --smooth-velocity 0.02
      writes ctrl/gearspec_model.h and .c; build with: cc -std=c99 -O2 -c ctrl/gearspec_model.c
  gearspec export model.json --format table --out lut/ --entries 3600
      writes lut/friction_grid.csv and lut/cogging_table.csv (interpolation error printed)
"""

#: options that belong to some formats only (refused with the others rather than ignored)
_FOR = {"smooth_velocity": ("c",), "joint": ("yaml",), "entries": ("table",), "speed": ("table",),
        "positions": ("table",), "speeds": ("table",), "load": ("table",), "temperature": ("table",),
        "period": ("table",)}


def _triple(text: str):
    parts = text.split(",")
    try:
        if len(parts) != 3:
            raise ValueError
        return float(parts[0]), float(parts[1]), int(parts[2])
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not START,STOP,N (two numbers and an integer)") from None


def register(sub) -> None:
    p = sub.add_parser("export", help=COMMAND_HELP["export"],
                       description="Export a friction model (gearspec fit --json or diagnose --json) for a "
                                   "controller. Refuses (exit 2) files of another gearspec version, keys it does "
                                   "not know and terms that need state (hysteresis, backlash, drift).",
                       epilog=_EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("model", metavar="MODEL.json", help="model file (gearspec fit --json or gearspec diagnose --json)")
    p.add_argument("--format", required=True, choices=("c", "yaml", "table", "json"),
                   help="c: gearspec_model.h/.c; yaml: friction_params.yaml; table: friction_grid.csv and "
                        "cogging_table.csv; json: friction_model.json (normalised, this version)")
    p.add_argument("--out", required=True, metavar="DIR", help="folder to write into")
    p.add_argument("--smooth-velocity", type=number(0), metavar="V",
                   help="c: default of GEARSPEC_SMOOTH_VELOCITY (rad/s or m/s): below it sign(v) becomes v/V "
                        "(default 0: the exact sign)")
    p.add_argument("--joint", metavar="NAME", help="yaml: the joint's name (default joint)")
    p.add_argument("--entries", type=number(2, integer=True), metavar="N",
                   help="table: entries of the one-revolution table (default 3600)")
    p.add_argument("--speed", type=number(0), metavar="V",
                   help="table: |v| of the one-revolution table (default 0: each line at the slow edge of its "
                        "speed range)")
    p.add_argument("--positions", type=_triple, metavar="START,STOP,N", help="table: grid rows (default one "
                   "revolution, 360 rows)")
    p.add_argument("--speeds", type=_triple, metavar="START,STOP,N", help="table: grid columns, velocities (default "
                   "+-the fastest speed a line was fitted on, 41 columns)")
    p.add_argument("--load", type=number(), metavar="NM", help="table: output load (default 0 when the model uses it)")
    p.add_argument("--temperature", type=number(), metavar="DEGC",
                   help="table: temperature (default the temperature term's reference)")
    p.add_argument("--period", type=number(0, low_open=True), metavar="P",
                   help="table: one revolution in units of theta (default 2 pi rad; needed on a linear axis)")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..export import export

    options = {}
    for key, formats in _FOR.items():
        value = getattr(args, key)
        if value is None:
            continue
        if args.format not in formats:
            raise InputError(f"--{key.replace('_', '-')} applies to --format {' or '.join(formats)}, "
                             f"not {args.format}")
        options[key] = int(value) if key == "entries" else value
    written = export(args.model, args.format, args.out, **options)
    for path in written:
        print(f"wrote {path}")
    for note in written.notes:
        print(note)
    return 0
