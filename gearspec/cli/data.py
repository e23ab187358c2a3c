"""``gearspec data``: the registry of real data sets."""

from __future__ import annotations


def register(sub) -> None:
    dp = sub.add_parser("data", help="the registry of real data sets")
    dp.add_argument("action", choices=("list", "describe", "fetch"))
    dp.add_argument("name", nargs="?")
    dp.set_defaults(func=run, check=_check)


def _check(parser, args) -> None:
    if args.action in ("describe", "fetch") and not args.name:
        parser.error(f"gearspec data {args.action} needs a data set name (see `gearspec data list`)")


def run(args) -> int:
    from .. import datasets

    if args.action == "list":
        print(datasets.list_datasets().to_string(index=False))
    elif args.action == "describe":
        print(datasets.describe(args.name))
    elif args.action == "fetch":
        for p in datasets.fetch(args.name, download=True).values():
            print(p)
    return 0
