#!/usr/bin/env python
"""Speed of FrictionModel.evaluate on the SILO4 model (issue 14 item 3), against a bare numpy
expression of the same law measured in the same run (see benchmarks/README.md).

    python benchmarks/bench_evaluate.py              # 10^3, 10^5 and 10^7 points (about a minute)
    python benchmarks/bench_evaluate.py --quick      # 10^3, 10^5 and 10^6 points, smoke run
    python benchmarks/bench_evaluate.py --json out.json

Two models, both law ``silo4`` with the three declared lines of the ``silo4-joint3`` gear (output
shaft, planetary output shaft, motor shaft), different parameters per direction:

- ``table2``: :func:`gearspec.simulate.silo4.table2_model` (the paper's Table 2; the twin's truth);
- ``fitted``: what ``gearspec fit --law silo4`` identified on the SILO4 twin (the file
  ``tests/data/models_0.4.1.json``; its lines carry speed ranges and the const and exp amplitude
  laws, its negative direction lacks the Stribeck part), or with ``--fit`` a fit run now on a short
  twin.

The baseline is the law written out in numpy for those models (``_bare`` below): per direction a
mask, the Stribeck curve, each line ``A g(|v|) sin(2 pi f theta + phi)`` with ``|v|`` held within
the line's speed range.  Inputs: theta uniform over three output revolutions (0..5410 motor rad),
|v| log-uniform over 0.1..400 rad/s (about 1..3800 motor rpm), both directions at random.

Times are CPU seconds of this process (``time.process_time``, best of ``--repeat``): on a shared
machine they do not count the time other processes hold the CPU, which wall-clock time would.
Prints per model and size: evaluations per second of evaluate and of the baseline, their ratio, and
the largest difference between the two (relative to the largest torque); then the cost of one call
on a scalar and on 32 points (the twin's vector of runs).  Target: >= 10^7 evaluations per second
of evaluate at 10^7 points (MET / NOT MET).  The script informs; it exits 0 when it ran.
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from gearspec.model import FrictionModel  # noqa: E402
from gearspec.simulate.silo4 import table2_model  # noqa: E402

TARGET = 1e7


def _parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--quick", action="store_true", help="10^3, 10^5, 10^6 points")
    p.add_argument("--sizes", default=None, help="comma-separated numbers of points (default 1e3,1e5,1e7)")
    p.add_argument("--repeat", type=int, default=3, help="timed runs per measurement, best taken (default 3)")
    p.add_argument("--fit", action="store_true", help="fit the 'fitted' model now on a short SILO4 twin")
    p.add_argument("--json", default=None, metavar="PATH", help="also write the numbers as JSON")
    p.add_argument("--seed", type=int, default=20261124)
    args = p.parse_args(argv)
    sizes = args.sizes or ("1e3,1e5,1e6" if args.quick else "1e3,1e5,1e7")
    args.sizes = [int(float(s)) for s in sizes.split(",")]
    return args


def fitted_model(fit_now: bool) -> FrictionModel:
    """The SILO4 law fitted by gearspec on its twin: stored (0.4.1's ``gearspec fit --law silo4``), or fitted now."""
    if not fit_now:
        d = json.loads((ROOT / "tests" / "data" / "models_0.4.1.json").read_text())
        return FrictionModel.from_dict(d["models"]["silo4 joint fit, harmonics with speed_range"]["model"])
    import gearspec
    from gearspec.simulate import silo4_twin

    rec, truth = silo4_twin(speeds_rpm=[200, 500, 1000, 2000, 3000], repetitions=2, seed=1)
    return gearspec.fit(rec, truth.gear, law="silo4").model_


def _bare(model: FrictionModel, theta, v):
    """The SILO4 law of ``model`` in plain numpy (the baseline): per direction a mask, the Stribeck
    curve (Coulomb + viscous where the Stribeck part was not identified), the lines with the exp or
    const amplitude law at |v| held within their speed range."""
    out = np.zeros_like(v)
    for d, name in ((1.0, "positive"), (-1.0, "negative")):
        sel = v > 0 if d > 0 else v < 0
        p = model.directions[name].values
        s, th = np.abs(v[sel]), theta[sel]
        if p["tau_s"] is None:
            mag = p["tau_c"] + p["viscous"] * s
        else:
            mag = p["tau_c"] + (p["tau_s"] - p["tau_c"]) * np.exp(-s / p["v_s"]) + p["viscous"] * s
        for h in model.directions[name].harmonics:
            sc = s if h.speed_range is None else np.clip(s, *h.speed_range)
            g = 1.0 if h.law == "const" else np.exp(-h.decay * sc)
            mag += h.amplitude * g * np.sin(2 * math.pi * h.frequency * th + h.phase)
        out[sel] = d * mag
    return out


def _cpu(f, repeat, min_time=0.2):
    """Best CPU seconds per call of ``f()`` over ``repeat`` runs of enough calls to last ``min_time``."""
    t0 = time.process_time()
    f()
    one = max(time.process_time() - t0, 1e-7)
    calls = max(1, int(min_time / one))
    best = math.inf
    for _ in range(repeat):
        t0 = time.process_time()
        for _ in range(calls):
            f()
        best = min(best, (time.process_time() - t0) / calls)
    return best


def _inputs(n, seed):
    rng = np.random.default_rng(seed)
    theta = rng.uniform(0.0, 3 * 2 * math.pi * 287, n)
    v = rng.choice([-1.0, 1.0], n) * 10 ** rng.uniform(-1, math.log10(400.0), n)
    return theta, v


def main(argv=None) -> int:
    args = _parse_args(argv)
    models = {"table2": table2_model(), "fitted": fitted_model(args.fit)}
    print(f"gearspec evaluate benchmark: numpy {np.__version__}, Python {platform.python_version()}, "
          f"{platform.machine()}; CPU seconds, best of {args.repeat}")
    rows = []
    print(f"{'model':8} {'points':>10} {'evaluate /s':>12} {'bare numpy /s':>14} {'ratio':>6} {'max diff':>9}")
    for name, model in models.items():
        for n in args.sizes:
            theta, v = _inputs(n, args.seed)
            got, want = model.evaluate(theta, v), _bare(model, theta, v)
            diff = float(np.max(np.abs(got - want)) / np.max(np.abs(want)))
            t_ev = _cpu(lambda: model.evaluate(theta, v), args.repeat)
            t_np = _cpu(lambda: _bare(model, theta, v), args.repeat)
            rows.append(dict(model=name, points=n, evaluate_per_s=n / t_ev, bare_per_s=n / t_np,
                             ratio=t_np / t_ev, max_rel_diff=diff))
            r = rows[-1]
            print(f"{name:8} {n:>10} {r['evaluate_per_s']:>12.3g} {r['bare_per_s']:>14.3g} {r['ratio']:>6.2f} "
                  f"{diff:>9.1e}")
            del theta, v, got, want
    print("\nper call (microseconds, CPU):")
    calls = []
    for name, model in models.items():
        for n in (1, 32):
            theta, v = (0.7, -12.0) if n == 1 else _inputs(n, args.seed)
            t_ev = _cpu(lambda: model.evaluate(theta, v), args.repeat)
            th, vv = np.atleast_1d(theta), np.atleast_1d(v)
            t_np = _cpu(lambda: _bare(model, th, vv), args.repeat)
            calls.append(dict(model=name, points=n, evaluate_us=t_ev * 1e6, bare_us=t_np * 1e6, ratio=t_np / t_ev))
            print(f"  {name:8} {'scalar' if n == 1 else f'{n} points':>10}: evaluate {t_ev * 1e6:7.1f}, "
                  f"bare numpy {t_np * 1e6:7.1f} (ratio {t_np / t_ev:.2f})")
    big = [r for r in rows if r["points"] == max(args.sizes)]
    print(f"\ntarget >= {TARGET:.0e} evaluations per second at {max(args.sizes):.0e} points:")
    for r in big:
        print(f"  {r['model']:8} {r['evaluate_per_s']:.3g} /s: {'MET' if r['evaluate_per_s'] >= TARGET else 'NOT MET'}"
              f" (bare numpy {r['bare_per_s']:.3g} /s)")
    if args.json:
        Path(args.json).write_text(json.dumps({"sizes": rows, "calls": calls, "target": TARGET}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
