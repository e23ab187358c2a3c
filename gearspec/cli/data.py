"""``gearspec data``: the registry of real data sets."""

from __future__ import annotations

from . import COMMAND_HELP


def register(sub) -> None:
    dp = sub.add_parser("data", help=COMMAND_HELP["data"])
    dp.add_argument("action", choices=("list", "describe", "fetch"))
    dp.add_argument("name", nargs="?")
    dp.set_defaults(func=run, check=_check)


def _check(parser, args) -> None:
    if args.action in ("describe", "fetch") and not args.name:
        parser.error(f"gearspec data {args.action} needs a data set name (see `gearspec data list`)")


def run(args) -> int:
    from .. import datasets

    if args.action == "list":
        table = datasets.list_datasets()
        print(table.to_string(index=False))
        if not table["present"].any():
            print("\nNo data set found; searched: " + ", ".join(f"{p} ({w})" for p, w in datasets.search_path())
                  + f". Set {datasets.ENV_VAR} to the folder holding emps/, kinova_gen3_joint7/, ..., or run "
                  "`gearspec data fetch NAME` to download one (the only command that uses the network).")
    elif args.action == "describe":
        print(datasets.describe(args.name))
    elif args.action == "fetch":
        for p in datasets.fetch(args.name, download=True).values():
            print(p)
    return 0
