"""ABB RAPID: ``MoveJ``/``MoveL`` to a ``robtarget``, ``MoveAbsJ`` to a ``jointtarget``.

A target is the instruction's first argument: a literal, or a ``robtarget``/``jointtarget`` declared
(``CONST``, ``PERS``, ``VAR``) or assigned in the module. A robtarget is
``[[x, y, z], [q1, q2, q3, q4], [cf1, cf4, cf6, cfx], [external axes]]``: mm, a unit quaternion
(``q1`` the scalar part), the configuration (:mod:`.configuration`); a jointtarget
``[[j1, ..., j6], [external axes]]`` in deg. External axes are kept as they are.

The tool is the instruction's fourth argument: ``tool0`` (the flange) or a ``tooldata`` declared in the
module (``[robhold, [[x, y, z], [q1, ..., q4]], load]``); another leaves the measured point as the TCP,
said. The frame is the ``\\WObj`` argument: ``wobj0`` (the base frame) or a ``wobjdata`` declared in the
module (user frame times object frame); another leaves its targets unfiltered. A tool the robot does
not hold, or a work object it holds, is not filtered.

Not filtered, and listed: circles (``MoveC``), ``MoveExtJ``, ``SearchL``/``SearchC``, the ``Trigg``
motions, targets that are expressions (``Offs(...)``, ``RelTool(...)``), and instructions that are
neither RAPID's common ones nor routines of the module.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from .grammar import elements, is_token, is_tree, numbers_of, parse, start_of, text_of
from .targets import Configuration, ParsedProgram, ProgramTarget, line_column, set_joint_numbers

LANGUAGE = "RAPID"

GRAMMAR = r"""
start: _item*
_item: statement | label | section | module | proc | func | trap | record | if_block | for_block | while_block
     | test_block
statement: _LOCAL? atom+ ";"
label: NAME ":"
section: ERROR | UNDO | BACKWARD
module: MODULE NAME group? _item* ENDMODULE
proc: _LOCAL? PROC NAME group _item* ENDPROC
func: _LOCAL? FUNC NAME NAME group _item* ENDFUNC
trap: _LOCAL? TRAP NAME _item* ENDTRAP
record: RECORD NAME _item* ENDRECORD
if_block: IF atom+ THEN _item* (ELSEIF atom+ THEN _item*)* (ELSE _item*)? ENDIF
for_block: FOR atom+ DO _item* ENDFOR
while_block: WHILE atom+ DO _item* ENDWHILE
test_block: TEST atom+ (CASE atom+ ":" _item*)* (DEFAULT ":" _item*)? ENDTEST
?atom: NAME | NUMBER | STRING | OP | bracket | group | brace
bracket: "[" atom* "]"
group: "(" atom* ")"
brace: "{" atom* "}"

MODULE.2: /module\b/i
ENDMODULE.2: /endmodule\b/i
_LOCAL.2: /local\b/i
PROC.2: /proc\b/i
ENDPROC.2: /endproc\b/i
FUNC.2: /func\b/i
ENDFUNC.2: /endfunc\b/i
TRAP.2: /trap\b/i
ENDTRAP.2: /endtrap\b/i
RECORD.2: /record\b/i
ENDRECORD.2: /endrecord\b/i
IF.2: /if\b/i
THEN.2: /then\b/i
ELSEIF.2: /elseif\b/i
ELSE.2: /else\b/i
ENDIF.2: /endif\b/i
FOR.2: /for\b/i
WHILE.2: /while\b/i
DO.2: /do\b/i
ENDFOR.2: /endfor\b/i
ENDWHILE.2: /endwhile\b/i
TEST.2: /test\b/i
CASE.2: /case\b/i
DEFAULT.2: /default\b/i
ENDTEST.2: /endtest\b/i
ERROR.2: /error\b/i
UNDO.2: /undo\b/i
BACKWARD.2: /backward\b/i
NAME: /[A-Za-z_][A-Za-z0-9_]*/
NUMBER: /(\d+\.\d*|\.\d+|\d+)([eE][-+]?\d+)?/
STRING: /"(""|[^"\n])*"/
OP: /:=|<>|<=|>=|[-+*\/<>=,.\\%?]/
COMMENT: /![^\n]*/
HEADER: /%%%[\s\S]*?%%%/
%ignore /[ \t\f\r\n]+/
%ignore COMMENT
%ignore HEADER
"""

#: Motions whose targets are filtered (tool: the fourth positional argument), and those listed.
POSE_MOTIONS = ("movej", "movel", "movejdo", "moveldo", "movejao", "moveldo", "movejgo", "movelgo", "movejsync",
                "movelsync")
JOINT_MOTIONS = ("moveabsj",)
OTHER_MOTIONS = ("movec", "movecdo", "movecao", "movecgo", "movecsync", "moveextj", "searchl", "searchc", "searchj",
                 "triggl", "triggj", "triggc", "triggjioc", "triggljoc", "movelrelative", "movejrelative")
#: Instructions RAPID itself knows (a statement's first word); anything else is listed unless the module
#: defines it.
KNOWN = frozenset("""
const pers var task local tpwrite tperase tpreadfk tpreadnum set reset setdo setao setgo pulsedo waittime waitdi
waitdo waituntil waitai waitao waitgi waitgo waitsyncta confj confl singarea accset velset pathaccel
gripload mechunitload stop exit return raise retry trynext goto incr decr add clear break
errwrite errlog stopmove startmove restopath storepath clearpath iwatch isleep idelete iconnect connect
isignaldi isignaldo itimer triggio triggequip triggint movej movel moveabsj movec
""".split())
ROBTARGET, JOINTTARGET, TOOLDATA, WOBJDATA = "robtarget", "jointtarget", "tooldata", "wobjdata"


def parse_program(text: str, source: str) -> ParsedProgram:
    """The motion targets of a RAPID module (see the module docstring)."""
    tree = parse(GRAMMAR, text, source, LANGUAGE)
    program = ParsedProgram(LANGUAGE, {source: text}, header={source: (_after_module_line(text, tree), "! ")})
    statements = list(_statements(tree))
    declared, routines = {}, set()
    for s in statements:
        if is_tree(s, "proc") or is_tree(s, "func") or is_tree(s, "trap"):
            words = [str(a).lower() for a in s.children if is_token(a, "NAME")]
            if words:
                routines.add(words[-1] if is_tree(s, "func") else words[0])
        if is_tree(s, "statement"):
            found = _declaration(s.children)
            if found is not None:
                declared.setdefault(found[1], []).append(found)
    targets = {}
    for s in statements:
        if not is_tree(s, "statement"):
            continue
        atoms = s.children
        word = str(atoms[0]).lower() if is_token(atoms[0], "NAME") else ""
        line = atoms[0].line if is_token(atoms[0]) else s.meta.line
        if word in POSE_MOTIONS or word in JOINT_MOTIONS:
            _motion(program, targets, str(atoms[0]), word in JOINT_MOTIONS, atoms[1:], declared, text, source)
        elif word in OTHER_MOTIONS:
            program.unknown.append(f"{source}:{line}: {text_of(text, atoms)} (a {atoms[0]}: not filtered)")
        elif word and word not in KNOWN and word not in routines and not _is_assignment(atoms):
            program.unknown.append(f"{source}:{line}: {text_of(text, atoms)} (neither a common RAPID instruction "
                                   "nor a routine of the module: kept as written)")
    program.targets = list(targets.values())
    return program


def _after_module_line(text: str, tree) -> int:
    """The offset after the line of ``MODULE name`` (the header comment goes inside the module)."""
    for child in tree.children:
        if is_tree(child, "module"):
            end = text.find("\n", child.children[0].end_pos)
            return len(text) if end < 0 else end + 1
    return 0


def _statements(tree):
    for child in tree.children:
        if hasattr(child, "data"):
            yield child
            if not is_tree(child, "statement"):
                yield from _statements(child)


def _is_assignment(atoms) -> bool:
    return any(is_token(a, "OP", ":=") for a in atoms[:4])


def _declaration(atoms):
    """(type, name, literal, statement atoms) of ``[LOCAL|TASK] CONST|PERS|VAR type name := literal``, or of an
    assignment ``name := literal``; None otherwise."""
    words = []
    for k, atom in enumerate(atoms):
        if is_token(atom, "OP", ":="):
            if k != len(atoms) - 2 or not is_tree(atoms[k + 1], "bracket"):
                return None
            if len(words) >= 3 and words[-3] in ("const", "pers", "var"):
                return words[-2], words[-1], atoms[k + 1]
            if len(words) == 1:
                return "", words[0], atoms[k + 1]
            return None
        if not is_token(atom, "NAME"):
            return None
        words.append(str(atom).lower())
    return None


def _split_arguments(atoms):
    """(positional arguments, {optional argument: its atoms}) of an instruction's argument atoms."""
    positional, optional = [], {}
    for element in elements(atoms):
        parts, current = [], []
        for atom in element:
            if is_token(atom, "OP", "\\"):
                parts.append(current)
                current = []
            else:
                current.append(atom)
        parts.append(current)
        if parts[0]:
            positional.append(parts[0])
        for part in parts[1:]:
            if part and is_token(part[0], "NAME"):
                value = part[2:] if len(part) >= 2 and is_token(part[1], "OP", ":=") else []
                optional[str(part[0]).lower()] = value
    return positional, optional


def _literal(argument, declared, wanted: str):
    """(literal bracket, variable, problem) of an argument naming a ``wanted``-type datum."""
    if len(argument) == 1 and is_tree(argument[0], "bracket"):
        return argument[0], "", ""
    if len(argument) == 1 and is_token(argument[0], "NAME"):
        name = str(argument[0])
        found = [d for d in declared.get(name.lower(), []) if d[0] in (wanted, "")]
        if len(found) == 1:
            return found[0][2], name, ""
        return None, name, (f"{name} is declared or assigned more than once" if found else
                            f"{name} is not declared in the module")
    return None, "", "an expression, not a literal"


def _parts(bracket):
    """The elements of a bracketed literal, each a nested bracket's children or None."""
    return [e[0].children if len(e) == 1 and is_tree(e[0], "bracket") else None for e in elements(bracket.children)]


def _frame(translation, quaternion) -> np.ndarray:
    """(4, 4) of mm and a quaternion [q1 (scalar), q2, q3, q4]."""
    w, x, y, z = (n.value for n in quaternion)
    q = pin.Quaternion(w, x, y, z)
    if abs(q.norm() - 1.0) > 1e-3:
        raise ValueError("not a unit quaternion")
    q.normalize()
    out = np.eye(4)
    out[:3, :3] = q.toRotationMatrix()
    out[:3, 3] = np.array([n.value for n in translation]) * 1e-3
    return out


def _pose_data(bracket, first: int):
    """(4, 4) of a ``[[x, y, z], [q1..q4]]`` pair inside ``bracket`` starting at element ``first``, or None."""
    parts = _parts(bracket)
    if len(parts) < first + 2 or parts[first] is None or parts[first + 1] is None:
        return None
    translation, quaternion = numbers_of(parts[first]), numbers_of(parts[first + 1])
    if translation is None or quaternion is None or len(translation) != 3 or len(quaternion) != 4:
        return None
    try:
        return _frame(translation, quaternion)
    except ValueError:
        return None


def _tool(argument, declared, source, line):
    """(flange_M_tcp or None, note, problem) of a motion's tool argument."""
    if len(argument) == 1 and is_token(argument[0], "NAME") and str(argument[0]).lower() == "tool0":
        return np.eye(4), "tool0 (the flange)", ""
    literal, name, problem = _literal(argument, declared, TOOLDATA)
    if literal is None:
        return None, f"the tool {name or '?'} at {source}:{line} cannot be read ({problem}): the measured point is " \
                     "the TCP", ""
    parts = elements(literal.children)
    robhold = parts[0] if parts else []
    if len(robhold) == 1 and is_token(robhold[0], "NAME") and str(robhold[0]).lower() == "false":
        return None, "", f"the tool {name} is not held by the robot (a stationary tool)"
    inner = parts[1][0] if len(parts) > 1 and len(parts[1]) == 1 and is_tree(parts[1][0], "bracket") else None
    frame = None if inner is None else _pose_data(inner, 0)
    if frame is None:
        return None, f"the tool {name or 'literal'} at {source}:{line} has no tframe of numbers: the measured " \
                     "point is the TCP", ""
    return frame, f"the tooldata {name or 'literal'}", ""


def _work_object(optional, declared):
    """(base_M_frame or None, note) of the \\WObj argument."""
    argument = optional.get("wobj")
    if argument is None or (len(argument) == 1 and is_token(argument[0], "NAME")
                            and str(argument[0]).lower() == "wobj0"):
        return np.eye(4), ""
    literal, name, problem = _literal(argument, declared, WOBJDATA)
    if literal is None:
        return None, f"the work object {name or '?'} cannot be read ({problem})"
    parts = elements(literal.children)
    words = [str(p[0]).lower() if len(p) == 1 and is_token(p[0], "NAME") else "" for p in parts[:2]]
    if len(parts) < 5 or words[0] != "false" or words[1] != "true":
        return None, f"the work object {name} is held by the robot or moved by a mechanical unit"
    user = _pose_data(_wrap(parts[3]), 0) if len(parts[3]) == 1 and is_tree(parts[3][0], "bracket") else None
    obj = _pose_data(_wrap(parts[4]), 0) if len(parts[4]) == 1 and is_tree(parts[4][0], "bracket") else None
    if user is None or obj is None:
        return None, f"the work object {name} has no frames of numbers"
    return user @ obj, f"the work object {name}"


def _wrap(element):
    return element[0]


def _motion(program, targets, instruction, joint_motion, atoms, declared, text, source):
    positional, optional = _split_arguments(atoms)
    first = positional[0] if positional else []
    line, column = line_column(text, start_of(first[0] if first else atoms[0]))
    wanted = JOINTTARGET if joint_motion else ROBTARGET
    literal, name, problem = _literal(first, declared, wanted)
    tool, tool_note, tool_problem = (_tool(positional[3], declared, source, line) if len(positional) > 3 else
                                     (None, f"no tool at {source}:{line}: the measured point is the TCP", ""))
    frame, frame_note = _work_object(optional, declared)
    key = id(literal) if literal is not None else (line, column)
    if key in targets:
        previous = targets[key]
        if not previous.problem and (previous.tool_note != tool_note or previous.frame_note != frame_note):
            previous.problem = f"used with two tools or work objects ({previous.tool_note}; {tool_note})"
        return
    target = ProgramTarget(source, line, column, instruction, name, "joints" if joint_motion else "pose", tool=tool,
                           tool_note=tool_note, frame=frame, frame_note=frame_note)
    targets[key] = target
    if literal is None or tool_problem:
        target.problem = tool_problem or f"its target is {problem} ({text_of(text, first)})"
        return
    target.line, target.column = line_column(text, literal.meta.start_pos)
    parts = _parts(literal)
    if joint_motion:
        numbers = numbers_of(parts[0]) if parts and parts[0] is not None else None
        if numbers is None or len(numbers) != 6:
            target.problem = "its robax is not six numbers"
            return
        set_joint_numbers(target, numbers, scale=np.pi / 180.0, decimals=7)
        return
    if len(parts) < 3 or any(p is None for p in parts[:3]):
        target.problem = "not a robtarget [[x, y, z], [q1, q2, q3, q4], [cf1, cf4, cf6, cfx], [external axes]]"
        return
    translation, quaternion, configuration = (numbers_of(p) for p in parts[:3])
    if translation is None or quaternion is None or configuration is None or \
            (len(translation), len(quaternion), len(configuration)) != (3, 4, 4):
        target.problem = "its position, orientation or configuration is not all numbers"
        return
    try:
        target.pose = _frame(translation, quaternion)
    except ValueError:
        target.problem = "its orientation is not a unit quaternion"
        return
    target.configuration = Configuration("abb", tuple(int(n.value) for n in configuration))
    target.write = lambda joints, pose, config: _write_pose(translation, quaternion, configuration, pose, config)


def _write_pose(translation, quaternion, configuration, pose, config):
    """Edits writing ``pose`` (4, 4) as mm and the quaternion of the original's sign, and the quadrants of the
    corrected joints."""
    q = pin.Quaternion(pose[:3, :3])
    values = np.array([q.w, q.x, q.y, q.z])
    old = np.array([n.value for n in quaternion])
    if values @ old < 0:
        values = -values
    edits = [n.edit(v, 6) for n, v in zip(translation, pose[:3, 3] * 1e3)]
    edits += [n.edit(v, 9) for n, v in zip(quaternion, values)]
    if config is not None:
        edits += [n.edit(float(v), 0) for n, v in zip(configuration, config.values)]
    return [e for e in edits if e]

