"""``gearspec spectrum``: constant-speed segments and their order spectra."""

from __future__ import annotations

import time

from ..errors import InputError
from ..spectrum.results import REPRESENTATIVES as AUTO_PAGES
from ..jsonsafe import dumps
from . import (
    COMMAND_HELP,
    POSITIVE,
    PROBABILITY,
    add_output_options,
    analysis_parser,
    command_line,
    load_from_args,
    number,
    print_outputs,
    segments_from_args,
    stages,
    write_json,
)

#: highest harmonic of the declared lines: the line count (and the time of the harmonic fit, which
#: grows faster than linearly in it) grows with it, and beyond this no drive's ripple is resolved
MAX_HARMONICS = 16
#: most undeclared peaks per segment
MAX_PEAKS = 64
#: more segments than this: the console prints a summary per speed and direction, not one line each
MAX_CONSOLE_SEGMENTS = 24


def register(sub) -> None:
    sp = analysis_parser(sub, "spectrum", run, help=COMMAND_HELP["spectrum"],
                         description="Find constant-speed segments per direction and analyse the torque ripple over "
                                     "position in each: amplitude, phase and standard error at every declared gear "
                                     "line, and peaks no declared line explains.")
    g = sp.add_argument_group("spectra")
    g.add_argument("--max-frequency", type=POSITIVE, help="highest frequency searched, cycles per unit of theta")
    g.add_argument("--min-cycles", type=POSITIVE, default=1.0, help="cycles a declared line must complete in a segment")
    g.add_argument("--harmonics", type=number(1, MAX_HARMONICS, integer=True), default=1,
                   help=f"fit declared lines up to this harmonic (default 1, at most {MAX_HARMONICS})")
    g.add_argument("--fap", type=PROBABILITY, default=0.01,
                   help="false-alarm probability for a found peak, between 0 and 1 (default 0.01)")
    g.add_argument("--max-peaks", type=number(0, MAX_PEAKS, integer=True), default=8,
                   help=f"most undeclared peaks per segment (default 8, at most {MAX_PEAKS})")
    g.add_argument("--method", default="auto", choices=("auto", "nifty", "astropy", "scipy"),
                   help="Lomb-Scargle implementation")
    g.add_argument("--pages", default="auto", choices=("auto", "all", "none"),
                   help="segments whose spectra are drawn in the report (spectra_NN.png, 8 a page): auto (default: "
                        "one representative segment per speed and direction, the most informative, at most "
                        f"{AUTO_PAGES}), all, or none; the summary figure always shows every segment")
    o = sp.add_argument_group("motion at varying speed (order map)")
    o.add_argument("--order-map", action="store_true",
                   help="also analyse whole motions per direction: amplitude over order and speed (order_map.png, "
                        "order_map.json) and the declared lines of --gear tracked against speed with 95 %% bands "
                        "(order_tracks.png); used automatically when no constant-speed segment is found and "
                        "--gear declares lines")
    o.add_argument("--track", action="append", metavar="FREQ|LABEL", default=None,
                   help="a line to track against speed: a frequency in cycles per unit of theta or a declared "
                        "line's label (repeatable; default with --order-map: every declared line of --gear)")
    o.add_argument("--knots", type=number(0, 20, integer=True), default=4,
                   help="interior knots of the B-splines in speed of a track (default 4)")
    add_output_options(sp)


def run(args) -> int:
    from ..report import write_spectrum_report
    from ..spectrum import analyze

    t0 = time.perf_counter()
    rec = load_from_args(args)
    seg = segments_from_args(rec, args)
    # without constant-speed segments the order map stands in when asked for or when the gear spec
    # declares lines to track; otherwise the refusal says how to ask for it
    no_seg = len(seg) == 0
    if no_seg and not (args.order_map or args.track or rec.gear is not None):
        raise InputError(f"{', '.join(rec.sources)}: no constant-speed segment found (rows: {dict(seg.excluded)}); "
                         "try a larger --rel-tol or a fixed --window, or --order-map to analyse the motion at "
                         "varying speed")
    orders = _order_analysis(rec, args) if (args.order_map or args.track or no_seg) else None
    if no_seg:
        return _orders_only(rec, seg, orders, args, t0)
    result = analyze(rec, segmentation=seg, inertia=not args.no_inertia, max_frequency=args.max_frequency,
                     min_cycles=args.min_cycles, harmonics=args.harmonics, fap_threshold=args.fap,
                     max_peaks=args.max_peaks, method=args.method,
                     # every segment's spectra only when every page is drawn (they take memory of the
                     # order of the samples); the report computes those of the pages it draws
                     keep_spectra=bool(args.out) and args.pages == "all",
                     progress=None if not args.quiet else False)
    st = stages(args)
    st.done(f"spectra of {len(result.segments)} segment(s)")
    if args.json:
        if orders is None:
            result.to_json(args.json)
        else:
            write_json(args.json, {**result.to_dict(), "order_map": orders.to_dict()}, rec, dumps)
        st.done(f"JSON written: {args.json}")
    if args.out:
        write_spectrum_report(result, rec, seg, args.out, command=command_line(), orders=orders, pages=args.pages,
                              stages=st)
        st.done(f"report written: {args.out}")
    if not args.quiet:
        _print_summary(result, time.perf_counter() - t0, args)
        if orders is not None:
            _print_orders(orders)
    return 0


def _order_analysis(rec, args):
    """The order maps and tracks of ``--order-map`` / ``--track`` (or of a recording without plateaus)."""
    from ..spectrum import order_analysis

    st = stages(args)
    st.start("order map over varying speed")
    gear = rec.gear
    lines = args.track if args.track else ([ln.label for ln in gear.declared_lines(1)] if gear is not None else [])
    inertia = 0 if args.no_inertia else None
    res = order_analysis(rec, lines, gear=gear, inertia=inertia, min_speed=args.min_speed, knots=args.knots,
                         map_options={"max_frequency": args.max_frequency} if args.max_frequency else None)
    st.done(f"order maps of {sum(m is not None for m in res.maps.values())} direction(s), "
            f"{len(res.tracks)} track(s)")
    return res


def _orders_only(rec, seg, orders, args, t0) -> int:
    """No constant-speed segment: the order map stands in for the segment spectra (and says so)."""
    from ..report.spectrum import write_order_report

    if all(m is None for m in orders.maps.values()) and not orders.tracks:
        raise InputError(f"{', '.join(rec.sources)}: no constant-speed segment found (rows: {dict(seg.excluded)}) "
                         "and too little motion for an order map; try a larger --rel-tol or a fixed --window")
    note = ("no constant-speed segment found (rows: " + ", ".join(f"{k} {v}" for k, v in sorted(seg.excluded.items()))
            + "): the order map over varying speed was used instead")
    if not args.quiet:
        print(f"gearspec: {note}")
    if args.json:
        write_json(args.json, {"segments": [], "excluded": dict(sorted(seg.excluded.items())), "notes": [note],
                               "order_map": orders.to_dict()}, rec, dumps)
    if args.out:
        write_order_report(orders, rec, args.out, command=command_line(), note=note)
    if not args.quiet:
        print(f"({time.perf_counter() - t0:.1f} s)")
        _print_orders(orders)
        print_outputs(args, as_path=True)
    return 0


def _print_orders(orders) -> None:
    import numpy as np

    unit = orders.unit
    tu = "Nm" if unit == "rad" else "N"
    for t in orders.tracks:
        ok = np.isfinite(t.amplitude)
        if not ok.any():
            continue
        name = (t.label.split(" = ")[0] if t.label else f"{t.frequency:.4g} cycles/{unit}")
        i = np.flatnonzero(ok)
        print(f"track {name} ({'+' if t.direction > 0 else '-'}): amplitude {t.amplitude[i[0]]:.3g} {tu} at "
              f"{t.speed[i[0]]:.3g} {unit}/s to {t.amplitude[i[-1]]:.3g} {tu} at {t.speed[i[-1]]:.3g} {unit}/s")
    for s in orders.skipped:
        print(f"not tracked: {s['what']}: {s['reason']}")


def _print_summary(result, elapsed, args) -> None:
    unit = result.unit
    tu = "Nm" if unit == "rad" else "N"
    print(f"{len(result.segments)} segments; rows: {result.n_rows} read, "
          f"{sum(s.segment.n for s in result.segments)} in segments"
          + "".join(f", {v} {k}" for k, v in sorted(result.excluded.items())) + f"  ({elapsed:.1f} s)")
    if len(result.segments) > MAX_CONSOLE_SEGMENTS:
        _print_groups(result)
    else:
        print(f"{'seg':>3} {'run':>3} {'dir':>3} {'speed':>10} {'n':>8}  strongest lines "
              f"(frequency cycles/{unit}: amplitude {tu})")
        for i, s in enumerate(result.segments):
            top = sorted(s.peaks, key=lambda p: -p.amplitude)[:3]
            txt = "; ".join(f"{p.frequency:.4g}: {p.amplitude:.3g}" + (f" [{_name(p)}]" if p.label else " [?]")
                            for p in top)
            print(f"{i:>3} {s.segment.run:>3} {s.direction:>+3d} {s.speed:>10.4g} {s.segment.n:>8}  {txt}")
    un = result.unexplained()
    if len(un):
        print(result.unexplained_sentence() + "; see the report" + ("" if args.out else " (--out DIR)"))
    print_outputs(args, as_path=True)


def _name(p) -> str:
    return p.label.split(" = ")[0] if p.label else "?"


def _print_groups(result, strongest: int = 3) -> None:
    """One line per speed and direction: segments, the strongest declared lines' median amplitude,
    the significant peaks no declared line fits (the per-segment table is in the report and JSON)."""
    import numpy as np

    unit = result.unit
    tu = "Nm" if unit == "rad" else "N"
    groups = result.speed_groups()
    print(f"summary of {len(groups)} groups of segments at one speed and direction (one line per segment: "
          "the report and --json)")
    print(f"{'dir':>3} {'speed':>10} {'segs':>4}  strongest declared lines (median amplitude {tu}; speed {unit}/s)")
    for d, speed, idx in groups:
        amps: dict[str, list[float]] = {}
        n_found = 0
        for i in idx:
            for p in result.segments[i].peaks:
                if p.declared:
                    amps.setdefault(_name(p), []).append(p.amplitude)
                elif p.fap <= 0.01 and p.label is None:
                    n_found += 1
        top = sorted(((float(np.median(v)), k) for k, v in amps.items()), reverse=True)[:strongest]
        txt = "; ".join(f"{k}: {a:.3g}" for a, k in top) or "no declared line fitted"
        print(f"{d:>+3d} {speed:>10.4g} {len(idx):>4}  {txt}"
              + (f"; {n_found} unexplained peak(s)" if n_found else ""))
