"""Writing files whole or not at all.

Every file the package writes goes through a temporary file in the same folder, is
flushed to disk and renamed over the target, so a crash or Ctrl-C never leaves half a
file behind, and the temporary file is removed on any failure. A failure to write is
one :class:`~tcr_accuracy.exceptions.InputError` line naming the path.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from .exceptions import InputError


def write_bytes_atomically(path, data: bytes) -> Path:
    """Write data to path through a temporary file and a rename; returns the path."""
    path = Path(path)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except OSError as exc:
        raise InputError(f"{path}: cannot write ({exc.strerror})") from None
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException as exc:  # Ctrl-C included: never leave the temporary file behind
        Path(tmp).unlink(missing_ok=True)
        if isinstance(exc, OSError):
            raise InputError(f"{path}: cannot write ({exc.strerror})") from None
        raise
    return path


def write_text_atomically(path, text: str) -> Path:
    """UTF-8 text through :func:`write_bytes_atomically`."""
    return write_bytes_atomically(path, text.encode("utf-8"))
