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

Folders written whole. Inside a staged block a writer declares with :func:`stage_folder`
that a folder is the run's own (a report folder, a plots folder), so that its files change
together, not one rename at a time (a kill between two renames would mix new plots with the
old index.html). At the commit the run's files under that folder are written into a new
folder beside it (``.<name>.<random>.tmp``, same parent, so that renaming is atomic):

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
  folder is written through (the folder it points to is swapped, the link stays);
* the temporary folder is removed on every failure, Ctrl-C and SIGTERM included;
* a file of the run where the old folder has a folder (or a folder where it has a file) is
  refused, as it is outside a swap;
* a folder that cannot be swapped safely is written file by file as above: it is or holds
  the current folder or a mount point, its parent takes no new folder, it holds a file of the
  run that is a special file, or something that cannot be carried (a named pipe, a device, a
  file that can be neither linked nor read). A file another program adds to the old folder
  while the run commits is not carried.

Folders declared inside one another are one swap, the outermost's. Outside a staged block
:func:`stage_folder` does nothing: files are written one by one, as they come.

A failure to write is one :class:`~tcr_accuracy.exceptions.InputError` line naming the path.
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
from contextlib import contextmanager
from contextvars import ContextVar
from pathlib import Path

from .exceptions import InputError


class _Stage:
    """The writes of one :func:`staged_outputs` block: target -> bytes, in order, and the
    folders written whole (:func:`stage_folder`)."""

    def __init__(self) -> None:
        self.files: dict[Path, bytes] = {}
        self.folders: set[Path] = set()
        self.messages: list[tuple[object, str, str]] = []  # (stream, text, kind): see hold_message
        self.committed = False  # every file of the last commit is in place

    def commit(self) -> None:
        """Write every staged file: the folders written whole into new folders beside them and
        every other file to a temporary file first, then the special files (a device, a pipe),
        then the swaps and renames, so a full disk or a full device fails before any target is
        touched. Nothing staged is left afterwards but the held messages (results, status
        lines), for :meth:`flush_messages`."""
        files, self.files = self.files, {}
        folders, self.folders = self.folders, set()
        messages, self.messages = self.messages, []
        swaps: list[_FolderSwap] = []
        prepared: list = []  # (tmp or None, target, data)
        created: list[Path] = []
        self.committed = False
        try:
            _remove_dead_leftovers({Path(os.path.realpath(p)) for p in [*files, *folders]})
            plain = _prepare_folders(files, folders, swaps, created)
            for path, data in plain.items():
                _make_parent(path, created)
                prepared.append(_prepare(path, data))
            for tmp, target, data in prepared:  # special files first: /dev/full fails before any rename
                if tmp is None:
                    _finish(tmp, target, data)
            with _signals_held():  # Ctrl-C or a kill waits until every rename is done
                for tmp, target, data in prepared:
                    if tmp is not None:
                        _finish(tmp, target, data)
                for swap in swaps:
                    swap.swap_in()
                self.committed = True
        except BaseException:
            for tmp, _, _ in prepared:
                if tmp is not None:
                    Path(tmp).unlink(missing_ok=True)
            for swap in swaps:
                swap.remove_leftover()
            if not self.committed:
                for folder in reversed(created):  # folders made for this run, if still empty
                    try:
                        folder.rmdir()
                    except OSError:
                        pass
            self.messages = messages  # for the caller to show what it chooses of them
            raise
        for swap in swaps:
            swap.remove_leftover()
        self.messages = messages + self.messages

    def flush_messages(self) -> None:
        """Write the held messages (after a commit), in the order they came."""
        messages, self.messages = self.messages, []
        for stream, text, _ in messages:
            stream.write(text)
            stream.flush()


@contextmanager
def _signals_held():
    """Hold SIGINT, SIGTERM and SIGHUP for the block (the renames of a commit take milliseconds), so
    that a run stopped then has either all its files or none; a signal that came meanwhile is
    raised again after it. Python runs signal handlers in the main thread only, so the
    handlers are swapped for a recorder there (elsewhere the block runs as it is)."""
    import signal

    came: list[int] = []
    previous = {}
    try:
        for sig in STOP_SIGNALS:
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


def _stop_signals() -> tuple:
    import signal

    return tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name))


#: The signals that stop a run as Ctrl-C does (SIGHUP: the terminal closed), held during renames.
STOP_SIGNALS = _stop_signals()

_stage: ContextVar[_Stage | None] = ContextVar("tcr_accuracy_stage", default=None)


@contextmanager
def staged_outputs():
    """Collect every write inside the block and commit them together at its end.

    On an exception (Ctrl-C and termination included) nothing is written. Blocks nest:
    an inner block commits its own files when it ends. Messages held with
    :func:`hold_message` are written after the files, and not on an exception.
    """
    stage = _Stage()
    token = _stage.set(stage)
    try:
        yield stage
        stage.commit()
    finally:
        _stage.reset(token)
    stage.flush_messages()  # an enclosing block, now the current one, holds them in turn


def stage_folder(path) -> None:
    """Declare that the current :func:`staged_outputs` block writes the folder ``path`` whole:
    at the commit its files are swapped in together (see the module docstring). Call it before
    or after writing the files; outside a staged block it does nothing."""
    stage = _stage.get()
    if stage is not None:
        stage.folders.add(_key(Path(path)))


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
        stage.flush_messages()


def hold_message(stream, text: str, kind: str = "out") -> None:
    """Write ``text`` to ``stream`` after the files of the current :func:`staged_outputs`
    block are committed, in the order held, and not at all if they are not (a result printed,
    or "JSON written to x", must not appear when the run then fails). ``kind`` ('out',
    'status', 'warning') lets a caller choose what to show of a failed run's messages
    (``stage.messages``). Outside a staged block the text is written at once."""
    stage = _stage.get()
    if stage is None:
        stream.write(text)
        stream.flush()
    else:
        stage.messages.append((stream, text, kind))


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
    _remove_dead_leftovers([Path(os.path.realpath(path))])
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
        shown = path.parent if not path.parent.is_dir() else folder
        if folder.exists():
            return f"the folder {shown} is a file"
        return f"the folder {shown} does not exist"
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
def is_special_file(path) -> bool:
    """Whether ``path`` is an existing device, pipe or socket (written directly, never renamed over)."""
    return _is_special(Path(path))


def _key(path: Path) -> Path:
    """One key per target, however it is spelt (relative, through a symlinked folder)."""
    return Path(os.path.abspath(path))


def _tmp_prefix(target: Path) -> str:
    """The start of the name of a temporary file or folder beside ``target``: ``.<name>.<pid>.``,
    so that the leftovers of a killed run are known by their dead process
    (:func:`_remove_dead_leftovers`)."""
    return f".{target.name}.{os.getpid()}."


def _remove_dead_leftovers(targets) -> None:
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
    return _umask_mode(0o666)


def _umask_mode(mode: int) -> int:
    """``mode`` less the process's umask: what a new file or folder gets."""
    umask = os.umask(0)
    os.umask(umask)
    return mode & ~umask


def _write_flushed(fd: int, data: bytes) -> None:
    """Write data to the open file ``fd``, flush it to disk and close it."""
    with os.fdopen(fd, "wb") as handle:
        handle.write(data)
        handle.flush()
        os.fsync(handle.fileno())


def _prepare(path: Path, data: bytes):
    """(temporary file or None, target, data): the data written and flushed beside the target.
    A special file gets no temporary file (None): it is written directly by :func:`_finish`."""
    if _is_special(path):
        return None, path, data
    if path.is_dir():
        raise InputError(f"{path}: is a folder, cannot write a file there")
    target = Path(os.path.realpath(path))  # a symlink is written through
    try:
        fd, tmp = tempfile.mkstemp(prefix=_tmp_prefix(target), suffix=".tmp", dir=target.parent)
    except OSError as exc:
        raise InputError(f"{path}: cannot write ({exc.strerror})") from None
    try:
        _write_flushed(fd, data)
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


# ---------------------------------------------------------------------------------------
# Folders written whole (stage_folder): prepared beside the target, then swapped in
# ---------------------------------------------------------------------------------------
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


def _prepare_folders(files: dict[Path, bytes], folders: set[Path], swaps: list[_FolderSwap],
                     created: list[Path]) -> dict[Path, bytes]:
    """Prepare a swap (appended to ``swaps``) for each folder written whole that holds files of
    the run, outermost first; returns the files left to write one by one."""
    real = {key: Path(os.path.realpath(key)) for key in files}
    plain = dict(files)
    for folder in sorted({Path(os.path.realpath(f)) for f in folders}, key=lambda f: len(f.parts)):
        members = [key for key in plain if folder in real[key].parents]
        if not members:
            continue
        try:
            swaps.append(_prepare_folder(folder, [(real[k], plain[k]) for k in members], created))
        except _NotSwappable:  # its files go one by one, or with a folder inside it
            continue
        for key in members:
            del plain[key]
    return plain


def _prepare_folder(target: Path, members: list[tuple[Path, bytes]], created: list[Path]) -> _FolderSwap:
    """The run's files under ``target`` (real paths, data) written into a new folder beside it,
    the old folder's other entries carried into it, all flushed: ready to swap in.
    Raises :class:`_NotSwappable` when the folder must be written file by file."""
    exists = target.is_dir()
    if os.path.lexists(target) and not exists:
        raise InputError(f"{target}: is not a folder")
    if _holds_cwd(target) or _holds_mount_point(target) or any(_is_special(p) for p, _ in members):
        raise _NotSwappable
    _make_parent(target, created)
    try:
        new = Path(tempfile.mkdtemp(prefix=_tmp_prefix(target), suffix=".tmp", dir=target.parent))
    except OSError:  # its parent takes no new folder
        raise _NotSwappable from None
    try:
        for path, data in members:
            _write_new_file(new / path.relative_to(target), data, _mode_for(path), shown=path)
        if exists:
            try:
                _carry(target, new, os.stat(target).st_dev)
            except OSError:  # an entry that can be neither linked nor read
                raise _NotSwappable from None
        _sync_folders(new)
        os.chmod(new, stat.S_IMODE(os.stat(target).st_mode) if exists else _umask_mode(0o777))
    except BaseException:  # Ctrl-C and SIGTERM (an interrupt in the CLI) included
        _remove_tree(new)
        raise
    return _FolderSwap(target, new)


def _write_new_file(path: Path, data: bytes, mode: int, *, shown: Path) -> None:
    """A file of a new folder, with its missing subfolders; ``shown``: the path an error names."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        _write_flushed(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600), data)
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
    aside = Path(tempfile.mkdtemp(prefix=_tmp_prefix(target), suffix=".tmp", dir=target.parent))
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
