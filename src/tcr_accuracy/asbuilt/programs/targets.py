"""What a program parser hands the filter: its motion targets, where their numbers sit, and what it
did not understand.

A parser (one module per language) reads the program's text with its grammar and returns a
:class:`ParsedProgram`: each motion target once (an inline literal, or the declaration a motion
names), with its values in SI, the tool and frame in force where it is used, the configuration the
program gave, and a ``write`` that turns new values into edits of the text (character spans and
their new text). Everything else stays as it is, byte for byte.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np


@dataclass(frozen=True)
class NumberText:
    """One number of the program's text: where it sits (character offsets, the sign included) and its value."""

    start: int
    end: int
    value: float
    text: str

    def edit(self, value: float, decimals: int) -> tuple[int, int, str] | None:
        """The edit writing ``value`` here with at most ``decimals`` decimals (trailing zeros dropped), or None
        when the number as written already reads as ``value`` at that precision (the text stays as it is)."""
        if abs(value - self.value) <= 0.5 * 10.0 ** -decimals:
            return None
        return self.start, self.end, format_number(value, decimals)


def format_number(value: float, decimals: int) -> str:
    """``value`` with at most ``decimals`` decimals, trailing zeros and a negative zero dropped."""
    text = f"{value:.{decimals}f}"
    if "." in text:
        text = text.rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


@dataclass(frozen=True)
class Configuration:
    """The arm configuration a target names (the branch of the inverse kinematics).

    kind : "kuka" (Status and Turn) or "abb" (confdata)
    values : the numbers as given: KUKA (S, T); ABB (cf1, cf4, cf6, cfx)
    """

    kind: str
    values: tuple


@dataclass
class ProgramTarget:
    """One motion target of a program.

    file : the file it is written in; line, column : where its literal starts (1-based)
    instruction : the motion that uses it (``movel``, ``PTP``, ``MoveL``, ``row``)
    name : the variable it is declared as, or "" (inline)
    kind : "joints" or "pose"
    joints : (n_joints,) [rad, m] for joint targets
    pose : (4, 4) frame_M_tcp [m] for pose targets, in the program's frame
    frame : (4, 4) base_M_frame of the program's frame (the controller's base frame, a work object) or None
        when it cannot be read (``frame_note`` says why: such a target is not filtered)
    tool : (4, 4) flange_M_tcp of the tool in force, or None when the program's tool data cannot be read
        (the measured point is the TCP then, ``tool_note`` says so)
    configuration : the configuration the program gave, or None
    write : (joints or None, pose or None, configuration or None) -> list of (start, end, text) edits
    problem : why it is not filtered at all ("" when it is: an expression, a relative motion, ...)
    """

    file: str
    line: int
    column: int
    instruction: str
    name: str
    kind: str
    joints: np.ndarray | None = None
    pose: np.ndarray | None = None
    frame: np.ndarray | None = None
    frame_note: str = ""
    tool: np.ndarray | None = None
    tool_note: str = ""
    configuration: Configuration | None = None
    write: Callable | None = None
    problem: str = ""

    @property
    def where(self) -> str:
        return f"{self.file}:{self.line}"

    def label(self) -> str:
        """``movel at prog.script:12`` (``PTP XP1 at prog.dat:4``)."""
        name = f" {self.name}" if self.name else ""
        return f"{self.instruction}{name} at {self.where}"


@dataclass
class ParsedProgram:
    """A program read by its language's parser.

    language : "URScript", "KRL", "RAPID" or "joint trajectory CSV"
    texts : file name -> its text (a KRL program: the .src and the .dat)
    targets : every motion target, in the order the program first uses them
    unknown : "file:line: what (why)" of each construct kept as written without being understood
    notes : what the parser assumed (an unknown tool, the frame of a base number, ...)
    header : file name -> (offset, comment prefix): where the header comment goes and how a comment line starts
    """

    language: str
    texts: dict
    targets: list = field(default_factory=list)
    unknown: list = field(default_factory=list)
    notes: list = field(default_factory=list)
    header: dict = field(default_factory=dict)


def apply_edits(text: str, edits) -> str:
    """``text`` with each (start, end, new) edit made (none overlapping)."""
    out, last = [], 0
    for start, end, new in sorted(edits):
        if start < last:
            raise ValueError("overlapping edits")
        out.append(text[last:start])
        out.append(new)
        last = end
    out.append(text[last:])
    return "".join(out)


def line_column(text: str, offset: int) -> tuple[int, int]:
    """(line, column) of a character offset, both 1-based."""
    line = text.count("\n", 0, offset) + 1
    return line, offset - (text.rfind("\n", 0, offset) + 1) + 1


def set_joint_numbers(target: ProgramTarget, numbers, *, scale: float = 1.0, decimals: int = 9) -> None:
    """Make ``target`` the joint target ``numbers`` write, each joint the number times ``scale`` [SI per the
    program's unit], corrected joints written back with at most ``decimals`` decimals."""
    target.joints = np.array([n.value for n in numbers]) * scale
    target.write = lambda joints, pose, configuration: [e for e in (n.edit(v / scale, decimals)
                                                                     for n, v in zip(numbers, joints)) if e]
