"""``gearspec simulate silo4|lola --out DIR``: a twin's recording (``<name>.csv``, or by ``--format``),
the gear spec to read it with (``<name>_gear.toml``), the truth (``<name>_truth.json``: the model
simulated, the effects injected, every setting) and, for the testbed, its operating points
(``<name>_points.csv``, eqs. 12-13), so that ``gearspec spectrum`` reads them back.  ``--profile`` drives
either twin through a whole motion (``gearspec.simulate.profiles``) instead of its plateaus."""

from __future__ import annotations

import time
from pathlib import Path

from ..errors import InputError
from ..simulate.profiles import PROFILES, SHAPES
from . import COMMAND_HELP, number

_FORMATS = ("csv", "parquet", "npz")


def register(sub) -> None:
    sp = sub.add_parser("simulate", help=COMMAND_HELP["simulate"],
                        description="Simulate a test bench whose friction is known and write its recording in the "
                                    "recording format, with the gear spec to read it and the truth as JSON.")
    tw = sp.add_subparsers(dest="twin", metavar="TWIN")
    tw.required = True
    s4 = tw.add_parser("silo4", help="SILO4 leg joint 3: closed-loop speed control, stick-slip, ten repetitions per speed",
                       description="The SILO4 joint-3 bench (Garcia et al. 2002): DC motor, planetary 14, worm 20.5, "
                                   "PID on a 500-line encoder, current through a 1 kHz Bessel filter sampled every "
                                   "4 ms; friction = Table 2's full model (11) plus any --effect.")
    _common(s4, "silo4_twin")
    s4.add_argument("--speeds-rpm", metavar="LIST", help="signed motor speeds in rpm, e.g. 280,-280,3000 "
                    "(default: 20 speeds from 2 to 6500 rpm, both directions)")
    s4.add_argument("--speeds", metavar="LIST", help="signed motor speeds in rad/s (instead of --speeds-rpm)")
    s4.add_argument("--repetitions", type=int, default=10,
                    help="runs per speed, or of the --profile (default 10, as in the paper)")
    s4.add_argument("--duration", type=float, help="seconds held at each speed (default: one output revolution, "
                    "3-10 s); with --profile: seconds of the profile per run (default 40)")
    _profile_option(s4)
    s4.add_argument("--top-speed-rpm", type=number(0, low_open=True), metavar="RPM",
                    help="with --profile: top motor speed, both directions (default 6500 rpm)")
    s4.add_argument("--scatter", type=number(0, 0.5, high_open=True), default=0.0, metavar="FRACTION",
                    help="repetition scatter: Coulomb, static and viscous friction and every line amplitude vary "
                         "from run to run by this relative standard deviation, each on its own (e.g. 0.03; "
                         "default 0); the truth JSON holds the run-mean model and every run's factors")
    s4.add_argument("--stick-slip", action="store_true",
                    help="instead, one creeping run at 1e-4 rad/s of the joint (the paper's Fig. 3), 30 s, "
                         "with the true velocity")
    s4.set_defaults(func=run_silo4)
    lo = tw.add_parser("lola", help="Lola/CROPS testbed: quasi-static grid of motor speeds x brake loads",
                       description="The Lola/CROPS friction testbed: a speed-controlled drive module loaded by a "
                                   "PI-controlled hysteresis brake, points held several seconds; friction = law (11) "
                                   "with Table IV's values plus any --effect.")
    _common(lo, "lola_{module}_twin")
    lo.add_argument("--module", default="A", type=str.upper, choices=("A", "B", "C"), help="drive module (Table II)")
    lo.add_argument("--speeds", metavar="LIST", help="signed motor speeds in rad/s (default: 8 per direction over the "
                    "module's range)")
    lo.add_argument("--loads", metavar="LIST", help="load torques in Nm at the output (default: 8 from 5 %% to 80 %% "
                    "of the nominal output torque)")
    lo.add_argument("--hold", type=float, help="seconds per operating point (default 5)")
    _profile_option(lo)
    lo.add_argument("--top-speed", type=number(0, low_open=True), metavar="RAD_S",
                    help="with --profile: top motor speed in rad/s, both directions (default: the module's top, "
                         "400 rad/s for A and C, 290 for B)")
    lo.add_argument("--duration", type=number(0, low_open=True), metavar="S",
                    help="with --profile: seconds of the profile per load (default 20)")
    lo.set_defaults(func=run_lola)


def _profile_option(p) -> None:
    shapes = "; ".join(f"{k}: {v}" for k, v in SHAPES.items() if k != "plateaus")
    p.add_argument("--profile", choices=PROFILES, default="plateaus",
                   help=f"motion of each run: plateaus (default: the twin's speed grid), or {shapes}. Every profile "
                        f"starts and ends at rest and reaches the top speed in both directions")
    p.add_argument("--profile-options", metavar="K=V,...",
                   help="the profile's own options, e.g. f0=0.05,f1=1,method=log (chirp, Hz); peaks=1;0.3,shares=1;1 "
                        "(bell, ';' between values); rest=2 (ramp, bell, s); harmonics=3,base=0.2,taper=0.3,seed=4 "
                        "(sine)")


def _common(p, default_name: str) -> None:
    p.add_argument("--out", required=True, metavar="DIR", help="folder to write the recording, gear spec and truth into")
    p.add_argument("--name", default=default_name, help=f"base name of the files (default {default_name})")
    p.add_argument("--format", choices=_FORMATS, default="csv", help="recording file format (default csv)")
    p.add_argument("--effect", action="append", default=[], metavar="NAME:K=V,...",
                   help="inject an effect the declared model lacks (repeatable), e.g. cogging:count=7,amplitude=2e-4; "
                        "names: cogging, extra_order, sideband, load_meshing, warming, drift, decay_shape, "
                        "nonlinear_viscous, asymmetry, hysteresis, backlash, extra_inertia")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--quiet", action="store_true", help="no summary on stdout")


def _options(args) -> dict | None:
    """``--profile-options k=v,...``: numbers where they parse (``;`` between the values of a list),
    else words; refused with a motion profile absent or a pair without ``=``."""
    if args.profile_options is None:
        return None
    if args.profile == "plateaus":
        raise InputError("--profile-options applies to a motion --profile (ramp, chirp, bell, sine), not to plateaus")
    out = {}
    for pair in filter(None, (x.strip() for x in args.profile_options.split(","))):
        key, eq, text = pair.partition("=")
        if not eq or not key.strip():
            raise InputError(f"--profile-options: '{pair}' is not KEY=VALUE (e.g. f1=0.5)")
        vals = [_word(x) for x in text.split(";")]
        out[key.strip()] = vals[0] if len(vals) == 1 else vals
    return out


def _word(text: str):
    text = text.strip()
    try:
        value = float(text)
    except ValueError:
        return text
    return int(value) if value.is_integer() and "." not in text and "e" not in text.lower() else value


def _floats(text: str | None, option: str):
    if text is None:
        return None
    try:
        vals = [float(x) for x in text.replace(";", ",").split(",") if x.strip()]
    except ValueError:
        raise InputError(f"{option}: '{text}' is not a comma-separated list of numbers") from None
    if not vals:
        raise InputError(f"{option}: no values given")
    return vals


def _write(args, name: str, rec, truth, elapsed: float, extra=None) -> None:
    """Write the recording, its gear spec, the truth and ``extra`` CSVs into --out, and say what."""
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"recording": rec.save(out / f"{name}.{args.format}"), "gear": out / f"{name}_gear.toml"}
    truth.gear.to_toml(paths["gear"])
    paths["truth"] = truth.to_json(out / f"{name}_truth.json")
    for k, (suffix, frame) in (extra or {}).items():
        paths[k] = out / f"{name}_{suffix}"
        frame.to_csv(paths[k], index=False, float_format="%.10g")
    if args.quiet:
        return
    print(f"{truth.twin} twin: {len(rec)} rows, {rec.data['run'].nunique()} runs, {rec.data['t'].iloc[-1]:.1f} s of "
          f"experiment ({elapsed:.1f} s to simulate)")
    for e in truth.effects:
        f = "" if e["frequency"] is None else f" at {e['frequency']:.6g} cycles/rad"
        print(f"  effect: {e['kind']}{f}: {e['description']}")
    if getattr(truth, "scatter", None):
        print(f"  repetition scatter: {100 * truth.scatter['fraction']:.3g} % per run on "
              f"{len(truth.scatter['parameters'])} parameters (truth: run-mean model and every run's factors)")
    for k, p in paths.items():
        print(f"{k}: {p}")
    print(f"read it with: gearspec spectrum {paths['recording']} --gear {paths['gear']}")


def _effects(args):
    from ..simulate.effects import parse_effect

    return [parse_effect(e) for e in args.effect]


def run_silo4(args) -> int:
    from ..model import RPM
    from ..simulate.silo4 import silo4_twin, stick_slip_run

    if args.speeds is not None and args.speeds_rpm is not None:
        raise InputError("give --speeds (rad/s) or --speeds-rpm, not both")
    if args.repetitions < 1:
        raise InputError("--repetitions must be at least 1")
    speeds = _floats(args.speeds_rpm, "--speeds-rpm")
    if args.speeds is not None:
        speeds = [s / RPM for s in _floats(args.speeds, "--speeds")]
    if speeds is not None and any(s == 0 for s in speeds):
        raise InputError("--speeds: a speed of 0 is no experiment; give nonzero signed speeds")
    if args.duration is not None and not args.duration > 0:
        raise InputError("--duration must be positive (seconds)")
    if args.profile == "plateaus" and args.top_speed_rpm is not None:
        raise InputError("--top-speed-rpm applies to a motion --profile (ramp, chirp, bell, sine), not to plateaus")
    if args.profile != "plateaus" and (speeds is not None or args.stick_slip):
        raise InputError(f"--profile {args.profile} sets its own speeds: give --top-speed-rpm, not --speeds, "
                         "--speeds-rpm or --stick-slip")
    effects, options = _effects(args), _options(args)
    t0 = time.perf_counter()
    if args.stick_slip:
        rec, truth = stick_slip_run(duration=args.duration or 30.0, seed=args.seed, effects=effects,
                                    scatter=args.scatter)
    else:
        extra = {} if args.profile == "plateaus" else {"profile": args.profile, "top_speed_rpm": args.top_speed_rpm,
                                                       "profile_options": options}
        rec, truth = silo4_twin(speeds, repetitions=args.repetitions, duration=args.duration, effects=effects,
                                seed=args.seed, scatter=args.scatter, **extra)
    _write(args, args.name, rec, truth, time.perf_counter() - t0)
    return 0


def run_lola(args) -> int:
    from ..simulate.lola import lola_twin

    if args.hold is not None and not args.hold > 0:
        raise InputError("--hold must be positive (seconds)")
    if args.profile == "plateaus" and (args.top_speed is not None or args.duration is not None):
        raise InputError("--top-speed and --duration apply to a motion --profile (ramp, chirp, bell, sine), not to "
                         "the plateau grid (use --speeds and --hold)")
    if args.profile != "plateaus" and (args.speeds is not None or args.hold is not None):
        raise InputError(f"--profile {args.profile} sets its own speeds: give --top-speed and --duration, not --speeds "
                         "or --hold")
    effects, options = _effects(args), _options(args)
    name = args.name.format(module=args.module)
    extra = {} if args.profile == "plateaus" else {"profile": args.profile, "top_speed": args.top_speed,
                                                   "duration": args.duration, "profile_options": options}
    t0 = time.perf_counter()
    rec, points = lola_twin(args.module, _floats(args.speeds, "--speeds"), _floats(args.loads, "--loads"),
                            hold=args.hold, effects=effects, seed=args.seed, **extra)
    _write(args, name, rec, points.attrs["truth"], time.perf_counter() - t0, {"points": ("points.csv", points)})
    return 0
