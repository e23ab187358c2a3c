"""Markdown reports, one module per command (``spectrum``, ``fit``, ...).  A leaf package: nothing in
the analysis imports it.  Shared helpers live here."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

__all__ = ["write_spectrum_report", "markdown_table"]


def markdown_table(df: pd.DataFrame, floatfmt: str = ".4g") -> str:
    """A pandas DataFrame as a GitHub Markdown table (no extra dependency)."""
    if df.empty:
        return "_(none)_\n"
    cols = list(df.columns)

    def fmt(v):
        if v is None or (isinstance(v, float) and math.isnan(v)):
            return ""
        if isinstance(v, (float, np.floating)):
            return format(float(v), floatfmt)
        return str(v).replace("|", "\\|")  # escaped: |v| stays |v| in the rendered table

    lines = ["| " + " | ".join(str(c) for c in cols) + " |", "|" + "---|" * len(cols)]
    for row in df.itertuples(index=False):
        lines.append("| " + " | ".join(fmt(v) for v in row) + " |")
    return "\n".join(lines) + "\n"


def _rpm(speed: float, unit: str) -> str:
    return f"{speed * 60 / (2 * math.pi):.4g}" if unit == "rad" else ""


from .spectrum import write_spectrum_report  # noqa: E402
