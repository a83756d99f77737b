"""Writing files whole or not at all, and the files of one run together or not at all.

Every file the package writes goes through :func:`write_bytes_atomically`:

* a regular file (new or existing) is written to a temporary file in the same folder,
  flushed to disk and renamed over the target, so a crash or Ctrl-C never leaves half a
  file behind; the temporary file is removed on any failure;
* a symlink is written through: the file it points to is replaced, the link stays;
* a special file (``/dev/null``, ``/dev/stdout``, a named pipe) is written directly,
  never renamed over (that would replace a device node by a plain file);
* a new file gets the mode the umask gives (``0o666 & ~umask``), a replaced one keeps its
  own (a 0600 file stays private).

Inside :func:`staged_outputs` (the command line runs every command in one) writes are
only collected; they reach the disk together when the block ends without an error, and
not at all otherwise: a run that fails half-way, or is stopped, leaves nothing behind.
:func:`output_file_problem` and :func:`output_folder_problem` test a target before the work,
by creating a file there and removing it (permission bits alone say yes to root on /proc,
/sys or a read-only mount).

A failure to write is one :class:`~tcr_accuracy.exceptions.InputError` line naming the path.
"""

from __future__ import annotations

import os
import stat
import tempfile
from contextlib import contextmanager
from contextvars import ContextVar
from pathlib import Path

from .exceptions import InputError


class _Stage:
    """The writes of one :func:`staged_outputs` block: target -> bytes, in order."""

    def __init__(self) -> None:
        self.files: dict[Path, bytes] = {}

    def commit(self) -> None:
        """Write every staged file: all temporary files first, then the renames, so a full
        disk fails before any target is touched. Nothing staged is left afterwards."""
        files, self.files = self.files, {}
        prepared: list = []  # (tmp or None, target, data)
        created: list[Path] = []
        try:
            for path, data in files.items():
                _make_parent(path, created)
                prepared.append(_prepare(path, data))
            with _signals_held():  # Ctrl-C or a kill waits until every rename is done
                for tmp, target, data in prepared:
                    if tmp is not None:
                        _finish(tmp, target, data)
            for tmp, target, data in prepared:  # special files last: a pipe may wait for its reader
                if tmp is None:
                    _finish(tmp, target, data)
        except BaseException:
            for tmp, _, _ in prepared:
                if tmp is not None:
                    Path(tmp).unlink(missing_ok=True)
            for folder in reversed(created):  # folders made for this run, if still empty
                try:
                    folder.rmdir()
                except OSError:
                    pass
            raise


@contextmanager
def _signals_held():
    """Hold SIGINT and SIGTERM for the block (the renames of a commit take milliseconds), so
    that a run stopped then has either all its files or none; a signal that came meanwhile is
    raised again after it. Python runs signal handlers in the main thread only, so the
    handlers are swapped for a recorder there (elsewhere the block runs as it is)."""
    import signal

    came: list[int] = []
    previous = {}
    try:
        for sig in (signal.SIGINT, signal.SIGTERM):
            previous[sig] = signal.signal(sig, lambda signum, frame: came.append(signum))
    except ValueError:  # not the main thread
        for sig, handler in previous.items():
            signal.signal(sig, signal.SIG_DFL if handler is None else handler)
        yield
        return
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, signal.SIG_DFL if handler is None else handler)  # None: set outside Python
        for sig in dict.fromkeys(came):
            signal.raise_signal(sig)


_stage: ContextVar[_Stage | None] = ContextVar("tcr_accuracy_stage", default=None)


@contextmanager
def staged_outputs():
    """Collect every write inside the block and commit them together at its end.

    On an exception (Ctrl-C and termination included) nothing is written. Blocks nest:
    an inner block commits its own files when it ends.
    """
    stage = _Stage()
    token = _stage.set(stage)
    try:
        yield stage
        stage.commit()
    finally:
        _stage.reset(token)


@contextmanager
def unstaged():
    """Write straight away inside the block, even inside :func:`staged_outputs` (for files in
    a temporary folder that is read back and removed within the run)."""
    token = _stage.set(None)
    try:
        yield
    finally:
        _stage.reset(token)


def commit_staged() -> None:
    """Write what the current :func:`staged_outputs` block has collected so far (before
    serving a view until Ctrl-C, say); later writes are staged again."""
    stage = _stage.get()
    if stage is not None:
        stage.commit()


def read_output(path) -> bytes:
    """The bytes of a file this run wrote: from the stage if not yet committed, else from disk."""
    stage = _stage.get()
    key = _key(Path(path))
    if stage is not None and key in stage.files:
        return stage.files[key]
    return Path(path).read_bytes()


def write_bytes_atomically(path, data: bytes) -> Path:
    """Write data to path whole (see the module docstring); returns the path.

    Missing parent folders are created. Inside :func:`staged_outputs` the write waits for
    the end of the block.
    """
    path = Path(path)
    stage = _stage.get()
    if stage is not None:
        stage.files[_key(path)] = bytes(data)
        return path
    created: list[Path] = []
    _make_parent(path, created)
    tmp, target, data = _prepare(path, data)
    try:
        _finish(tmp, target, data)
    except BaseException:
        if tmp is not None:
            Path(tmp).unlink(missing_ok=True)
        raise
    return path


def write_text_atomically(path, text: str) -> Path:
    """UTF-8 text through :func:`write_bytes_atomically`."""
    return write_bytes_atomically(path, text.encode("utf-8"))


# ---------------------------------------------------------------------------------------
# Checks before the work
# ---------------------------------------------------------------------------------------
def output_file_problem(path) -> str | None:
    """Why ``path`` could not be written at the end of a run (it is a folder, its folder is
    missing or not writable, it is a special file we may not write), or None. ``-`` passes."""
    if path is None or str(path) == "-":
        return None
    path = Path(path)
    if path.is_dir():
        return "is a folder; give a file name"
    if _is_special(path):
        return None if os.access(path, os.W_OK) else "not writable"
    folder = Path(os.path.realpath(path)).parent
    if not folder.is_dir():
        return f"the folder {path.parent if not path.parent.is_dir() else folder} does not exist"
    return _creation_problem(folder)


def output_folder_problem(path) -> str | None:
    """As :func:`output_file_problem` for a folder a run fills (created, with its parents,
    if missing): not an existing file, and writable or creatable."""
    if path is None:
        return None
    path = Path(path)
    if path.exists() and not path.is_dir():
        return "exists and is not a folder"
    existing = Path(os.path.realpath(path))
    while not existing.exists():
        existing = existing.parent
    if not existing.is_dir():
        return f"the folder {existing} is a file"
    return _creation_problem(existing)


def _creation_problem(folder: Path) -> str | None:
    """Why no file can be created in the existing ``folder``, or None: found by creating one
    and removing it, since ``os.access`` reads permission bits only and says yes to root on
    /proc, /sys and chmod 0o555 folders."""
    try:
        fd, probe = tempfile.mkstemp(prefix=".tcr-accuracy-probe.", suffix=".tmp", dir=folder)
    except OSError as exc:
        return f"the folder {folder} is not writable ({exc.strerror})"
    os.close(fd)
    os.unlink(probe)
    return None


# ---------------------------------------------------------------------------------------
def _key(path: Path) -> Path:
    """One key per target, however it is spelt (relative, through a symlinked folder)."""
    return Path(os.path.abspath(path))


def _is_special(path: Path) -> bool:
    """An existing file that is neither a regular file nor a folder (device, pipe, socket)."""
    try:
        mode = os.stat(path).st_mode  # follows symlinks: /dev/stdout -> the terminal or pipe
    except OSError:
        return False
    return not (stat.S_ISREG(mode) or stat.S_ISDIR(mode))


def _make_parent(path: Path, created: list[Path]) -> None:
    if _is_special(path):
        return
    folder = Path(os.path.realpath(path)).parent
    missing = []
    while not folder.exists():
        missing.append(folder)
        folder = folder.parent
    for f in reversed(missing):
        try:
            f.mkdir()
        except FileExistsError:
            continue
        except OSError as exc:
            raise InputError(f"{path}: cannot create the folder {f} ({exc.strerror})") from None
        created.append(f)


def _mode_for(target: Path) -> int:
    try:
        st = os.stat(target)
        if stat.S_ISREG(st.st_mode):
            return stat.S_IMODE(st.st_mode)  # a file replaced keeps its mode
    except OSError:
        pass
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


def _prepare(path: Path, data: bytes):
    """(temporary file or None, target, data): the data written and flushed beside the target.
    A special file gets no temporary file (None): it is written directly by :func:`_finish`."""
    if _is_special(path):
        return None, path, data
    if path.is_dir():
        raise InputError(f"{path}: is a folder, cannot write a file there")
    target = Path(os.path.realpath(path))  # a symlink is written through
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    except OSError as exc:
        raise InputError(f"{path}: cannot write ({exc.strerror})") from None
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
        os.chmod(tmp, _mode_for(target))
    except BaseException as exc:  # Ctrl-C included: never leave the temporary file behind
        Path(tmp).unlink(missing_ok=True)
        if isinstance(exc, OSError):
            raise InputError(f"{path}: cannot write ({exc.strerror})") from None
        raise
    return tmp, target, data


def _finish(tmp, target: Path, data: bytes) -> None:
    try:
        if tmp is None:
            with open(target, "wb") as handle:
                handle.write(data)
        else:
            os.replace(tmp, target)
    except OSError as exc:
        raise InputError(f"{target}: cannot write ({exc.strerror})") from None
