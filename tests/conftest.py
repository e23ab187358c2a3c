"""Shared fixtures: where the real data sets are (GEARSPEC_DATA), and small synthetic recordings."""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def data_root() -> Path:
    """GEARSPEC_DATA, defaulting to ../shared/datasets beside the project (as in CI)."""
    return Path(os.environ.get("GEARSPEC_DATA", ROOT.parent / "shared" / "datasets"))


@pytest.fixture(scope="session")
def data_dir() -> Path:
    root = data_root()
    if not root.is_dir():
        pytest.skip(f"real data sets not found at {root} (set GEARSPEC_DATA)")
    os.environ.setdefault("GEARSPEC_DATA", str(root))
    return root


if os.environ.get("PYTEST_XDIST_WORKER") and not os.environ.get("GEARSPEC_THREADS"):
    # pytest-xdist already runs one test process per core: a command's forked workers
    # (core.parallel) and evaluation threads would only contend with the other test process.
    # Tests of the parallel paths set GEARSPEC_THREADS (or workers=) themselves.
    os.environ["GEARSPEC_THREADS"] = "1"


@pytest.fixture(autouse=True)
def _quiet_gearspec_warnings():
    from gearspec.errors import GearspecWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GearspecWarning)
        yield
