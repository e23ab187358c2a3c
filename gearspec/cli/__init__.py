"""The ``gearspec`` command line (``CONTRACTS.md`` section 4).  A leaf: nothing imports it.

One module per command (``spectrum``, ``fit``, ...), each with ``register(subparsers)``; this
module holds the options every analysing command shares and :func:`main`.

Exit status: 0 on success, 2 on bad input (one message on stderr), 1 on an internal failure.
"""

from __future__ import annotations

import argparse
import importlib
import sys
import traceback
import warnings

from .. import __version__
from ..errors import GearspecWarning, InputError

__all__ = ["main", "build_parser", "COMMANDS"]

#: command modules of this package, in the order ``gearspec --help`` lists them
COMMANDS = ("spectrum", "fit", "diagnose", "discover", "simulate", "repro", "gears", "data", "demo")


def _show_warning(message, category, filename, lineno, file=None, line=None):
    stream = sys.stderr if file is None else file
    if issubclass(category, GearspecWarning):
        print(f"gearspec: warning: {message}", file=stream)
    else:
        print(f"warning: {category.__name__}: {message}", file=stream)


# ---------------------------------------------------------------------- shared options
def add_recording_options(p: argparse.ArgumentParser) -> None:
    """RECORDING... --gear and the column options of CONTRACTS.md section 1."""
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
    g.add_argument("--lag", metavar="SECONDS|auto", help="torque (current) logged this long behind position: shifted "
                   "back; 'auto': estimated from the declared lines' phases across speeds, reported and applied")


def add_output_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("output")
    g.add_argument("--out", metavar="DIR", help="write the report (Markdown + PNG figures + CSV) here")
    g.add_argument("--json", metavar="FILE", help="write the machine-readable result here")
    g.add_argument("--quiet", action="store_true", help="no summary on stdout")


def add_segment_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("segments")
    g.add_argument("--window", default="auto", help="speed window in s, or 'auto' (default)")
    g.add_argument("--rel-tol", type=float, default=0.15, help="allowed relative speed change (default 0.15)")
    g.add_argument("--min-speed", type=float, help="speeds below this (unit/s) are standstill")
    g.add_argument("--min-duration", type=float, help="shortest segment kept, s")
    g.add_argument("--no-inertia", action="store_true", help="do not subtract J*thetadd even if the spec gives J")
    g.add_argument("--quasi-static", action=argparse.BooleanOptionalAction, default=None,
                   help="every monotonic sweep of each run is a quasi-static segment (rows taken at rest: torque "
                        "against position, no time derivative); --no-quasi-static: plateaus only; default: recognised")


def load_from_args(args):
    """The recording named by the recording options."""
    from ..recording import load_recording

    from ..lag import lag_option

    rec = load_recording(args.recordings, args.gear, map=args.map, scale=args.scale, fs=args.fs, sep=args.sep,
                         header=not args.no_header, names=args.names, signal=args.signal)
    return lag_option(rec, getattr(args, "lag", None), say=lambda s: getattr(args, "quiet", False) or print(s),
                      **{k: getattr(args, k, None) for k in ("window", "rel_tol", "min_speed", "min_duration")})


def parse_lines(text: str | None) -> list[float] | None:
    """``--lines F,F,...``: frequencies in cycles per unit of theta (None when not given)."""
    if not text:
        return None
    try:
        return [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise InputError(f"--lines takes frequencies separated by commas, got '{text}'") from None


def segments_from_args(rec, args):
    """Constant-speed segments with the segment options."""
    from ..segment import find_segments

    return find_segments(rec, window=args.window if args.window == "auto" else float(args.window),
                         rel_tol=args.rel_tol, min_speed=args.min_speed, min_duration=args.min_duration,
                         quasi_static=getattr(args, "quasi_static", None))


# ---------------------------------------------------------------------- parser
def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="gearspec", description="Spectral analysis and modelling of friction in "
                                "robot gear drives.")
    p.add_argument("--version", action="version", version=f"gearspec {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        importlib.import_module(f"{__name__}.{name}").register(sub)
    return p


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "command", None):
        parser.print_help()
        return 2
    check = getattr(args, "check", None)
    if check is not None:
        check(parser, args)
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
