"""What every command pays before its own work (issue 13, scale): ``gearspec --help`` and a
command's parser import only what they need, with the help text of the parser built whole.

The checks are on which modules a fresh interpreter has imported (a known answer, unlike a time):
the analysis libraries (scipy, pandas) take about 1.5 s of CPU to import and are not needed to print
the list of commands, nor to import :mod:`gearspec.segment`.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

import gearspec
from gearspec.cli import COMMAND_HELP, COMMANDS, build_parser, main

HEAVY = ("scipy", "scipy.signal", "pandas", "matplotlib")


def _modules_after(code: str) -> set[str]:
    """The modules a fresh interpreter holds after running ``code``."""
    script = f"import sys, json, contextlib, io\n{code}\nprint(json.dumps(sorted(sys.modules)))"
    root = str(Path(gearspec.__file__).resolve().parent.parent)  # this gearspec, not an installed one
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [root, os.environ.get("PYTHONPATH")]))}
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True, env=env).stdout
    return set(json.loads(out.splitlines()[-1]))


def test_the_list_of_commands_imports_no_command_and_no_analysis_library():
    mods = _modules_after("from gearspec.cli import main\n"
                          "with contextlib.redirect_stdout(io.StringIO()):\n    main(['--help'])")
    assert not [m for m in HEAVY if m in mods]
    assert not [m for m in mods if m.startswith("gearspec.cli.") and m != "gearspec.cli.examples"]


def test_a_command_imports_its_own_module_only():
    mods = _modules_after("from gearspec.cli import main\n"
                          "with contextlib.redirect_stdout(io.StringIO()):\n    main(['fit', '--help'])")
    assert {m for m in mods if m.startswith("gearspec.cli.")} == {"gearspec.cli.examples", "gearspec.cli.fit"}
    assert not [m for m in HEAVY if m in mods]


def test_the_segment_package_imports_scipy_signal_when_it_filters():
    assert "scipy.signal" not in _modules_after("import gearspec.segment")


def _help(argv) -> str:
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf), pytest.raises(SystemExit):
        build_parser().parse_args(argv + ["--help"])
    return buf.getvalue()


@pytest.mark.parametrize("path", [[], *([c] for c in COMMANDS), ["simulate", "silo4"], ["simulate", "lola"]],
                         ids=lambda p: " ".join(p) or "gearspec")
def test_help_is_the_help_of_the_parser_built_whole(path):
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(path + ["--help"]) == 0
    assert buf.getvalue() == _help(path)


def test_commands_listed_in_their_order_after_one_is_built():
    eager = build_parser()
    lazy = build_parser(lazy=True)
    sub = next(a for a in lazy._actions if isinstance(a, argparse._SubParsersAction))
    sub.load("fit")
    sub.load("batch")
    assert lazy.format_help() == eager.format_help()
    assert list(sub.choices) == list(COMMANDS)


def test_each_command_registers_the_line_it_is_listed_with():
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    assert {a.dest: a.help for a in sub._choices_actions} == COMMAND_HELP


def test_a_refused_option_is_refused_as_before(capsys):
    # the lazily built parser still refuses with the one-line message (exit 2)
    assert main(["fit", "run.csv", "--rel-tol", "2"]) == 2
    assert "--rel-tol" in capsys.readouterr().err
