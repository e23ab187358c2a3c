"""``gearspec diagnose``: the closed loop -- baseline model, residual, effects found, terms added,
error before and after on held-out data (CONTRACTS.md section 4)."""

from __future__ import annotations

import time
from types import SimpleNamespace

from ..jsonsafe import dumps
from . import (
    COMMAND_HELP,
    POSITIVE,
    PROBABILITY,
    add_motion_option,
    add_output_options,
    analysis_parser,
    command_line,
    load_from_args,
    number,
    parse_lines,
    print_outputs,
    segments_from_args,
    stages,
    write_json,
)
from .fit import law_choices

KINDS = ("periodic", "speed_law", "load", "temperature", "drift", "asymmetry", "inertia", "hysteresis", "lag", "other")


def register(sub) -> None:
    p = analysis_parser(sub, "diagnose", run,
                        help=COMMAND_HELP["diagnose"],
                        description="Fit the model you believe in, look for structure in its residual (over position, "
                                    "against speed, load, temperature, time, acceleration and near reversals), add a "
                                    "term for an effect only when it lowers the error on held-out data (whole segments "
                                    "or runs) by more than noise would, and repeat until nothing more is accepted.")
    g = p.add_argument_group("model")
    g.add_argument("--law", default="silo4", choices=law_choices("silo4", "stribeck"),
                   help="base law of the baseline model (default silo4: eq. 11 with the gear's declared lines)")
    g.add_argument("--model", metavar="MODEL.json",
                   help="start from this model instead (the `gearspec fit --json` form): its law, lines and terms")
    g.add_argument("--lines", metavar="F,F,...",
                   help="frequencies (cycles per unit of theta) of the lines the baseline fits instead of the declared ones")
    g.add_argument("--symmetric", action="store_true",
                   help="one parameter set for both directions (the loop then tests whether the data want two)")
    add_motion_option(g)
    g.add_argument("--trajectory", action="store_true",
                   help="use every sample of the whole trajectory (inverse dynamic model: filtered position, central "
                        "differences, decimation) instead of the constant-speed segments; the baseline is then "
                        "--law coulomb_viscous with an inertia term")
    g.add_argument("--cutoff", type=POSITIVE, default=100.0, help="--trajectory: Butterworth cut-off, Hz (default 100)")
    g.add_argument("--decimate", type=number(1, integer=True), default=10, help="--trajectory: decimation factor (default 10)")
    g.add_argument("--offset", action="store_true", help="--trajectory: the baseline has a constant force offset too")
    a = p.add_argument_group("acceptance")
    a.add_argument("--holdout", default="segment", choices=("segment", "run"),
                   help="held-out unit: whole segments (default) or runs (trajectories: whole moves)")
    a.add_argument("--folds", type=number(2, 100, integer=True), default=5, help="cross-validation folds (default 5)")
    a.add_argument("--alpha", type=PROBABILITY, default=0.01,
                   help="family-wise level of the held-out test per round (default 0.01)")
    a.add_argument("--min-gain", type=number(0, 1, high_open=True), default=0.005,
                   help="smallest relative fall of the held-out rmse worth a term (default 0.005)")
    a.add_argument("--max-rounds", type=number(0, 100, integer=True), default=8, help="at most this many terms are added (default 8)")
    a.add_argument("--kinds", metavar="K,K,...", help=f"only these effect kinds ({', '.join(KINDS)})")
    a.add_argument("--validate", metavar="RECORDING", nargs="+",
                   help="independent recording(s), read with the same column options: every accepted term must also "
                        "lower the error there, or it is removed again")
    add_output_options(p)


def run(args) -> int:
    from .. import diagnose as dg
    from ..diagnose.results import verdict_line
    from ..errors import InputError
    from ..model import FrictionModel

    t0 = time.perf_counter()
    kinds = None
    if args.kinds:
        kinds = [k.strip() for k in args.kinds.split(",") if k.strip()]
        bad = [k for k in kinds if k not in KINDS]
        if bad:
            raise InputError(f"--kinds: unknown kind(s) {', '.join(bad)} (known: {', '.join(KINDS)})")
    harmonics = parse_lines(args.lines)

    def prepare(r):  # the whole trajectory, or the constant-speed segments of a recording
        if args.trajectory:
            return dg.trajectory_data(r, cutoff=args.cutoff, decimate_by=args.decimate)
        return dg.DiagnoseData.from_recording(r, segments_from_args(r, args), by=args.holdout,
                                              inertia=not args.no_inertia, motion=args.motion)

    rec = load_from_args(args)
    data = prepare(rec)
    # what the outputs read of the recording (its summary, its lag): its samples are let go before the loop
    summary, lag = rec.summary(), SimpleNamespace(meta=rec.meta)
    del rec
    validation = prepare(load_from_args(args, args.validate)) if args.validate else None
    model = None
    if args.model:
        model = FrictionModel.from_json(args.model)
        if model.unit != data.unit:
            raise InputError(f"{args.model}: the model is for theta in {model.unit}, the recording has {data.unit}")
    elif args.trajectory:
        args.law = "coulomb_viscous"
        terms = [{"kind": "inertia", "inertia": 0.0}] + ([{"kind": "offset", "offset": 0.0}] if args.offset else [])
        model = dg.baseline_model(data, "coulomb_viscous", symmetric=args.symmetric, terms=terms)
    # a model read from a file keeps its own symmetry unless --symmetric; otherwise per direction
    symmetric = True if args.symmetric else (None if args.model else False)
    unit, torque_unit = data.unit, data.torque_unit
    box, data = [data], None     # the loop alone holds the data (a long recording's untrimmed copy is freed)
    diag = dg.diagnose(box.pop(), model, law=args.law, harmonics=harmonics, symmetric=symmetric,
                       folds=args.folds, alpha=args.alpha, min_gain=args.min_gain, max_rounds=args.max_rounds,
                       kinds=kinds, validation=validation,
                       progress=None if args.quiet else (lambda s: print(s, flush=True)))
    stages(args).done(f"diagnosis: {sum(e.accepted for e in diag.effects)} effect(s) accepted")
    if args.json:
        write_json(args.json, diag.to_dict(), lag, dumps)
    if args.out:
        from ..report.diagnose import write_diagnose_report

        write_diagnose_report(diag, args.out, command=command_line(), recording_summary=summary)
    if not args.quiet:
        print()
        print(diag.summary_table().to_string(index=False, float_format=lambda x: f"{x:.4g}"))
        for e in diag.effects:
            # the one decision record of each candidate, as the report and the JSON show it
            print(verdict_line(e, unit, torque_unit))
        for n in diag.notes:
            print(f"note: {n}")
        print(f"({time.perf_counter() - t0:.1f} s)")
        print_outputs(args)
    return 0
