"""A joint trajectory as a CSV, in ROS's ``JointTrajectory`` layout: ``time_from_start`` and one column
per joint, named after the robot's joints, positions in rad (m for a prismatic joint) as ROS keeps
them; a joint column may carry a unit suffix instead (``_rad``, ``_deg``, ``_m``, ``_mm``). Every row
is a joint target; ``#`` lines are comments. Other columns (velocities, accelerations, efforts) are
kept as written and listed: a corrected position changes what they should be.
"""

from __future__ import annotations

import numpy as np

from ...exceptions import InputError
from .grammar import parse
from .targets import NumberText, ParsedProgram, ProgramTarget

LANGUAGE = "joint trajectory CSV"

GRAMMAR = r"""
start: _line*
_line: COMMENT? _NL | row _NL
row: cell ("," cell)*
cell: VALUE?
COMMENT.2: /#[^\n]*/
VALUE: /"[^"\n]*"|[^,\r\n"]+/
_NL: /\r?\n/
"""

UNITS = {"": 1.0, "_rad": 1.0, "_m": 1.0, "_deg": np.pi / 180.0, "_mm": 1e-3}
DECIMALS = {"": 9, "_rad": 9, "_m": 9, "_deg": 7, "_mm": 6}


def parse_program(text: str, source: str, robot) -> ParsedProgram:
    """The rows of a joint trajectory CSV as joint targets of ``robot``."""
    tree = parse(GRAMMAR, text if text.endswith("\n") else text + "\n", source, LANGUAGE)
    program = ParsedProgram(LANGUAGE, {source: text}, header={source: (0, "# ")})
    rows = [r for r in tree.children if hasattr(r, "data")]
    if not rows:
        raise InputError(f"{source}: no header row (time_from_start and a column per joint)")
    header = [_cell_text(c).strip() for c in rows[0].children]
    columns = _joint_columns(header, robot, source, rows[0].meta.line)
    for k, name in enumerate(header):
        if k not in [c for c, _ in columns.values()] and name != "time_from_start":
            program.unknown.append(f"{source}:{rows[0].meta.line}: column {name!r} (not a joint position: kept as "
                                   "written)")
    for row in rows[1:]:
        cells = row.children
        line = row.meta.line
        if len(cells) != len(header):
            raise InputError(f"{source}:{line}:1: {len(cells)} cells, the header has {len(header)}")
        numbers, problem = [], ""
        for joint in robot.joint_names:
            k, suffix = columns[joint]
            number = _number(cells[k])
            if number is None:
                problem = f"its {header[k]} is not a number"
                break
            numbers.append((number, suffix))
        target = ProgramTarget(source, line, 1, "row", "", "joints",
                               tool_note="a joint trajectory holds no tool: the measured point is the TCP")
        if problem:
            target.problem = problem
        else:
            target.joints = np.array([n.value * UNITS[s] for n, s in numbers])
            target.write = lambda joints, pose, configuration, numbers=numbers: [
                e for e in (n.edit(v / UNITS[s], DECIMALS[s]) for (n, s), v in zip(numbers, joints)) if e]
        program.targets.append(target)
    return program


def _cell_text(cell) -> str:
    return str(cell.children[0]) if cell.children else ""


def _number(cell) -> NumberText | None:
    if not cell.children:
        return None
    token = cell.children[0]
    text = str(token)
    stripped = text.strip()
    try:
        value = float(stripped)
    except ValueError:
        return None
    if not np.isfinite(value):
        return None
    start = token.start_pos + text.index(stripped)
    return NumberText(start, start + len(stripped), value, stripped)


def _joint_columns(header: list[str], robot, source: str, line: int) -> dict:
    """joint -> (column index, unit suffix); InputError naming what is missing."""
    if "time_from_start" not in header:
        raise InputError(f"{source}:{line}:1: no time_from_start column (a JointTrajectory CSV: time_from_start and "
                         f"a column per joint: {', '.join(robot.joint_names)})")
    out = {}
    for joint in robot.joint_names:
        found = [(k, name[len(joint):]) for k, name in enumerate(header)
                 if name.startswith(joint) and name[len(joint):] in UNITS]
        if len(found) != 1:
            raise InputError(f"{source}:{line}:1: " + (f"no column for joint {joint}" if not found else
                                                       f"joint {joint} has {len(found)} columns")
                             + f" (the robot's joints: {', '.join(robot.joint_names)})")
        out[joint] = found[0]
    return out
