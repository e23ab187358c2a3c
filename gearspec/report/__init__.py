"""Markdown reports, one module per command (``spectrum``, ``fit``, ...).  A leaf package: nothing in
the analysis imports it.  Shared helpers live here."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

__all__ = ["write_spectrum_report", "markdown_table", "write_report", "write_html"]


def markdown_table(df: pd.DataFrame, floatfmt: str = ".4g") -> str:
    """A pandas DataFrame as a GitHub Markdown table (no extra dependency)."""
    if df.empty:
        return "_(none)_\n"
    def fmt(v):
        if v is None or (isinstance(v, float) and math.isnan(v)):
            return ""
        if isinstance(v, (float, np.floating)):
            return format(float(v), floatfmt)
        return str(v).replace("|", "\\|")  # escaped: |v| stays |v| in the rendered table

    lines = ["| " + " | ".join(str(c) for c in df.columns) + " |", "|" + "---|" * len(df.columns)]
    lines += ["| " + " | ".join(fmt(v) for v in row) + " |" for row in df.itertuples(index=False)]
    return "\n".join(lines) + "\n"


def _rpm(speed: float, unit: str) -> str:
    return f"{speed * 60 / (2 * math.pi):.4g}" if unit == "rad" else ""


def report_dir(out) -> Path:
    """The folder ``out`` of a report, created if needed."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    return out


def header(title: str, command: str = "", recording_summary: str = "") -> list[str]:
    """A report's first Markdown lines: title, command line and recording (each when given)."""
    md = [f"# {title}", ""]
    if command:
        md += [f"Command: `{command}`", ""]
    if recording_summary:
        md += ["## Recording", "", "```", recording_summary, "```", ""]
    return md


def bullets(items, heading: str = "") -> list[str]:
    """``items`` as a Markdown list (after ``heading`` when given); nothing when there are none."""
    if not items:
        return []
    return ([heading, ""] if heading else []) + [f"- {n}" for n in items] + [""]


def model_table(m, paper: bool = False) -> pd.DataFrame:
    """A model's parameters per direction in SI with standard errors (``paper``: and in the papers' units)."""
    cols = ("parameter", "unit", "positive", "positive_se", "negative", "negative_se")
    t = m.table()
    return t[[c for c in cols + (("paper_unit", "positive_paper", "negative_paper") if paper else ()) if c in t]]


def write_report(out: Path, md: list[str]) -> Path:
    """Write the Markdown lines ``md`` as ``out/report.md`` and the same content as the self-contained page
    ``out/report.html`` (figures embedded: :func:`gearspec.report.html.write_html`); returns the
    Markdown's path."""
    out = Path(out)
    path = out / "report.md"
    text = "\n".join(md)
    path.write_text(text)
    write_html(text, out)
    return path


from .html import write_html  # noqa: E402
from .spectrum import write_spectrum_report  # noqa: E402
