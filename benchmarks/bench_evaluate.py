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

Since 0.6 ``evaluate`` shares the blocks of a long input among threads (``threads=``, default the
environment variable ``GEARSPEC_THREADS`` or the CPUs the process may use, at most 4).  Threads only
help in wall-clock time, so the main table is **wall-clock** seconds (``time.perf_counter``, best of
``--repeat``, the four variants interleaved in each repeat so that load from other processes hits
them alike), beside the CPU seconds of this process (all its threads) over that call: a CPU/wall
ratio near the number of threads means the threads really ran at once; well below 1, other
processes held the CPUs.  A second table gives evaluations per CPU second, which load changes less
(the measure of earlier versions of this script).  Per model and size:

- ``evaluate 1t``: ``evaluate(threads=1)``, the single-thread path;
- ``evaluate Nt``: ``evaluate(threads=N)`` (``--threads``, default as evaluate's);
- ``numpy 1t``: the bare numpy expression on the whole input, one thread (THE baseline: ratios are
  against it);
- ``numpy Nt``: the same expression over blocks of the same size on N threads, so that the gain
  of threads is not mistaken for a gain of gearspec's code.

Then the cost of one call on a scalar and on 32 points (the twin's vector of runs; single-thread
path), and the load average before and after.  Target: >= 10^7 evaluations per second of
``evaluate`` (wall-clock, default threads) at the largest size (MET / NOT MET).  The script informs;
it exits 0 when it ran.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import os
import platform
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from gearspec.model import FrictionModel  # noqa: E402
from gearspec.simulate.silo4 import table2_model  # noqa: E402
from gearspec.terms.lines import default_threads  # noqa: E402

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
    p.add_argument("--threads", type=int, default=None,
                   help="threads of the parallel variants (default: evaluate's default, "
                        "GEARSPEC_THREADS or the CPUs, at most 4)")
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


def _timed(fs: dict, repeat, min_time=0.2) -> dict:
    """Per name of ``fs``: (best wall seconds per call, CPU seconds of that best run per call), the
    functions interleaved in each of ``repeat`` rounds, each round of enough calls to last ``min_time``."""
    calls = {}
    for k, f in fs.items():
        t0 = time.perf_counter()
        f()
        calls[k] = max(1, int(min_time / max(time.perf_counter() - t0, 1e-7)))
    best = {k: (math.inf, math.inf) for k in fs}
    for _ in range(repeat):
        for k, f in fs.items():
            c0, t0 = time.process_time(), time.perf_counter()
            for _ in range(calls[k]):
                f()
            wall, cpu = (time.perf_counter() - t0) / calls[k], (time.process_time() - c0) / calls[k]
            if wall < best[k][0]:
                best[k] = (wall, cpu)
    return best


def _bare_threaded(model, theta, v, threads, pool, block):
    """:func:`_bare` over blocks of ``block`` samples shared among ``threads`` threads (the calling one
    and ``pool``), taken in turn as evaluate takes its blocks."""
    out = np.empty_like(v)
    starts = range(0, len(v), block)
    following = itertools.count()

    def work():
        for k in following:
            if k >= len(starts):
                return
            i = starts[k]
            out[i:i + block] = _bare(model, theta[i:i + block], v[i:i + block])

    futures = [pool.submit(work) for _ in range(threads - 1)]
    work()
    for f in futures:
        f.result()
    return out


def _inputs(n, seed):
    rng = np.random.default_rng(seed)
    theta = rng.uniform(0.0, 3 * 2 * math.pi * 287, n)
    v = rng.choice([-1.0, 1.0], n) * 10 ** rng.uniform(-1, math.log10(400.0), n)
    return theta, v


def _load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def _sizes_table(models, args, threads, pool) -> list:
    """The wall-clock table (see the module docstring): one row per model and size."""
    rows = []
    print(f"{'model':8} {'points':>9} | {'evaluate 1t':>11} {f'evaluate {threads}t':>11} {'numpy 1t':>9} "
          f"{f'numpy {threads}t':>9} | {f'ev {threads}t/np 1t':>11} {f'ev 1t/np 1t':>11} "
          f"{f'np {threads}t/np 1t':>11} | {'cpu/wall':>8} {'max diff':>8}")
    for name, model in models.items():
        block = model._compiled().block
        for n in args.sizes:
            theta, v = _inputs(n, args.seed)
            got, want = model.evaluate(theta, v, threads=threads), _bare(model, theta, v)
            same = bool(np.array_equal(got, model.evaluate(theta, v, threads=1)))
            diff = float(np.max(np.abs(got - want)) / np.max(np.abs(want)))
            del got, want
            t = _timed({"ev1": lambda th=theta, vv=v: model.evaluate(th, vv, threads=1),
                        "evN": lambda th=theta, vv=v: model.evaluate(th, vv, threads=threads),
                        "np1": lambda th=theta, vv=v: _bare(model, th, vv),
                        "npN": lambda th=theta, vv=v: _bare_threaded(model, th, vv, threads, pool, block)},
                       args.repeat)
            rate = {k: n / w for k, (w, _) in t.items()}
            r = dict(model=name, points=n, threads=threads, identical_to_1_thread=same, max_rel_diff=diff,
                     evaluate_1t_per_s=rate["ev1"], evaluate_per_s=rate["evN"], bare_per_s=rate["np1"],
                     bare_threaded_per_s=rate["npN"], ratio=rate["evN"] / rate["np1"],
                     ratio_1t=rate["ev1"] / rate["np1"], bare_threaded_ratio=rate["npN"] / rate["np1"],
                     cpu_per_wall=t["evN"][1] / t["evN"][0], load=os.getloadavg(),
                     per_cpu_second={k: n / c for k, (_, c) in t.items()})
            rows.append(r)
            print(f"{name:8} {n:>9} | {rate['ev1']:>11.3g} {rate['evN']:>11.3g} {rate['np1']:>9.3g} "
                  f"{rate['npN']:>9.3g} | {r['ratio']:>11.2f} {r['ratio_1t']:>11.2f} "
                  f"{r['bare_threaded_ratio']:>11.2f} | {r['cpu_per_wall']:>8.2f} {diff:>8.1e}"
                  + ("" if same else "  NOT IDENTICAL to 1 thread"))
            theta = v = t = None          # free the inputs before the next size
    return rows


def main(argv=None) -> int:
    args = _parse_args(argv)
    threads = args.threads or default_threads()
    models = {"table2": table2_model(), "fitted": fitted_model(args.fit)}
    print(f"gearspec evaluate benchmark: numpy {np.__version__}, Python {platform.python_version()}, "
          f"{platform.machine()}, {os.cpu_count()} CPUs; {threads} threads; wall-clock, best of {args.repeat}")
    load_before = os.getloadavg()
    print(f"load average (1, 5, 15 min) before: {_load()}\n")
    print("evaluations per second (wall-clock) and ratios to the single-thread bare numpy expression:")
    with ThreadPoolExecutor(max_workers=max(1, threads - 1)) as pool:
        rows = _sizes_table(models, args, threads, pool)
    print(f"\nevaluations per CPU second of this process (all threads; what load from other processes changes "
          f"least):\n{'model':8} {'points':>9} | {'evaluate 1t':>11} {f'evaluate {threads}t':>11} {'numpy 1t':>9} "
          f"{f'numpy {threads}t':>9}")
    for r in rows:
        c = r["per_cpu_second"]
        print(f"{r['model']:8} {r['points']:>9} | {c['ev1']:>11.3g} {c['evN']:>11.3g} {c['np1']:>9.3g} "
              f"{c['npN']:>9.3g}")
    print("\nper call (microseconds, CPU; the single-thread path):")
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
    load_after = os.getloadavg()
    print(f"\nload average (1, 5, 15 min) after: {_load()} on {os.cpu_count()} CPUs")
    big = [r for r in rows if r["points"] == max(args.sizes)]
    print(f"target >= {TARGET:.0e} evaluations per second at {max(args.sizes):.0e} points (wall-clock, "
          f"{threads} threads):")
    for r in big:
        print(f"  {r['model']:8} {r['evaluate_per_s']:.3g} /s: {'MET' if r['evaluate_per_s'] >= TARGET else 'NOT MET'}"
              f" (1 thread {r['evaluate_1t_per_s']:.3g} /s; bare numpy {r['bare_per_s']:.3g} /s on 1 thread, "
              f"{r['bare_threaded_per_s']:.3g} /s on {threads})")
    if args.json:
        Path(args.json).write_text(json.dumps({"sizes": rows, "calls": calls, "target": TARGET, "threads": threads,
                                               "load_before": load_before, "load_after": load_after,
                                               "cpus": os.cpu_count()}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
