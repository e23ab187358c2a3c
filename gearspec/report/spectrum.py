"""The report of ``gearspec spectrum``: segments, declared lines, unexplained peaks, spectra."""

from __future__ import annotations

from itertools import groupby
from pathlib import Path

import numpy as np
import pandas as pd

from .. import plots
from ..errors import InputError
from ..progress import Stages
from ..recording import Recording
from ..segment import Segmentation
from ..spectrum.analysis import SpectrumResult
from ..spectrum.results import REPRESENTATIVES
from . import _rpm, bullets, header, markdown_table, report_dir, write_report

__all__ = ["write_spectrum_report", "write_order_report", "order_section"]


def _ranges(idx: list[int]) -> str:
    """'0-3, 7' from [0, 1, 2, 3, 7]."""
    runs = [[i for _, i in g] for _, g in groupby(enumerate(idx), lambda ki: ki[1] - ki[0])]
    return ", ".join(f"{r[0]}" if len(r) == 1 else f"{r[0]}-{r[-1]}" for r in runs)


#: ``pages="auto"``: at most this many segments get a panel of spectra
AUTO_PAGES = REPRESENTATIVES
PAGES = ("auto", "all", "none")


def write_spectrum_report(result: SpectrumResult, rec: Recording, seg: Segmentation, out: str | Path,
                          command: str = "", orders=None, pages: str = "all", stages=None) -> Path:
    """Write ``report.md``, the figures and ``peaks.csv`` of a spectrum analysis into ``out``
    (``orders``: an :class:`~gearspec.spectrum.OrderAnalysis`, its section and files added).

    ``pages``: the segments whose spectra are drawn (8 a page, ``spectra_NN.png``): ``"all"``,
    ``"none"`` or ``"auto"`` (at most ``AUTO_PAGES`` representative segments,
    :meth:`~gearspec.spectrum.SpectrumResult.representatives`; every segment when there are no
    more); segments analysed without their spectra get them computed for their page
    (:func:`~gearspec.spectrum.pipeline.attach_spectra`), where the page is drawn: in a worker
    process (``result`` is left as it was) when the figures are drawn in two or more.  ``stages``: a
    :class:`~gearspec.progress.Stages` told of each step.
    """
    if pages not in PAGES:
        raise InputError(f"--pages must be one of {', '.join(PAGES)}, got '{pages}'")
    st = stages if stages is not None else Stages(enabled=False)
    out = report_dir(out)
    unit = result.unit
    tu = "Nm" if unit == "rad" else "N"
    n_all = len(result.segments)
    drawn = (list(range(n_all)) if pages == "all" else [] if pages == "none" else
             result.representatives(AUTO_PAGES))
    figs = _draw_figures(result, rec, seg, out, drawn, st)
    table = result.peaks_table()
    table.to_csv(out / "peaks.csv", index=False)

    md = header("gearspec spectrum report", command, rec.summary())
    n_seg = sum(s.segment.n for s in result.segments)
    md += [f"Rows read: {result.n_rows}; in segments: {n_seg}; excluded: "
           + (", ".join(f"{k} {v}" for k, v in sorted(result.excluded.items())) or "none")
           + ". (Every row is in one segment or counted once.)", ""]
    md += ["## Gear train", ""] + (["```", result.gear.describe(), "```", ""] if result.gear is not None else
                                  ["No gear spec: no line is declared; every peak found is reported unlabelled.", ""])
    if figs["summary"] is not None:
        md += ["## Summary over all segments", "",
               f"All {len(result.segments)} segments on one figure per direction: the amplitude of every declared "
               "line against speed (dots: segments; line: median of the repetitions of a speed) and the strongest "
               "significant peaks of each segment that no declared line fits (crosses).", "",
               f"![summary]({figs['summary'].name})", ""]
    ws = seg.settings.get("windows_chosen")
    md += ["## Segments", "",
           "Found from position alone (" + (f"speed window(s) {', '.join(f'{w:g} s' for w in ws)}, " if ws else "")
           + f"relative tolerance {seg.settings.get('rel_tol')})"
           + (f"; {seg.settings['quasi_static_segments']} quasi-static sweep(s) (rows taken at rest: torque against "
              "position, no time derivative, nominal speed = travel / duration)"
              if seg.settings.get("quasi_static_segments") else "") + ".", "",
           f"![segments]({figs['segments'].name})", ""]
    rows = []
    for i, s in enumerate(result.segments):
        g = s.segment
        rows.append({"segment": i, "kind": g.kind.replace("_", "-"), "run": g.run, "dir": g.direction,
                     f"speed ({unit}/s)": g.speed,
                     **({"speed (rpm)": _rpm(g.speed, unit)} if unit == "rad" else {}),
                     "samples": g.n, f"travel ({unit})": s.span, f"mean friction ({tu})": s.level,
                     f"residual sd ({tu})": s.sigma, "speed ripple (rel. sd)": g.speed_ripple})
    md += [markdown_table(pd.DataFrame(rows)), ""] + _lines_sections(result, table, figs)
    md += ["## Order spectra", "", _pages_sentence(drawn, n_all, pages), ""]
    if figs["spectra"]:
        md += ["FFT of torque resampled over position (Hann window, amplitude-calibrated) in grey, Lomb-Scargle of "
               "the raw samples in green, the local noise level dotted (each curve drawn as its maximum over "
               "logarithmic frequency bins); dots are the jointly fitted amplitudes (purple: declared, orange: "
               "harmonic/sideband, red: unexplained). Where the two curves part at high frequency (the green one far "
               "above), the Lomb-Scargle periodogram, which has no taper, shows the leakage of strong lines and of "
               "low-frequency content through its rectangular window (side lobes falling as 1/f); the Hann-windowed "
               "FFT (side lobes falling as 1/f^3) shows the torque's own spectrum there. The local noise level, taken "
               "from the Lomb-Scargle, is then conservative (errors and false-alarm probabilities too large, never "
               "too small).", ""]
    md += [f"![spectra]({p.name})" for p in figs["spectra"]]
    md += ["", "## Method", "",
           "Friction magnitude y = direction x (torque - J thetadd) over position; joint least-squares fit of all "
           "declared lines and significant peaks with a Legendre nuisance polynomial, peaks searched again in the "
           "residual of every line found until none is left (a dense comb of lines raises the noise level around "
           "each); standard errors scaled by the local noise level of the Lomb-Scargle periodogram; false-alarm "
           "probabilities against the local noise level (one frequency for declared lines, all searched frequencies "
           "for found peaks). "
           f"Frequencies in cycles/{unit}; amplitudes in {tu}; phases in rad of A sin(2 pi f theta + phi).", ""]
    if orders is not None:
        md += order_section(orders, out)
    return write_report(out, md + bullets(result.notes, "Notes:"))


def _draw_figures(result: SpectrumResult, rec: Recording, seg: Segmentation, out: Path, drawn: list[int],
                  st) -> dict:
    """The report's figures, each drawn by one task of :func:`~gearspec.core.parallel.forked_map`
    (in worker processes forked from this one: they inherit the results; each returns its path,
    None for a figure with nothing to show).  A page of spectra is one task: its segments' spectra
    are computed there (:func:`~gearspec.spectrum.pipeline.attach_spectra`) and dropped with the
    worker, as the figure is all that needs them.  The same figures as drawn one after the other."""
    from ..core.parallel import forked_map
    from ..plots.spectrum import PER_PAGE, plot_spectrum_summary
    from ..spectrum.pipeline import attach_spectra, can_hold_spectra

    pattern = str(out / "spectra_{:02d}.png")
    shown = [i for i in drawn if can_hold_spectra(result.segments[i])]
    chunks = [shown[k:k + PER_PAGE] for k in range(0, len(shown), PER_PAGE)]

    def page(k: int) -> list[Path]:
        attach_spectra(result, rec, chunks[k])
        return plots.plot_order_spectra(result, pattern, indices=chunks[k], first_page=k + 1)

    # the longest first: the segments figure (24 panels) and the pages, then the summaries
    tasks = ([("segments", lambda: plots.plot_segments(rec, seg, out / "segments.png"))]
             + [("spectra", lambda k=k: page(k)) for k in range(len(chunks))]
             + [("summary", lambda: plot_spectrum_summary(result, out / "spectrum_summary.png")),
                ("amplitude", lambda: plots.plot_amplitude_vs_speed(result, out / "amplitude_vs_speed.png")),
                ("relative", lambda: plots.plot_amplitude_vs_speed(result, out / "amplitude_vs_speed_relative.png",
                                                                   relative=True)),
                ("unexplained", lambda: plots.plot_unexplained(result, out / "unexplained_peaks.png"))])
    st.start(f"{len(tasks)} figures" + (f", spectra of {len(drawn)} segment(s) for the pages" if drawn else ""))
    figs: dict = {"spectra": []}
    for (name, _), path in zip(tasks, forked_map(lambda task: task[1](), tasks)):
        if name == "spectra":
            figs["spectra"] += path
        else:
            figs[name] = path
    st.done(f"{len(tasks) - len(chunks)} summary figures drawn"
            + (f", {len(figs['spectra'])} page(s) of spectra for {len(drawn)} of {len(result.segments)} segment(s)"
               if drawn else ""))
    return figs


def _lines_sections(result: SpectrumResult, table: pd.DataFrame, figs: dict) -> list[str]:
    """The sections 'Declared lines' and 'Peaks no declared line explains'."""
    unit = result.unit
    tu = "Nm" if unit == "rad" else "N"
    md = ["## Declared lines", ""]
    if result.gear is None or table.empty or not table["declared"].any():
        md += ["_No declared line fits in any segment._", ""]
    else:
        md += ["Amplitude (with 95 % error bars) of every declared line in every segment where it completes at "
               "least one cycle and lies below the position Nyquist frequency.", "",
               f"![amplitude vs speed]({figs['amplitude'].name})", "",
               f"![relative amplitude vs speed]({figs['relative'].name})", ""]
        dec = table[table["declared"]]
        summary = (dec.groupby(["label", "direction"])
                   .agg(frequency=("frequency", "first"), segments=("segment", "count"),
                        amplitude_min=("amplitude", "min"), amplitude_max=("amplitude", "max"),
                        median_snr=("snr", "median"))
                   .reset_index())
        md += [markdown_table(summary), ""]
    slow, above, coarse = {}, {}, {}
    for i, s in enumerate(result.segments):
        for k in s.skipped:
            kind = k.get("kind")
            (above if kind == "above_nyquist" else coarse if kind == "above_quantisation_limit" else slow).setdefault(
                k["label"], []).append(i)
    for lines, text in ((slow, "Lines not fitted in some segments because they complete less than a cycle there: "),
                        (above, "Lines above the position Nyquist frequency of some segments -- **not measured there** "
                                "(never fitted; a peak found at the frequency where such a line aliases is labelled "
                                "`alias of <label>`): "),
                        (coarse, "Lines above the quantisation limit of some segments -- **not measured there** "
                                 "(never fitted): ")):
        if lines:
            md += [text + "; ".join(f"{k} (segments {_ranges(v)})" for k, v in lines.items()) + ".", ""]
    md += _quantisation_sentence(result)
    md += ["## Peaks no declared line explains", ""]
    found = table[~table["declared"]] if not table.empty else table
    if found.empty:
        md += ["_None significant (false-alarm probability < 0.01)._", ""]
    else:
        md += [result.unexplained_sentence() + "; below, every peak found that no declared line fits "
               "(`label`: those a harmonic, sideband or alias of one explains).", ""]
        if figs["unexplained"] is not None:
            md += [f"![unexplained peaks]({figs['unexplained'].name})", ""]
        cols = [c for c in ("segment", "direction", "speed", "frequency", "order", "amplitude", "amplitude_se", "fap",
                            "label", "hint", "order_exact") if c in found.columns]
        md += [markdown_table(found.sort_values(["frequency"])[cols].rename(
            columns={"speed": f"speed ({unit}/s)", "frequency": f"frequency (cycles/{unit})",
                     "amplitude": f"amplitude ({tu})", "amplitude_se": "s.e."})), ""]
        md += ["`label`: the harmonic or sideband of declared lines that explains the peak; empty when nothing "
               "declared does; `alias of <label>` when it is where a line above the segment's position Nyquist "
               "frequency shows up (that line is not measured). `hint`: an integer multiple of a shaft the peak "
               "sits on within its frequency uncertainty (a motor pole-pair or cogging order looks like this), a "
               "clue, not an explanation; given only when the uncertainty tells neighbouring multiples apart, with "
               "the exact order in `order_exact` beside the measured one.", ""]
    return md


def _quantisation_sentence(result: SpectrumResult) -> list[str]:
    """The quantisation limit, stated where it limits a segment (below its position Nyquist frequency)."""
    lim = [(i, s) for i, s in enumerate(result.segments) if s.quantisation_limit < s.nyquist]
    if not lim:
        return []
    unit = result.unit
    steps = sorted({float(f"{s.quantisation_step:.4g}") for _, s in lim})
    limits = [s.quantisation_limit for _, s in lim]
    return [f"Position quantised (encoder step {', '.join(f'{q:g}' for q in steps)} {unit}) in segments "
            f"{_ranges([i for i, _ in lim])}: nothing above the quantisation limit, 1/8 of the inverse step "
            f"({min(limits):.4g} cycles/{unit}), is searched or fitted there (a line loses 2.6 % of its amplitude "
            "to the staircase at that limit, and the encoder's counts make lines of their own). A peak labelled "
            "`encoder counts xm, folded` sits where the m-th harmonic of the count rate, "
            "folded by the sampling, falls: the drive's reaction to the counts, which moves with the speed, not "
            "a position-locked line.", ""]


def _pages_sentence(drawn: list[int], n_all: int, pages: str) -> str:
    """What the pages of spectra show, and how to get the others."""
    if len(drawn) == n_all:
        return f"Spectra of all {n_all} segments."
    if not drawn:
        return (f"No page of spectra drawn (--pages none); the summary figure shows all {n_all} segments; "
                "--pages all draws every one.")
    return (f"Pages for {len(drawn)} of {n_all} segments ({_ranges(drawn)}): in each group of repetitions of one "
            "speed and direction the segment with the most significant peaks no declared line fits (then the "
            f"highest signal-to-noise ratio), at most {AUTO_PAGES} groups, those that show the most. The summary "
            "figure and the tables hold every segment; --pages all draws every one.")


def write_order_report(orders, rec: Recording, out: str | Path, command: str = "", note: str = "") -> Path:
    """The report of a recording analysed by its order map alone (no constant-speed segment)."""
    out = report_dir(out)
    md = header("gearspec spectrum report", command, rec.summary())
    if note:
        md += [f"**{note[0].upper() + note[1:]}.** The segment spectra need constant speed; the order map "
               "analyses whole motions per direction instead.", ""]
    return write_report(out, md + order_section(orders, out))


def order_section(orders, out: Path) -> list[str]:
    """The order-map section of a report; writes ``order_map.png``, ``order_tracks.png`` and
    ``order_map.json`` into ``out``."""
    from ..jsonsafe import dumps
    from ..plots.ordermap import plot_order_map, plot_order_tracks

    unit = orders.unit
    tu = "Nm" if unit == "rad" else "N"
    maps = [orders.maps.get(d) for d in (1, -1)]
    lines = sorted({(t.frequency, (t.label or f"{t.frequency:.4g}").split(" = ")[0]) for t in orders.tracks})
    f_map = plot_order_map(maps, out / "order_map.png", lines=lines)
    f_tr = plot_order_tracks(orders.tracks, out / "order_tracks.png")
    (out / "order_map.json").write_text(dumps(orders.to_dict(), indent=1))
    md = ["## Order map over varying speed", "",
          "Whole motions, per direction (samples slower than the minimum speed are rest or reversal). Each piece "
          "of one direction is resampled over position and cut into windows (Hann, 50 % overlap); a cell is the "
          "root-mean-square amplitude of the windows of its speed bin that measure its frequency: below 0.8 x "
          "the position Nyquist frequency of the window's samples. Cells no window measures are grey, never a "
          "number (the white curve is the highest frequency measured in each bin). A cell reads "
          "sqrt(A^2 + noise^2): compare with the bin's noise (median cell) in `order_map.json`.", "",
          f"![order map]({f_map.name})", ""]
    rows = []
    for t in orders.tracks:
        ok = np.isfinite(t.amplitude)
        if not ok.any():
            continue
        i = np.flatnonzero(ok)
        rows.append({"line": (t.label or "").split(" = ")[0] or "-", f"frequency (cycles/{unit})": t.frequency,
                     "dir": t.direction, f"speeds ({unit}/s)": f"{t.speed_range[0]:.4g} to {t.speed_range[1]:.4g}",
                     "samples": t.n, "above Nyquist": t.n_above_nyquist,
                     f"amplitude at slowest ({tu})": f"{t.amplitude[i[0]]:.3g} ± {t.amplitude_se[i[0]]:.2g}",
                     f"amplitude at fastest ({tu})": f"{t.amplitude[i[-1]]:.3g} ± {t.amplitude_se[i[-1]]:.2g}",
                     "inertia": f"{t.inertia:.3g} ({t.inertia_how})" if t.inertia is not None else t.inertia_how})
    md += ["### Order tracks", "",
           "Each line's amplitude against speed: a least-squares fit of direction x torque = level(v) + a(v) "
           "sin(2 pi f theta) + c(v) cos(2 pi f theta) (+ J thetadd) with cubic B-splines in speed, on the samples "
           "where the line lies below 0.8 x their position Nyquist frequency; band: "
           f"{orders.tracks[0].level if orders.tracks else 0.95:.0%} pointwise (delta method, white noise). "
           "A band reaching 0 means the line is not distinguished from none at that speed.", "",
           f"![order tracks]({f_tr.name})", "",
           markdown_table(pd.DataFrame(rows)) if rows else "_No line tracked._", ""]
    md += bullets([f"{s['what']}: {s['reason']}" for s in orders.skipped], "Not analysed:")
    return md
