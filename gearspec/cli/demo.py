"""``gearspec demo``: the main analysis on built-in data (what ``make demo`` runs)."""

from __future__ import annotations


def register(sub) -> None:
    dm = sub.add_parser("demo", help="run the main analysis on built-in data and write a report")
    dm.add_argument("--out", default="demo-out", help="output folder (default demo-out)")
    dm.set_defaults(func=run)


def run(args) -> int:
    from ..demo import run_demo

    report = run_demo(args.out)
    print(f"demo report: {report}")
    return 0
