"""An output that is an input, or another output, refused when the command line is read.

``diagnose in.csv --json in.csv`` would overwrite the measurements; ``simulate --out s.csv
--truth s.csv`` would keep one of the two files. The outputs of a command are its options
whose argparse type is an output type of :mod:`tcr_accuracy.cli.common` (and the side file
of ``--as-built-urdf``); its inputs, every other value that names an existing file or
folder. Standard output (``-``) and special files (``/dev/stdout``, a pipe) are streams, not
files a run could lose, and are left out.
"""

from __future__ import annotations

import argparse
import os

from ..exceptions import InputError
from .common import as_built_file, effects_side_file, output_file, output_folder

_OUTPUT_TYPES = (output_file, output_folder, as_built_file)


def check_distinct_paths(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """Refuse, in one line naming both options, an output that is an input or another output.

    Raises
    ------
    InputError
    """
    from ..atomic import is_special_file

    outputs, inputs = [], []
    for action in _command_actions(parser, args):
        value = getattr(args, action.dest, None)
        name = action.option_strings[0] if action.option_strings else (action.metavar or action.dest)
        values = value if isinstance(value, list) else [value]
        for text in (v for v in values if isinstance(v, str) and v and v != "-"):
            if action.type in _OUTPUT_TYPES:
                if not is_special_file(text):
                    outputs.append((name, text))
                    if action.type is as_built_file:
                        outputs.append((f"{name}'s side file", str(effects_side_file(text))))
            elif os.path.exists(text) and not is_special_file(text):
                inputs.append((name, text))
    for k, (name, path) in enumerate(outputs):
        for in_name, in_path in inputs:
            if _same(path, in_path):
                raise InputError(f"{name} {path}: is also {in_name} {in_path}, an input: the run would overwrite "
                                 "it; write the output elsewhere")
        for other_name, other in outputs[:k]:
            if _same(path, other):
                raise InputError(f"{name} {path}: the same file as {other_name} {other}: one of the two "
                                 "would be lost; give each output its own name")


def _command_actions(parser: argparse.ArgumentParser, args: argparse.Namespace) -> list:
    """The actions of the subcommand that was run (and the top-level parser's)."""
    actions = list(parser._actions)
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            chosen = action.choices.get(getattr(args, action.dest, None) or "")
            if chosen is not None:
                actions += chosen._actions
    return actions


def _same(a: str, b: str) -> bool:
    """Whether two paths name one file: the same file on disk, or (where one does not exist
    yet) the same real path."""
    try:
        return os.path.samefile(a, b)
    except OSError:
        return os.path.realpath(a) == os.path.realpath(b)
