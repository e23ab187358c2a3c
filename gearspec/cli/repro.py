"""``gearspec repro NAME --out DIR``: a paper's figures and tables (paper_repro/: scripts over the
public API beside the library, not in it, imported only here and by ``gearspec demo``)."""

from __future__ import annotations

import time

from ..errors import InputError
from . import COMMAND_HELP, print_html


def register(sub) -> None:
    p = sub.add_parser("repro", help=COMMAND_HELP["repro"],
                       description="Reproduce the figures and tables of a paper or benchmark with the public API: "
                                   "writes DIR/report.md, the figures as PNG and each table as CSV with the columns "
                                   "quantity, paper, gearspec, rel_diff.")
    p.add_argument("name", metavar="NAME", help="silo4 | lola | emps")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--seed", type=int, default=0, help="seed of the twins' noise (default 0)")
    p.set_defaults(func=run)


def reproductions(command: str):
    """The ``paper_repro`` package, or an :class:`InputError` naming ``command`` when it is not
    installed (a wheel of the library alone)."""
    try:
        import paper_repro
    except ModuleNotFoundError as exc:
        if exc.name != "paper_repro":
            raise
        raise InputError(f"gearspec {command} needs the paper reproductions (the paper_repro folder of gearspec's "
                         "source), which are not installed; install gearspec from its source folder "
                         "(pip install -e .)") from None
    return paper_repro


def run(args) -> int:
    paper_repro = reproductions("repro")
    if args.name not in paper_repro.available():
        raise InputError(f"no reproduction '{args.name}' (available: {', '.join(paper_repro.available())})")
    t0 = time.perf_counter()
    report = paper_repro.run(args.name, args.out, seed=args.seed)
    print(f"report: {report}  ({time.perf_counter() - t0:.0f} s)")
    print_html(report)
    return 0
