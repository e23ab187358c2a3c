#!/usr/bin/env python
"""Run time of the sparse-regression explorer (``gearspec.discover``) on a long recording with a
library of about 100 terms, against a baseline measured in the same run: one plain numpy
least-squares fit (``np.linalg.lstsq``) of the same library on the same samples (see
benchmarks/README.md).

    python benchmarks/bench_discover.py              # 10^6 samples
    python benchmarks/bench_discover.py --quick      # 2 x 10^5 samples
    python benchmarks/bench_discover.py --samples 3e6 --json out.json
    python benchmarks/bench_discover.py --recording /tmp/s23/twin/silo4_twin.csv \
        --gear /tmp/s23/twin/silo4_twin_gear.toml      # the command on a file, against pandas reading it

Prints the recording, the library, the timings of each stage of the explorer, the baseline and
their ratio, the law the explorer selected (a sanity check: the twin's true structure), and the
target (the whole explorer under a minute on 2 cores) as MET / NOT MET.  Always exits 0 when it
ran: it informs, it does not gate.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time


def _parse(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--samples", type=float, default=1e6, help="samples in the recording (default 1e6)")
    p.add_argument("--quick", action="store_true", help="2 x 10^5 samples")
    p.add_argument("--plateaus", type=int, default=20, help="constant-speed plateaus (default 20, both directions)")
    p.add_argument("--repeat", type=int, default=1, help="explorer runs, best taken (default 1)")
    p.add_argument("--threads", type=int, default=None, help="BLAS threads for the baseline (sets OMP_NUM_THREADS ...)")
    p.add_argument("--no-baseline", action="store_true", help="skip the dense lstsq baseline (it needs ~2 GB)")
    p.add_argument("--json", help="write every number here")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--recording", help="instead: time `gearspec discover RECORDING --gear GEAR` (a subprocess, "
                                       "with its peak memory) against pandas.read_csv of the same file")
    p.add_argument("--gear", help="gear spec of --recording")
    return p.parse_args(argv)


def bench_recording(args) -> int:
    """``gearspec discover`` on a file as a user runs it (spectrum search for lines included),
    against reading the file with pandas in the same run; peak memory against the data's size."""
    import resource
    import subprocess

    import pandas as pd

    load = os.getloadavg()
    t0 = time.perf_counter()
    df = pd.read_csv(args.recording)
    t_read = time.perf_counter() - t0
    size = float(df.memory_usage(deep=True).sum())
    print(f"1. pandas.read_csv: {len(df)} rows x {df.shape[1]} columns in {t_read:.2f} s "
          f"({size / 1e6:.0f} MB in memory)")
    del df
    # what the interpreter with gearspec's discover and CLI imported holds before reading anything
    probe = ("import resource, gearspec.cli, gearspec.discover, gearspec.spectrum; "
             "print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024)")
    imports = float(subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True).stdout.strip()
                    or "nan")
    cmd = [sys.executable, "-m", "gearspec", "discover", args.recording, "--gear", args.gear]
    t0 = time.perf_counter()
    run = subprocess.run(cmd, capture_output=True, text=True)
    t_disc = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024.0
    print(f"2. {' '.join(cmd[2:])}: {t_disc:.1f} s, exit {run.returncode}, peak memory {peak / 1e6:.0f} MB")
    print("   " + "\n   ".join(run.stderr.strip().splitlines()[-14:]))
    print(f"3. discover / read = {t_disc / t_read:.1f} "
          f"(target <= 30: {'MET' if t_disc <= 30 * t_read else 'NOT MET'}); "
          f"peak memory / data = {peak / size:.1f} copies (target <= 3: {'MET' if peak <= 3 * size else 'NOT MET'}); "
          f"load average at the start {load[0]:.1f}, at the end {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    print(f"   of the peak, {imports / 1e6:.0f} MB is the interpreter with gearspec imported (before any data): "
          f"(peak - imports) / data = {(peak - imports) / size:.1f} copies")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"t_read": t_read, "t_discover": t_disc, "ratio": t_disc / t_read, "peak_bytes": peak,
                       "data_bytes": size, "import_bytes": imports, "load": load,
                       "stdout": run.stdout}, fh, indent=1)
    return 0


def _rss() -> float:
    """Resident memory of this process now (bytes; Linux /proc, else NaN)."""
    try:
        with open("/proc/self/status") as fh:
            return next(float(line.split()[1]) * 1024 for line in fh if line.startswith("VmRSS"))
    except (OSError, StopIteration):
        return float("nan")


def main(argv=None) -> int:
    args = _parse(argv)
    if args.recording:
        return bench_recording(args)
    if args.threads:
        for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
            os.environ[k] = str(args.threads)
    import numpy as np

    from gearspec.discover import discover
    from gearspec.fitdata import FitData
    from gearspec.model import RPM, FrictionModel
    from gearspec.simulate import model_recording

    n_target = int(2e5 if args.quick else args.samples)
    out: dict = {"samples_requested": n_target}

    # ---- the recording: a SILO4-joint-3 twin (eq. 11 with Table 2's direction-dependent values)
    t0 = time.perf_counter()
    f2, f3 = 1 / (2 * np.pi * 14), 1 / (2 * np.pi)
    pos = {"tau_c": 7.106e-3, "tau_s": 8.596e-3, "v_s": 28.18 * RPM, "viscous": 0.0134e-3 / RPM,
           "harmonics": [dict(frequency=f2, amplitude=0.576e-3, decay=1.27e-4 / RPM, phase=np.pi / 2),
                         dict(frequency=f3, amplitude=0.133e-3, decay=5.28e-5 / RPM, phase=np.pi)]}
    neg = {"tau_c": 7.909e-3, "tau_s": 9.399e-3, "v_s": 28.18 * RPM, "viscous": 0.0138e-3 / RPM,
           "harmonics": [dict(frequency=f2, amplitude=0.526e-3, decay=1.12e-4 / RPM, phase=np.pi / 2),
                         dict(frequency=f3, amplitude=0.152e-3, decay=7.49e-6 / RPM, phase=np.pi)]}
    truth = FrictionModel("silo4", pos, neg)
    n_speeds = max(args.plateaus // 2, 2)
    speeds = [s * d for s in np.geomspace(0.5, 600, n_speeds) for d in (1, -1)]
    fs = 1000.0
    duration = n_target / fs / len(speeds)
    rec, _ = model_recording(truth, speeds, duration=duration, fs=fs, ramp=0.2, noise=0.2e-3, gear="silo4-joint3",
                             one_run_per_plateau=False, seed=args.seed)
    t_rec = time.perf_counter() - t0
    t0 = time.perf_counter()
    data = FitData.from_recording(rec)
    t_fitdata = time.perf_counter() - t0
    N = len(data)
    print(f"1. recording: SILO4 joint-3 twin (eq. 11, Table 2), {len(rec)} rows, {len(speeds)} plateaus of "
          f"{duration:.1f} s at 1 kHz, speeds 0.5..600 rad/s; {N} samples in {data.n_segments} segments")
    print(f"   built in {t_rec:.1f} s; segmented (FitData.from_recording) in {t_fitdata:.1f} s "
          "(not part of the explorer's time)")
    out.update(samples=N, segments=data.n_segments, t_recording=t_rec, t_fitdata=t_fitdata)

    # ---- the explorer
    import resource

    data_bytes = float(sum(a.nbytes for a in (data.y, data.v, data.theta, data.segment, data.run, data.direction)
                           if a is not None))
    rss_before = _rss()
    peak_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024.0
    best = None
    for _ in range(max(args.repeat, 1)):
        t0 = time.perf_counter()
        res = discover(data, gear="silo4-joint3", references=(), n_models=50)
        dt = time.perf_counter() - t0
        best = dt if best is None else min(best, dt)
    lib = res.library
    print(f"2. library: {lib.describe()}")
    print(f"3. explorer (discover, default settings, 50 bootstrap replicates, no paper-law comparison): "
          f"{best:.2f} s")
    for k, v in res.timings.items():
        if k != "total":
            print(f"     {k:<18} {v:7.2f} s")
    out.update(library_columns=len(lib), t_explorer=best, timings=res.timings, laws_scored=len(res.candidates))
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024.0
    grew = max(peak - rss_before, 0.0) if peak > peak_before else float("nan")
    print(f"   memory: the samples the explorer reads (y, v, theta, ids) {data_bytes / 1e6:.0f} MB; the process's peak "
          f"grew by {grew / 1e6:.0f} MB during the explorer: {grew / data_bytes:.2f} x the data "
          f"(peak {peak / 1e6:.0f} MB including the interpreter and the recording)")
    out.update(data_bytes=data_bytes, explorer_peak_growth=grew, peak_bytes=peak)

    # ---- the baseline: one dense least-squares fit of the same library on the same samples
    if not args.no_baseline:
        t0 = time.perf_counter()
        X = lib.evaluate(data, res.moments)
        t_dense = time.perf_counter() - t0
        t0 = time.perf_counter()
        w = np.linalg.lstsq(X, data.y, rcond=None)[0]
        t_lstsq = time.perf_counter() - t0
        cond = float(np.linalg.cond(X[:: max(1, N // 200_000)] / np.sqrt(np.mean(X * X, axis=0) + 1e-300)))
        print(f"4. baseline: np.linalg.lstsq of the {N} x {X.shape[1]} library matrix: {t_lstsq:.2f} s "
              f"(building the matrix: {t_dense:.2f} s; {X.nbytes / 1e9:.2f} GB)")
        print(f"   explorer / lstsq = {best / t_lstsq:.2f}   (the lstsq weights: largest |w| x column RMS = "
              f"{np.max(np.abs(w) * np.sqrt(np.mean(X * X, axis=0))):.3g} Nm for a friction of RMS "
              f"{np.sqrt(np.mean(data.y ** 2)):.3g} Nm; condition number of the scaled columns {cond:.3g})")
        out.update(t_lstsq=t_lstsq, t_dense_matrix=t_dense, ratio=best / t_lstsq, condition=cond)
        del X
    sel = res.best
    print(f"5. selected law (complexity {sel.complexity}, held-out RMSE {sel.rmse_holdout:.4g} Nm):")
    print(f"   {sel.equation}")
    met = best < 60.0
    print(f"6. target: explorer on {N} samples with {len(lib)} columns under 60 s: {best:.1f} s -> "
          f"{'MET' if met else 'NOT MET'} (on {os.cpu_count()} cores)")
    out.update(selected=sel.equation, target_met=met, cores=os.cpu_count())
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=1, default=float)
    return 0


if __name__ == "__main__":
    sys.exit(main())
