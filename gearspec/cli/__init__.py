"""The ``gearspec`` command line (``CONTRACTS.md`` section 4; a leaf: nothing imports it): one module per
command with ``register(subparsers)``; here the shared options, the checks of option values at parse
time (one sentence each) and :func:`main`."""

from __future__ import annotations

import argparse
import importlib
import math
import shlex
import sys
import tempfile
import traceback
import warnings
from pathlib import Path

from .. import __version__
from ..errors import GearspecWarning, InputError

__all__ = ["main", "build_parser", "COMMANDS", "COMMAND_HELP", "number", "check_outputs", "analysis_parser"]

#: command modules of this package, in the order ``gearspec --help`` lists them, with the line it
#: gives each (the module's ``register`` passes it to ``add_parser``; :func:`main` lists the
#: commands without importing their modules)
COMMAND_HELP = {
    "spectrum": "constant-speed segments and their order spectra",
    "fit": "identify a friction law (SILO4 eq. 11, eq. 3, Lola laws 8 and 11)",
    "diagnose": "find what the model misses: residual -> effect -> new term -> held-out error",
    "discover": "search a library of friction terms for the laws the data support",
    "simulate": "twin recordings with known friction (SILO4 joint 3, Lola/CROPS testbed)",
    "repro": "reproduce a paper's figures and tables (silo4, lola, emps)",
    "gears": "list gear presets or describe a gear spec",
    "data": "the registry of real data sets",
    "demo": "run the main analysis on built-in data and write a report",
    "export": "export a fitted model for a controller: C99, YAML, lookup tables, JSON",
    "compensate": "a fitted model as friction feed-forward in a twin's speed loop: ripple and tracking error "
                  "without / Coulomb+viscous / the model",
    "batch": "fit many recordings and joints (on Dask) and report the fleet",
    "formats": "the input and output formats (recording columns, gear spec, JSON)",
}
COMMANDS = tuple(COMMAND_HELP)
#: longest message printed for a refusal (a message listing thousands of names helps nobody)
MAX_MESSAGE = 600


_SHOWN: set = set()


def _show_warning(message, category, filename, lineno, file=None, line=None):
    """One line a warning; the same sentence once per command (a finding about the data, such as
    an inverted torque sign, reached by each of the models a command fits)."""
    prefix = "gearspec: warning" if issubclass(category, GearspecWarning) else f"warning: {category.__name__}"
    text = f"{prefix}: {_one_line(message)}"
    if text not in _SHOWN:
        _SHOWN.add(text)
        print(text, file=sys.stderr if file is None else file)


def _one_line(message) -> str:
    text = " ".join(str(message).split())
    return text if len(text) <= MAX_MESSAGE else text[:MAX_MESSAGE - 5] + " ..."


class _Parser(argparse.ArgumentParser):
    """argparse with gearspec's one-line refusals (exit 2) instead of usage + message."""

    def error(self, message):
        self.exit(2, f"gearspec: error: {self.prog}: {_one_line(message)} (see {self.prog} --help)\n")


def number(low: float | None = None, high: float | None = None, *, integer: bool = False,
           low_open: bool = False, high_open: bool = False, what: str = ""):
    """An argparse ``type`` for a number within bounds, refused at parse time with one sentence.

    ``number(0, low_open=True)``: a positive number; ``number(0, 1, low_open=True, high_open=True)``:
    a probability strictly between 0 and 1; ``number(1, 64, integer=True)``: an integer from 1 to 64.
    """

    def parse(text: str):
        kind = "an integer" if integer else "a number"
        try:
            value = int(text) if integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"'{text}' is not {kind}") from None
        if not integer and not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"'{text}' is not a finite number")
        bad_low = low is not None and (value <= low if low_open else value < low)
        bad_high = high is not None and (value >= high if high_open else value > high)
        if bad_low or bad_high:
            lo = "" if low is None else f"{'above' if low_open else 'at least'} {low:g}"
            hi = "" if high is None else f"{'below' if high_open else 'at most'} {high:g}"
            rng = " and ".join(x for x in (lo, hi) if x)
            raise argparse.ArgumentTypeError(f"must be {rng}{' ' + what if what else ''}, got {text}")
        return value

    parse.__name__ = "integer" if integer else "number"
    return parse


def _window(text: str):
    if text == "auto":
        return text
    try:
        float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is neither 'auto' nor a time in s") from None
    return number(0, low_open=True, what="(a speed window in s, or 'auto')")(text)


def _separator(text: str) -> str:
    if text == "":
        raise argparse.ArgumentTypeError("the separator is empty; give a character such as ';' or 'whitespace'")
    return text


#: positive numbers
POSITIVE = number(0, low_open=True)
#: strictly between 0 and 1 (probabilities, levels)
PROBABILITY = number(0, 1, low_open=True, high_open=True)


def check_outputs(args) -> None:
    """Refuse, before any analysis, an ``--out`` folder or a ``--json`` file that cannot be written."""
    for option, kind in (("json", "file"), ("out", "folder")):
        value = getattr(args, option, None)
        if not value:
            continue
        path = Path(value)
        if kind == "file" and path.is_dir():
            raise InputError(f"--json {value}: is a folder; give a file name")
        if kind == "folder" and path.exists() and not path.is_dir():
            raise InputError(f"--out {value}: is a file, not a folder")
        # the nearest existing folder must be a folder we may write into
        probe = path if (kind == "folder" and path.is_dir()) else path.parent
        while not probe.exists() and probe != probe.parent:
            probe = probe.parent
        if not probe.is_dir():
            raise InputError(f"--{option} {value}: cannot be written ({probe} is not a folder)")
        try:  # the one sure test (permissions, read-only and virtual file systems): write a file there
            with tempfile.TemporaryFile(dir=probe):
                pass
        except OSError as exc:
            raise InputError(f"--{option} {value}: cannot be written ({probe}: {exc.strerror})") from None


def stages(args):
    """The :class:`~gearspec.progress.Stages` of this run (silent with ``--quiet``)."""
    from ..progress import Stages

    if getattr(args, "_stages", None) is None:
        args._stages = Stages(enabled=not getattr(args, "quiet", False))
    return args._stages


def analysis_parser(sub, name: str, run, **kwargs) -> argparse.ArgumentParser:
    """The parser of an analysing command ``name`` (``kwargs``: help, description) with the recording
    and segment options; the command adds its own groups, then :func:`add_output_options`."""
    p = sub.add_parser(name, **kwargs)
    add_recording_options(p)
    add_segment_options(p)
    p.set_defaults(func=run)
    return p


def add_recording_options(p: argparse.ArgumentParser) -> None:
    """RECORDING... --gear and the column options of CONTRACTS.md section 1."""
    g = p.add_argument_group("recording (columns and units: `gearspec formats recording`)")
    g.add_argument("recordings", nargs="+", metavar="RECORDING",
                   help="recording files (.csv, .parquet, .mat, .npz), ROS bags (.bag, .mcap, .db3, rosbag2 folder) "
                        "or folders; one experiment (run) per file")
    g.add_argument("--gear", metavar="SPEC_OR_PRESET",
                   help="gear spec TOML file or preset name (see `gearspec gears`)")
    g.add_argument("--map", metavar="CANON=NAME,...",
                   help="source column for canonical columns, e.g. theta=qm,torque=vir; "
                        "in a ROS bag another topic's field: temperature=/motor_temperature.temperature")
    g.add_argument("--scale", metavar="COL=FACTOR,...",
                   help="multiply columns after mapping, e.g. torque=35.15 (a factor may name a scalar in a .mat file)")
    g.add_argument("--fs", type=POSITIVE, metavar="HZ", help="sample rate when the files have no time column")
    g.add_argument("--max-gap", type=POSITIVE, metavar="SECONDS",
                   help="a time step longer than this splits a run (default: per run, 5 x its 99th-percentile "
                        "step; reported)")
    g.add_argument("--sep", type=_separator, help="csv separator (default: sniffed; 'whitespace' for blanks)")
    g.add_argument("--decimal", choices=(".", ","), help="csv decimal separator (default '.'); ',' for files "
                   "written as 1,25;3,5 (columns then separated by ';' or tabs)")
    g.add_argument("--no-header", action="store_true", help="csv files have no header row (give --names)")
    g.add_argument("--names", metavar="A,B,...", help="column names for --no-header files")
    g.add_argument("--signal", choices=("torque", "current"), help="channel to analyse when both are present")
    g.add_argument("--topic", default="/joint_states", help="ROS bags: the sensor_msgs/msg/JointState topic "
                   "(default /joint_states); position -> theta, velocity -> velocity, effort -> torque")
    g.add_argument("--joint", metavar="NAME", help="ROS bags: the joint to analyse (needed when the topic carries "
                   "several), e.g. --joint elbow; also the joint looked up in --urdf")
    g.add_argument("--urdf", metavar="FILE", help="robot URDF: without --gear, the joint's <transmission> reduction "
                   "(classic or ros2_control form) is the gear ratio, e.g. robot.urdf --joint elbow")
    g.add_argument("--lag", metavar="SECONDS|auto", help="torque (current) logged this long behind position: shifted "
                   "back; 'auto': estimated from the declared lines' phases across speeds, reported and applied")


def add_output_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("output")
    g.add_argument("--out", metavar="DIR", help="write the report (Markdown + PNG figures + CSV) here")
    g.add_argument("--json", metavar="FILE", help="write the machine-readable result here")
    g.add_argument("--quiet", action="store_true", help="no summary on stdout")


def add_segment_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("segments")
    g.add_argument("--window", type=_window, default="auto", help="speed window in s, or 'auto' (default)")
    g.add_argument("--rel-tol", type=number(0, 1, low_open=True), default=0.15,
                   help="allowed relative speed change (default 0.15)")
    g.add_argument("--min-speed", type=POSITIVE, help="speeds below this (unit/s) are standstill")
    g.add_argument("--min-duration", type=POSITIVE, help="shortest segment kept, s")
    g.add_argument("--no-inertia", action="store_true", help="do not subtract J*thetadd even if the spec gives J")
    g.add_argument("--quasi-static", action=argparse.BooleanOptionalAction, default=None,
                   help="every monotonic sweep of each run is a quasi-static segment (rows taken at rest: torque "
                        "against position, no time derivative); --no-quasi-static: plateaus only; default: recognised")


def add_motion_option(g) -> None:
    """``--motion``: what a fit uses (:func:`gearspec.segment.free_motion`)."""
    g.add_argument("--motion", default="auto", choices=("auto", "plateaus", "free"),
                   help="what to fit: auto (default: plateaus and sweeps, plus free motion -- ramps, moves, chirps -- "
                        "when it holds most of the moving rows; the inertia is then identified unless the gear spec "
                        "gives it), plateaus (plateaus and sweeps only), free (every moving row)")


def load_from_args(args, paths=None):
    """The recording named by the recording options (``paths``: other files read with the same options)."""
    from ..lag import lag_option
    from ..recording import load_recording

    paths = args.recordings if paths is None else paths
    if getattr(args, "joint", None) == "all":
        _refuse_all_joints(args, paths)
    st = stages(args)
    st.start(f"loading {len(paths)} path(s)")
    rec = load_recording(paths, args.gear, map=args.map, scale=args.scale, fs=args.fs, sep=args.sep,
                         header=not args.no_header, names=args.names, signal=args.signal,
                         max_gap=getattr(args, "max_gap", None), topic=getattr(args, "topic", "/joint_states"),
                         joint=getattr(args, "joint", None), urdf=getattr(args, "urdf", None),
                         decimal=getattr(args, "decimal", None))
    st.done(f"loaded {rec.n_read:,} rows from {len(rec.sources)} file(s), {len(rec):,} usable")
    return lag_option(rec, getattr(args, "lag", None), say=lambda s: getattr(args, "quiet", False) or print(s),
                      **{k: getattr(args, k, None) for k in ("window", "rel_tol", "min_speed", "min_duration")})


def _refuse_all_joints(args, paths) -> None:
    """``--joint all`` on a command that analyses one recording: refused, naming the joints."""
    from ..recording.bags import bag_joints, is_bag

    bags = [p for p in paths if is_bag(p)]
    joints = list(dict.fromkeys(j for p in bags for j in bag_joints(p, args.topic))) if bags else []
    raise InputError(f"--joint all: `gearspec {args.command}` analyses one joint at a time; give --joint NAME "
                     f"(joints on {args.topic}: {', '.join(joints) or 'none, no ROS bag given'}) and run it once "
                     "per joint")


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

    st = stages(args)
    st.start("finding segments")
    seg = find_segments(rec, window=args.window if args.window == "auto" else float(args.window),
                        rel_tol=args.rel_tol, min_speed=args.min_speed, min_duration=args.min_duration,
                        quasi_static=getattr(args, "quasi_static", None))
    st.done(f"{len(seg)} segment(s) found, {sum(s.n for s in seg):,} of {rec.n_read:,} rows in them")
    return seg


def command_line() -> str:
    """This run's command line, as the reports quote it."""
    return "gearspec " + shlex.join(sys.argv[1:])


def write_json(path, out: dict, rec, dumps) -> None:
    """``--json``: ``out`` plus the lag ``--lag`` applied (s; with its standard error when estimated)."""
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    out.update({k: rec.meta[k] for k in ("lag", "lag_se") if k in rec.meta})
    Path(path).write_text(dumps(out, indent=1))


def print_html(report) -> None:
    """Name the HTML page written beside the Markdown ``report`` (when it was), as ``html: PATH``."""
    report = str(report)
    page = (report[:-3] if report.endswith(".md") else report) + ".html"
    if Path(page).is_file():
        print(f"html: {page}")


def print_outputs(args, as_path: bool = False) -> None:
    """Say which files were written (``as_path``: the report's path as pathlib prints it)."""
    if args.out:
        report = str(Path(args.out) / "report.md") if as_path else args.out + "/report.md"
        print(f"report: {report}")
        print_html(report)
    if args.json:
        print(f"json: {args.json}")


class _Commands(argparse._SubParsersAction):
    """The sub-commands, each parser built from its module when first needed: ``gearspec --help``
    lists them from :data:`COMMAND_HELP` (no command module imported), ``gearspec NAME ...`` imports
    the module of NAME alone.  The parsers and their help are those of the eager build."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._pending: set[str] = set()

    def add_pending(self, name: str) -> None:
        """List ``name`` with its help line; its parser is built by :meth:`load`."""
        self.add_parser(name, help=COMMAND_HELP[name])
        self._pending.add(name)

    def load(self, name: str) -> argparse.ArgumentParser:
        """The parser of the command ``name``, built by its module's ``register`` (once)."""
        if name in self._pending:
            from .examples import attach

            self._pending.discard(name)
            del self._name_parser_map[name]
            self._choices_actions = [a for a in self._choices_actions if a.dest != name]
            importlib.import_module(f"{__name__}.{name}").register(self)
            # the listing and the choices in the order of COMMANDS, as the eager build has them
            rank = {c: i for i, c in enumerate(COMMANDS)}
            self._choices_actions.sort(key=lambda a: rank.get(a.dest, len(rank)))
            ordered = sorted(self._name_parser_map.items(), key=lambda kv: rank.get(kv[0], len(rank)))
            self._name_parser_map.clear()
            self._name_parser_map.update(ordered)
            attach(self._name_parser_map[name], name)
        return self._name_parser_map[name]

    def __call__(self, parser, namespace, values, option_string=None):
        if values and values[0] in self._pending:
            self.load(values[0])
        super().__call__(parser, namespace, values, option_string)


def build_parser(lazy: bool = False) -> argparse.ArgumentParser:
    """The ``gearspec`` parser.  ``lazy``: a command's parser (and module) only when the command is
    named (:func:`main`: start-up without the analysis libraries); default every parser built."""
    p = _Parser(prog="gearspec", description="Spectral analysis and modelling of friction in robot gear drives.")
    p.add_argument("--version", action="version", version=f"gearspec {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", action=_Commands)
    for name in COMMANDS:
        if lazy:
            sub.add_pending(name)
        else:
            importlib.import_module(f"{__name__}.{name}").register(sub)
    from .examples import attach

    attach(p)
    return p


def main(argv=None) -> int:
    parser = build_parser(lazy=True)
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, --version, or a refused option value (one line printed)
        return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 2)
    if not getattr(args, "command", None):
        parser.print_help()
        return 2
    import numpy as np

    with warnings.catch_warnings(), np.errstate(all="ignore"):
        _SHOWN.clear()
        warnings.showwarning = _show_warning
        warnings.simplefilter("always", GearspecWarning)
        # numerical noise of runs that succeed (empty means, 0/0 already handled) is not the
        # user's business; what matters reaches them as a GearspecWarning or an InputError
        warnings.simplefilter("ignore", RuntimeWarning)
        try:
            check = getattr(args, "check", None)
            if check is not None:
                check(parser, args)
            check_outputs(args)
            return int(args.func(args) or 0)
        except InputError as exc:
            print(f"gearspec: error: {_one_line(exc)}", file=sys.stderr)
            return 2
        except KeyboardInterrupt:
            print("gearspec: interrupted", file=sys.stderr)
            return 1
        except Exception:  # an internal failure, not the user's fault
            traceback.print_exc()
            print("gearspec: internal error (a bug in gearspec; please report it with the command line above)",
                  file=sys.stderr)
            return 1
