"""``gearspec formats``: the file formats and outputs users rely on, from the copy of CONTRACTS.md
the package ships (``gearspec/docs/CONTRACTS.md``; ``tests/test_cli_help.py`` checks it against the
project's contract)."""

from __future__ import annotations

from importlib import resources

from ..errors import InputError
from . import COMMAND_HELP

#: topic name -> the number of its section in CONTRACTS.md
SECTIONS = {"recording": 1, "gear": 2, "frequencies": 3, "outputs": 4}


def register(sub) -> None:
    p = sub.add_parser("formats", help=COMMAND_HELP["formats"],
                       description="Print the formats gearspec reads and writes: the recording columns and "
                                   "units, the gear spec, frequencies, the command line and the JSON outputs.")
    p.add_argument("topic", nargs="?", metavar="TOPIC", help=" | ".join(SECTIONS) + " (default: all)")
    p.set_defaults(func=run)


def contract_text() -> str:
    """The whole contract as the package ships it (Markdown)."""
    return resources.files("gearspec").joinpath("docs/CONTRACTS.md").read_text(encoding="utf-8")


def section(topic: str | None) -> str:
    """The contract's section for ``topic`` (one of :data:`SECTIONS`), or the whole text for None."""
    text = contract_text()
    if topic is None:
        return text
    if topic not in SECTIONS:
        raise InputError(f"gearspec formats {topic}: unknown topic; one of {', '.join(SECTIONS)}")
    start = text.index(f"\n## {SECTIONS[topic]}. ")
    stop = text.find("\n## ", start + 1)
    return text[start + 1:stop if stop > 0 else None].rstrip() + "\n"


def run(args) -> int:
    print(section(args.topic), end="")
    return 0
