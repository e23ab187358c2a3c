"""Reproductions of the papers' figures and tables: thin scripts over gearspec's public API.

One sub-package per paper or data set (``silo4``, ``lola``, ``emps``), each with
``run(out, **options) -> Path`` writing ``out/report.md``, the figures (PNG) and every table as
CSV with the columns ``quantity, paper, gearspec, rel_diff`` (CONTRACTS.md section 4).  The
command line runs them as ``gearspec repro NAME --out DIR``; each can also be run as a script:
``python -m paper_repro.NAME --out DIR``.
"""

import importlib
import pkgutil

__all__ = ["available", "run"]


def available() -> list[str]:
    """Names of the reproductions present."""
    return sorted(m.name for m in pkgutil.iter_modules(__path__) if m.ispkg)


def run(name: str, out, **options):
    """Run reproduction ``name`` into folder ``out``; returns the path of its report.md."""
    if name not in available():
        raise ValueError(f"no reproduction '{name}' (available: {', '.join(available())})")
    return importlib.import_module(f"{__name__}.{name}").run(out, **options)
