"""``gearspec compensate``: does the model help as a feed-forward?  A twin's speed loop run without,
with a Coulomb + viscous and with the model's exported C as friction compensation; the report, the
figures (ripple against speed; a time trace) and the JSON.

This module parses and calls: the analysis is :func:`gearspec.export.compensate.compensate`, the
report :mod:`gearspec.report.compensate`, the figures :mod:`gearspec.plots.compensate`.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from ..errors import InputError
from . import COMMAND_HELP, command_line, number, print_html

_EXAMPLES = """examples:
  gearspec fit twin/silo4_twin.csv --gear twin/silo4_twin_gear.toml --law silo4 --json model.json --quiet
  gearspec compensate model.json --twin silo4 --speeds-rpm 50,100,280,560,1000,3000 --out comp/
      velocity ripple and tracking error per speed and direction: none / Coulomb+viscous / the model (via its C)
"""


def _speeds(text: str) -> list[float]:
    try:
        out = [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a list of speeds in rpm such as 100,280,560") from None
    if not out or any(not (s > 0 and s < float("inf")) for s in out):
        raise argparse.ArgumentTypeError(f"'{text}': give positive motor speeds in rpm (each runs in both directions)")
    return out


def register(sub) -> None:
    p = sub.add_parser("compensate", help=COMMAND_HELP["compensate"],
                       description="Run the speed plateaus of a twin (the SILO4 joint 3 or a direct drive with "
                                   "cogging) three times: no compensation, a Coulomb + viscous feed-forward from "
                                   "the model's own tau_c and viscous, and the model itself as feed-forward through "
                                   "its exported C (compiled with cc, called with ctypes). Reports velocity ripple "
                                   "and speed tracking error per speed and direction.",
                       epilog=_EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("model", metavar="MODEL.json", help="model file (gearspec fit --json or gearspec diagnose --json)")
    p.add_argument("--twin", choices=("silo4", "direct-drive"), default="silo4",
                   help="the speed loop to run (default silo4); theta, speeds and torques at its motor")
    p.add_argument("--speeds-rpm", type=_speeds, metavar="LIST",
                   help="motor speeds in rpm, comma-separated, each run in both directions (default silo4: "
                        "50,100,280,560,1000,3000; direct-drive: 10,20,30,60,120,240)")
    p.add_argument("--duration", type=number(0, low_open=True), default=3.0, metavar="S",
                   help="seconds held at each speed (default 3)")
    p.add_argument("--repetitions", type=number(1, integer=True), default=1, metavar="N",
                   help="runs per speed and direction, averaged (default 1)")
    p.add_argument("--seed", type=int, default=1, help="the twin's seed, the same for the three runs (default 1)")
    p.add_argument("--trace-rpm", type=number(0, low_open=True), metavar="RPM",
                   help="speed of the time-trace figure, one of --speeds-rpm (default nearest 280 / 30 rpm)")
    p.add_argument("--cc", metavar="COMPILER", help="C compiler (default $CC or cc)")
    p.add_argument("--out", metavar="DIR", help="write report.md, figures and compensation.csv here")
    p.add_argument("--json", metavar="FILE", help="write the machine-readable result here")
    p.add_argument("--quiet", action="store_true", help="no summary on stdout")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..export.compensate import compensate
    from ..report.compensate import summary_text, write_compensate_report

    if not Path(args.model).is_file():
        raise InputError(f"{args.model}: no such model file")
    result = compensate(args.model, args.twin, args.speeds_rpm, duration=args.duration,
                        repetitions=int(args.repetitions), seed=args.seed, cc=args.cc, trace_rpm=args.trace_rpm)
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(result.to_dict(), indent=1))
    if args.out:
        write_compensate_report(result, args.out, command=command_line())
    if not args.quiet:
        print(summary_text(result))
        for n in result.notes:
            print(f"note: {n}")
        if args.out:
            print(f"report: {Path(args.out) / 'report.md'}")
            print_html(Path(args.out) / "report.md")
        if args.json:
            print(f"json: {args.json}")
    return 0
