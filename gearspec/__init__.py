"""gearspec: spectral analysis and modelling of friction in robot gear drives.

The names a user calls, in the order data flows through them::

    rec = gearspec.load_recording("run.csv", "silo4-joint3")    # or gearspec.datasets.load("emps")
    spectra = gearspec.analyze(rec)                             # segments + per-segment order spectra
    data = gearspec.FitData.from_recording(rec)                 # samples in constant-speed segments
    model = gearspec.fit(data, "silo4", gear=rec.gear)          # a FrictionModel
    diagnosis = gearspec.diagnose(rec, model)                   # what the model lacks, held out
    laws = gearspec.discover(data)                              # which laws the data support

They are imported on first use (``import gearspec`` loads neither scipy nor pandas); the engines'
parts live in their modules (:mod:`gearspec.identify`, :mod:`gearspec.diagnose.loop`, ...).
``gearspec.diagnose`` and ``gearspec.discover`` are packages that can be called as their main
function.
"""

from __future__ import annotations

import importlib
import types

from .errors import GearspecWarning, InputError

__version__ = "0.13.0"

#: public name -> (module, attribute); attribute None: the module itself
_LAZY = {
    "load_recording": ("gearspec.recording", "load_recording"),
    "Recording": ("gearspec.recording", "Recording"),
    "GearTrain": ("gearspec.gears", "GearTrain"),
    "load_gear": ("gearspec.gears", "load_gear"),
    "find_segments": ("gearspec.segment", "find_segments"),
    "analyze": ("gearspec.spectrum", "analyze"),
    "FitData": ("gearspec.fitdata", "FitData"),
    "fit": ("gearspec.identify", "fit"),
    "FrictionModel": ("gearspec.model", "FrictionModel"),
    "RPM": ("gearspec.model", "RPM"),
    "estimate_lag": ("gearspec.lag", "estimate_lag"),
    "apply_lag": ("gearspec.lag", "apply_lag"),
    "silo4_twin": ("gearspec.simulate", "silo4_twin"),
    "lola_twin": ("gearspec.simulate", "lola_twin"),
    "model_recording": ("gearspec.simulate", "model_recording"),
    "plateau_recording": ("gearspec.simulate", "plateau_recording"),
    "diagnose": ("gearspec.diagnose", None),
    "discover": ("gearspec.discover", None),
    "identify": ("gearspec.identify", None),
    "spectrum": ("gearspec.spectrum", None),
    "simulate": ("gearspec.simulate", None),
    "datasets": ("gearspec.datasets", None),
}

__all__ = ["__version__", "InputError", "GearspecWarning", *_LAZY]


def __getattr__(name: str):
    """Import a public name on first use (PEP 562)."""
    try:
        module, attr = _LAZY[name]
    except KeyError:
        raise AttributeError(f"module 'gearspec' has no attribute '{name}'") from None
    value = importlib.import_module(module)
    if attr is not None:
        value = getattr(value, attr)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))


class _CallablePackage(types.ModuleType):
    """A package called as its main function of the same name: ``gearspec.diagnose(data, model)``
    is ``gearspec.diagnose.diagnose(data, model)``.  A package sets it as its module class."""

    def __call__(self, *args, **kwargs):
        return getattr(self, self.__name__.rpartition(".")[2])(*args, **kwargs)
