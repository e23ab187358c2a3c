"""The ``gearspec`` command line (``CONTRACTS.md`` section 4).  A leaf module.

Exit status: 0 on success, 2 on bad input (one message on stderr), 1 on an internal failure.
"""

from __future__ import annotations

import argparse
import shlex
import sys
import time
import traceback
import warnings
from pathlib import Path

from . import __version__
from .errors import GearspecWarning, InputError

__all__ = ["main"]


def _show_warning(message, category, filename, lineno, file=None, line=None):
    stream = sys.stderr if file is None else file
    if issubclass(category, GearspecWarning):
        print(f"gearspec: warning: {message}", file=stream)
    else:
        print(f"warning: {category.__name__}: {message}", file=stream)


# ---------------------------------------------------------------------- shared options
def _add_recording_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("recording (CONTRACTS.md section 1)")
    g.add_argument("recordings", nargs="+", metavar="RECORDING",
                   help="recording files (.csv, .parquet, .mat, .npz) or folders; one experiment (run) per file")
    g.add_argument("--gear", metavar="SPEC_OR_PRESET",
                   help="gear spec TOML file or preset name (see `gearspec gears`)")
    g.add_argument("--map", metavar="CANON=NAME,...", help="source column for canonical columns, e.g. theta=qm,torque=vir")
    g.add_argument("--scale", metavar="COL=FACTOR,...",
                   help="multiply columns after mapping, e.g. torque=35.15 (a factor may name a scalar in a .mat file)")
    g.add_argument("--fs", type=float, metavar="HZ", help="sample rate when the files have no time column")
    g.add_argument("--sep", help="csv separator (default: sniffed; 'whitespace' for blanks)")
    g.add_argument("--no-header", action="store_true", help="csv files have no header row (give --names)")
    g.add_argument("--names", metavar="A,B,...", help="column names for --no-header files")
    g.add_argument("--signal", choices=("torque", "current"), help="channel to analyse when both are present")


def _add_output_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("output")
    g.add_argument("--out", metavar="DIR", help="write the report (Markdown + PNG figures + CSV) here")
    g.add_argument("--json", metavar="FILE", help="write the machine-readable result here")
    g.add_argument("--quiet", action="store_true", help="no summary on stdout")


def _add_segment_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("segments")
    g.add_argument("--window", default="auto", help="speed window in s, or 'auto' (default)")
    g.add_argument("--rel-tol", type=float, default=0.15, help="allowed relative speed change (default 0.15)")
    g.add_argument("--min-speed", type=float, help="speeds below this (unit/s) are standstill")
    g.add_argument("--min-duration", type=float, help="shortest segment kept, s")
    g.add_argument("--no-inertia", action="store_true", help="do not subtract J*thetadd even if the spec gives J")


def _load(args):
    from .recording import load_recording

    return load_recording(args.recordings, args.gear, map=args.map, scale=args.scale, fs=args.fs, sep=args.sep,
                          header=not args.no_header, names=args.names, signal=args.signal)


# ---------------------------------------------------------------------- commands
def _cmd_spectrum(args) -> int:
    from .report import write_spectrum_report
    from .segment import find_segments
    from .spectrum import analyze

    t0 = time.perf_counter()
    rec = _load(args)
    seg = find_segments(rec, window=args.window if args.window == "auto" else float(args.window),
                        rel_tol=args.rel_tol, min_speed=args.min_speed, min_duration=args.min_duration)
    result = analyze(rec, segmentation=seg, inertia=not args.no_inertia, max_frequency=args.max_frequency,
                     min_cycles=args.min_cycles, harmonics=args.harmonics, fap_threshold=args.fap,
                     max_peaks=args.max_peaks, method=args.method, keep_spectra=bool(args.out),
                     progress=None if not args.quiet else False)
    if args.json:
        result.to_json(args.json)
    if args.out:
        write_spectrum_report(result, rec, seg, args.out, command="gearspec " + " ".join(map(shlex.quote, sys.argv[1:])))
    if not args.quiet:
        _print_spectrum_summary(result, time.perf_counter() - t0, args)
    return 0


def _print_spectrum_summary(result, elapsed, args) -> None:
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
    if args.out:
        print(f"report: {Path(args.out) / 'report.md'}")
    if args.json:
        print(f"json: {args.json}")


def _cmd_gears(args) -> int:
    from .gears import load_gear, presets

    if args.name:
        print(load_gear(args.name).describe())
        return 0
    for name, g in presets().items():
        print(f"{name:<22} {g.name}")
    print("\n`gearspec gears NAME` describes one (or give a TOML file path).")
    return 0


def _cmd_data(args) -> int:
    from . import datasets

    if args.action == "list":
        df = datasets.list_datasets()
        with_pd = df.to_string(index=False)
        print(with_pd)
    elif args.action == "describe":
        print(datasets.describe(args.name))
    elif args.action == "fetch":
        paths = datasets.fetch(args.name, download=True)
        for p in paths.values():
            print(p)
    return 0


def _cmd_demo(args) -> int:
    from .demo import run_demo

    report = run_demo(args.out)
    print(f"demo report: {report}")
    return 0


# ---------------------------------------------------------------------- parser
def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="gearspec", description="Spectral analysis and modelling of friction in "
                                "robot gear drives.")
    p.add_argument("--version", action="version", version=f"gearspec {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")

    sp = sub.add_parser("spectrum", help="constant-speed segments and their order spectra",
                        description="Find constant-speed segments per direction and analyse the torque ripple over "
                                    "position in each: amplitude, phase and standard error at every declared gear "
                                    "line, and peaks no declared line explains.")
    _add_recording_options(sp)
    _add_segment_options(sp)
    g = sp.add_argument_group("spectra")
    g.add_argument("--max-frequency", type=float, help="highest frequency searched, cycles per unit of theta")
    g.add_argument("--min-cycles", type=float, default=1.0, help="cycles a declared line must complete in a segment")
    g.add_argument("--harmonics", type=int, default=1, help="fit declared lines up to this harmonic (default 1)")
    g.add_argument("--fap", type=float, default=0.01, help="false-alarm probability for a found peak (default 0.01)")
    g.add_argument("--max-peaks", type=int, default=8, help="most undeclared peaks per segment (default 8)")
    g.add_argument("--method", default="auto", choices=("auto", "nifty", "astropy", "scipy"),
                   help="Lomb-Scargle implementation")
    _add_output_options(sp)
    sp.set_defaults(func=_cmd_spectrum)

    gp = sub.add_parser("gears", help="list gear presets or describe a gear spec")
    gp.add_argument("name", nargs="?", help="preset name or TOML file")
    gp.set_defaults(func=_cmd_gears)

    dp = sub.add_parser("data", help="the registry of real data sets")
    dp.add_argument("action", choices=("list", "describe", "fetch"))
    dp.add_argument("name", nargs="?")
    dp.set_defaults(func=_cmd_data)

    dm = sub.add_parser("demo", help="run the main analysis on built-in data and write a report")
    dm.add_argument("--out", default="demo-out", help="output folder (default demo-out)")
    dm.set_defaults(func=_cmd_demo)
    return p


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "command", None):
        parser.print_help()
        return 2
    if args.command == "data" and args.action in ("describe", "fetch") and not args.name:
        parser.error(f"gearspec data {args.action} needs a data set name (see `gearspec data list`)")
    warnings.showwarning = _show_warning
    warnings.simplefilter("always", GearspecWarning)
    try:
        return int(args.func(args) or 0)
    except InputError as exc:
        print(f"gearspec: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("gearspec: interrupted", file=sys.stderr)
        return 1
    except Exception:  # an internal failure, not the user's fault
        traceback.print_exc()
        print("gearspec: internal error (a bug in gearspec; please report it with the command line above)",
              file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
