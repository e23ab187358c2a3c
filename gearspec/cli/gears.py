"""``gearspec gears``: list the gear presets or describe a gear spec."""

from __future__ import annotations

from . import COMMAND_HELP


def register(sub) -> None:
    gp = sub.add_parser("gears", help=COMMAND_HELP["gears"])
    gp.add_argument("name", nargs="?", help="preset name or TOML file")
    gp.set_defaults(func=run)


def run(args) -> int:
    from ..gears import load_gear, presets

    if args.name:
        print(load_gear(args.name).describe())
        return 0
    for name, g in presets().items():
        print(f"{name:<22} {g.name}")
    print("\n`gearspec gears NAME` describes one (or give a TOML file path).")
    return 0
