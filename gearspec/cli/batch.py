"""``gearspec batch``: spectrum + fit (+ diagnosis) of many recordings and joints on Dask, and the
fleet report (CONTRACTS.md section 4): what ran, what was refused, parameters over time per joint,
and the joints flagged by :func:`~gearspec.fleet.trend.trend_tests` (``DIR/report.md`` and
``report.html``; here because the command line, reports and figures are leaves nothing imports)."""

from __future__ import annotations

import argparse
import json
import re
import time
from pathlib import Path

from . import analysis_parser, command_line, number, print_html
from .fit import law_choices

EXAMPLES = """examples:
  gearspec batch bags/robot*/ --gear arm.toml --out fleet          # every joint of every bag, one process per CPU
  gearspec batch run1.csv run2.csv --gear lola-a --law lola8 --workers 1 --out lola   # a plain loop, no Dask
"""


def register(sub) -> None:
    p = analysis_parser(sub, "batch", run, help="fit many recordings and joints (on Dask) and report the fleet",
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
    from ..fleet import batch
    from ..fleet.trend import flagged_joints, trend_tests
    from ..gears import load_gear

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
        n = df.groupby(["source", "joint"], dropna=False).ngroups
        print(f"{n} recording-joint pair(s): {n - len(bad)} fitted, {len(bad)} refused")
        for r in bad.itertuples(index=False):
            where = f" [{r.joint}]" if isinstance(r.joint, str) else ""
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


# ---------------------------------------------------------------------- the fleet report
#: the multiple-testing corrections, as the report names them
CORRECTIONS = {"holm": "Holm's step-down method", "bonferroni": "Bonferroni's method", "none": "no correction"}
#: the flagging rule, as the report states it
RULE = ("Per robot, joint, direction and parameter with at least {min_dates} dates: a weighted least-squares line "
        "of the parameter against the date (weights 1/se^2, se: the fit's standard error), its slope's standard "
        "error widened by the Birge ratio sqrt(chi2/(n-2)) when the dates scatter more than their standard "
        "errors say, a two-sided test of a zero slope (Student's t with n-2 degrees of freedom when widened, "
        "else normal); the {tests} tests made "
        "corrected together by {correction} (family-wise error {alpha:g}). A joint is flagged when any of its "
        "series is. The robot is the folder holding the recording.")


def _unit(parameter: str, laws) -> str:
    from ..terms import BASE_LAWS

    if parameter.endswith(" amplitude"):
        return "Nm"
    for law in laws:
        spec = BASE_LAWS.get(law)
        if spec is not None and parameter in spec.params:
            return spec.units[spec.params.index(parameter)]
    return ""


def _dates(t):
    import pandas as pd

    return pd.to_datetime(pd.Series(t, dtype=float), unit="s")


def _date_axis(ax) -> None:
    """Dates on the x axis: a few ticks, written concisely (no overlapping labels)."""
    import matplotlib.dates as mdates

    ax.xaxis.set_major_locator(mdates.AutoDateLocator(minticks=2, maxticks=4))
    ax.xaxis.set_major_formatter(mdates.DateFormatter("%Y-%m-%d"))
    ax.tick_params(axis="x", labelrotation=20, labelsize=8)


def _well_determined(df, p: str) -> bool:
    """A parameter worth an overview panel: its typical value at least 3 standard errors."""
    import numpy as np
    import pandas as pd

    v, se = pd.to_numeric(df[p], errors="coerce"), pd.to_numeric(df[p + "_se"], errors="coerce")
    ratio = (v.abs() / se).replace([np.inf], np.nan).dropna()
    return len(ratio) > 0 and float(ratio.median()) >= 3


def plot_fleet_overview(df, trends, path) -> Path | None:
    """Every well-determined tested parameter over the dates, as a change from each series' mean
    (%), one grey line per (robot, joint, direction); the flagged series in colour (``df``: the
    batch table, ``trends``: :func:`~gearspec.fleet.trend.trend_tests`)."""
    import pandas as pd

    from ..plots import plt, save

    params = [p for p in dict.fromkeys(trends["parameter"]) if _well_determined(df, p)]
    if not params:
        return None
    ok = df[df["status"] == "ok"]
    flagged = set(map(tuple, trends.loc[trends["flagged"], ["robot", "joint", "direction", "parameter"]].to_numpy()))
    ncol = min(3, len(params))
    nrow = -(-len(params) // ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.6 * ncol, 3.2 * nrow), squeeze=False)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, p in zip(axes.flat, params):
        k = 0
        for (robot, joint, d), g in ok.groupby(["robot", "joint", "direction"], sort=True):
            g = g.sort_values("start_time")
            y = pd.to_numeric(g[p], errors="coerce")
            rel = 100 * (y / y.mean() - 1)
            if (robot, joint, d, p) in flagged:
                ax.plot(_dates(g["start_time"]), rel, "o-", color=colours[k % len(colours)], lw=1.6, ms=3,
                        label=f"{robot} {joint} {d}", zorder=3)
                k += 1
            else:
                ax.plot(_dates(g["start_time"]), rel, "-", color="0.7", lw=0.7, zorder=1)
        ax.set_title(p, fontsize=10)
        ax.set_ylabel("change from the series' mean, %")
        ax.set_xlabel("recording date (UTC)")
        _date_axis(ax)
        ax.grid(alpha=0.3)
        if k:
            ax.legend(fontsize=7, loc="upper left")
    for ax in list(axes.flat)[len(params):]:
        ax.set_visible(False)
    fig.suptitle("Fleet: parameters over time (grey: not flagged; colour: flagged)", fontsize=11)
    fig.tight_layout()
    return save(fig, path)


def plot_flagged_joint(df, trends, robot, joint, path) -> Path:
    """One flagged joint: each flagged parameter against the date with its standard error, both
    directions, and the fitted trend line."""
    from ..fleet.trend import DAY

    from ..plots import DIRS, plt, save

    t = trends[(trends["robot"] == robot) & (trends["joint"] == joint) & trends["flagged"]]
    params = list(dict.fromkeys(t["parameter"]))
    laws = df["law"].dropna().unique()
    fig, axes = plt.subplots(1, len(params), figsize=(4.8 * len(params), 3.4), squeeze=False)
    g = df[(df["robot"] == robot) & (df["joint"] == joint) & (df["status"] == "ok")].sort_values("start_time")
    for ax, p in zip(axes[0], params):
        for _, dname, colour, marker in DIRS:
            s = g[g["direction"] == dname]
            if s.empty:
                continue
            x = s["start_time"].to_numpy(float)
            ax.errorbar(_dates(x), s[p].astype(float), yerr=s[p + "_se"].astype(float), fmt=marker, color=colour,
                        ms=4, capsize=2, label=dname)
            tr = t[(t["direction"] == dname) & (t["parameter"] == p)]
            if len(tr):
                r = tr.iloc[0]
                line = r["mean"] + r["slope_per_day"] * ((x - r["t_ref"]) / DAY)
                ax.plot(_dates(x), line, "-", color=colour, lw=1,
                        label=f"{dname} trend {100 * r['relative_change']:+.1f} % (p_adj {r['p_adjusted']:.1e})")
        unit = _unit(p, laws)
        ax.set_ylabel(f"{p} ({unit})" if unit else p)
        ax.set_xlabel("recording date (UTC)")
        _date_axis(ax)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle(f"{robot} {joint}: flagged parameters (error bars: one standard error)", fontsize=11)
    fig.tight_layout()
    return save(fig, path)


def _safe(name) -> str:
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in str(name))


def write_fleet_report(df, trends, out, command: str = "") -> Path:
    """Write ``out/report.md`` (and ``report.html``) with the figures beside it; returns its path."""
    from ..fleet.trend import MIN_DATES, flagged_joints

    from ..report import bullets, header, markdown_table, report_dir, write_report

    out = report_dir(out)
    n_tasks = df.groupby(["source", "joint"], dropna=False).ngroups
    bad = df[df["status"] != "ok"]
    md = header("Fleet report", command)
    md += [f"{n_tasks} recording-joint pair(s) analysed: {n_tasks - len(bad)} fitted, {len(bad)} refused.", ""]
    if len(bad):
        md += ["## Refused", "", markdown_table(bad[["source", "joint", "error"]]), ""]
    md += ["## Rule", "", RULE.format(min_dates=MIN_DATES, tests=trends.attrs.get("tests", len(trends)),
                                      correction=CORRECTIONS[trends.attrs.get("correction", "holm")],
                                      alpha=trends.attrs.get("alpha", 0.01)), ""]
    joints = flagged_joints(trends)
    md += ["## Flagged joints", ""]
    md += [markdown_table(joints) if len(joints) else "No joint changed by more than its uncertainty allows.", ""]
    fig = plot_fleet_overview(df, trends, out / "fleet_overview.png")
    if fig is not None:
        md += ["## Parameters over time", "", f"![parameters over time]({fig.name})", ""]
    for robot, joint in joints[["robot", "joint"]].itertuples(index=False):
        p = plot_flagged_joint(df, trends, robot, joint, out / f"flagged_{_safe(robot)}_{_safe(joint)}.png")
        md += [f"### {robot} {joint}", "", f"![{robot} {joint}]({p.name})", ""]
    if len(trends):
        cols = ["robot", "joint", "direction", "parameter", "n", "relative_change", "chi2_dof", "p", "p_adjusted",
                "flagged"]
        md += ["## Smallest p-values", "", markdown_table(trends.sort_values("p").head(12)[cols]), ""]
    md += bullets(["start times are the recordings' own (ROS bag stamps); files without one are fitted but "
                   "not tested over time"] if df["start_time"].isna().any() else [], "Notes")
    return write_report(out, md)
