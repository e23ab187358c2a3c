"""Every command's --help ends with examples that parse, and the formats the help points to ship
with the package (issue 16 item 5)."""

from __future__ import annotations

import argparse
import shlex
from pathlib import Path

import pytest

from gearspec.cli import build_parser, main
from gearspec.cli.formats import SECTIONS, contract_text, section

ROOT = Path(__file__).resolve().parents[1]


def _parsers(parser, path=""):
    """(command path, parser) of every command and sub-command."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, child in action.choices.items():
                sub = f"{path} {name}".strip()
                yield sub, child
                yield from _parsers(child, sub)


PARSERS = dict(_parsers(build_parser()))


def _example_commands(parser) -> list[str]:
    lines = (parser.epilog or "").splitlines()
    return [line.split("  #")[0].strip() for line in lines if line.strip().startswith("gearspec ")]


@pytest.mark.parametrize("path", sorted(PARSERS))
def test_every_command_has_examples_that_parse(path):
    parser = PARSERS[path]
    text = parser.format_help()
    assert "examples:" in text, f"gearspec {path} --help has no examples"
    commands = _example_commands(parser)
    assert len(commands) >= 2, f"gearspec {path}: {len(commands)} example(s)"
    for line in commands:
        argv = shlex.split(line)[1:]
        try:
            build_parser().parse_args(argv)
        except SystemExit as exc:  # argparse refused the example: a wrong option or value
            pytest.fail(f"example of gearspec {path} does not parse ({exc.code}): {line}")


def test_a_wrong_example_is_caught():
    """The check above can fail: an example naming an option that does not exist is refused."""
    with pytest.raises(SystemExit):
        build_parser().parse_args(shlex.split("gearspec fit run.csv --gear silo4-joint3 --lw silo4")[1:])


def test_examples_keep_their_lines_and_descriptions_wrap():
    text = PARSERS["fit"].format_help()
    ex = text[text.index("examples:"):].splitlines()
    assert ex[1].startswith("  gearspec fit run1.csv --gear silo4-joint3 --law silo4 --out fit/")
    batch = PARSERS["batch"].format_help()
    head = batch[:batch.index("examples:")]
    assert max(len(s) for s in head.splitlines()) <= 100  # the long description is wrapped, not one line


def test_the_help_points_to_a_command_not_a_file():
    assert "CONTRACTS.md" not in PARSERS["fit"].format_help()
    assert "gearspec formats recording" in PARSERS["fit"].format_help()


def test_formats_prints_one_section(capsys):
    assert main(["formats", "recording"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("## 1. Recording files") and "## 2." not in out and "`theta`" in out
    for topic, number in SECTIONS.items():
        assert section(topic).startswith(f"## {number}. ")
    assert main(["formats", "bogus"]) == 2


def test_the_shipped_formats_are_the_contract():
    """The package carries the project's contract verbatim (users of a wheel have no ../shared)."""
    shared = ROOT.parent / "shared" / "CONTRACTS.md"
    if not shared.exists():
        pytest.skip(f"{shared} not beside the repository")
    assert contract_text() == shared.read_text(encoding="utf-8"), \
        "gearspec/docs/CONTRACTS.md differs from ../shared/CONTRACTS.md: copy it"
