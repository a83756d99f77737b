"""The signals that stop a run, handled in one place.

Ctrl-C (SIGINT), a kill or a job scheduler's stop (SIGTERM) and a closed terminal (SIGHUP)
stop a run. The command line handles them twice, both through :func:`stop_signals_handled`:

* for the whole run, SIGTERM and SIGHUP end it as Ctrl-C does (:func:`as_interrupt`): through
  the exception handlers, so that staged and temporary files are removed;
* for the few milliseconds of a commit's renames, all three are held (:func:`held`) and raised
  again after it, so that a run stopped then has either all its files or none.

Python runs signal handlers in the main thread only: elsewhere (and in an interpreter without
signals) the blocks run as they are.
"""

from __future__ import annotations

import signal
from contextlib import contextmanager


def _stop_signals() -> tuple:
    return tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name))


#: The signals that stop a run as Ctrl-C does (SIGHUP: the terminal closed).
STOP_SIGNALS = _stop_signals()


@contextmanager
def stop_signals_handled(handler, signals=STOP_SIGNALS):
    """Call ``handler(signum, frame)`` for each of ``signals`` inside the block, and restore
    the handlers found before it afterwards (one set outside Python, None, becomes the default).
    Yields whether the handlers were installed (False off the main thread)."""
    previous = {}
    try:
        for sig in signals:
            previous[sig] = signal.signal(sig, handler)
    except (ValueError, OSError):  # not the main thread, or no signals here
        _restore(previous)
        yield False
        return
    try:
        yield True
    finally:
        _restore(previous)


def _restore(previous: dict) -> None:
    for sig, handler in previous.items():
        signal.signal(sig, signal.SIG_DFL if handler is None else handler)


@contextmanager
def held():
    """Hold the stop signals for the block; one that came meanwhile is raised after it."""
    came: list[int] = []
    try:
        with stop_signals_handled(lambda signum, frame: came.append(signum)):
            yield
    finally:
        for sig in dict.fromkeys(came):
            signal.raise_signal(sig)


def _interrupt(signum, frame):
    raise KeyboardInterrupt


@contextmanager
def as_interrupt():
    """SIGTERM and SIGHUP raise KeyboardInterrupt inside the block, as Ctrl-C does."""
    with stop_signals_handled(_interrupt, tuple(s for s in STOP_SIGNALS if s != getattr(signal, "SIGINT", None))):
        yield
