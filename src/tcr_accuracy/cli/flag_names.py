"""Library parameters worded as the flags that set them.

A library names no flag: a message of an :class:`~tcr_accuracy.exceptions.InputError` or of a
warning names the Python parameter at fault in keyword form (``folds=1: need at least 2``, a
hint ``give tool=FRAME``, ``tracker_map["x_mm"]="HEADER"``, ``give robot= as in the diagnosis``)
or, at its start, by name (``effects: unknown effect(s) ...``). The command line words each such
parameter as its flag (``--folds 1: need at least 2``), from one table: the ``dest`` of every
option of the command that ran (so a new option is known by its parser alone) and, for a library
parameter named otherwise, :data:`ALIASES`.
"""

from __future__ import annotations

import argparse
import re

#: Library parameter -> the ``dest`` of the options that set it, where the names differ (the
#: first the command has is used). Only the parameter an error or warning is about
#: (``InputError.parameter``, a warning class's ``parameter``) is looked up here: ``source`` is
#: :func:`~tcr_accuracy.model.robot.load_robot`'s, not every function's.
ALIASES = {
    "source": ("robot",),                # load_robot(source, tool)
    "package_dirs": ("package_dir",),    # load_robot(..., package_dirs=[...])
    "preset": ("error_preset",),         # seed_budget(robot, preset): view's --error-preset
    "n_steps": ("steps",),               # tool_change_motion(robot, n_steps)
    "tracker_map": ("map",),             # import_tracker(tracker_path, tracker_map, ...)
    "tool_rotation": ("tool_rpy",),      # plan_iso_cube(..., tool_rotation=R): iso9283 plan's --tool-rpy [deg]
    "tracker": ("tracker_mm",),          # plan_iso_cube(..., tracker=p): --tracker-mm [mm]
    "size": ("cube_size_mm",),           # plan_iso_cube(..., size=s): --cube-size-mm [mm]
    "tcp_offset": ("tcp_mm",),           # GapDiagnosis(tcp_offset=...): diagnose's --tcp-mm [mm]
}


def option_flags(actions) -> dict[str, str]:
    """``{dest: flag}`` of the argparse ``actions`` that have a long option (its first)."""
    flags = {}
    for action in actions:
        long = [o for o in action.option_strings if o.startswith("--")]
        if long and action.dest not in flags:
            flags[action.dest] = long[0]
    return flags


def command_flags(parser: argparse.ArgumentParser, args: argparse.Namespace) -> dict[str, str]:
    """``{dest: flag}`` of the command that ``args`` ran (its subcommand and step included)."""
    from .output_paths import command_actions

    return option_flags(command_actions(parser, args))


def in_flags(text: str, flags: dict[str, str], parameter: str | None = None) -> str:
    """``text`` with every library parameter it names in keyword form written as its flag.

    Parameters
    ----------
    text : str
        A library message.
    flags : dict of str to str
        ``{dest: flag}`` of the command (:func:`command_flags`).
    parameter : str, optional
        The parameter the message is about; where its name is not a ``dest``, :data:`ALIASES`
        says which option sets it.

    Returns
    -------
    str
        ``name=value`` -> ``--flag value``; ``name=`` before a space, a comma, a semicolon, a parenthesis or the end -> ``--flag``;
        ``name["key"]=`` -> ``--flag key=``; ``name:`` opening the text -> ``--flag:``.
    """
    names = dict(flags)
    for dest in ALIASES.get(parameter, ()):
        if dest in flags and parameter not in flags:
            names[parameter] = flags[dest]
            break
    if not names:
        return text
    alternatives = "|".join(re.escape(n) for n in sorted(names, key=len, reverse=True))
    pattern = re.compile(rf"(?<![\w.\-\[\"'])(?P<name>{alternatives})"
                         rf"(?:\[(?P<quote>[\"']?)(?P<key>\w+)(?P=quote)\]=|=(?P<value>[^\s,;)]?)|(?P<colon>:))")

    def flag(match: re.Match) -> str:
        if match["colon"] is not None:  # only as the text's subject
            return match[0] if match.start() else f"{names[match['name']]}:"
        if match["key"] is not None:
            return f"{names[match['name']]} {match['key']}="
        value = match["value"]
        return f"{names[match['name']]} {value}" if value else names[match["name"]]

    return pattern.sub(flag, text)
