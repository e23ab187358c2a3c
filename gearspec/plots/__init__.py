"""Figures (matplotlib, Agg), one module per command; a leaf package: nothing in the analysis
imports it.  Every function draws one figure from results, saves it as PNG and returns its path."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

__all__ = ["plot_segments", "plot_order_spectra", "plot_amplitude_vs_speed", "plot_unexplained", "save", "plt",
           "POS", "NEG", "DIRS", "present_dirs", "plain_log_axis"]

#: colours of the positive and negative direction in every figure
POS, NEG = "#1f77b4", "#d62728"
#: direction, its name, colour and marker in every figure
DIRS = ((1, "positive", POS, "o"), (-1, "negative", NEG, "s"))


def present_dirs(directions) -> list:
    """The entries of :data:`DIRS` whose direction occurs in ``directions`` (a column of +1/-1): one
    panel per direction the data hold, never an empty panel for a direction never driven (the
    positive one alone when there is none)."""
    found = set(int(d) for d in directions)
    return [x for x in DIRS if x[0] in found] or list(DIRS[:1])


def plain_log_axis(axis) -> None:
    """A logarithmic axis labelled 0.02, 0.05, 0.1 (not 2 x 10^-2): majors and the 2 and 5 minors."""
    from matplotlib.ticker import FuncFormatter

    axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    axis.set_minor_formatter(FuncFormatter(lambda v, _: f"{v:g}" if f"{v:.0e}"[0] in "25" else ""))


def one_direction_note(present) -> str:
    """The caption addition when a figure has one direction's panel only."""
    other = "negative" if present[0][0] > 0 else "positive"
    return "" if len(present) == 2 else f" ({present[0][1]} direction only: no {other} segment)"


#: zlib level of the PNG files: the same pixels as the library's default (6) in 0.64 of its time,
#: files 2-4 % larger (the figures of `gearspec spectrum` on the default twin: 0.34 s instead of 0.53)
PNG_COMPRESS_LEVEL = 3


def save(fig, path, *, tight: bool = True) -> Path:
    """Save a figure as PNG (110 dpi, zlib level :data:`PNG_COMPRESS_LEVEL`) and close it.  ``tight``:
    crop to the drawn content (matplotlib then draws the figure twice); False for a figure laid out
    already (one draw: long pages of spectra)."""
    path = Path(path)
    png = {"pil_kwargs": {"compress_level": PNG_COMPRESS_LEVEL}} if path.suffix.lower() == ".png" else {}
    fig.savefig(path, dpi=110, **png, **({"bbox_inches": "tight"} if tight else {}))
    plt.close(fig)
    return path


from .spectrum import plot_amplitude_vs_speed, plot_order_spectra, plot_segments, plot_unexplained  # noqa: E402
