"""``make demo`` / ``gearspec demo``: the SILO4 reproduction on its digital twin, in a smaller
configuration that runs in well under a minute.

The twin of the SILO4 joint-3 bench (:func:`gearspec.simulate.silo4_twin`: closed-loop speed
control on a 500-line encoder, Bessel-filtered current sampled every 4 ms, friction = the paper's
Table 2) is recorded at 11 motor speeds from 5 to 6500 rpm in both directions, three repetitions
each, saved in the recording format with its gear spec, read back, and analysed by the public
pipeline exactly as ``gearspec spectrum`` and ``gearspec fit --law silo4`` would: segments,
per-segment spectra (``spectrum.json``), the joint fit beside the published procedure
(``fit/report.md``), and the paper's figures and Tables 2-3 with the audit of its numbers
(``report.md``).  ``gearspec repro silo4`` runs the full configuration (20 speeds, ten
repetitions, as the paper).  It lives with the reproductions: the library never imports them.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["run_demo", "DEMO_SPEEDS_RPM", "DEMO_REPETITIONS"]

#: motor speeds of the demo (rpm, each in both directions): the Stribeck region, Table 3's 280 /
#: 560 / 3000 rpm and Fig. 5's 2000 / 4500 / 6500 rpm
DEMO_SPEEDS_RPM = (5, 20, 50, 100, 280, 560, 1000, 2000, 3000, 4500, 6500)
DEMO_REPETITIONS = 3


def run_demo(out: str | Path = "demo-out", seed: int = 0) -> Path:
    """Run the SILO4 reproduction in the demo configuration into ``out``; returns ``out/report.md``."""
    from . import silo4

    return silo4.run(out, seed=seed, speeds_rpm=DEMO_SPEEDS_RPM, repetitions=DEMO_REPETITIONS,
                     stick_slip_duration=5.0, control_repetitions=2)
