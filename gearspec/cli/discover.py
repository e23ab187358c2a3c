"""``gearspec discover``: the sparse-regression explorer for alternative friction laws."""

from __future__ import annotations

import time

from . import (
    COMMAND_HELP,
    PROBABILITY,
    add_motion_option,
    add_output_options,
    analysis_parser,
    command_line,
    load_from_args,
    number,
    print_outputs,
    segments_from_args,
    stages,
)
from .fit import law_choices


def register(sub) -> None:
    sp = analysis_parser(
        sub, "discover", run, help=COMMAND_HELP["discover"],
        description="Search a library of physically meaningful friction terms (Coulomb, viscous, power laws, "
                    "Stribeck of three shapes on a grid of velocities, load- and temperature-coupled terms, "
                    "position ripple at the declared and found lines with constant or decaying amplitude, each "
                    "symmetric and direction-dependent) with sparse regression, refine the candidates' nonlinear "
                    "parameters, and rank them by their error on held-out segments against their complexity. "
                    "Compares them with the papers' laws fitted on the same folds.")
    g = sp.add_argument_group("library")
    g.add_argument("--frequencies", metavar="F1,F2,...",
                   help="extra ripple lines, cycles per unit of theta (besides the gear's declared lines)")
    g.add_argument("--no-declared", action="store_true", help="leave out the gear spec's declared lines")
    g.add_argument("--no-spectrum", action="store_true",
                   help="do not run the spectrum analysis for lines the gear spec does not declare")
    g.add_argument("--spectrum-fap", type=PROBABILITY, default=1e-3,
                   help="false-alarm probability for a found line to enter the library (default 1e-3)")
    g.add_argument("--families", metavar="NAME,...",
                   help="library families to use (default: all the data allow; see the report for the names)")
    g.add_argument("--stribeck-grid", type=number(1, 50, integer=True), default=5, help="Stribeck velocities per shape (default 5)")
    g.add_argument("--decay-grid", type=number(1, 50, integer=True), default=3, help="decay constants per ripple amplitude law (default 3)")
    g.add_argument("--symmetric", action="store_true", help="symmetric terms only (no direction dependence)")
    g.add_argument("--no-acceleration-term", dest="no_inertia_term", action="store_true",
                   help="no residual-inertia (acceleration) column in the library")
    add_motion_option(g)
    s = sp.add_argument_group("search and selection")
    s.add_argument("--optimizer", choices=("stlsq", "sr3"), default="stlsq", help="pysindy optimiser (default stlsq)")
    s.add_argument("--alpha", type=number(0), default=1e-4, help="STLSQ ridge weight, relative (default 1e-4)")
    s.add_argument("--thresholds", type=number(2, 1000, integer=True), default=24, help="thresholds on the path (default 24)")
    s.add_argument("--folds", type=number(2, 100, integer=True), default=5, help="cross-validation folds (default 5)")
    s.add_argument("--by", choices=("segment", "run"), default="segment",
                   help="hold out whole segments or whole runs (default segment)")
    s.add_argument("--se-rule", type=number(0), default=4.0,
                   help="select the simplest law within this many standard errors of the best held-out error "
                        "(default 4)")
    s.add_argument("--test-alpha", type=PROBABILITY, default=0.01,
                   help="level of the held-out test every line and every term of the selected law must pass "
                        "(Bonferroni over the candidates tried; diagnose's --alpha, default 0.01)")
    s.add_argument("--min-gain", type=number(0, 1, high_open=True), default=0.005,
                   help="smallest relative fall of the held-out rmse worth a term (diagnose's, default 0.005)")
    s.add_argument("--validate", metavar="RECORDING", nargs="+",
                   help="an independent recording (same columns and gear): every term of the selected law must "
                        "also lower the error there, or it is removed")
    s.add_argument("--max-terms", type=number(1, 200, integer=True), default=12, help="most terms in a law (default 12)")
    s.add_argument("--bootstrap", type=number(0, 10000, integer=True), default=50,
                   help="segment-bootstrap replicates for inclusion probabilities (default 50; 0: none)")
    s.add_argument("--no-local-search", action="store_true", help="only the sparse-regression path's laws")
    s.add_argument("--compare", default=",".join(law_choices()),
                   help="papers' laws to fit on the same folds (comma-separated; 'none' for none)")
    s.add_argument("--no-published", action="store_true", help="leave out published models of the data set (EMPS)")
    s.add_argument("--seed", type=int, default=0, help="of the bootstrap")
    add_output_options(sp)
    sp.add_argument("--top", type=number(1, integer=True), default=8, help="laws shown on stdout (default 8)")


def _floats(text: str | None, option: str) -> list[float]:
    from ..errors import InputError

    if not text:
        return []
    out = []
    for part in text.split(","):
        try:
            out.append(float(part))
        except ValueError:
            raise InputError(f"{option}: '{part}' is not a number (give frequencies in cycles per unit of theta, "
                             "comma-separated)") from None
    return out


def run(args) -> int:
    from ..discover import PAPER_LAWS, discover, published_models
    from ..errors import InputError
    from ..fitdata import FitData
    from ..segment import free_motion
    from ..report.discover import write_discover_report

    t0 = time.perf_counter()
    freqs = _floats(args.frequencies, "--frequencies")
    compare = [] if args.compare.strip().lower() == "none" else [c.strip() for c in args.compare.split(",") if c.strip()]
    bad = [c for c in compare if c not in PAPER_LAWS]
    if bad:
        raise InputError(f"--compare: unknown law(s) {', '.join(bad)} (known: {', '.join(PAPER_LAWS)}, or 'none')")
    rec = load_from_args(args)
    seg = segments_from_args(rec, args)
    data = FitData.from_recording(rec, free_motion(rec, seg, motion=args.motion), inertia=not args.no_inertia)
    spectrum = None
    if not args.no_spectrum and data.theta is not None:
        from ..spectrum import analyze

        stages(args).done(f"{len(data)} samples in {data.n_segments} segments prepared")
        spectrum = analyze(rec, segmentation=seg, inertia=not args.no_inertia, keep_spectra=False, progress=False,
                           fap_threshold=args.spectrum_fap)
        stages(args).done(f"spectrum of {len(spectrum.segments)} segments searched for lines")
    validation = None
    if args.validate:
        vrec = load_from_args(args, args.validate)
        vseg = segments_from_args(vrec, args)
        validation = FitData.from_recording(vrec, free_motion(vrec, vseg, motion=args.motion),
                                            inertia=not args.no_inertia)
    options = {"n_stribeck": args.stribeck_grid, "n_decay": args.decay_grid,
               "directions": "sym" if args.symmetric else "auto"}
    if args.families:
        options["families"] = [f.strip() for f in args.families.split(",") if f.strip()]
    result = discover(data, frequencies=freqs, gear=None if args.no_declared else rec.gear, spectrum=spectrum,
                      library_options=options, optimizer=args.optimizer, alpha=args.alpha,
                      thresholds=args.thresholds, folds=args.folds, by=args.by, n_models=args.bootstrap,
                      max_parts=args.max_terms, se_rule=args.se_rule, local_search=not args.no_local_search,
                      references=compare, published=None if args.no_published else published_models(rec.gear),
                      inertia=not args.no_inertia_term and "auto", seed=args.seed, test_alpha=args.test_alpha,
                      min_gain=args.min_gain, validation=validation, progress=stages(args).done)
    stages(args).done(f"{len(result.candidates)} laws scored")
    if args.json:
        result.to_json(args.json)
    if args.out:
        write_discover_report(result, rec, args.out, command=command_line())
    if not args.quiet:
        _print_summary(result, time.perf_counter() - t0, args)
    return 0


def _print_summary(result, elapsed, args) -> None:
    M = result.moments
    print(f"{M.N} samples in {M.S} segments; library of {len(result.library)} columns; "
          f"{len(result.candidates)} laws scored on held-out {result.settings['by']}s ({elapsed:.1f} s)")
    lines = result.summary().splitlines()[1:]
    front = lines[1:1 + len(result.front)]
    if len(front) > args.top:
        keep = sorted(set(range(len(front) - args.top, len(front))) | {result.front.index(result.selected)})
        front = [front[i] for i in keep]
    print("\n".join([lines[0]] + front + lines[1 + len(result.front):]))
    print_outputs(args, as_path=True)
