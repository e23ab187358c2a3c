#!/usr/bin/env python
"""Speed and memory of the per-segment spectrum of a long recording, against baselines measured
in the same process (see benchmarks/README.md).

    python benchmarks/bench_spectrum.py              # 10^7 samples (about 2 minutes)
    python benchmarks/bench_spectrum.py --quick      # 10^6 samples, smoke run
    python benchmarks/bench_spectrum.py --samples 30000000 --json out.json
    python benchmarks/bench_spectrum.py --profile    # also cProfile the analysis

Prints, in this order:

1. the synthetic recording (built with numpy in a few seconds, deterministic) and how long
   ``Recording.from_arrays`` took to validate it (not part of any ratio);
2. timings: bare ``np.fft.rfft`` of all torque samples (best of 3, the baseline, one thread),
   ``find_segments`` and ``analyze`` (default options: segments in two threads on a machine
   with two or more CPUs), with their ratios to the FFT, and ``analyze`` again on one thread;
3. a per-stage breakdown of ``analyze_segment`` on the longest segment, each stage against an FFT
   of that segment's samples;
4. gearspec's Lomb-Scargle (nifty backend) against ``scipy.signal.lombscargle`` (and astropy)
   on the same subsampled segment and the same frequencies: speed ratio and agreement;
5. peak memory during ``analyze``, in copies of the data (one float64 array of the N samples),
   from tracemalloc and from the growth of the process's peak RSS, in separate passes;
6. a summary table with MET / NOT MET per target.

The script always exits 0 when it ran: it informs, it does not gate CI.
"""

from __future__ import annotations

import argparse
import os
import sys


def _parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--samples", type=float, default=1e7, help="samples in the recording (default 1e7)")
    p.add_argument("--quick", action="store_true", help="smoke run: 10^6 samples, small periodogram comparison")
    p.add_argument("--plateaus", type=int, default=8, help="constant-speed plateaus (default 8)")
    p.add_argument("--fs", type=float, default=1000.0, help="sample rate, Hz (default 1000)")
    p.add_argument("--repeat", type=int, default=1,
                   help="runs of find_segments/analyze, best taken (default 1; the FFT is always best of 3)")
    p.add_argument("--ls-samples", type=int, default=None,
                   help="samples (and frequencies) in the periodogram comparison (default 10000, --quick 5000); "
                        "scipy's and astropy's cost grows as the square: 20000 takes ~20 s each")
    p.add_argument("--no-scipy", action="store_true", help="skip the O(N M) scipy/astropy periodogram comparison")
    p.add_argument("--no-memory", action="store_true", help="skip the memory passes")
    p.add_argument("--profile", nargs="?", const=25, type=int, default=0, metavar="TOP",
                   help="also run analyze under cProfile and print the TOP (default 25) functions")
    p.add_argument("--threads", type=int, default=None,
                   help="limit OpenMP/BLAS threads (sets OMP_NUM_THREADS etc. before numpy is imported)")
    p.add_argument("--workers", default="auto",
                   help="segments analysed at once by analyze (threads; default auto: 2 on >= 2 CPUs for long "
                        "segments); analyze is always timed with workers=1 too")
    p.add_argument("--json", default=None, metavar="PATH", help="also write the numbers as JSON")
    p.add_argument("--seed", type=int, default=20240611)
    args = p.parse_args(argv)
    if args.quick:
        args.samples = 1e6
        if args.ls_samples is None:
            args.ls_samples = 5000
    if args.ls_samples is None:
        args.ls_samples = 10000
    args.samples = int(args.samples)
    return args


ARGS = _parse_args() if __name__ == "__main__" else None
if ARGS is not None and ARGS.threads:
    for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS"):
        os.environ[_var] = str(ARGS.threads)

import gc  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import platform  # noqa: E402
import resource  # noqa: E402
import time  # noqa: E402
import tracemalloc  # noqa: E402
import warnings  # noqa: E402

import numpy as np  # noqa: E402

import gearspec  # noqa: E402
from gearspec.gears import load_gear  # noqa: E402
from gearspec.recording import Recording  # noqa: E402
from gearspec.segment import find_segments  # noqa: E402
from gearspec.spectrum import (LombScargle, analyze, analyze_segment, harmonic_fit, local_noise,  # noqa: E402
                               order_spectrum, resample_over_position)
from gearspec.spectrum.harmonic import NormalEquations, refine_frequencies  # noqa: E402

GEAR = "silo4-joint3"
TARGET_SPEED = 5.0      # whole per-segment analysis within 5 x the bare FFT
TARGET_MEMORY = 2.0     # no copy of the data held more than twice
TWO_PI = 2.0 * math.pi


# ---------------------------------------------------------------------- the recording
def build_arrays(n: int, fs: float = 1000.0, n_plateaus: int = 8, seed: int = 0):
    """A SILO4-joint-3-like test-bench run, vectorised: ``n_plateaus`` constant motor speeds in
    alternating directions joined by 0.5 s linear ramps (from and back to standstill), 1 kHz.

    Torque (motor shaft, Nm) is ``sign(v) (level(|v|) + ripple(theta)) + noise`` with ripple at the
    three declared shaft lines (motor 1/(2 pi), planetary output 1/(2 pi 14), output
    1/(2 pi 287) cycles/rad; the output one direction dependent) and two undeclared ones (twice
    the motor shaft, and a line at 0.0893 cycles/rad that no gear line explains), white noise, and
    a 4000-count motor encoder.
    """
    rng = np.random.default_rng(seed)
    dt = 1.0 / fs
    ramp = max(2, round(0.5 * fs))
    hold = (n - (n_plateaus + 1) * ramp) // n_plateaus
    if hold < 10 * ramp:
        raise SystemExit(f"--samples {n} is too few for {n_plateaus} plateaus of at least {10 * ramp} samples")
    mags = np.geomspace(10.0, 80.0, (n_plateaus + 1) // 2)          # motor rad/s
    speeds = [float(mags[i // 2]) * (1 if i % 2 == 0 else -1) for i in range(n_plateaus)]
    knots, values, k = [0.0], [0.0], 0
    for v in speeds:
        k += ramp
        knots.append(k); values.append(v)
        k += hold
        knots.append(k); values.append(v)
    knots.append(n - 1); values.append(0.0)  # last ramp takes the remainder
    idx = np.arange(n, dtype=float)
    vel = np.interp(idx, knots, values)
    t = idx * dt
    del idx
    theta = np.empty(n)
    theta[0] = 0.0
    np.cumsum(vel[:-1], out=theta[1:])
    theta *= dt
    gear = load_gear(GEAR)  # motor -> planetary 14 -> worm 20.5; theta is the motor angle
    f_motor = 1.0 / TWO_PI
    f_planet = f_motor / gear.stages[0].ratio
    f_out = f_motor / gear.total_ratio
    ripples = [  # frequency, amplitude (v > 0), amplitude (v < 0), phase, label, declared
        (f_out, 0.030, 0.020, 0.7, "output shaft", True),
        (f_planet, 0.012, 0.012, -1.1, "planetary output shaft", True),
        (f_motor, 0.008, 0.008, 2.0, "motor shaft", True),
        (2 * f_motor, 0.004, 0.004, 0.3, "2x motor shaft (undeclared harmonic)", False),
        (0.0893, 0.005, 0.005, -2.5, "0.0893 cycles/rad (no gear line)", False),
    ]
    speed = np.abs(vel)
    y = 0.40 + 0.002 * speed                   # Coulomb + viscous level, Nm
    pos = vel > 0
    ph = np.empty(n)
    for f, a_pos, a_neg, phi, _, _ in ripples:
        np.multiply(theta, TWO_PI * f, out=ph)
        ph += phi
        np.sin(ph, out=ph)
        ph *= np.where(pos, a_pos, a_neg) if a_pos != a_neg else a_pos
        y += ph
    del ph, speed, pos
    torque = np.sign(vel) * y
    del y
    torque += rng.normal(0.0, 0.05, n)
    quantum = TWO_PI / 4000
    theta_meas = np.round(theta / quantum) * quantum
    del theta
    truth = {"speeds_rad_s": speeds, "ramp_samples": ramp, "hold_samples": int(hold), "fs": fs,
             "noise_nm": 0.05, "encoder_counts_per_rev": 4000,
             "ripples": [{"frequency": f, "amplitude": [ap, an], "phase": phi, "label": lab, "declared": dec}
                         for f, ap, an, phi, lab, dec in ripples]}
    return t, theta_meas, torque, truth


# ---------------------------------------------------------------------- helpers
def best_of(fn, repeat: int = 3):
    """(best seconds, last result) over ``repeat`` calls."""
    best, out = math.inf, None
    for _ in range(max(1, repeat)):
        out = None
        gc.collect()
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def _fast_len(n: int) -> int:
    from scipy.fft import next_fast_len

    return int(next_fast_len(int(n), real=True))


def _status_kib(key: str) -> int | None:
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith(key + ":"):
                    return int(line.split()[1])
    except OSError:
        pass
    return None


def _reset_peak_rss() -> bool:
    """Reset the kernel's peak-RSS high-water mark (Linux >= 4.0, /proc/self/clear_refs = 5)."""
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
        return True
    except OSError:
        return False


def _malloc_trim() -> None:
    """Give freed heap memory back to the OS (glibc), so that earlier passes' leftovers do not
    serve this pass's allocations unseen by the RSS."""
    try:
        import ctypes

        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass


def _maxrss_kib() -> int:
    r = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return r // 1024 if sys.platform == "darwin" else r  # bytes on macOS, KiB on Linux


def traced_peak(fn):
    """(peak extra bytes, retained extra bytes, result) of fn() under tracemalloc."""
    gc.collect()
    tracemalloc.start()
    try:
        tracemalloc.reset_peak()
        base = tracemalloc.get_traced_memory()[0]
        out = fn()
        cur, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    return peak - base, cur - base, out


def rss_peak(fn):
    """(peak RSS growth in bytes, whether it is exact, result) of fn()."""
    gc.collect()
    _malloc_trim()
    exact = _reset_peak_rss()
    before_rss = _status_kib("VmRSS")
    before_max = _maxrss_kib()
    out = fn()
    after_max = _maxrss_kib()
    if exact and before_rss is not None:
        return (after_max - before_rss) * 1024, True, out
    return max(0, after_max - before_max) * 1024, False, out  # a lower bound: earlier peaks mask it


def _git_state() -> str:
    """Commit of the gearspec checkout and whether it has local changes (read-only git calls)."""
    import subprocess

    root = os.path.dirname(os.path.dirname(os.path.abspath(gearspec.__file__)))
    try:
        head = subprocess.run(["git", "-C", root, "rev-parse", "--short", "HEAD"], check=False,
                              capture_output=True, text=True, timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "-C", root, "status", "--porcelain", "--untracked-files=no", "gearspec"],
                               check=False, capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown (no git)"
    return f"{root} @ {head or '?'}" + (" + local changes in gearspec/" if dirty else "")


def _workers_arg(w):
    return w if w == "auto" else int(w)


def _analysis_threads(workers, seg) -> int:
    """Threads analyze will use (its own rule for "auto")."""
    try:
        from gearspec.spectrum.analysis import _n_workers

        return _n_workers(workers, seg)
    except ImportError:  # an older gearspec: one thread
        return 1


def verdict(ok: bool) -> str:
    return "MET" if ok else "NOT MET"


def fmt_s(x: float) -> str:
    return f"{x * 1e3:8.1f} ms" if x < 1 else f"{x:8.2f} s "


def section(title: str):
    print(f"\n== {title} " + "=" * max(0, 86 - len(title)), flush=True)


def _scipy_chunked(theta, y, freqs, floating_mean=True, max_elements=1 << 20):
    """scipy.signal.lombscargle over frequency blocks: it holds seven (N, M) float64 arrays at
    its peak, so one call with N = M = 2e4 would need 22 GB.  Blocks do not change the result
    (each frequency is computed independently); blocks of ~1e6 elements are also its fastest."""
    from scipy.signal import lombscargle

    w = TWO_PI * np.asarray(freqs, float)
    step = max(1, max_elements // len(theta))
    out = np.empty(len(w))
    for i in range(0, len(w), step):
        out[i:i + step] = lombscargle(theta, y, w[i:i + step], floating_mean=floating_mean)
    return out


# ---------------------------------------------------------------------- the benchmark
def make_recording(args, R):
    section(f"1. recording: {args.samples:.3g} samples, {args.plateaus} plateaus, gear '{GEAR}'")
    t_build, (t, theta, torque, truth) = best_of(
        lambda: build_arrays(args.samples, args.fs, args.plateaus, args.seed), 1)
    t_rec, rec = best_of(lambda: Recording.from_arrays(t=t, theta=theta, torque=torque, gear=GEAR,
                                                       source="bench"), 1)
    N = len(rec)
    R.update(build_s=t_build, from_arrays_s=t_rec, rows=N, truth=truth)
    print(f"motor speeds (rad/s): {', '.join(f'{v:+.3g}' for v in truth['speeds_rad_s'])}; "
          f"{truth['hold_samples']} samples per plateau, {truth['ramp_samples']}-sample ramps, "
          f"{truth['fs']:g} Hz, 4000-count encoder, white noise {truth['noise_nm']:g} Nm")
    print("ripple: " + "; ".join(f"{r['label']} {r['frequency']:.5g} c/rad A={r['amplitude'][0]:g}"
                                 for r in truth["ripples"]))
    print(f"built with numpy in {t_build:.2f} s; Recording.from_arrays (validation) {t_rec:.2f} s "
          f"(not part of any ratio); one copy of the data = 8 N = {8 * N / 2**20:.1f} MiB")
    return rec, truth


def time_whole(args, R, rec, tau):
    section("2. timings in this process (baseline: bare np.fft.rfft of all torque samples)")
    N = len(tau)
    np.fft.rfft(tau[: min(N, 1 << 16)])  # warm-up
    t_fft, _ = best_of(lambda: np.fft.rfft(tau), 3)
    n_fast = _fast_len(N)
    if n_fast != N:  # an awkward N makes the bare FFT slow and would flatter every ratio
        t_fft_pad, _ = best_of(lambda: np.fft.rfft(tau, n_fast), 3)
        print(f"  N = {N} is not a fast FFT length: rfft takes {fmt_s(t_fft).strip()}, zero-padded to {n_fast} "
              f"{fmt_s(t_fft_pad).strip()}; the faster is the baseline")
        t_fft = min(t_fft, t_fft_pad)
    t_seg, seg = best_of(lambda: find_segments(rec), args.repeat)
    try:
        t_seg1, seg1 = best_of(lambda: find_segments(rec, workers=1), args.repeat)
        seg_same = seg1.segments == seg.segments
    except TypeError:  # an older gearspec: find_segments has no workers (one thread)
        t_seg1, seg_same = t_seg, True
    n_in = sum(s.n for s in seg)
    workers = _workers_arg(args.workers)
    n_threads = _analysis_threads(workers, seg)
    t_an, res = best_of(lambda: analyze(rec, GEAR, segmentation=seg, progress=False, workers=workers), args.repeat)
    t_an1, res1 = best_of(lambda: analyze(rec, GEAR, segmentation=seg, progress=False, workers=1), args.repeat)
    same = json.dumps(res.to_dict(), default=float) == json.dumps(res1.to_dict(), default=float)
    ratio_seg, ratio_an, ratio_an1 = t_seg / t_fft, t_an / t_fft, t_an1 / t_fft
    ratio_seg1 = t_seg1 / t_fft
    ratio_both, ratio_both1 = (t_seg + t_an) / t_fft, (t_seg1 + t_an1) / t_fft
    R.update(fft_s=t_fft, segmentation_s=t_seg, analysis_s=t_an, analysis_threads=n_threads,
             analysis_1thread_s=t_an1, segments=len(seg), samples_in_segments=n_in,
             ratio_segmentation=ratio_seg, ratio_analysis=ratio_an, ratio_total=ratio_both,
             ratio_analysis_1thread=ratio_an1, ratio_total_1thread=ratio_both1, threads_same_result=same,
             segmentation_1thread_s=t_seg1, ratio_segmentation_1thread=ratio_seg1, threads_same_segments=seg_same)
    print(f"{len(seg)} segments hold {n_in} samples ({n_in / N:.1%}); "
          f"lengths {min(s.n for s in seg)} .. {max(s.n for s in seg)}")
    print(f"  np.fft.rfft, all {N} samples (best of 3) {fmt_s(t_fft)}   1.00 x   (one thread)")
    print(f"  find_segments(rec)                          {fmt_s(t_seg)} {ratio_seg:7.2f} x   "
          "(default: windows in threads for long pieces)")
    print(f"  find_segments(rec, workers=1), one thread   {fmt_s(t_seg1)} {ratio_seg1:7.2f} x")
    print(f"  analyze(rec, segmentation=seg), {n_threads} thread{'s' if n_threads > 1 else ' '}  {fmt_s(t_an)} "
          f"{ratio_an:7.2f} x   target <= {TARGET_SPEED:g} x: {verdict(ratio_an <= TARGET_SPEED)}"
          + ("   (default: segments in threads)" if n_threads > 1 else ""))
    print(f"  analyze(..., workers=1), one thread         {fmt_s(t_an1)} {ratio_an1:7.2f} x   "
          f"target <= {TARGET_SPEED:g} x: {verdict(ratio_an1 <= TARGET_SPEED)}")
    print(f"  find_segments + analyze                     {fmt_s(t_seg + t_an)} {ratio_both:7.2f} x   "
          f"(segmentation included: {verdict(ratio_both <= TARGET_SPEED)})")
    print(f"  find_segments + analyze, one thread         {fmt_s(t_seg1 + t_an1)} {ratio_both1:7.2f} x   "
          f"(segmentation included: {verdict(ratio_both1 <= TARGET_SPEED)})")
    if n_threads > 1:
        print(f"  analyze: {n_threads} threads give {t_an1 / t_an:.2f} x the speed of one; results identical: "
              f"{'yes' if same else 'NO'}; find_segments: {t_seg1 / t_seg:.2f} x, segments identical: "
              f"{'yes' if seg_same else 'NO'}")
    # what the analysis found: a sanity check that it did the real work
    found = res.peaks_table()
    if len(found):
        summary = (found.groupby(found["label"].fillna("(unlabelled)"))["amplitude"]
                   .agg(["count", "median"]).sort_values("count", ascending=False))
        print("  peaks found (label: segments, median amplitude): " +
              "; ".join(f"{k}: {int(r['count'])}, {r['median']:.4g}" for k, r in summary.head(6).iterrows()))
    return seg


def stage_breakdown(R, s, th, y, gear):
    n = len(th)
    section(f"3. stages of analyze_segment on the longest segment ({n} samples, {s.speed:.3g} rad/s)")
    t_fft_seg_raw, _ = best_of(lambda: np.fft.rfft(y), 3)
    t_fft_seg, _ = best_of(lambda: np.fft.rfft(y, _fast_len(n)), 3)
    stages = []

    def stage(name, fn, repeat=1):
        """Time one building block; a block whose API changed is reported, not fatal."""
        try:
            dt_, out = best_of(fn, repeat)
        except Exception as exc:  # noqa: BLE001 - the library evolves; the breakdown only informs
            stages.append((name, float("nan"), f"n/a: {type(exc).__name__}: {exc}"[:60]))
            return None
        stages.append((name, dt_, ""))
        return out

    full = stage("analyze_segment (default: keep_spectra=False)",
                 lambda: analyze_segment(th, y, gear, segment=s))
    stage("analyze_segment (keep_spectra=True, for figures)",
          lambda: analyze_segment(th, y, gear, segment=s, keep_spectra=True))
    span = float(np.ptp(th))
    declared = [p for p in full.peaks if p.declared]
    undeclared = [p for p in full.peaks if not p.declared]
    f_dec = [p.frequency for p in declared]
    f_found = [p.frequency for p in undeclared]
    deg = full.degree
    # what analyze_segment runs on a long segment, step by step (internal functions: a row says
    # n/a when they change)
    from gearspec.spectrum import analysis as _an

    stage("  1 position Nyquist (selection)", lambda: _an.position_nyquist(th))
    eq = stage(f"  2 normal equations, {len(f_dec)} declared lines (1 pass)",
               lambda: NormalEquations.accumulate(th, y, f_dec, deg))
    if eq is not None:
        fmax = 0.5 * (n - 1) / span
        sp = stage("  3 search spectrum (resample, Hann FFT float32)",
                   lambda: _an._fft_residual_power(th, y, eq.fit(), 2.0, fmax))
        if sp is not None:
            stage("  4 its noise levels (noise_blocks)",
                  lambda: _an.noise_blocks(sp[3], width=200, min_width=40))
        if f_found:
            start = f_dec + [f + 0.1 / span for f in f_found]
            stage(f"  5 refine_frequencies ({len(f_found)} free), on step 2's",
                  lambda: refine_frequencies(th, y, start, range(len(f_dec), len(start)), degree=deg, iterations=3,
                                             base=eq))
    # the public building blocks on their own
    stage(f"  harmonic_fit, declared ({len(f_dec)}), residual=True",
          lambda: harmonic_fit(th, y, f_dec, degree=deg, residual=True))
    ls = stage("  LombScargle(theta, y) (sort check)", lambda: LombScargle(th, y))
    fmin, df, nf = ls.autogrid(oversample=2.0, fmax=0.5 * (n - 1) / span)
    power = stage(f"  LombScargle.power_grid, nifty, 1 signal ({nf} f)", lambda: ls.power_grid(fmin, df, nf))
    stage("  LombScargle.power_grid, nifty, batch of 2 signals",
          lambda: LombScargle(th, np.vstack([y, y])).power_grid(fmin, df, nf))
    freqs = fmin + df * np.arange(nf)
    mask = np.zeros(nf, bool)
    for f0 in f_dec:
        mask |= np.abs(freqs - f0) < 1.0 / span
    stage("  local_noise", lambda: local_noise(power, width=200, mask=mask))
    if f_found:
        # start a tenth of a resolution step away, as a periodogram peak would
        start = f_dec + [f + 0.1 / span for f in f_found]
        stage(f"  refine_frequencies ({len(f_found)} free of {len(start)}, degree {deg}), alone",
              lambda: refine_frequencies(th, y, start, range(len(f_dec), len(start)), degree=deg))
    stage(f"  harmonic_fit ({len(f_dec) + len(f_found)} lines, degree {deg}), once",
          lambda: harmonic_fit(th, y, f_dec + f_found, degree=deg))
    grid_vals = stage("  resample_over_position", lambda: resample_over_position(th, y))
    if grid_vals is not None:
        stage("  order_spectrum (Hann, rfft)",
              lambda: order_spectrum(grid_vals[1], grid_vals[0][1] - grid_vals[0][0]))
    stage("  2 x LombScargle.amplitude", lambda: (ls.amplitude(power=power), ls.amplitude(power=power)))
    print(f"  {'np.fft.rfft of the segment, padded to ' + str(_fast_len(n)) + ' (baseline)':<52s} "
          f"{fmt_s(t_fft_seg)}    1.00 x")
    print(f"  {'np.fft.rfft of the segment, ' + str(n) + ' samples as is':<52s} {fmt_s(t_fft_seg_raw)} "
          f"{t_fft_seg_raw / t_fft_seg:7.2f} x" + ("   (an awkward FFT length)" if t_fft_seg_raw > 1.5 * t_fft_seg else ""))
    for name, dt_, err in stages:
        print(f"  {name:<52s} " + (err if err else f"{fmt_s(dt_)} {dt_ / t_fft_seg:7.2f} x"))
    print("  (steps 1-5 are what analyze_segment runs on a long segment, refinement started a tenth of a\n"
          "   resolution step off; the rest are the public building blocks alone. --profile gives the exact split)")
    print(f"  {len(declared)} declared + {len(undeclared)} found lines in this segment: "
          + ", ".join(f"{p.label or 'unlabelled'} {p.frequency:.5g}" for p in full.peaks))
    R["segment_stages"] = {"n": n, "fft_s": t_fft_seg, "fft_unpadded_s": t_fft_seg_raw,
                           **{name.strip(): dt_ for name, dt_, _ in stages}}


def periodogram_vs_scipy(args, R, th, y):
    n = len(th)
    m = min(args.ls_samples, n)
    section(f"4. periodogram: gearspec (nifty) vs scipy.signal.lombscargle, {m} samples x {m} frequencies")
    rng = np.random.default_rng(args.seed + 1)
    pick = np.sort(rng.choice(n, size=m, replace=False))   # irregular positions, from the segment
    ths, ys = th[pick].copy(), y[pick].copy()
    span = float(np.ptp(ths))
    fmin, df, nf = 1.0 / span, 0.5 / span, m
    f = fmin + df * np.arange(nf)
    LombScargle(ths, ys, method="nifty").power_grid(fmin, df, 16)  # warm-up (import, plans)
    t_g, p_g = best_of(lambda: LombScargle(ths, ys, method="nifty").power_grid(fmin, df, nf), 3)
    yc = ys - ys.mean()
    t_sp, p_sp = best_of(lambda: _scipy_chunked(ths, yc, f), 1)
    rows = [("gearspec LombScargle.power_grid (nifty)", t_g, p_g),
            ("scipy.signal.lombscargle (floating_mean)", t_sp, p_sp)]
    try:
        t_ap, p_ap = best_of(lambda: LombScargle(ths, ys, method="astropy").power(f), 1)
        rows.append(("astropy LombScargle (cython, psd)", t_ap, p_ap))
        R.update(ls_astropy_s=t_ap)
    except Exception as exc:  # noqa: BLE001 - astropy is a dependency, but be informative
        print(f"  astropy skipped: {exc}")
    scale = float(np.max(p_sp))
    big = p_sp > 1e-3 * scale
    print(f"  {'method':<44s} {'time':>11s} {'x nifty':>8s} {'max|dP|/maxP':>13s} {'max|dP|/P (P>1e-3 max)':>24s}")
    for name, dt_, pw in rows:
        d = np.abs(pw - p_sp)
        print(f"  {name:<44s} {fmt_s(dt_)} {dt_ / t_g:8.1f} {np.max(d) / scale:13.2e} "
              f"{np.max(d[big] / p_sp[big]):24.2e}")
    speedup = t_sp / t_g
    rel = float(np.max(np.abs(p_g - p_sp)) / scale)
    rel_bin = float(np.max(np.abs(p_g - p_sp)[big] / p_sp[big]))
    # normalisation: power = N A^2 / 4 for a sinusoid of amplitude A, on the same positions, at a
    # frequency on the grid (no noise: the only departure is leakage of order 1/N)
    a_test, k_test = 0.01, nf // 3
    y_test = a_test * np.sin(TWO_PI * f[k_test] * ths + 0.3)
    expect = m * a_test**2 / 4
    pn_g = float(LombScargle(ths, y_test, method="nifty").power_grid(fmin, df, nf)[k_test]) / expect
    pn_s = float(_scipy_chunked(ths, y_test - y_test.mean(), f[k_test:k_test + 1])[0]) / expect
    print(f"  speed: gearspec / scipy = {t_g / t_sp:.2e} (scipy is {speedup:.0f} x slower); agreement: "
          f"max |dP| / max P = {rel:.1e}, max per-bin |dP|/P where P > 1e-3 max = {rel_bin:.1e}")
    print(f"  normalisation: a sinusoid of amplitude A = {a_test:g} at {f[k_test]:.5g} c/rad on the same "
          f"positions gives P / (N A^2/4) = {pn_g:.5f} (gearspec), {pn_s:.5f} (scipy)")
    R.update(ls_samples=m, ls_freqs=nf, ls_gearspec_s=t_g, ls_scipy_s=t_sp, ls_speedup_vs_scipy=speedup,
             ls_max_rel_diff=rel, ls_max_rel_diff_per_bin=rel_bin, ls_norm_gearspec=pn_g, ls_norm_scipy=pn_s)


def memory_passes(args, R, rec, tau, seg, s, th, y, gear):
    section("5. peak memory (separate passes; unit = one float64 copy of the data, 8 N bytes)")
    c = 8 * len(tau)
    n = len(th)
    workers = _workers_arg(args.workers)
    n_threads = _analysis_threads(workers, seg)
    fft_peak, _, _ = traced_peak(lambda: np.fft.rfft(tau))
    seg_peak, _, _ = traced_peak(lambda: find_segments(rec))
    an_peak, an_kept, _ = traced_peak(lambda: analyze(rec, GEAR, segmentation=seg, progress=False, workers=workers))
    an1_peak, _, _ = traced_peak(lambda: analyze(rec, GEAR, segmentation=seg, progress=False, workers=1))
    one = {ks: traced_peak(lambda ks=ks: analyze_segment(th, y, gear, segment=s, keep_spectra=ks))[0] / (8 * n)
           for ks in (False, True)}
    rss1_grow, _, _ = rss_peak(lambda: analyze(rec, GEAR, segmentation=seg, progress=False, workers=1))
    rss_grow, exact, _ = rss_peak(lambda: analyze(rec, GEAR, segmentation=seg, progress=False, workers=workers))
    print(f"  tracemalloc, np.fft.rfft (baseline)      peak extra {fft_peak / c:6.2f} copies "
          f"({fft_peak / 2**20:8.1f} MiB)")
    print(f"  tracemalloc, find_segments               peak extra {seg_peak / c:6.2f} copies "
          f"({seg_peak / 2**20:8.1f} MiB)")
    th_ = f"{n_threads} thread{'s' if n_threads > 1 else ''}"
    print(f"  tracemalloc, analyze ({th_:9s})        peak extra {an_peak / c:6.2f} copies "
          f"({an_peak / 2**20:8.1f} MiB); held by the result afterwards {an_kept / c:.2f} copies")
    print(f"  peak RSS growth (ru_maxrss), analyze     peak extra {rss_grow / c:6.2f} copies "
          f"({rss_grow / 2**20:8.1f} MiB)" + ("" if exact else "  [lower bound: peak RSS could not be reset]"))
    if n_threads > 1:
        print(f"  the same with workers=1 (one thread):    tracemalloc {an1_peak / c:.2f}, RSS growth "
              f"{rss1_grow / c:.2f} copies (each segment in flight holds its own temporaries)")
    print(f"  tracemalloc, analyze_segment on the longest segment alone: peak extra {one[False]:.1f} "
          f"(keep_spectra=False) / {one[True]:.1f} (True)\n    copies of *its* samples (8 n bytes): what a "
          f"recording that is one long segment would need; {len(seg)} segments dilute it above")
    worst = max(an_peak, rss_grow) / c
    print(f"  peak extra memory = {worst:.2f} copies of the data; target <= {TARGET_MEMORY:g}: "
          f"{verdict(worst <= TARGET_MEMORY)}")
    print("  (tracemalloc sees numpy/Python allocations, not finufft/FFTW's own buffers; RSS sees "
          "everything, allocator slack included)")
    R.update(mem_copy_bytes=c, mem_fft_copies=fft_peak / c, mem_segmentation_copies=seg_peak / c,
             mem_analysis_traced_copies=an_peak / c, mem_result_copies=an_kept / c,
             mem_analysis_rss_copies=rss_grow / c, mem_rss_exact=exact, mem_worst_copies=worst,
             mem_analysis_1thread_traced_copies=an1_peak / c, mem_analysis_1thread_rss_copies=rss1_grow / c,
             mem_segment_copies_no_spectra=one[False], mem_segment_copies=one[True])


def profile(top, rec, seg):
    import cProfile
    import pstats

    section(f"profile of analyze on one thread (cProfile sees only its own thread; top {top})")
    prof = cProfile.Profile()
    prof.enable()
    analyze(rec, GEAR, segmentation=seg, progress=False, workers=1)
    prof.disable()
    st = pstats.Stats(prof, stream=sys.stdout).strip_dirs()
    st.sort_stats("tottime").print_stats(top)
    st.sort_stats("cumulative").print_stats(top)


def summary(R):
    section("summary")
    ra, rb = R["ratio_analysis"], R["ratio_total"]
    ra1, rb1 = R["ratio_analysis_1thread"], R["ratio_total_1thread"]
    nt = R.get("analysis_threads", 1)
    tag = f" ({nt} threads)" if nt > 1 else ""
    rows = [("samples / segments", f"{R['rows']:,} / {R['segments']}", ""),
            ("np.fft.rfft (baseline, one thread)", f"{R['fft_s']:.3f} s", ""),
            ("find_segments / FFT" + tag, f"{R['ratio_segmentation']:.2f} x", ""),
            ("analyze / FFT" + tag, f"{ra:.2f} x", f"<= {TARGET_SPEED:g} x  {verdict(ra <= TARGET_SPEED)}"),
            ("(find_segments + analyze) / FFT" + tag, f"{rb:.2f} x",
             f"<= {TARGET_SPEED:g} x  {verdict(rb <= TARGET_SPEED)}")]
    if nt > 1:
        rows += [("find_segments / FFT (one thread)", f"{R['ratio_segmentation_1thread']:.2f} x", ""),
                 ("analyze / FFT (one thread)", f"{ra1:.2f} x", f"<= {TARGET_SPEED:g} x  {verdict(ra1 <= TARGET_SPEED)}"),
                 ("(find_segments + analyze) / FFT (one thr.)", f"{rb1:.2f} x",
                  f"<= {TARGET_SPEED:g} x  {verdict(rb1 <= TARGET_SPEED)}")]
    if "ls_speedup_vs_scipy" in R:
        agree = R["ls_max_rel_diff"] < 1e-5
        rows += [("gearspec LS time / scipy lombscargle", f"{1 / R['ls_speedup_vs_scipy']:.2e}",
                  f"({R['ls_samples']} samples x {R['ls_freqs']} frequencies)"),
                 ("LS agreement max|dP|/max P", f"{R['ls_max_rel_diff']:.1e}",
                  f"< 1e-5  {'AGREE' if agree else 'DISAGREE'}")]
    if "mem_worst_copies" in R:
        mt, mr = R["mem_analysis_traced_copies"], R["mem_analysis_rss_copies"]
        rows += [("peak extra memory (tracemalloc)" + tag, f"{mt:.2f} copies",
                  f"<= {TARGET_MEMORY:g}  {verdict(mt <= TARGET_MEMORY)}"),
                 ("peak extra memory (RSS growth)" + tag, f"{mr:.2f} copies",
                  f"<= {TARGET_MEMORY:g}  {verdict(mr <= TARGET_MEMORY)}"),
                 ("held by the result afterwards", f"{R['mem_result_copies']:.2f} copies", ""),
                 ("one segment alone (its own copies)", f"{R['mem_segment_copies']:.1f} copies",
                  f"(a one-segment recording: {verdict(R['mem_segment_copies'] <= TARGET_MEMORY)})")]
    for a, b, c in rows:
        print(f"  {a:<44s} {b:>14s}   {c}")
    R["speed_target_met"] = ra <= TARGET_SPEED
    R["speed_target_met_1thread"] = ra1 <= TARGET_SPEED
    if "mem_worst_copies" in R:
        R["memory_target_met"] = R["mem_worst_copies"] <= TARGET_MEMORY


def main(args) -> dict:
    R: dict = {"samples": args.samples}
    warnings.simplefilter("ignore", DeprecationWarning)
    print(f"gearspec {getattr(gearspec, '__version__', '?')} | numpy {np.__version__} | python "
          f"{platform.python_version()} | {os.cpu_count()} cpu(s) | OMP_NUM_THREADS="
          f"{os.environ.get('OMP_NUM_THREADS', 'unset')}")
    print(f"source: {_git_state()}")
    rec, _ = make_recording(args, R)
    gc.collect()
    tau = rec.tau
    gear = load_gear(GEAR)
    seg = time_whole(args, R, rec, tau)
    gc.collect()
    s = max(seg, key=lambda x: x.n)
    th = rec.theta[s.rows]
    y = s.direction * tau[s.rows]
    stage_breakdown(R, s, th, y, gear)
    gc.collect()
    if not args.no_scipy:
        periodogram_vs_scipy(args, R, th, y)
        gc.collect()
    if not args.no_memory:
        memory_passes(args, R, rec, tau, seg, s, th, y, gear)
    if args.profile:
        profile(args.profile, rec, seg)
    summary(R)
    return R


if __name__ == "__main__":
    result = main(ARGS)
    if ARGS.json:
        with open(ARGS.json, "w") as fh:
            json.dump(result, fh, indent=1, default=float)
        print(f"\nwrote {ARGS.json}")
    sys.exit(0)
