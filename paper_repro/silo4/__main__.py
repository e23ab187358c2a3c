"""``python -m paper_repro.silo4 --out DIR [--seed N]``: the SILO4 reproduction (same as
``gearspec repro silo4``)."""

import argparse
import time

from . import run


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m paper_repro.silo4", description=__doc__)
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--seed", type=int, default=0, help="seed of the twins' noise (default 0)")
    p.add_argument("--repetitions", type=int, default=10, help="runs per speed and direction (default 10)")
    args = p.parse_args(argv)
    t0 = time.perf_counter()
    report = run(args.out, seed=args.seed, repetitions=args.repetitions)
    print(f"report: {report}  ({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
