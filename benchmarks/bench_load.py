#!/usr/bin/env python
"""Loading speed: ``load_recording`` against pandas reading the same file, in the same process.

    python benchmarks/bench_load.py                 # 10^7 rows (csv ~330 MB, written to a temp folder)
    python benchmarks/bench_load.py --rows 1e6      # a quick run

For a CSV and a parquet file of a plateau recording (t, theta, torque), prints the best of
``--repeat`` times of ``pandas.read_csv`` / ``pandas.read_parquet`` (the baseline), of
``load_recording`` (read + validate: numeric columns, NaN, time stamps, gaps, saturation, unwrap,
motion and unit checks), their ratio, and a cProfile of gearspec's load with ``--profile``.
Exits 0 when it ran: it informs, it does not gate CI.
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
import pandas as pd


def _best(fn, repeat):
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--rows", type=float, default=1e7)
    p.add_argument("--repeat", type=int, default=2)
    p.add_argument("--profile", action="store_true")
    args = p.parse_args(argv)
    from gearspec.recording import load_recording

    n = int(args.rows)
    t = np.arange(n) / 1000.0
    rng = np.random.default_rng(0)
    v = np.where((t // 5) % 2 == 0, 40.0, -40.0)  # 5 s plateaus forth and back at 40 rad/s
    theta = np.concatenate(([0.0], np.cumsum(v[:-1]) / 1000.0))
    torque = 0.01 * np.sign(v) + 1e-3 * np.sin(theta) + 1e-4 * rng.standard_normal(n)
    frame = pd.DataFrame({"t": t, "theta": theta, "torque": torque})
    with tempfile.TemporaryDirectory() as tmp:
        files = {"csv": Path(tmp) / "rec.csv", "parquet": Path(tmp) / "rec.parquet"}
        frame.to_csv(files["csv"], index=False)
        frame.to_parquet(files["parquet"], index=False)
        del frame
        print(f"{n:,} rows; csv {files['csv'].stat().st_size / 1e6:.0f} MB, "
              f"parquet {files['parquet'].stat().st_size / 1e6:.0f} MB")
        print(f"{'format':8s} {'pandas s':>9s} {'gearspec s':>11s} {'ratio':>6s}")
        for kind, path in files.items():
            reader = pd.read_csv if kind == "csv" else pd.read_parquet
            reader(path)  # warm up (imports, caches)
            base = _best(lambda: reader(path), args.repeat)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                ours = _best(lambda: load_recording(path), args.repeat)
                if args.profile:
                    pr = cProfile.Profile()
                    pr.runcall(load_recording, path)
            print(f"{kind:8s} {base:9.2f} {ours:11.2f} {ours / base:6.2f}")
            if args.profile:
                pstats.Stats(pr).sort_stats("tottime").print_stats(12)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
