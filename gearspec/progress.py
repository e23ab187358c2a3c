"""Progress of a command's stages on stderr: one line per finished stage with its duration (so a
batch log shows where the time went); on a terminal the stage under way too, overwritten when done."""

from __future__ import annotations

import sys
import time

__all__ = ["Stages"]


class Stages:
    """Stage lines for one command run; ``enabled`` False prints nothing (``--quiet``); ``stream``
    default ``sys.stderr``, looked up at each call (so redirection and capture work)."""

    def __init__(self, enabled: bool = True, stream=None):
        self.enabled = enabled
        self._stream = stream
        self._t0 = time.perf_counter()
        self._pending = False

    @property
    def stream(self):
        return self._stream if self._stream is not None else sys.stderr

    def _tty(self) -> bool:
        try:
            return bool(self.stream.isatty())
        except (AttributeError, ValueError):
            return False

    def start(self, what: str) -> None:
        """A stage begins: shown on a terminal only (a log gets the line of :meth:`done`)."""
        self._t0 = time.perf_counter()
        if self.enabled and self._tty():
            print(f"gearspec: {what} ...", end="\r", file=self.stream, flush=True)
            self._pending = True

    def done(self, text: str) -> None:
        """The stage is done: one line with its duration."""
        if not self.enabled:
            return
        line = f"gearspec: {text} ({time.perf_counter() - self._t0:.1f} s)"
        if self._pending:
            line += "\033[K"  # clear what remains of the 'under way' line
            self._pending = False
        print(line, file=self.stream, flush=True)
        self._t0 = time.perf_counter()
