"""Robot programs filtered through the calibrated model ("program filtering").

A customer with a drilling or machining program wants that program back, every motion target
replaced by the command that puts the real robot on it, and nothing else changed:

* :mod:`.urscript`: URScript (``movej``/``movel``/``movep``; joint lists [rad], ``p[...]`` poses [m, rad]);
* :mod:`.krl`: KUKA KRL, a ``.src`` and its ``.dat`` (``E6POS``/``POS``/``FRAME``, ``E6AXIS``/``AXIS``
  aggregates; mm, deg, A/B/C as ZYX Euler angles; Status and Turn);
* :mod:`.rapid`: ABB RAPID (``robtarget`` with its quaternion and ``confdata``, ``jointtarget``; mm, deg);
* :mod:`.trajectory_csv`: a joint trajectory CSV as ROS's ``JointTrajectory`` holds one
  (``time_from_start`` and a column per joint, rad and m).

Each language is read with a grammar (:mod:`.grammar`, lark): a file that does not parse is one line
naming the file, the line and the column; a construct the filter does not understand is kept as
written and listed; only the numbers of the targets change, every other character stays. The
compensation itself: :mod:`.compensate`.
"""

from __future__ import annotations

from pathlib import Path

from ...exceptions import InputError
from ..model import AsBuiltModel
from .compensate import FilteredProgram, TargetResult, check_language_robot, filter_parsed
from .targets import ParsedProgram

#: File suffix -> language.
LANGUAGES = {".script": "URScript", ".urscript": "URScript", ".src": "KRL", ".dat": "KRL", ".mod": "RAPID",
             ".modx": "RAPID", ".prg": "RAPID", ".sys": "RAPID", ".csv": "joint trajectory CSV"}

__all__ = ["FilteredProgram", "TargetResult", "filter_program", "program_language", "parse_program_files",
           "check_language_robot", "LANGUAGES"]


def program_language(name: str) -> str:
    """The language of a program file by its suffix; InputError naming the suffixes known otherwise."""
    language = LANGUAGES.get(Path(name).suffix.lower())
    if language is None:
        raise InputError(f"{name}: not a program this filter reads (suffixes: {', '.join(LANGUAGES)})")
    return language


def parse_program_files(files: dict, robot) -> ParsedProgram:
    """The program of ``files`` (file name -> text, one program: a KRL ``.src`` with its ``.dat``, else one
    file), read by its language's parser."""
    names = list(files)
    languages = {program_language(n) for n in names}
    if len(languages) != 1 or (len(names) > 1 and languages != {"KRL"}):
        raise InputError(f"{', '.join(names)}: one program at a time (a KRL .src with its .dat)")
    language = languages.pop()
    if language == "URScript":
        from .urscript import parse_program

        return parse_program(files[names[0]], names[0])
    if language == "KRL":
        from .krl import parse_program

        return parse_program(files)
    if language == "RAPID":
        from .rapid import parse_program

        return parse_program(files[names[0]], names[0])
    from .trajectory_csv import parse_program

    return parse_program(files[names[0]], names[0], robot)


def filter_program(model: AsBuiltModel, files: dict, *, threshold: float = 1e-7, payload_kg: float = 0.0,
                   header: list[str] | None = None) -> FilteredProgram:
    """A program filtered through the calibrated model.

    Parameters
    ----------
    model : AsBuiltModel
        The full calibrated model.
    files : dict
        File name -> text of one program (a KRL ``.src`` and its ``.dat`` together).
    threshold : float, default=1e-7
        Stop correcting a target when the full model's miss is below this [m].
    payload_kg : float, default=0.0
        The load the program's targets are reached with [kg].
    header : list of str, optional
        The header comment's lines (what was done, with which model, when); without it no header is written.

    Returns
    -------
    FilteredProgram
        The filtered texts, what became of each target, what was not understood.

    Raises
    ------
    InputError
        A file that does not parse (file, line, column), or targets of another number of joints.
    """
    program = parse_program_files(files, model.robot)
    check_language_robot(program, model.robot)
    return filter_parsed(model, program, threshold=threshold, payload_kg=payload_kg, header=header)
