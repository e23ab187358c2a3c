"""``python -m paper_repro.emps --out DIR``: the EMPS reproduction (same as ``gearspec repro emps``)."""

import argparse
import time

from . import run


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m paper_repro.emps", description=__doc__)
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--seed", type=int, default=0, help="accepted for the common interface (nothing is random)")
    args = p.parse_args(argv)
    t0 = time.perf_counter()
    report = run(args.out, seed=args.seed, progress=print)
    print(f"report: {report}  ({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
