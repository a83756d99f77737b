"""The one output writer: the files of a run written whole, together, or not at all.

Every file the command line writes goes through :func:`write_bytes` (or :func:`write_text`):

* its target is resolved by the run's :class:`~tcr_accuracy.cli.output_paths.OutputPaths`
  (the outputs named on the command line): a symlink, device or pipe planted inside an output
  folder is refused, an input of the run is never written over, two outputs never share a path
  (see that module for the policy);
* a regular file (new or existing) is written to a temporary file in the same folder, opened
  through a descriptor of that folder, flushed to disk and renamed over the target, so a crash
  or Ctrl-C never leaves half a file behind, and a link put in its place meanwhile is replaced,
  never written through; the temporary file is removed on any failure;
* a special file the user named (``/dev/null``, ``/dev/stdout``, a named pipe) is written
  directly, never renamed over (that would replace a device node by a plain file);
* a new file gets the mode the umask gives (``0o666 & ~umask``), a replaced one keeps its
  own (a 0600 file stays private).

Inside :func:`staged_outputs` (the command line runs every command in one) writes are
only collected; they reach the disk together when the block ends without an error, and
not at all otherwise: a run that fails half-way, or is stopped, leaves nothing behind. The
targets are resolved again at the commit, before anything is written. Folders a run writes
whole (:func:`stage_folder`: a report folder, a plots folder) are swapped in at once
(:mod:`tcr_accuracy.cli.folder_swap`). What a run prints is held with :func:`hold_message` and
shown after its files are in place.

A failure to write is one :class:`~tcr_accuracy.exceptions.InputError`
line naming the path.
"""

from __future__ import annotations

import os
from contextlib import contextmanager
from contextvars import ContextVar
from pathlib import Path

from ..exceptions import InputError
from ..input_files import SIZE_LIMITS, read_input_bytes, recording_inputs
from . import signals
from .folder_swap import prepare_folders
from .output_paths import OutputPaths, Target, named_target
from .write_file import make_parent, prepare, remove_dead_leftovers


class _Stage:
    """The writes of one :func:`staged_outputs` block: target key -> (target, bytes), in order,
    the folders written whole (:func:`stage_folder`) and the held messages."""

    def __init__(self, outputs: OutputPaths | None) -> None:
        self.outputs = outputs
        self.files: dict[Path, tuple[Target, bytes]] = {}
        self.folders: set[Path] = set()
        self.messages: list[tuple[object, str, str]] = []  # (stream, text, kind): see hold_message
        self.committed = False  # every file of the last commit is in place

    def add(self, path, data: bytes) -> Path:
        target = resolve(path, self.outputs)
        first = self.files.get(target.key)
        if first is not None:
            raise InputError(f"{target.shown}: this run would write it twice (also as {first[0].shown}); one of "
                             "the two would be lost: give each output its own name")
        self.files[target.key] = (target, bytes(data))
        return Path(path)

    def commit(self) -> None:
        """Write every staged file: each target resolved again, the folders written whole into
        new folders beside them and every other file to a temporary file first, then the special
        files (a device, a pipe), then the swaps and renames, so a full disk or a full device
        fails before any target is touched. Nothing staged is left afterwards but the held
        messages (results, status lines), for :meth:`flush_messages`."""
        staged, self.files = self.files, {}
        folders, self.folders = self.folders, set()
        messages, self.messages = self.messages, []
        swaps: list = []
        prepared: list = []
        created: list[Path] = []
        self.committed = False
        try:
            targets, keys = {}, {}
            for target, data in staged.values():  # again: the folders may have changed since
                now = resolve(target.shown, self.outputs)
                if now.key in keys:  # a link put in meanwhile made two outputs one file
                    raise InputError(f"{now.shown}: now the same file as {keys[now.key]}; one of the two would be "
                                     "lost: give each output its own name")
                keys[now.key] = now.shown
                targets[now] = data
            remove_dead_leftovers({t.path for t in targets} | {Path(os.path.realpath(f)) for f in folders})
            plain = prepare_folders(targets, folders, swaps, created)
            for target, data in plain.items():
                make_parent(target, created)
                prepared.append(prepare(target, data))
            for item in prepared:  # special files first: /dev/full fails before any rename
                if item.tmp is None:
                    item.finish()
            with signals.held():  # Ctrl-C or a kill waits until every rename is done
                for item in prepared:
                    if item.tmp is not None:
                        item.finish()
                for swap in swaps:
                    swap.swap_in()
                self.committed = True
        except BaseException:
            for item in prepared:
                item.discard()
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


_stage: ContextVar[_Stage | None] = ContextVar("tcr_accuracy_stage", default=None)


def resolve(path, outputs: OutputPaths | None) -> Target:
    """The target of ``path``: by the run's named outputs, or as named by the caller."""
    return outputs.target(path) if outputs is not None else named_target(Path(path))


@contextmanager
def staged_outputs(outputs: OutputPaths | None = None):
    """Collect every write inside the block and commit them together at its end.

    ``outputs``: the outputs named on the command line and its inputs
    (:func:`~tcr_accuracy.cli.output_paths.outputs_of_command`); every file read inside the
    block is added to its inputs. On an exception (Ctrl-C and termination included) nothing
    is written. Blocks nest: an inner block commits its own files when it ends. Messages held
    with :func:`hold_message` are written after the files, and not on an exception.
    """
    stage = _Stage(outputs)
    token = _stage.set(stage)
    try:
        with recording_inputs() as inputs:
            if outputs is not None:
                inputs.extend(outputs.inputs)
                outputs.inputs = inputs  # one list: those named and those read
            yield stage
            stage.commit()
    finally:
        _stage.reset(token)
    stage.flush_messages()  # an enclosing block, now the current one, holds them in turn


def stage_folder(path) -> None:
    """Declare that the current :func:`staged_outputs` block writes the folder ``path`` whole:
    at the commit its files are swapped in together (:mod:`tcr_accuracy.cli.folder_swap`).
    Call it before or after writing the files; outside a staged block it does nothing."""
    stage = _stage.get()
    if stage is not None:
        stage.folders.add(Path(os.path.abspath(path)))


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
    if stage is not None:
        for target, data in stage.files.values():
            if Path(os.path.abspath(target.shown)) == Path(os.path.abspath(path)):
                return data
    return read_input_bytes(path, "file this run wrote", limit=SIZE_LIMITS["json"])


def write_bytes(path, data: bytes) -> Path:
    """Write data to path whole (see the module docstring); returns the path.

    Missing parent folders are created. Inside :func:`staged_outputs` the write waits for
    the end of the block.
    """
    stage = _stage.get()
    if stage is not None:
        return stage.add(path, data)
    target = named_target(Path(path))
    created: list[Path] = []
    remove_dead_leftovers([target.path])
    make_parent(target, created)
    item = prepare(target, data)
    try:
        item.finish()
    except BaseException:
        item.discard()
        raise
    return Path(path)


def write_text(path, text: str) -> Path:
    """UTF-8 text through :func:`write_bytes`."""
    return write_bytes(path, text.encode("utf-8"))
