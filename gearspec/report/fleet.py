"""The fleet report of ``gearspec batch`` (CONTRACTS.md section 4): what ran, what was refused, the
flagging rule as applied, the flagged joints with their figures, parameters over time, and the
smallest p-values (``DIR/report.md`` and ``report.html``)."""

from __future__ import annotations

from pathlib import Path

from ..fleet import pair_counts
from ..fleet.trend import MIN_DATES, flagged_joints
from ..plots.fleet import plot_fleet_overview, plot_flagged_joint
from . import bullets, header, markdown_table, report_dir, write_report

__all__ = ["write_fleet_report", "RULE", "CORRECTIONS"]


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


def _safe(name) -> str:
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in str(name))


def write_fleet_report(df, trends, out, command: str = "") -> Path:
    """Write ``out/report.md`` (and ``report.html``) with the figures beside it; returns its path."""
    out = report_dir(out)
    c = pair_counts(df)
    bad = df[df["status"] != "ok"]
    md = header("Fleet report", command)
    md += [f"{c['pairs']} recording-joint pair(s) analysed: {c['fitted']} fitted, {c['refused']} refused"
           + (f", {c['partly']} fitted in one direction only" if c["partly"] else "") + ".", ""]
    if len(bad):
        md += ["## Refused", "", "One row per recording, joint and direction not analysed (no direction: the "
               "recording could not be read).", "", markdown_table(bad[["source", "joint", "direction", "error"]]), ""]
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
