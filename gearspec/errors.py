"""Errors and warnings a user sees: :class:`InputError` refuses bad input (exit status 2 on the
command line); :class:`GearspecWarning` flags doubtful but usable input."""

from __future__ import annotations

import warnings

__all__ = ["InputError", "GearspecWarning", "warn"]


class InputError(ValueError):
    """Input gearspec cannot use; one sentence for a robotics engineer naming the file, column or
    option, what is wrong, and what to do."""


class GearspecWarning(UserWarning):
    """Input that is usable but doubtful (units that look wrong, rows excluded, ...)."""


def warn(message: str) -> None:
    """Issue a :class:`GearspecWarning` attributed to the caller of the public function."""
    warnings.warn(message, GearspecWarning, stacklevel=3)
