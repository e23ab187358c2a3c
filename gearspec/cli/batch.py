"""``gearspec batch``: spectrum + fit (+ diagnosis) of many recordings and joints on Dask, and the
fleet report (CONTRACTS.md section 4).  This module only parses the options and calls
:func:`gearspec.fleet.batch`, :func:`gearspec.fleet.trend_tests` and
:func:`gearspec.report.fleet.write_fleet_report` (the report's figures: :mod:`gearspec.plots.fleet`)."""

from __future__ import annotations

import argparse
import json
import re
import time
from pathlib import Path

from . import COMMAND_HELP, analysis_parser, command_line, number, print_html
from .fit import law_choices

EXAMPLES = """examples:
  gearspec batch bags/robot*/ --gear arm.toml --out fleet          # every joint of every bag, one process per CPU
  gearspec batch run1.csv run2.csv --gear lola-a --law lola8 --workers 1 --out lola   # a plain loop, no Dask
"""


#: names that lived here before 0.6, now in the report and plots packages (imported when asked for:
#: the command line does not load matplotlib until a report is drawn)
_MOVED = {"write_fleet_report": "gearspec.report.fleet", "RULE": "gearspec.report.fleet",
          "CORRECTIONS": "gearspec.report.fleet", "plot_fleet_overview": "gearspec.plots.fleet",
          "plot_flagged_joint": "gearspec.plots.fleet"}


def __getattr__(name):
    if name in _MOVED:
        import importlib

        return getattr(importlib.import_module(_MOVED[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def register(sub) -> None:
    p = analysis_parser(sub, "batch", run, help=COMMAND_HELP["batch"],
                        description="Analyse every recording (and, in ROS bags, every joint) as `gearspec fit` "
                                    "does on it alone, in parallel on Dask, into DIR/fleet.parquet (one row per "
                                    "source, joint and direction); then test each joint's parameters over the "
                                    "recordings' dates and flag those that changed by more than their "
                                    "uncertainty allows (DIR/report.md).",
                        epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    g = p.add_argument_group("batch")
    g.add_argument("--law", default="silo4", choices=law_choices("silo4", "stribeck", "lola8", "lola11"),
                   help="the law fitted to every recording (default silo4, as `gearspec fit`)")
    g.add_argument("--diagnose", action="store_true", help="also run the closed loop (`gearspec diagnose` defaults)")
    g.add_argument("--workers", type=number(1, 1024, integer=True),
                   help="local Dask worker processes (default: one per CPU); 1: a plain loop without Dask")
    g.add_argument("--scheduler", metavar="ADDRESS", help="an existing Dask scheduler, e.g. tcp://10.0.0.5:8786 "
                   "(the files must be readable there under the same paths)")
    g.add_argument("--alpha", type=number(0, 1, low_open=True, high_open=True), default=0.01,
                   help="family-wise error of all the trend tests together (Holm; default 0.01)")
    o = p.add_argument_group("output")
    o.add_argument("--out", metavar="DIR", required=True, help="folder: fleet.parquet, trends.csv, fits/, report.md")
    o.add_argument("--quiet", action="store_true", help="no progress bar, no summary on stdout")
    p.set_defaults(joint="all")


def _load_options(args) -> dict:
    """The recording and segment options as :func:`gearspec.fleet.batch` takes them."""
    opts = {"map": args.map, "scale": args.scale, "fs": args.fs, "sep": args.sep, "header": not args.no_header,
            "names": args.names, "signal": args.signal, "max_gap": args.max_gap, "topic": args.topic,
            "urdf": args.urdf, "lag": args.lag, "window": args.window if args.window == "auto" else float(args.window),
            "rel_tol": args.rel_tol, "min_speed": args.min_speed, "min_duration": args.min_duration,
            "quasi_static": args.quasi_static}
    return opts


def _fit_name(source: str, joint) -> str:
    stem = Path(source).name or "recording"
    name = f"{Path(source).parent.name}_{stem}" + (f"_{joint}" if joint else "")
    return re.sub(r"[^A-Za-z0-9_.-]", "_", name) + ".json"


def run(args) -> int:
    from ..fleet import batch, pair_counts
    from ..fleet.trend import flagged_joints, trend_tests
    from ..gears import load_gear
    from ..report.fleet import write_fleet_report

    t0 = time.perf_counter()
    gear = load_gear(args.gear) if args.gear else None   # refused here, once, before any task
    fits: dict = {}
    df = batch(args.recordings, gear, law=args.law, diagnose=args.diagnose, workers=args.workers,
               scheduler=args.scheduler, joint=args.joint, progress=not args.quiet, fits=fits, **_load_options(args))
    out = Path(args.out)
    (out / "fits").mkdir(parents=True, exist_ok=True)
    df.to_parquet(out / "fleet.parquet", index=False)
    for (source, joint), fit in fits.items():
        (out / "fits" / _fit_name(source, joint)).write_text(json.dumps(fit, indent=1))
    trends = trend_tests(df, alpha=args.alpha)
    trends.to_csv(out / "trends.csv", index=False)
    report = write_fleet_report(df, trends, out, command=command_line())
    bad = df[df["status"] != "ok"]
    if not args.quiet:
        c = pair_counts(df)
        print(f"{c['pairs']} recording-joint pair(s): {c['fitted']} fitted, {c['refused']} refused"
              + (f", {c['partly']} fitted in one direction only" if c["partly"] else ""))
        for r in bad.itertuples(index=False):
            where = " ".join(x for x in (r.joint, r.direction) if isinstance(x, str))
            where = f" [{where}]" if where else ""
            said = r.error if str(r.error).startswith(str(r.source)) else f"{r.source}: {r.error}"
            print(f"refused{where}: {said}")
        flagged = flagged_joints(trends)
        print(f"{len(trends)} trend test(s), {len(flagged)} joint(s) flagged"
              + "".join(f"\nflagged: {r.robot} {r.joint}: {r.flagged}" for r in flagged.itertuples(index=False)))
        print(f"({time.perf_counter() - t0:.1f} s)")
        print(f"table: {out / 'fleet.parquet'}")
        print(f"report: {report}")
        print_html(report)
    if bad["error"].astype(str).str.startswith("internal error").any():
        return 1
    return 2 if len(bad) else 0
