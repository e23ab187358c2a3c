"""The README's quoted numbers are checked by the tests that compute them (tests/readme_numbers.py)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from readme_numbers import blocks, check

TESTS = Path(__file__).resolve().parent


def test_every_marked_paragraph_is_checked_by_a_test():
    names = set(blocks())
    assert names, "README.md marks no paragraph of quoted numbers"
    sources = "\n".join(p.read_text(encoding="utf-8") for p in TESTS.glob("test_*.py") if p.name != Path(__file__).name)
    checked = set(re.findall(r"""check\(\s*["']([\w-]+)["']""", sources))
    assert names <= checked, f"README paragraphs no test checks: {sorted(names - checked)}"
    assert checked <= names, f"tests check paragraphs the README no longer marks: {sorted(checked - names)}"


def test_a_stale_number_is_caught():
    text = "x\n<!-- numbers: t -->\nheld-out rmse 0.1031 -> 0.0963 Nm\n<!-- /numbers -->\n"
    check("t", "0.1031 -> 0.0963", text=text)
    with pytest.raises(AssertionError, match="stale"):
        check("t", "0.1031 -> 0.0966", text=text)
