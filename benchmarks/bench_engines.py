"""The three estimation engines on one SILO4 twin: ``fit``, ``diagnose`` and ``discover``, each
timed against a plain least-squares solve of the same samples measured in the same run.

    .venv/bin/python benchmarks/bench_engines.py                  # 2 repetitions per speed, ~1.5 min
    .venv/bin/python benchmarks/bench_engines.py --no-diagnose    # fit and discover only, ~15 s
    PYTHONPATH=OTHER_TREE .venv/bin/python benchmarks/bench_engines.py   # another revision, to compare

It prints each engine's time and its ratio to the baseline (``np.linalg.lstsq`` of the samples
against 8 columns, best of 3), and the joint fit's held-out rmse (which must not move when only the
code's structure changes). It reports; it does not gate.
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np


def _best(f, k):
    times, out = [], None
    for _ in range(k):
        t = time.perf_counter()
        out = f()
        times.append(time.perf_counter() - t)
    return min(times), out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--repetitions", type=int, default=2, help="twin repetitions per speed (default 2)")
    p.add_argument("--seed", type=int, default=3)
    p.add_argument("--no-diagnose", action="store_true", help="skip the closed loop (the slowest engine)")
    p.add_argument("--json", help="write every number here")
    args = p.parse_args()

    from gearspec import identify
    from gearspec.diagnose.loop import diagnose
    from gearspec.discover.explorer import discover
    from gearspec.fitdata import FitData
    from gearspec.simulate import silo4_twin

    rec, _ = silo4_twin(repetitions=args.repetitions, seed=args.seed)
    data = FitData.from_recording(rec)
    X = np.column_stack([np.sign(data.v), data.v, np.abs(data.v) * data.v]
                        + [np.sin(k * data.theta) for k in range(1, 6)])
    base, _ = _best(lambda: np.linalg.lstsq(X, data.y, rcond=None), 3)
    out = {"rows": len(data), "baseline_s": base}
    out["fit_s"], model = _best(lambda: identify.fit(data, "silo4", gear=rec.gear), 2)
    if not args.no_diagnose:
        out["diagnose_s"], _ = _best(lambda: diagnose(data, model), 1)
    out["discover_s"], _ = _best(lambda: discover(data), 1)
    out["rmse_holdout"] = model.rmse_holdout
    print(f"{out['rows']:,} rows; baseline lstsq {base:.4f} s")
    for k in ("fit", "diagnose", "discover"):
        if f"{k}_s" in out:
            out[f"{k}_ratio"] = out[f"{k}_s"] / base
            print(f"  {k:9s} {out[f'{k}_s']:8.2f} s   {out[f'{k}_ratio']:9.1f} x baseline")
    print(f"  joint fit held-out rmse {model.rmse_holdout:.6g} Nm")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=1)


if __name__ == "__main__":
    main()
