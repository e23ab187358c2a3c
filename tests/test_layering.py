"""The shape of the package (GUIDE.md, "The pipeline"): what ``import gearspec`` offers and costs,
which modules may import which, and the signal helpers shared by every engine (known answers).

The import rules are read from the source with :mod:`ast` (imports inside functions included), so a
violation is named by file and line whatever code path would reach it.
"""

from __future__ import annotations

import ast
import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import pytest

import gearspec
from gearspec.signals import butter_filtfilt, central_difference, decimate, decimation_index

PACKAGE = Path(gearspec.__file__).parent
#: leaves of the pipeline: nothing outside them imports them
LEAVES = ("gearspec.report", "gearspec.plots", "gearspec.cli")


# ---------------------------------------------------------------------- the public names
def test_public_names_import():
    for name in gearspec.__all__:
        assert getattr(gearspec, name) is not None, name
    assert set(gearspec.__all__) <= set(dir(gearspec))
    assert gearspec.fit is gearspec.identify.fit and _within(gearspec.load_recording.__module__, "gearspec.recording")
    with pytest.raises(AttributeError, match="no attribute 'nonexistent'"):
        gearspec.nonexistent  # noqa: B018


@pytest.mark.parametrize("package", ["gearspec.diagnose", "gearspec.discover", "gearspec.spectrum",
                                     "gearspec.simulate"])
def test_subpackage_names_import(package):
    import importlib

    mod = importlib.import_module(package)
    for name in mod.__all__:
        assert hasattr(mod, name), f"{package}.{name}"


def test_engine_internals_are_not_exported():
    import gearspec.diagnose as dg
    import gearspec.discover as dc

    def private(mod, name):   # absent, or only the submodule of that name
        return name not in mod.__all__ and isinstance(getattr(mod, name, types), types.ModuleType)

    for name in ("butter_filtfilt", "decimate", "State", "BaseBlock", "folds_of", "Candidate", "evaluate_candidate"):
        assert private(dg, name), name
    for name in ("Moments", "moments", "fit_law", "fold_ids", "LawFit", "Part"):
        assert private(dc, name), name


@pytest.mark.parametrize("package", ["diagnose", "discover"])
def test_package_is_called_as_its_main_function(package, monkeypatch):
    mod = getattr(gearspec, package)
    monkeypatch.setattr(mod, package, lambda *a, **k: ("called", a, k))
    assert mod(1, x=2) == ("called", (1,), {"x": 2})
    assert getattr(mod, "__all__")[0] == package


def test_import_gearspec_is_cheap():
    # neither the heavy dependencies nor the paper scripts load with the package itself
    code = ("import sys, gearspec; heavy = ('paper_repro', 'matplotlib', 'pysindy', 'scipy', 'scipy.optimize', "
            "'pandas', 'gearspec.cli', 'gearspec.report', 'gearspec.plots'); "
            "print(','.join(m for m in heavy if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         cwd=PACKAGE.parent).stdout.strip()
    assert out == ""


# ---------------------------------------------------------------------- who imports whom
def _imports(path: Path) -> list[tuple[int, str]]:
    """(line, absolute module name) of every import in ``path`` (``from a import b``: ``a`` and
    ``a.b``, as ``b`` may be a module)."""
    rel = path.relative_to(PACKAGE.parent).with_suffix("")
    parts = list(rel.parts)
    package = parts if parts[-1] == "__init__" else parts[:-1]
    package = [p for p in package if p != "__init__"]
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = package[:len(package) - node.level + 1] if node.level else []
            mod = ".".join(base + ([node.module] if node.module else []))
            out += [(node.lineno, mod)] + [(node.lineno, f"{mod}.{a.name}") for a in node.names]
    return out


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _within(name: str, package: str) -> bool:
    return name == package or name.startswith(package + ".")


def _violations(rule) -> list[str]:
    return [f"{p.relative_to(PACKAGE.parent)}:{line} imports {name}"
            for p in sorted(PACKAGE.rglob("*.py")) for line, name in _imports(p) if rule(_module_name(p), name)]


def test_import_parser_resolves_relative_imports():
    found = dict((name, line) for line, name in _imports(PACKAGE / "diagnose" / "data.py"))
    assert "gearspec.signals.decimate" in found and "gearspec.errors" in found


def test_library_does_not_import_paper_repro():
    # the command line is a leaf (nothing imports it); its `repro` and `demo` commands run the
    # reproductions that ship beside the library
    bad = _violations(lambda mod, name: _within(name, "paper_repro") and not _within(mod, "gearspec.cli"))
    assert bad == []


@pytest.mark.parametrize("argv", [["demo"], ["repro", "silo4"]])
def test_commands_without_the_reproductions_say_so(argv, tmp_path, monkeypatch, capsys):
    from gearspec.cli import main

    monkeypatch.setitem(sys.modules, "paper_repro", None)      # a library installed without paper_repro/
    assert main(argv + ["--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert f"gearspec {argv[0]} needs the paper reproductions" in err and err.count("\n") == 1


def test_leaves_are_not_imported_by_the_library():
    def rule(mod, name):
        # gearspec/__main__.py (``python -m gearspec``) is an entry point, like the command itself
        return (any(_within(name, leaf) for leaf in LEAVES) and not any(_within(mod, leaf) for leaf in LEAVES)
                and mod != "gearspec.__main__")

    assert _violations(rule) == []


# ---------------------------------------------------------------------- signal helpers: known answers
def test_central_difference_is_exact_for_a_parabola():
    dt = 0.01
    t = np.arange(50) * dt
    d = central_difference(3 * t ** 2 + t, dt)
    assert d[1:-1] == pytest.approx(6 * t[1:-1] + 1, rel=1e-12)       # exact inside for a quadratic
    assert d[0] == pytest.approx(3 * dt + 1) and d[-1] == pytest.approx(6 * t[-1] - 3 * dt + 1)
    assert np.array_equal(d, np.gradient(3 * t ** 2 + t, dt))          # numpy's convention, bit for bit
    assert np.array_equal(central_difference([2.0], dt), [0.0])


def test_butter_filtfilt_halves_the_cutoff_without_phase():
    fs, fc = 1000.0, 50.0
    t = np.arange(20000) / fs
    mid = slice(5000, 15000)
    for f, gain in ((fc, 0.5), (1.0, 1.0)):                 # Butterworth -3 dB, applied twice; pass band
        y = butter_filtfilt(np.sin(2 * np.pi * f * t), fc, fs)
        X = np.column_stack([np.sin(2 * np.pi * f * t[mid]), np.cos(2 * np.pi * f * t[mid])])
        b = np.linalg.lstsq(X, y[mid], rcond=None)[0]
        assert b[0] == pytest.approx(gain, abs=1e-6) and b[1] == pytest.approx(0.0, abs=1e-6)   # zero phase
    assert np.abs(butter_filtfilt(np.sin(2 * np.pi * 400 * t), fc, fs)[mid]).max() < 1e-6     # stop band
    with pytest.raises(gearspec.InputError, match="cut-off"):
        butter_filtfilt(t, 600.0, fs)


def test_decimation_keeps_matlabs_samples():
    assert list(decimation_index(10, 3)) == [0, 3, 6, 9]     # ceil(10/3) = 4 samples, the last one kept
    assert list(decimation_index(9, 3)) == [2, 5, 8]
    x = np.full(1000, 2.5)
    # an even-order Chebyshev I sits at the bottom of its 0.05 dB ripple at DC; filtfilt applies it twice
    assert decimate(x, 10) == pytest.approx(np.full(100, 2.5 * 10 ** (-2 * 0.05 / 20)), rel=1e-6)  # 8th-order rounding
    assert np.array_equal(decimate(x, 1), x)
