"""Folders written whole: prepared beside the target, then swapped in at once.

Inside a staged run (:func:`tcr_accuracy.cli.staging.staged_outputs`) a writer declares with
:func:`~tcr_accuracy.cli.staging.stage_folder` that a folder is the run's own (a report folder,
a plots folder), so that its files change together, not one rename at a time (a kill between
two renames would mix new plots with the old index.html). At the commit the run's files under
that folder are written into a new folder beside it (``.<name>.<pid>.<random>.tmp``, same
parent, so that renaming is atomic):

* every entry of the old folder that the run does not write is carried into the new one, a
  file as a hard link (a copy, flushed, where no link can be made), a symlink as a symlink,
  a subfolder with its mode: nothing kept there is lost;
* the new folder is flushed and swapped in: on Linux in one step (``renameat2`` with
  ``RENAME_EXCHANGE``), elsewhere or on a filesystem that refuses it, by renaming the old
  folder aside and the new one in; the old folder is then removed. A process killed at any
  moment, SIGKILL included, leaves the folder all old or all new (a kill between the
  fallback's two renames leaves it missing, the old and the new one beside it); at worst a
  ``.tmp`` folder remains beside it, never a file inside it;
* a new folder gets the mode the umask gives, a replaced one keeps its mode; a symlinked
  folder the user named is written through (the folder it points to is swapped, the link stays);
* the temporary folder is removed on every failure, Ctrl-C and SIGTERM included;
* a file of the run where the old folder has a folder (or a folder where it has a file) is
  refused, as it is outside a swap;
* a folder that cannot be swapped safely is written file by file: it is or holds the current
  folder or a mount point, its parent takes no new folder, it holds a file of the run that is
  a special file, or something that cannot be carried (a named pipe, a device, a file that
  can be neither linked nor read). A file another program adds to the old folder while the
  run commits is not carried.

Folders declared inside one another are one swap, the outermost's.
"""

from __future__ import annotations

import errno
import functools
import os
import re
import shutil
import stat
import sys
import tempfile
import warnings
from pathlib import Path

from ..exceptions import InputError
from .output_paths import Target
from .write_file import make_folders, mode_for, tmp_prefix, umask_mode, write_flushed


class _NotSwappable(Exception):
    """A folder written whole that must be written file by file instead (see the module docstring)."""


class _FolderSwap:
    """A folder written whole: ``leftover`` is the ``.tmp`` folder beside ``target`` to remove
    at the end, the new content until it is swapped in, the old content after."""

    def __init__(self, target: Path, new: Path) -> None:
        self.target = target
        self.leftover: Path | None = new

    def swap_in(self) -> None:
        self.leftover = _swap_in(self.leftover, self.target)

    def remove_leftover(self) -> None:
        if self.leftover is not None:
            _remove_tree(self.leftover)
            self.leftover = None


def prepare_folders(files: dict[Target, bytes], folders: set[Path], swaps: list[_FolderSwap],
                    created: list[Path]) -> dict[Target, bytes]:
    """Prepare a swap (appended to ``swaps``) for each folder written whole that holds files of
    the run, outermost first; returns the files left to write one by one."""
    plain = dict(files)
    for folder in sorted({Path(os.path.realpath(f)) for f in folders}, key=lambda f: len(f.parts)):
        members = [t for t in plain if folder in t.path.parents]
        if not members:
            continue
        try:
            swaps.append(_prepare_folder(folder, [(t, plain[t]) for t in members], created))
        except _NotSwappable:  # its files go one by one, or with a folder inside it
            continue
        for t in members:
            del plain[t]
    return plain


def _prepare_folder(target: Path, members: list[tuple[Target, bytes]], created: list[Path]) -> _FolderSwap:
    """The run's files under ``target`` (a real path) written into a new folder beside it,
    the old folder's other entries carried into it, all flushed: ready to swap in.
    Raises :class:`_NotSwappable` when the folder must be written file by file."""
    exists = target.is_dir()
    if os.path.lexists(target) and not exists:
        raise InputError(f"{target}: is not a folder")
    if _holds_cwd(target) or _holds_mount_point(target) or any(t.special for t, _ in members):
        raise _NotSwappable
    make_folders(target.parent, created)
    try:
        new = Path(tempfile.mkdtemp(prefix=tmp_prefix(target.name), suffix=".tmp",
                                    dir=target.parent))
    except OSError:  # its parent takes no new folder
        raise _NotSwappable from None
    try:
        for t, data in members:
            _write_new_file(new / t.path.relative_to(target), data, mode_for(None, t.path), shown=t.shown)
        if exists:
            try:
                _carry(target, new, os.stat(target).st_dev)
            except OSError:  # an entry that can be neither linked nor read
                raise _NotSwappable from None
        _sync_folders(new)
        os.chmod(new, stat.S_IMODE(os.stat(target).st_mode) if exists else umask_mode(0o777))
    except BaseException:  # Ctrl-C and SIGTERM (an interrupt in the CLI) included
        _remove_tree(new)
        raise
    return _FolderSwap(target, new)


def _write_new_file(path: Path, data: bytes, mode: int, *, shown: Path) -> None:
    """A file of a new folder, with its missing subfolders; ``shown``: the path an error names."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_flushed(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0), 0o600), data)
        os.chmod(path, mode)
    except OSError as exc:
        raise InputError(f"{shown}: cannot write ({exc.strerror})") from None


def _carry(old: Path, new: Path, device: int) -> None:
    """Give the folder ``new`` every entry of ``old`` it lacks: a file as a hard link (a flushed
    copy where no link can be made), a symlink as a symlink, a subfolder (on ``device``) with
    its content and mode. A file of the run in place of a folder, or the other way round, is an
    InputError; what cannot be carried (a special file, a mount point) is :class:`_NotSwappable`."""
    with os.scandir(old) as entries:
        for entry in entries:
            source, dest = Path(entry.path), new / entry.name
            st = entry.stat(follow_symlinks=False)
            dest_is_folder = dest.is_dir() and not dest.is_symlink()
            if stat.S_ISDIR(st.st_mode):
                if st.st_dev != device:
                    raise _NotSwappable
                if os.path.lexists(dest) and not dest_is_folder:
                    raise InputError(f"{source}: is a folder, cannot write a file there")
                dest.mkdir(exist_ok=True)
                _carry(source, dest, device)
                os.chmod(dest, stat.S_IMODE(st.st_mode))
            elif dest_is_folder:
                raise InputError(f"{source}: is a file, cannot make a folder there")
            elif os.path.lexists(dest):
                continue  # the run wrote it anew
            elif stat.S_ISLNK(st.st_mode):
                os.symlink(os.readlink(source), dest)
            elif stat.S_ISREG(st.st_mode):
                _link_or_copy(source, dest)
            else:
                raise _NotSwappable  # a named pipe, a socket, a device


def _link_or_copy(source: Path, dest: Path) -> None:
    try:
        os.link(source, dest)
    except OSError:  # no hard links on this filesystem, or not for this file (protected_hardlinks)
        shutil.copy2(source, dest)
        _fsync_path(dest)


def _sync_folders(top: Path) -> None:
    """Flush the entries of ``top`` and of every folder under it to disk."""
    for folder, _, _ in os.walk(top):
        _fsync_path(folder)


def _fsync_path(path) -> None:
    """Flush a file or folder to disk, as far as this system allows (a folder that cannot be
    opened or flushed, as on some filesystems, is left to the kernel: the swap is done anyway)."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _holds_cwd(folder: Path) -> bool:
    """Whether ``folder`` is the current folder or holds it (a swap would leave this process,
    and the user's shell, in the removed old folder)."""
    try:
        cwd = Path(os.getcwd())
    except OSError:  # the current folder was removed
        return False
    return cwd == folder or folder in cwd.parents


def _holds_mount_point(folder: Path) -> bool:
    """Whether ``folder`` is a mount point or holds one (a mount point cannot be renamed, and
    removing the old folder must not reach into another filesystem)."""
    return os.path.ismount(folder) or any(m == folder or folder in m.parents for m in _mount_points())


def _mount_points() -> list[Path]:
    """The mount points of this process (Linux: /proc/self/mountinfo; elsewhere none known,
    and :func:`_carry` still stops at another device)."""
    try:
        lines = Path("/proc/self/mountinfo").read_text().splitlines()
    except OSError:
        return []
    fields = [line.split() for line in lines]
    return [Path(_OCTAL_ESCAPE.sub(lambda m: chr(int(m[1], 8)), f[4])) for f in fields if len(f) > 4]


#: How mountinfo writes a space, a tab, a newline or a backslash in a path: ``\040``
_OCTAL_ESCAPE = re.compile(r"\\([0-7]{3})")


def _swap_in(new: Path, target: Path) -> Path | None:
    """Put the folder ``new`` in the place of ``target``; returns where the old folder is now
    (None when there was none)."""
    try:
        if not os.path.lexists(target):
            os.rename(new, target)
            old = None
        elif _exchange(new, target):
            old = new
        else:
            old = _rename_aside_and_in(new, target)
    except OSError as exc:
        raise InputError(f"{target}: cannot write ({exc.strerror})") from None
    _fsync_path(target.parent)
    return old


def _rename_aside_and_in(new: Path, target: Path) -> Path:
    """The swap where no atomic exchange is to be had: the old folder renamed to a ``.tmp``
    name beside it (returned), then the new one to its name; undone if the second fails."""
    aside = Path(tempfile.mkdtemp(prefix=tmp_prefix(target.name), suffix=".tmp",
                                  dir=target.parent))
    try:
        os.rename(target, aside)  # over an empty folder: replaces it
    except BaseException:
        aside.rmdir()
        raise
    try:
        os.rename(new, target)
    except BaseException:
        os.rename(aside, target)
        raise
    return aside


#: renameat2's arguments: paths relative to the current folder (<fcntl.h>), and the flag
#: that swaps the two names (<linux/fs.h>)
_AT_FDCWD, _RENAME_EXCHANGE = -100, 2


def _exchange(a: Path, b: Path) -> bool:
    """Swap the names of the folders ``a`` and ``b`` in one step; False, having done nothing,
    where this system or filesystem cannot (then the caller renames twice).

    Hand-written, through ctypes on the C library: Python's os module has no renameat2, and
    the one PyPI wrapper (``renameat2``) is a compiled CFFI module that refuses to import off
    Linux, a dependency for one call whose fallback is needed anyway."""
    renameat2 = _renameat2()
    if renameat2 is None:
        return False
    if renameat2(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    import ctypes

    err = ctypes.get_errno()
    if err in (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP):  # no such flag, call or support here
        return False
    raise OSError(err, os.strerror(err), str(b))


@functools.lru_cache(maxsize=None)
def _renameat2():
    """libc's renameat2 (glibc 2.28+, Linux 3.15+) as a ctypes function, or None."""
    if not sys.platform.startswith("linux"):
        return None
    import ctypes

    try:
        function = ctypes.CDLL(None, use_errno=True).renameat2
    except (OSError, AttributeError):  # no C library to load, or one without renameat2 (old glibc, musl)
        return None
    function.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    function.restype = ctypes.c_int
    return function


def _remove_tree(path: Path) -> None:
    """Remove a ``.tmp`` folder of a commit; one that will not go is a warning naming it."""
    try:
        shutil.rmtree(path)
    except FileNotFoundError:
        pass
    except OSError as exc:
        warnings.warn(f"{path}: could not remove this temporary folder ({exc.strerror}); remove it by hand",
                      stacklevel=2)
