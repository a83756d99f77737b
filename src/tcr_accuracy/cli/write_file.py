"""One file written whole: a temporary file in its folder, flushed, renamed over it.

The folder is opened once and the temporary file created, flushed and renamed through that
descriptor, so the rename lands where the checks of
:mod:`tcr_accuracy.cli.output_paths` looked, and a link put at the target's name meanwhile is
replaced, never written through. A special file the user named (a device, a pipe) is written
directly. The temporary file is removed on any failure, Ctrl-C included; one a killed run left
is removed by the next run on the same target (:func:`remove_dead_leftovers`).
"""

from __future__ import annotations

import os
import re
import secrets
import shutil
import stat
from pathlib import Path

from ..exceptions import InputError
from .output_paths import Target


def tmp_prefix(name: str) -> str:
    """The start of the name of a temporary file or folder beside ``name``: ``.<name>.<pid>.``;
    a random part and ``.tmp`` follow, so that the leftovers of a killed run are known by
    their dead process (:func:`remove_dead_leftovers`)."""
    return f".{name}.{os.getpid()}."


def tmp_name(name: str) -> str:
    """A fresh temporary name beside ``name``: ``.<name>.<pid>.<random>.tmp``."""
    return f"{tmp_prefix(name)}{secrets.token_hex(4)}.tmp"


def remove_dead_leftovers(targets) -> None:
    """Remove the temporary files and folders that a run killed with SIGKILL (or a power cut)
    left beside any of ``targets`` (real paths): those whose process is gone. A concurrent
    live run's are kept; what cannot be removed is left as it is."""
    for target in targets:
        pattern = re.compile(re.escape(f".{target.name}.") + r"(\d+)\.[^/]*\.tmp")
        try:
            entries = list(os.scandir(target.parent))
        except OSError:
            continue
        for entry in entries:
            match = pattern.fullmatch(entry.name)
            if match is None or _alive(int(match[1])):
                continue
            try:
                if entry.is_dir(follow_symlinks=False):
                    shutil.rmtree(entry.path)
                else:
                    os.unlink(entry.path)
            except OSError:
                pass


def _alive(pid: int) -> bool:
    """Whether a process ``pid`` exists (ours, another user's or a zombie: all count as alive)."""
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, OSError):
        return True
    return True


def make_parent(target: Target, created: list[Path]) -> None:
    """Create the missing folders above ``target`` (each appended to ``created``)."""
    if not target.special:
        make_folders(target.folder, created, shown=target.shown)


def make_folders(folder: Path, created: list[Path], *, shown=None) -> None:
    """Create ``folder`` and its missing parents (each appended to ``created``); ``shown``: the
    path an error names (default: the folder)."""
    missing = []
    while not os.path.lexists(folder):
        missing.append(folder)
        folder = folder.parent
    for f in reversed(missing):
        try:
            f.mkdir()
        except FileExistsError:
            continue
        except OSError as exc:
            raise InputError(f"{shown or f}: cannot create the folder {f} ({exc.strerror})") from None
        created.append(f)


def umask_mode(mode: int) -> int:
    """``mode`` less the process's umask: what a new file or folder gets."""
    umask = os.umask(0)
    os.umask(umask)
    return mode & ~umask


def mode_for(folder_fd: int | None, name) -> int:
    """The mode a file written at ``name`` gets: its own if it is a regular file now (a
    replaced file keeps its mode), else what the umask gives."""
    try:
        st = os.stat(name, dir_fd=folder_fd, follow_symlinks=False)
        if stat.S_ISREG(st.st_mode):
            return stat.S_IMODE(st.st_mode)
    except OSError:
        pass
    return umask_mode(0o666)


def write_flushed(fd: int, data: bytes) -> None:
    """Write data to the open file ``fd``, flush it to disk and close it."""
    with os.fdopen(fd, "wb") as handle:
        handle.write(data)
        handle.flush()
        os.fsync(handle.fileno())


class _Prepared:
    """A file of a commit written and flushed beside its target (``tmp`` in the folder open as
    ``folder_fd``), or, for a special file, only the data to write into it (``tmp`` None)."""

    def __init__(self, target: Target, data: bytes, folder_fd: int | None = None, tmp: str | None = None):
        self.target, self.data, self.folder_fd, self.tmp = target, data, folder_fd, tmp

    def finish(self) -> None:
        """Rename the temporary file over the target (or write the special file)."""
        target = self.target
        try:
            if self.tmp is None:
                with open(target.shown, "wb") as handle:
                    handle.write(self.data)
            else:
                os.replace(self.tmp, target.name, src_dir_fd=self.folder_fd, dst_dir_fd=self.folder_fd)
                self.tmp = None
                self._close()
        except OSError as exc:
            raise InputError(f"{target.shown}: cannot write ({exc.strerror})") from None

    def discard(self) -> None:
        """Remove the temporary file, if it is still there."""
        if self.tmp is not None and self.folder_fd is not None:
            try:
                os.unlink(self.tmp, dir_fd=self.folder_fd)
            except OSError:
                pass
            self.tmp = None
        self._close()

    def _close(self) -> None:
        if self.folder_fd is not None:
            os.close(self.folder_fd)
            self.folder_fd = None


def prepare(target: Target, data: bytes) -> _Prepared:
    """The data written and flushed to a temporary file beside the target, in the folder opened
    once (so the rename lands where the checks looked). A special file gets no temporary file."""
    if target.special:
        return _Prepared(target, data)
    try:
        folder_fd = os.open(target.folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0) | getattr(os, "O_CLOEXEC", 0))
    except OSError as exc:
        raise InputError(f"{target.shown}: cannot write ({exc.strerror})") from None
    item = _Prepared(target, data, folder_fd)
    try:
        if stat.S_ISDIR(os.stat(target.name, dir_fd=folder_fd, follow_symlinks=False).st_mode):
            raise InputError(f"{target.shown}: is a folder, cannot write a file there")
    except FileNotFoundError:
        pass
    except BaseException:
        item.discard()
        raise
    try:
        name = tmp_name(target.name)
        flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
        fd = os.open(name, flags, 0o600, dir_fd=folder_fd)
        item.tmp = name
        try:
            os.fchmod(fd, mode_for(folder_fd, target.name))
        except BaseException:
            os.close(fd)
            raise
        write_flushed(fd, data)
    except BaseException as exc:  # Ctrl-C included: never leave the temporary file behind
        item.discard()
        if isinstance(exc, OSError):
            raise InputError(f"{target.shown}: cannot write ({exc.strerror})") from None
        raise
    return item
