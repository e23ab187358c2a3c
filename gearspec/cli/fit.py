"""``gearspec fit``: identify a friction law from a recording (CONTRACTS.md section 4)."""

from __future__ import annotations

import json
import time

from . import (
    COMMAND_HELP,
    POSITIVE,
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


def law_choices(*first: str) -> tuple[str, ...]:
    """The laws a fit can use: every base law of :data:`gearspec.terms.BASE_LAWS` with parameters
    (so a law registered there is accepted), those named in ``first`` first (the order ``--help``
    lists them in)."""
    from ..terms import fittable_laws

    laws = list(fittable_laws())
    return tuple(dict.fromkeys([k for k in first if k in laws] + laws))


def register(sub) -> None:
    p = analysis_parser(sub, "fit", run, help=COMMAND_HELP["fit"],
                        description="Identify a friction law per direction from the constant-speed segments and "
                                    "the free motion (ramps, moves, chirps) of a recording: the joint weighted least-squares fit beside the published procedure "
                                    "and simpler laws, with standard errors and held-out errors.")
    g = p.add_argument_group("fit")
    g.add_argument("--law", default="silo4", choices=law_choices("silo4", "stribeck", "lola8", "lola11"),
                   help="silo4: the full model (11) with direction-dependent parameters (default); stribeck: eq. 3; "
                        "lola8, lola11: the Lola/CROPS laws (need a load channel); coulomb_viscous")
    g.add_argument("--lines", metavar="F,F,...",
                   help="frequencies (cycles per unit of theta) of the lines to fit instead of the gear's declared ones")
    g.add_argument("--holdout", default="segment", choices=("segment", "run"),
                   help="held-out error leaves out whole segments (default) or runs")
    g.add_argument("--folds", type=number(2, 100, integer=True), default=5, help="cross-validation folds (default 5)")
    g.add_argument("--se", default="covariance", choices=("covariance", "bootstrap", "independent"),
                   help="standard errors: cluster-robust over runs (default), a bootstrap over segments, or "
                        "'independent' (the covariance of independent samples, too small on real benches)")
    add_motion_option(g)
    g.add_argument("--no-published", action="store_true", help="skip the SILO4 published procedure")
    g.add_argument("--load-ratio", type=POSITIVE, metavar="N",
                   help="subtract |load|/N from the torque (default for lola laws: the gear's total ratio)")
    add_output_options(p)


def run(args) -> int:
    from ..identify import identify_recording

    t0 = time.perf_counter()
    rec = load_from_args(args)
    seg = segments_from_args(rec, args)
    harmonics = parse_lines(args.lines)
    result = identify_recording(rec, args.law, segmentation=seg, harmonics=harmonics,
                                published=False if args.no_published else None, holdout=args.holdout,
                                folds=args.folds, se=args.se, load_ratio=args.load_ratio, motion=args.motion,
                                inertia=not args.no_inertia)
    st = stages(args)
    st.done(f"fitted {args.law}")
    if args.json:
        write_json(args.json, result.to_dict(), rec, json.dumps)
        st.done(f"JSON written: {args.json}")
    if args.out:
        from ..report.fit import write_fit_report

        st.start("report and figures")
        write_fit_report(result, args.out, command=command_line(), recording_summary=rec.summary(),
                         reference=rec.gear.reference if rec.gear else None)
        st.done(f"report written: {args.out}")
    if not args.quiet:
        print(result.model.describe())
        print()
        print(comparison_text(result.comparison))
        for n in result.notes or []:
            print(f"note: {n}")
        print(f"({time.perf_counter() - t0:.1f} s)")
        print_outputs(args)
    return 0


def comparison_text(comp) -> str:
    """The comparison table as printed: a missing held-out rmse shows as n/a, with its reason below
    (never a number in its place)."""
    import pandas as pd

    show = comp.drop(columns=["rmse_holdout_reason"], errors="ignore")
    for col in ("rmse", "rmse_holdout"):  # None (an object column) prints as n/a like NaN
        if col in show:
            show[col] = pd.to_numeric(show[col], errors="coerce")
    lines = [show.to_string(index=False, na_rep="n/a", float_format=lambda x: f"{x:.4g}")]
    for _, r in comp.iterrows():
        why = r.get("rmse_holdout_reason")
        if isinstance(why, str) and why:
            lines.append(f"held-out rmse {'n/a' if pd.isna(r['rmse_holdout']) else 'partial'} for {r['model']}: {why}")
    return "\n".join(lines)
