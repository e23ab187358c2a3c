"""``gearspec demo``: the main analysis on built-in data (what ``make demo`` runs): the SILO4
reproduction in a small configuration (:mod:`paper_repro.demo`)."""

from __future__ import annotations

from . import COMMAND_HELP, print_html
from .repro import reproductions


def register(sub) -> None:
    dm = sub.add_parser("demo", help=COMMAND_HELP["demo"])
    dm.add_argument("--out", default="demo-out", help="output folder (default demo-out)")
    dm.set_defaults(func=run)


def run(args) -> int:
    reproductions("demo")
    from paper_repro.demo import run_demo

    report = run_demo(args.out)
    print(f"demo report: {report}")
    print_html(report)
    return 0
