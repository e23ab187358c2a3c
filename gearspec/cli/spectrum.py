"""``gearspec spectrum``: constant-speed segments and their order spectra."""

from __future__ import annotations

import time

from . import (
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
)

#: highest harmonic of the declared lines: the line count (and the time of the harmonic fit, which
#: grows faster than linearly in it) grows with it, and beyond this no drive's ripple is resolved
MAX_HARMONICS = 16
#: most undeclared peaks per segment
MAX_PEAKS = 64


def register(sub) -> None:
    sp = analysis_parser(sub, "spectrum", run, help="constant-speed segments and their order spectra",
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
    add_output_options(sp)


def run(args) -> int:
    from ..report import write_spectrum_report
    from ..spectrum import analyze

    t0 = time.perf_counter()
    rec = load_from_args(args)
    seg = segments_from_args(rec, args)
    result = analyze(rec, segmentation=seg, inertia=not args.no_inertia, max_frequency=args.max_frequency,
                     min_cycles=args.min_cycles, harmonics=args.harmonics, fap_threshold=args.fap,
                     max_peaks=args.max_peaks, method=args.method, keep_spectra=bool(args.out),
                     progress=None if not args.quiet else False)
    stages(args).done(f"spectra of {len(result.segments)} segment(s)")
    if args.json:
        result.to_json(args.json)
    if args.out:
        write_spectrum_report(result, rec, seg, args.out, command=command_line())
    if not args.quiet:
        _print_summary(result, time.perf_counter() - t0, args)
    return 0


def _print_summary(result, elapsed, args) -> None:
    unit = result.unit
    tu = "Nm" if unit == "rad" else "N"
    print(f"{len(result.segments)} segments; rows: {result.n_rows} read, "
          f"{sum(s.segment.n for s in result.segments)} in segments"
          + "".join(f", {v} {k}" for k, v in sorted(result.excluded.items())) + f"  ({elapsed:.1f} s)")
    print(f"{'seg':>3} {'run':>3} {'dir':>3} {'speed':>10} {'n':>8}  strongest lines "
          f"(frequency cycles/{unit}: amplitude {tu})")
    for i, s in enumerate(result.segments):
        top = sorted(s.peaks, key=lambda p: -p.amplitude)[:3]
        txt = "; ".join(f"{p.frequency:.4g}: {p.amplitude:.3g}" + (f" [{p.label.split(' = ')[0]}]" if p.label else " [?]")
                        for p in top)
        print(f"{i:>3} {s.segment.run:>3} {s.direction:>+3d} {s.speed:>10.4g} {s.segment.n:>8}  {txt}")
    un = result.unexplained()
    if len(un):
        print(f"{len(un)} significant peak(s) no declared line explains; see the report"
              + ("" if args.out else " (--out DIR)"))
    print_outputs(args, as_path=True)
