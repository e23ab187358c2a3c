"""Errors and warnings a user of gearspec sees.

Every refusal of bad input raises :class:`InputError` with one sentence that names the file, the
column and the reason; the command line turns it into exit status 2.  Doubtful but usable input
(a position that looks like degrees, a few NaN rows) gives a :class:`GearspecWarning` and goes on.
"""

from __future__ import annotations

import warnings

__all__ = ["InputError", "GearspecWarning", "warn"]


class InputError(ValueError):
    """Input that gearspec cannot use: a file, a column, a value or an option.

    The message is meant for a robotics engineer, not a programmer: it says what is wrong with
    which file or column, and what to do about it.
    """


class GearspecWarning(UserWarning):
    """Input that is usable but doubtful (units that look wrong, rows excluded, ...)."""


def warn(message: str) -> None:
    """Issue a :class:`GearspecWarning` attributed to the caller of the public function."""
    warnings.warn(message, GearspecWarning, stacklevel=3)
