"""Examples shown at the end of each command's ``--help`` (issue 16 item 5).

One table, ``EXAMPLES``: command path (``"spectrum"``, ``"simulate silo4"``) -> lines of
``gearspec ...  # what it does``.  :func:`attach` puts them under every parser that has none of its
own (``export``, ``compensate`` and ``batch`` write theirs beside their options), and
:class:`HelpFormatter` keeps an examples block as written while still wrapping the description.
``tests/test_cli_help.py`` parses every example line, so an example cannot name an option that does
not exist.
"""

from __future__ import annotations

import argparse

__all__ = ["EXAMPLES", "HelpFormatter", "attach", "example_lines"]

_EMPS = "DATA_EMPS.mat --gear emps --map theta=qm,torque=vir --scale torque=gtau"

#: command path -> example lines (the command line, two spaces, then ``# what it does``)
EXAMPLES: dict[str, tuple[str, ...]] = {
    "spectrum": (
        "gearspec spectrum run1.csv run2.csv --gear silo4-joint3 --out report/ --json spectrum.json",
        f"gearspec spectrum {_EMPS} --out emps/   # a linear axis (cycles/m)",
        "gearspec spectrum chirp.csv --gear silo4-joint3 --order-map --track 1.5 --out om/   # whole motions",
    ),
    "fit": (
        "gearspec fit run1.csv --gear silo4-joint3 --law silo4 --out fit/ --json model.json",
        "gearspec fit testbed.csv --gear lola-a --law lola11 --out lola/   # needs a load channel",
        "gearspec fit moves.csv --gear my-drive.toml --law silo4 --motion free --out moves/   # no plateaus",
    ),
    "diagnose": (
        "gearspec diagnose run1.csv --gear silo4-joint3 --law silo4 --out diag/ --json diagnose.json",
        "gearspec diagnose run1.csv --gear silo4-joint3 --model model.json --validate run2.csv --out diag/",
        f"gearspec diagnose {_EMPS} --trajectory --out emps-diag/   # inverse dynamics on every sample",
    ),
    "discover": (
        "gearspec discover run1.csv --gear silo4-joint3 --out disc/ --json discover.json",
        f"gearspec discover {_EMPS} --out disc/   # laws found from the data, against IDIM-LS",
        "gearspec discover run1.csv --gear silo4-joint3 --families coulomb,viscous,stribeck_exp,ripple_exp --symmetric",
    ),
    "simulate": (
        "gearspec simulate silo4 --out twin/   # SILO4 joint 3: 20 speeds x 2 directions x 10 runs",
        "gearspec simulate lola --module A --out twin/   # Lola/CROPS: speed x brake-load grid",
    ),
    "simulate silo4": (
        "gearspec simulate silo4 --out twin/ --speeds-rpm 280,-280,3000,-3000 --repetitions 3",
        "gearspec simulate silo4 --out twin/ --effect cogging:count=7,amplitude=2e-4",
        "gearspec simulate silo4 --profile chirp --out twin/   # a speed chirp instead of plateaus",
    ),
    "simulate lola": (
        "gearspec simulate lola --module A --out twin/",
        "gearspec simulate lola --module B --profile ramp --out twin/   # slow ramps, once per brake load",
    ),
    "repro": (
        "gearspec repro silo4 --out repro-silo4/   # Figs. 3-7, 9, Tables 2-3",
        "gearspec repro lola --out repro-lola/     # Figs. 7-11, Tables III-V",
        "gearspec repro emps --out repro-emps/     # IDIM-LS replicated, then the closed loop",
    ),
    "gears": (
        "gearspec gears                  # the built-in gear trains",
        "gearspec gears silo4-joint3     # one preset: stages, ratios, every declared line",
        "gearspec gears my-drive.toml    # check a gear spec of your own",
    ),
    "data": (
        "gearspec data list              # the real data sets: source, licence, checksum, where they are",
        "gearspec data describe emps     # one set: files, columns, how to read it",
        "gearspec data fetch emps        # download it (the only command that uses the network)",
    ),
    "demo": (
        "gearspec demo                   # the SILO4 paper on its twin -> demo-out/report.html",
        "gearspec demo --out /tmp/demo",
    ),
    "formats": (
        "gearspec formats                # every input and output format",
        "gearspec formats recording      # the recording columns and units",
        "gearspec formats gear           # the gear spec (TOML)",
    ),
}


def example_lines(path: str) -> list[str]:
    """The command lines of ``EXAMPLES[path]`` without their comments (for tests)."""
    return [line.split("  #")[0].strip() for line in EXAMPLES.get(path, ())]


class HelpFormatter(argparse.HelpFormatter):
    """argparse's formatter, except that a text starting with ``examples:`` is printed as written."""

    def _fill_text(self, text, width, indent):
        if text.startswith("examples:"):
            return "\n".join(indent + line for line in text.splitlines())
        return super()._fill_text(text, width, indent)


def _epilog(lines) -> str:
    return "examples:\n" + "\n".join("  " + line for line in lines)


def attach(parser: argparse.ArgumentParser, path: str = "") -> None:
    """Give ``parser`` (the command ``path``) and its sub-commands their examples and the formatter."""
    if path in EXAMPLES and not parser.epilog:
        parser.epilog = _epilog(EXAMPLES[path])
    if parser.epilog and parser.epilog.lstrip().startswith("examples"):
        parser.epilog = parser.epilog.strip()
    parser.formatter_class = HelpFormatter
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, child in action.choices.items():
                attach(child, f"{path} {name}".strip())
