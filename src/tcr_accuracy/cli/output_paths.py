"""Where a run may write: the outputs named on the command line, and nothing through them.

The outputs of a command are its options whose argparse type is an output type of
:mod:`tcr_accuracy.cli.common` (``--json``, ``--out``, ``--plots``, ``--view``, ``--csv``, ``--to``,
``--truth``, ``--as-built-urdf`` and its side file); its inputs, every other value that names an
existing file, and every file the run reads (:func:`tcr_accuracy.input_files.recording_inputs`).
:func:`outputs_of_command` reads them when the command line is read and refuses, in one line
naming both options, an output that is an input or another output. Every file the run then
writes is resolved by :meth:`OutputPaths.target` (the staging writer calls it for each file, and
again when it commits), which holds this policy:

* **A path the user named is taken as named.** A symlink in it is followed, the last name
  included (``--json latest.json`` where ``latest.json`` is a link writes the file it points to),
  as a shell's ``>`` would, except where the kernel would not follow it either
  (``fs.protected_symlinks``): a link in a sticky, world-writable folder such as ``/tmp`` that
  is owned neither by the user running nor by the folder's owner is refused (another user may
  have planted it there, aimed at a file of ours).
* **Inside a folder the user named, nothing is followed.** A file the run names itself
  (``DIR/index.html``, ``DIR/as_built.yaml``, a plot, the ``.effects.yaml`` beside an as-built
  URDF) is refused when its name, or any folder between it and the named folder, is a symbolic
  link, a device or a pipe: the user chose the folder, not where a link in it points. The file
  is written to a temporary file in that folder, opened by descriptor, then renamed over the
  name (a rename replaces a link, never writes through it), so a link planted after the check
  is not followed either.
* **Never over an input.** A target that is the same file as any input of the run (same device
  and inode, however the paths are spelt: through a link, a hard link, ``..``) is refused.
* **Never twice.** Two files of one run on one real path are refused (one would be lost).
* **Nowhere else.** A file outside every named output is a bug of the command, refused.

Outside a command line run (no :class:`OutputPaths`), the caller named the path: it is taken
as named.
"""

from __future__ import annotations

import argparse
import os
import stat
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from ..exceptions import InputError


@dataclass(frozen=True)
class Target:
    """Where one file of a run goes.

    ``shown``: the path as the run named it (for messages); ``folder``: the real folder it is
    written in (symlinks resolved); ``name``: its name there; ``special``: an existing device
    or pipe the user named, written directly (never renamed over)."""

    shown: Path
    folder: Path
    name: str
    special: bool = False

    @property
    def path(self) -> Path:
        """The real path written."""
        return self.folder / self.name

    @property
    def key(self) -> Path:
        """One key per real file, however it was spelt."""
        return self.path


@dataclass
class OutputPaths:
    """The outputs the user named (absolute paths, not resolved) and the run's inputs."""

    files: set = field(default_factory=set)  # a file named: its last name may be a link
    siblings: set = field(default_factory=set)  # a file the run names beside a named one
    folders: set = field(default_factory=set)  # a folder named: the run names the files in it
    inputs: list = field(default_factory=list)  # (path, st_dev, st_ino) of every input

    def add_input(self, path) -> None:
        try:
            st = os.stat(path)
        except OSError:
            return
        if stat.S_ISREG(st.st_mode):
            self.inputs.append((str(path), st.st_dev, st.st_ino))

    # -- the policy ------------------------------------------------------------------
    def target(self, path) -> Target:
        """Where ``path`` is written, or one InputError line saying why it may not be (see the
        module docstring)."""
        shown = Path(path)
        absolute = Path(os.path.abspath(shown))
        if absolute in self.files:
            target = named_target(shown)
        else:
            root = next((f for f in sorted(self.folders, key=lambda f: -len(f.parts))
                         if f in absolute.parents), None)
            if root is None and absolute in self.siblings:
                root = absolute.parent
            if root is None:
                raise RuntimeError(f"{shown}: the command writes outside the outputs named on its command line "
                                   f"({', '.join(map(str, sorted(self.files | self.folders))) or 'none'})")
            target = _target_below(shown, absolute, root)
        self.check_not_input(target)
        return target

    def check_not_input(self, target: Target) -> None:
        """Refuse ``target`` when it is the same file as an input of the run."""
        try:
            st = os.stat(target.path, follow_symlinks=False)
        except OSError:
            return
        for path, dev, ino in self.inputs:
            if (st.st_dev, st.st_ino) == (dev, ino):
                raise InputError(f"{target.shown}: is also an input of this run ({path}); writing it would "
                                 "overwrite the input: write the output elsewhere")


def named_target(shown: Path) -> Target:
    """The target of a path the caller named: symlinks followed as the kernel would follow them."""
    check_followable(shown)
    if is_special_file(shown):
        return Target(shown, Path(os.path.realpath(shown)).parent, Path(os.path.realpath(shown)).name, True)
    real = Path(os.path.realpath(shown))
    return Target(shown, real.parent, real.name)


def _target_below(shown: Path, absolute: Path, root: Path) -> Target:
    """The target of a file the run names below the named folder ``root``: no link, device or
    pipe on the way from ``root`` to it, nor at its name."""
    check_followable(root)
    real_root = Path(os.path.realpath(root))
    parts = absolute.relative_to(root).parts
    named_root = shown.parents[len(parts) - 1] if len(shown.parts) > len(parts) else root  # as the run spelt it
    here, real = named_root, real_root
    for k, part in enumerate(parts):
        here, real = here / part, real / part
        try:
            mode = os.lstat(real).st_mode
        except FileNotFoundError:
            break  # created by the run, below a checked folder
        except OSError as exc:
            raise InputError(f"{here}: cannot write ({exc.strerror})") from None
        last = k == len(parts) - 1
        if stat.S_ISLNK(mode):
            raise InputError(f"{here}: is a symbolic link (to {_link_text(real)}) inside the output folder "
                             f"{named_root}; "
                             "the run writes its own files there and never through a link it was not given: "
                             "remove the link or choose another folder")
        if last and not stat.S_ISREG(mode) and not stat.S_ISDIR(mode):
            raise InputError(f"{here}: is a device, pipe or socket inside the output folder {named_root}; the run "
                             "writes a regular file there: remove it or choose another folder")
        if not last and not stat.S_ISDIR(mode):
            raise InputError(f"{here}: is a file inside the output folder {named_root}, where the run needs a folder")
    return Target(shown, real_root.joinpath(*parts[:-1]), parts[-1])


def check_followable(path: Path) -> None:
    """Refuse a path whose walk would follow a symlink the kernel's ``fs.protected_symlinks``
    would not: one in a sticky, world-writable folder (``/tmp``), owned neither by the user
    running nor by that folder's owner."""
    absolute = Path(os.path.abspath(path))
    here = Path(absolute.anchor)
    for part in absolute.parts[1:]:
        parent, here = here, here / part
        try:
            st = os.lstat(here)
        except OSError:
            return  # missing from here on: created by the run
        if stat.S_ISLNK(st.st_mode):
            folder = os.stat(parent)
            shared = folder.st_mode & stat.S_ISVTX and folder.st_mode & stat.S_IWOTH
            if shared and st.st_uid not in (os.geteuid(), folder.st_uid):
                raise InputError(f"{here}: a symbolic link in the shared folder {parent} owned by another user "
                                 f"(uid {st.st_uid}); not followed (as the kernel would not): name the file it "
                                 "points to, or write elsewhere")
            here = Path(os.path.realpath(here))


def _link_text(path: Path) -> str:
    try:
        return os.readlink(path)
    except OSError:
        return "?"


# ---------------------------------------------------------------------------------------
# The command line's outputs and inputs, read when it is parsed
# ---------------------------------------------------------------------------------------
def outputs_of_command(parser: argparse.ArgumentParser, args: argparse.Namespace) -> OutputPaths:
    """The outputs and inputs named on the command line of ``args``; refuses, in one line naming
    both options, an output that is an input or another output.

    Raises
    ------
    InputError
    """
    plan = OutputPaths()
    outputs, inputs = [], []
    for action in command_actions(parser, args):
        value = getattr(args, action.dest, None)
        name = action.option_strings[0] if action.option_strings else (action.metavar or action.dest)
        values = value if isinstance(value, list) else [value]
        for text in (v for v in values if isinstance(v, str) and v and v != "-"):
            absolute = Path(os.path.abspath(text))
            if action.type is output_folder:
                plan.folders.add(absolute)
            elif action.type in OUTPUT_TYPES:
                plan.files.add(absolute)
                if action.type is as_built_file:
                    plan.siblings.add(Path(os.path.abspath(effects_side_file(text))))
            if action.type in OUTPUT_TYPES:
                if not is_special_file(Path(text)):
                    outputs.append((name, text))
                    if action.type is as_built_file:
                        outputs.append((f"{name}'s side file", str(effects_side_file(text))))
            elif os.path.exists(text) and not is_special_file(Path(text)):
                inputs.append((name, text))
                plan.add_input(text)
    implied = getattr(args, "implied_outputs", None)  # a file a command writes by default (view's view.html)
    for text in (implied(args) if implied else []):
        if text:
            plan.files.add(Path(os.path.abspath(text)))
            outputs.append(("the default output", text))
    for k, (name, path) in enumerate(outputs):
        for in_name, in_path in inputs:
            if _same(path, in_path):
                raise InputError(f"{name} {path}: is also {in_name} {in_path}, an input: the run would overwrite "
                                 "it; write the output elsewhere")
        for other_name, other in outputs[:k]:
            if _same(path, other):
                raise InputError(f"{name} {path}: the same file as {other_name} {other}: one of the two "
                                 "would be lost; give each output its own name")
    return plan


def command_actions(parser: argparse.ArgumentParser, args: argparse.Namespace) -> list:
    """The actions of the parser and of the subcommands (and their steps) that were chosen."""
    actions = []
    todo = [parser]
    while todo:
        current = todo.pop()
        actions += current._actions
        for action in current._actions:
            if isinstance(action, argparse._SubParsersAction):
                chosen = action.choices.get(getattr(args, action.dest, None) or "")
                if chosen is not None:
                    todo.append(chosen)
    return actions


def _same(a: str, b: str) -> bool:
    """Whether two paths name one file: the same file on disk, or (where one does not exist
    yet) the same real path."""
    try:
        return os.path.samefile(a, b)
    except OSError:
        return os.path.realpath(a) == os.path.realpath(b)


# ---------------------------------------------------------------------------------------
# Checks before the work: argparse types of the output options
# ---------------------------------------------------------------------------------------
def output_file_problem(path) -> str | None:
    """Why ``path`` could not be written at the end of a run (it is a folder, its folder is
    missing or not writable, it is a special file we may not write, the system refuses the
    name itself: too long, a loop of links), or None. ``-`` passes."""
    if path is None or str(path) == "-":
        return None
    try:
        return _file_problem(Path(path))
    except OSError as exc:  # ENAMETOOLONG, ELOOP, ...: the name cannot be a file at all
        return f"the system refuses this name ({exc.strerror})"


def _file_problem(path: Path) -> str | None:
    if path.is_dir():
        return "is a folder; give a file name"
    if is_special_file(path):
        return None if os.access(path, os.W_OK) else "not writable"
    folder = Path(os.path.realpath(path)).parent
    if not folder.is_dir():
        named = path.parent if not path.parent.is_dir() else folder
        if folder.exists():
            return f"the folder {named} is a file"
        return f"the folder {named} does not exist"
    return _creation_problem(folder)


def output_folder_problem(path) -> str | None:
    """As :func:`output_file_problem` for a folder a run fills (created, with its parents,
    if missing): not an existing file, and writable or creatable. An empty name is refused
    (it would be the current folder, unsaid)."""
    if path is None:
        return None
    if not str(path).strip():
        return "an empty folder name; give a folder (. for the current one)"
    if str(path) == "-":  # not stdout here, and left out of the outputs a run may write (as stdout is)
        return "'-' names standard output, not a folder; for a folder of that name give ./-"
    try:
        return _folder_problem(Path(path))
    except OSError as exc:  # ENAMETOOLONG, ELOOP, ...: the name cannot be a folder at all
        return f"the system refuses this name ({exc.strerror})"


def _folder_problem(path: Path) -> str | None:
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


def is_special_file(path) -> bool:
    """Whether ``path`` is an existing device, pipe or socket (written directly, never renamed over)."""
    try:
        mode = os.stat(path).st_mode  # follows symlinks: /dev/stdout -> the terminal or pipe
    except OSError:
        return False
    return not (stat.S_ISREG(mode) or stat.S_ISDIR(mode))


def shown(text: str) -> str:
    """An option's value as a message shows it: as typed, or quoted when empty, spaced or long."""
    return text if text and len(text) <= 200 and not any(c.isspace() for c in text) else repr(text[:200])


def output_file(text: str) -> str:
    """argparse type of an option naming a file the run writes (``-``: stdout): refused now,
    before any work, if it could not be written at the end."""
    problem = output_file_problem(text)
    if problem:
        raise argparse.ArgumentTypeError(f"{shown(text)}: {problem}")
    return text


def output_file_only(text: str) -> str:
    """argparse type of an option naming a file the run writes that is never standard output
    (``plan-poses --out``, ``view --html``): ``-`` is refused now, as ``--to -`` is (it was
    written as a file named ``-`` and stopped the run as a write outside its outputs, exit 1)."""
    if text == "-":
        raise argparse.ArgumentTypeError("-: '-' names standard output, which this option does not write; for a "
                                         "file of that name give ./-")
    return output_file(text)


def output_folder(text: str) -> str:
    """argparse type of an option naming a folder the run fills (see :func:`output_file`)."""
    problem = output_folder_problem(text)
    if problem:
        raise argparse.ArgumentTypeError(f"{shown(text)}: {problem}")
    return text


def effects_side_file(path) -> Path:
    """The file written beside an as-built URDF ``x.urdf``: ``x.effects.yaml`` (the effects a URDF cannot hold)."""
    path = Path(path)
    return path.with_name(path.stem + ".effects.yaml")


def as_built_file(text: str) -> str:
    """argparse type of ``--as-built-urdf``: a regular file that can be written, with its side
    file (:func:`effects_side_file`) too; a device or pipe is refused, as the pair would then
    be one file written and another created beside the device (``/dev/null.effects.yaml``)."""
    if text == "-" or is_special_file(text):
        raise argparse.ArgumentTypeError(f"{shown(text)}: not a regular file; the as-built model is two files "
                                         f"(the URDF and {effects_side_file(text).name} beside it)")
    output_file(text)
    side = effects_side_file(text)
    problem = output_file_problem(side) or ("is a device or pipe" if is_special_file(side) else None)
    if problem:
        raise argparse.ArgumentTypeError(f"{shown(text)}: its side file {shown(str(side))}: {problem}")
    return text


#: The argparse types that name an output of the run.
OUTPUT_TYPES = (output_file, output_file_only, output_folder, as_built_file)
