"""``gearspec repro NAME --out DIR``: reproduce a paper's figures and tables (paper_repro/)."""

from __future__ import annotations

import time


def register(sub) -> None:
    p = sub.add_parser("repro", help="reproduce a paper's figures and tables (silo4, lola, emps)",
                       description="Reproduce the figures and tables of a paper or benchmark with the public API: "
                                   "writes DIR/report.md, the figures as PNG and each table as CSV with the columns "
                                   "quantity, paper, gearspec, rel_diff.")
    p.add_argument("name", metavar="NAME", help="silo4 | lola | emps")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--seed", type=int, default=0, help="seed of the twins' noise (default 0)")
    p.set_defaults(func=run)


def run(args) -> int:
    import paper_repro

    from ..errors import InputError

    if args.name not in paper_repro.available():
        raise InputError(f"no reproduction '{args.name}' (available: {', '.join(paper_repro.available())})")
    t0 = time.perf_counter()
    report = paper_repro.run(args.name, args.out, seed=args.seed)
    print(f"report: {report}  ({time.perf_counter() - t0:.0f} s)")
    return 0
