"""Numbers the README quotes from a command, checked where the test computes them (issue 16 item 4).

A README paragraph that quotes results is wrapped in ``<!-- numbers: NAME -->`` ...
``<!-- /numbers -->``.  The test that computes those results calls :func:`check` with NAME and the
values formatted as the README prints them; if the code's output moves, the test fails and names
the stale text.  ``tests/test_readme_numbers.py`` checks that every marked paragraph is checked by
some test, so a marker cannot be left behind unchecked.
"""

from __future__ import annotations

import re
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"
_BLOCK = re.compile(r"<!-- numbers: ([\w-]+) -->\n(.*?)<!-- /numbers -->", re.S)


def blocks(text: str | None = None) -> dict[str, str]:
    """NAME -> the README text of each marked paragraph (line breaks as spaces)."""
    text = README.read_text(encoding="utf-8") if text is None else text
    return {m.group(1): " ".join(m.group(2).split()) for m in _BLOCK.finditer(text)}


def check(name: str, *quoted: str, text: str | None = None) -> None:
    """Assert that README paragraph ``name`` contains every string of ``quoted`` (numbers formatted
    as the README prints them)."""
    found = blocks(text)
    assert name in found, f"README.md has no paragraph marked <!-- numbers: {name} -->"
    missing = [q for q in quoted if q not in found[name]]
    assert not missing, (f"README.md paragraph '{name}' is stale: the code now gives {missing}; "
                         f"the paragraph reads: {found[name][:600]}")
