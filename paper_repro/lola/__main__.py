"""``python -m paper_repro.lola --out DIR [--seed N]``: the Lola/CROPS testbed reproduction (same as
``gearspec repro lola``)."""

import argparse
import time

from . import run


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m paper_repro.lola", description=__doc__)
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--seed", type=int, default=0, help="seed of the twins' noise (default 0)")
    p.add_argument("--modules", default="A,B,C", help="drive modules (default A,B,C)")
    args = p.parse_args(argv)
    t0 = time.perf_counter()
    report = run(args.out, seed=args.seed, modules=tuple(m.strip().upper() for m in args.modules.split(",")))
    print(f"report: {report}  ({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
