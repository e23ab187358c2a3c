"""The one table format of every reproduction: ``quantity, paper, gearspec, rel_diff`` (+ others)."""

from __future__ import annotations

import math
from pathlib import Path

import pandas as pd

__all__ = ["comparison_table", "write_table"]


def comparison_table(rows) -> pd.DataFrame:
    """Rows of ``{"quantity", "paper", "gearspec", ...}``; ``rel_diff = (gearspec - paper) / |paper|``
    (empty where the paper gives no number or it is 0)."""
    df = pd.DataFrame(list(rows))
    for c in ("quantity", "paper", "gearspec"):
        if c not in df:
            df[c] = None

    def rel(r):
        try:
            p, g = float(r["paper"]), float(r["gearspec"])
        except (TypeError, ValueError):
            return float("nan")
        return (g - p) / abs(p) if p and math.isfinite(p) and math.isfinite(g) else float("nan")

    df["rel_diff"] = df.apply(rel, axis=1) if len(df) else []
    cols = ["quantity", "paper", "gearspec", "rel_diff"]
    return df[cols + [c for c in df.columns if c not in cols]]


def write_table(df: pd.DataFrame, path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    df.to_csv(path, index=False)
    return path
