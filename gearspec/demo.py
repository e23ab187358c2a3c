"""``make demo`` / ``gearspec demo``: the most complete analysis gearspec has, on built-in data.

The built-in data is a synthetic recording of a SILO4-like joint (motor -> planetary 14 -> worm
20.5, theta at the motor), with friction from the SILO4 paper's Table 2 (positive direction,
converted to SI: rad/s at the motor, Nm): a Stribeck curve per direction, a constant ripple once
per joint revolution, and meshing ripple at the worm and motor shafts that decays exponentially
with speed.  It is written to ``demo_recording.csv`` in the recording format and then analysed
exactly as a user's file would be (``gearspec spectrum demo_recording.csv --gear silo4-joint3``).

The closed loop of the simulated drive ripples its speed by 1 % seven times per motor turn (as a
motor with seven pole pairs might); through the viscous term this puts an undeclared component
into the friction at 7x the motor shaft, which the analysis should find and leave unlabelled.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from .gears import load_gear
from .recording import load_recording
from .segment import find_segments
from .simulate import Ripple, plateau_recording
from .spectrum import analyze

__all__ = ["demo_recording", "run_demo"]

RPM = 2 * math.pi / 60  # rad/s per rpm
PER_RPM = 60 / (2 * math.pi)  # (1/rpm) -> (s/rad)


def demo_recording(seed: int = 7):
    """The built-in SILO4-like recording and its truth (see the module docstring)."""
    gear = load_gear("silo4-joint3")
    lines = {ln.label: ln.frequency for ln in gear.declared_lines()}
    f_joint, f_worm, f_motor = lines["output shaft"], lines["planetary output shaft"], lines["motor shaft"]
    tau_c, tau_e, v_s, visc = (7.106e-3, 7.909e-3), (8.58e-3, 9.41e-3), (28.18 * RPM, 26.58 * RPM), (
        0.0134e-3 / RPM, 0.0138e-3 / RPM)

    def level(speed, d):
        i = 0 if d > 0 else 1
        return tau_c[i] + (tau_e[i] - tau_c[i]) * np.exp(-speed / v_s[i]) + visc[i] * speed

    ripples = [Ripple(f_joint, 0.3e-3, math.pi / 2),
               Ripple(f_worm, (0.576e-3, 0.526e-3), math.pi / 2, (1.27e-4 * PER_RPM, 1.12e-4 * PER_RPM)),
               Ripple(f_motor, (0.133e-3, 0.152e-3), math.pi, (5.28e-5 * PER_RPM, 7.49e-6 * PER_RPM))]
    rpm = [10, 20, 50, 100, 280, 560, 1000, 2000, 3000]
    speeds = [r * RPM for r in rpm] + [-r * RPM for r in rpm]
    # two worm-shaft cycles where that takes less than 45 s (the slowest plateaus see part of one:
    # the joint fit accounts for it, the per-segment spectra leave the line out there)
    durations = [max(2.5, min(2.2 / (f_worm * abs(v)), 45.0)) for v in speeds]
    return plateau_recording(speeds, ripples=ripples, level=level, duration=durations, fs=1000.0, ramp=0.3,
                             speed_ripple=0.01, speed_ripple_frequency=7 * f_motor, noise=0.05e-3,
                             one_run_per_plateau=True, gear=gear, seed=seed)


def run_demo(out: str | Path = "demo-out") -> Path:
    """Write the demo recording, its spectrum report (``out/report.md``) and the identified
    friction model (``out/fit/report.md``); returns the spectrum report's path."""
    from .identify import identify_recording
    from .report import write_spectrum_report
    from .report.fit import write_fit_report

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rec, _ = demo_recording()
    path = rec.save(out / "demo_recording.csv")
    rec = load_recording(path, "silo4-joint3")
    seg = find_segments(rec)
    result = analyze(rec, segmentation=seg, keep_spectra=True)
    result.to_json(out / "spectrum.json")
    report = write_spectrum_report(result, rec, seg, out, command=f"gearspec spectrum {path} --gear silo4-joint3 "
                                                                     f"--out {out} --json {out / 'spectrum.json'}")
    fitted = identify_recording(rec, "silo4", segmentation=seg)
    (out / "fit").mkdir(exist_ok=True)
    (out / "fit" / "fit.json").write_text(json.dumps(fitted.to_dict(), indent=1))
    write_fit_report(fitted, out / "fit", command=f"gearspec fit {path} --gear silo4-joint3 --out {out / 'fit'} "
                                                  f"--json {out / 'fit' / 'fit.json'}", recording_summary=rec.summary())
    with open(report, "a") as fh:
        fh.write("\n## Friction model\n\nThe SILO4 model (eq. 11) identified from the same segments, beside the "
                 "published procedure and simpler laws: [fit/report.md](fit/report.md).\n")
    return report
