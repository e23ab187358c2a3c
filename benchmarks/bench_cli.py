#!/usr/bin/env python
"""The commands as a user runs them, on the default twin and on a 10^7-row recording: each of
``spectrum --out``, ``fit --out``, ``diagnose --out`` and ``discover --out`` as a subprocess, its wall
time as a ratio to ``pandas.read_csv`` of the same file measured in the same run, its peak memory
(max RSS of the child, from ``os.wait4``) as copies of the data (the DataFrame's memory).

    python benchmarks/bench_cli.py                   # default twin + 10^7 rows
    python benchmarks/bench_cli.py --quick           # the default twin only
    python benchmarks/bench_cli.py --twin /tmp/s23/twin --only spectrum --json out.json

The default twin is ``gearspec simulate silo4`` (947k rows, 400 plateaus), generated into a temporary
folder unless ``--twin DIR`` holds it.  The 10^7-row recording is synthetic (not the twin's closed
loop: :func:`gearspec.simulate.plateau_recording`, the twin's 20 speeds per direction at 1 kHz,
10 repetitions, 25 s plateaus, the silo4 gear's three shaft lines and white noise), written once into
``--big DIR`` (default a temporary folder) and reused when present there.

Targets (issue 13, on 2 cores) printed beside each number: spectrum <= 5x the read, fit <= 10x,
diagnose and discover <= 30x, peak memory <= 3 copies of the data, the four commands together on
the default twin < 120 s.  A Python process that has imported gearspec holds ~0.2 GB before it reads
a row, more than 3 copies of the default twin (~38 MB): the memory column also shows the copies
above that floor (the floor measured in the same run).  Time has a floor too: a process that only
imports numpy, pandas and pyplot (what any command that reads a table and draws a figure needs)
takes about 1 s, several times the default twin's read; each file's line prints that ratio.  A child is stopped when its memory passes
``--max-memory`` GB or its time ``--timeout`` s, and the row says so.  Timed under whatever load the
machine has: the load average is printed.  Exits 0 when it ran: it informs, it does not gate CI.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

COMMANDS = ("spectrum", "fit", "diagnose", "discover")
TARGET = {"spectrum": 5.0, "fit": 10.0, "diagnose": 30.0, "discover": 30.0}
TARGET_COPIES = 3.0
TARGET_TOTAL_S = 120.0
EXTRA = {"fit": ["--law", "silo4"]}


def run_child(argv, max_rss: float, timeout: float, poll: float = 0.2) -> dict:
    """Run ``argv``; wall time (s), peak memory (bytes: the larger of the largest process's peak RSS,
    ``os.wait4``, and the process tree's memory polled in /proc, :func:`_tree_rss`), exit status, and
    why it was stopped (memory over ``max_rss`` bytes; or over ``timeout`` s)."""
    t0 = time.perf_counter()
    p = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True)
    stopped, seen = None, 0
    while True:
        pid, status, usage = os.wait4(p.pid, os.WNOHANG)
        if pid:
            break
        rss = _tree_rss(p.pid)
        seen = max(seen, rss)
        if rss > max_rss or time.perf_counter() - t0 > timeout:
            stopped = (f"stopped at {rss / 1e9:.1f} GB (--max-memory)" if rss > max_rss else
                       f"stopped after {timeout:.0f} s (--timeout)")
            os.killpg(p.pid, signal.SIGKILL)
            pid, status, usage = os.wait4(p.pid, 0)
            break
        time.sleep(poll)
    wall = time.perf_counter() - t0
    err = p.stderr.read().decode(errors="replace").strip().splitlines() if p.stderr else []
    p.stderr.close()
    return {"seconds": wall, "max_rss": max(usage.ru_maxrss * 1024, seen), "exit": os.waitstatus_to_exitcode(status),
            "stopped": stopped, "stderr_tail": err[-1] if err else ""}


def _tree_rss(pid: int) -> int:
    """Memory (bytes) of ``pid`` and its direct children (forked workers, Dask or loky workers): the
    sum of their proportional set sizes (``Pss`` in /proc/PID/smaps_rollup: a page shared by k
    processes counts 1/k in each), so that a worker forked from the command does not count the
    command's pages it shares a second time; ``VmRSS`` where the kernel has no smaps_rollup."""
    total = 0
    pids = [pid]
    try:
        pids += [int(c) for c in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]
    except OSError:
        pass
    for q in pids:
        total += _memory(q)
    return total


def _memory(pid: int) -> int:
    """Proportional set size of one process (bytes), else its resident set size, else 0 (gone)."""
    for path, key in ((f"/proc/{pid}/smaps_rollup", "Pss:"), (f"/proc/{pid}/status", "VmRSS:")):
        try:
            for line in Path(path).read_text().splitlines():
                if line.startswith(key):
                    return int(line.split()[1]) * 1024
        except OSError:
            continue
    return 0


def read_baseline(csv: Path, repeat: int = 2) -> tuple[float, int, int]:
    """Best of ``repeat`` ``pandas.read_csv`` times (s), the DataFrame's memory (bytes) and rows,
    measured in a child process: this one stays small, as a child's peak RSS (``ru_maxrss``) starts
    from the resident size of the process that forked it (a 0.12 measurement of every command on the
    10^7-row file was this process's 1.77 GB, not the command's 1.13-1.70)."""
    code = ("import json, sys, time, pandas\n"
            "best = float('inf')\n"
            f"for _ in range({int(repeat)}):\n"
            "    t0 = time.perf_counter(); frame = pandas.read_csv(sys.argv[1]); best = min(best, time.perf_counter() - t0)\n"
            "print(json.dumps([best, int(frame.memory_usage(deep=True).sum()), len(frame)]))")
    out = subprocess.run([sys.executable, "-c", code, str(csv)], check=True, capture_output=True, text=True).stdout
    best, nbytes, rows = json.loads(out.strip().splitlines()[-1])
    return float(best), int(nbytes), int(rows)


def read_peak(csv: Path, max_rss: float) -> int:
    """Peak RSS (bytes) of a child that imports pandas and reads ``csv`` (what the read alone holds
    at its peak: the parser's buffers beside the frame)."""
    return run_child([sys.executable, "-c", f"import pandas; pandas.read_csv({str(csv)!r})"], max_rss, 600)["max_rss"]


def default_twin(tmp: Path) -> tuple[Path, Path]:
    out = tmp / "twin"
    subprocess.run([sys.executable, "-m", "gearspec", "simulate", "silo4", "--out", str(out), "--quiet"], check=True)
    return out / "silo4_twin.csv", out / "silo4_twin_gear.toml"


def big_recording(folder: Path, rows: float = 1e7) -> tuple[Path, str]:
    """The synthetic 10^7-row recording (written once into ``folder``) and its gear (the preset
    ``silo4-joint3``)."""
    from gearspec.gears import load_gear
    from gearspec.simulate import Ripple, plateau_recording

    folder.mkdir(parents=True, exist_ok=True)
    csv = folder / f"big_{rows:.0e}.csv"
    if csv.exists():
        return csv, "silo4-joint3"
    gear = load_gear("silo4-joint3")
    rpm = np.geomspace(2, 6500, 20)
    speeds = [d * r * 2 * np.pi / 60 for _ in range(10) for r in rpm for d in (1, -1)]  # 400 plateaus
    duration = max(1.0, rows / 1000.0 / len(speeds) - 0.4)  # 1 kHz; a 0.2 s ramp at each end
    lines = [Ripple(ln.frequency, 2e-4) for ln in gear.declared_lines(1)]
    rec, _ = plateau_recording(speeds, ripples=lines, level=0.008, duration=duration, fs=1000.0, noise=3e-4,
                               one_run_per_plateau=True, seed=13, gear=gear)
    rec.save(csv)
    return csv, "silo4-joint3"


def floor_rss(max_rss: float) -> int:
    """Peak RSS of a child that imports the analysis and exits (the interpreter's own floor)."""
    code = ("import gearspec.cli, gearspec.spectrum, gearspec.identify, gearspec.diagnose, gearspec.discover, "
            "gearspec.plots")
    return run_child([sys.executable, "-c", code], max_rss, 300)["max_rss"]


def floor_seconds(max_rss: float, repeat: int = 3) -> float:
    """Wall time (s, the least of ``repeat``) of a child that only imports numpy, pandas and
    matplotlib's pyplot and exits: what any command that reads a table and draws a figure pays
    before its first row."""
    code = "import numpy, pandas, matplotlib; matplotlib.use('Agg'); import matplotlib.pyplot"
    return min(run_child([sys.executable, "-c", code], max_rss, 300)["seconds"] for _ in range(repeat))


def bench_file(name: str, csv: Path, gear, commands, args, floor: int, floor_s: float) -> dict:
    read_s, data_bytes, rows = read_baseline(csv)
    print(f"\n{name}: {csv} ({rows:,} rows; DataFrame {data_bytes / 1e6:.0f} MB; pandas.read_csv {read_s:.2f} s; "
          f"load average {os.getloadavg()[0]:.1f})")
    out = {"file": str(csv), "rows": rows, "data_bytes": data_bytes, "read_s": read_s, "commands": {},
           "floor_s": floor_s, "floor_ratio": floor_s / read_s}
    peak = read_peak(csv, args.max_memory * 1e9)
    out["read_peak_rss"], out["read_peak_copies"] = peak, peak / data_bytes
    print(f"(a process that only reads it with pandas peaks at {peak / 1e9:.2f} GB = {peak / data_bytes:.1f} copies "
          "of the data, as the column 'copies' counts)")
    print(f"(a process that only imports numpy, pandas and pyplot takes {floor_s:.2f} s = {floor_s / read_s:.1f}x "
          "this read: no command that draws a figure can be faster)")
    print(f"{'command':9s} {'s':>8s} {'x read':>7s} {'target':>7s} {'peak GB':>8s} {'copies':>7s} {'above floor':>11s}"
          f" {'target':>7s}  status")
    with tempfile.TemporaryDirectory() as tmp:
        for cmd in commands:
            argv = [sys.executable, "-m", "gearspec", cmd, str(csv), "--gear", str(gear), "--out",
                    str(Path(tmp) / cmd), "--quiet", *EXTRA.get(cmd, [])]
            r = run_child(argv, args.max_memory * 1e9, args.timeout)
            ratio, copies, above = r["seconds"] / read_s, r["max_rss"] / data_bytes, (r["max_rss"] - floor) / data_bytes
            status = r["stopped"] or ("ok" if r["exit"] == 0 else f"exit {r['exit']}: {r['stderr_tail'][:80]}")
            print(f"{cmd:9s} {r['seconds']:8.1f} {ratio:7.1f} {'<= ' + format(TARGET[cmd], 'g'):>7s} "
                  f"{r['max_rss'] / 1e9:8.2f} {copies:7.1f} {above:11.1f} {'<= 3':>7s}  {status}", flush=True)
            out["commands"][cmd] = {**r, "ratio": ratio, "copies": copies, "copies_above_floor": above,
                                    "target_ratio": TARGET[cmd], "target_copies": TARGET_COPIES}
    total = sum(c["seconds"] for c in out["commands"].values())
    out["total_s"] = total
    print(f"total of {len(out['commands'])} command(s): {total:.1f} s"
          + (f" (target < {TARGET_TOTAL_S:g} s for the four on the default twin)" if len(commands) == 4 else "")
          + f"; load average {os.getloadavg()[0]:.1f}")
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true", help="the default twin only")
    p.add_argument("--only", choices=COMMANDS, action="append", help="run only this command (repeatable)")
    p.add_argument("--json", metavar="FILE", help="write the numbers as JSON")
    p.add_argument("--twin", metavar="DIR", help="a folder holding silo4_twin.csv and silo4_twin_gear.toml")
    p.add_argument("--big", metavar="DIR", help="folder of the 10^7-row recording (written once, then reused)")
    p.add_argument("--rows", type=float, default=1e7, help="rows of the big recording (default 1e7)")
    p.add_argument("--max-memory", type=float, default=3.0, help="GB at which a command is stopped (default 3)")
    p.add_argument("--timeout", type=float, default=900.0, help="seconds after which a command is stopped")
    p.add_argument("--write-big", metavar="DIR", help=argparse.SUPPRESS)     # (a child of this script)
    args = p.parse_args(argv)
    if args.write_big:
        big_recording(Path(args.write_big), args.rows)
        return 0
    commands = args.only or list(COMMANDS)
    report = {"load_average_start": os.getloadavg(), "cpus": os.cpu_count()}
    with tempfile.TemporaryDirectory() as tmp:
        floor, floor_s = floor_rss(args.max_memory * 1e9), floor_seconds(args.max_memory * 1e9)
        report["floor_rss"], report["floor_s"] = floor, floor_s
        print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs; a process importing gearspec: "
              f"{floor / 1e9:.2f} GB (the memory floor); one importing numpy, pandas and pyplot: {floor_s:.2f} s "
              "(the time floor)")
        if args.twin:
            csv, gear = Path(args.twin) / "silo4_twin.csv", Path(args.twin) / "silo4_twin_gear.toml"
        else:
            csv, gear = default_twin(Path(tmp))
        report["default_twin"] = bench_file("default twin", csv, gear, commands, args, floor, floor_s)
        if not args.quick:
            big = Path(args.big) if args.big else Path(tmp) / "big"
            t0 = time.perf_counter()
            # written by a child: this process stays small (see read_baseline)
            subprocess.run([sys.executable, __file__, "--write-big", str(big), "--rows", str(args.rows)], check=True)
            csv, gear = big_recording(big, args.rows)
            print(f"\n(the big recording: {time.perf_counter() - t0:.0f} s to write or find)")
            report["big"] = bench_file(f"{args.rows:.0e}-row recording", csv, gear, commands, args, floor, floor_s)
    report["load_average_end"] = os.getloadavg()
    if args.json:
        Path(args.json).write_text(json.dumps(report, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
