"""What a command prints, held until its files are committed.

A run's results (stdout), status lines ("JSON written to x") and warnings are held in the
run's stage (`tcr_accuracy.cli.staging.hold_message`) and shown after its files are in
place, in the order they came; a run refused for bad input shows its one error line and
nothing else, a run that failed shows its warnings, never a result or a "written to" line
for a file that was not written.
"""

from __future__ import annotations

import io
import sys
from contextlib import contextmanager

from .staging import hold_message


class _HeldStdout(io.TextIOBase):
    """``sys.stdout`` during a run: writes held in the current stage (written through when
    there is none); everything else (``isatty``, ``encoding``, ``fileno``) is the real stream's."""

    def __init__(self, real):
        self._real = real

    def write(self, text: str) -> int:
        hold_message(self._real, text, "out")
        return len(text)

    def flush(self) -> None:  # held text is flushed when it is written
        pass

    def writable(self) -> bool:
        return True

    def isatty(self) -> bool:
        return self._real.isatty()

    def fileno(self) -> int:
        return self._real.fileno()

    @property
    def encoding(self):
        return getattr(self._real, "encoding", "utf-8")

    def __getattr__(self, name):
        return getattr(self._real, name)


@contextmanager
def held_stdout():
    """Route ``sys.stdout`` through the run's stage inside the block."""
    real = sys.stdout
    sys.stdout = _HeldStdout(real)
    try:
        yield
    finally:
        sys.stdout = real


def show_warnings_of(stage) -> None:
    """After a run that failed (not for bad input): its held warnings, which may explain it."""
    for stream, text, kind in getattr(stage, "messages", []):
        if kind == "warning":
            stream.write(text)
            stream.flush()
