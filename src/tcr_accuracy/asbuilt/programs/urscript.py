"""URScript (Universal Robots): ``movej``, ``movel`` and ``movep`` with joint and pose targets.

A target is the first argument of the motion: a joint list ``[q1, ..., q6]`` [rad] or a pose
``p[x, y, z, rx, ry, rz]`` [m, rad; a rotation vector] in the robot's base frame, written inline or
as a variable assigned such a literal (``p1 = p[...]``, ``global``/``local``). The TCP is the one
``set_tcp(p[...])`` set last before the motion (in the file's order); without one, the measured
point. URScript has no configuration: the controller takes the solution nearest its current joints,
so each pose target is solved from the target before it.

Not filtered, and listed: other motions (``movec``, ``servoj``, ``speedl``, ...), a target that is an
expression (``pose_trans(...)``) or a variable assigned twice, calls of functions that are neither
URScript's nor defined in the program (a URCap's may move the robot).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from .grammar import elements, is_token, is_tree, numbers_of, parse, start_of, text_of
from .targets import ParsedProgram, ProgramTarget, line_column, set_joint_numbers

LANGUAGE = "URScript"

GRAMMAR = r"""
start: _NL* _item*
_item: statement | block
statement: atom+ _NL+
block: OPENER atom* ":" _NL+ _item* clause* END _NL*
clause: ELIF atom* ":" _NL+ _item*
      | ELSE ":" _NL+ _item*
?atom: NAME | NUMBER | STRING | OP | pose | list | group
pose: _POSE_OPEN _inner "]"
list: "[" _inner "]"
group: "(" _inner ")"
_inner: (atom | _NL)*

_POSE_OPEN.3: "p["
OPENER.2: /(def|thread|sec|if|while)\b/
ELIF.2: /elif\b/
ELSE.2: /else\b/
END.2: /end\b/
NAME: /[A-Za-z_][A-Za-z0-9_]*/
NUMBER: /(\d+\.\d*|\.\d+|\d+)([eE][-+]?\d+)?/
STRING: /"(\\.|[^"\\\n])*"/ | /'(\\.|[^'\\\n])*'/
OP: /==|!=|<=|>=|[-+*\/%<>=!&|^~,.$@?;]/
COMMENT: /#[^\n]*/
_NL: /\r?\n/
%ignore /[ \t\f]+/
%ignore /\\\r?\n/
%ignore COMMENT
"""

#: Motions whose targets are filtered, and motions that are not (listed).
MOTIONS = ("movej", "movel", "movep")
OTHER_MOTIONS = ("movec", "servoj", "servoc", "speedj", "speedl", "stopj", "stopl", "movepath", "position_deviation_warning",
                 "freedrive_mode", "teach_mode", "force_mode")
#: URScript's own functions and words a statement may start with (anything else that is called and not
#: defined in the program is listed as unknown).
BUILTINS = frozenset("""
textmsg popup sleep sync halt set_digital_out set_standard_digital_out set_configurable_digital_out
set_tool_digital_out set_analog_out set_standard_analog_out set_analog_outputdomain set_tool_voltage
get_digital_in get_standard_digital_in get_configurable_digital_in get_tool_digital_in get_analog_in
get_standard_analog_in get_tool_analog_in set_payload set_payload_mass set_payload_cog set_target_payload
set_tcp set_gravity set_tool_communication set_tool_output_mode set_input_actions_to_default
get_actual_joint_positions get_actual_tcp_pose get_target_tcp_pose get_target_joint_positions
get_inverse_kin get_inverse_kin_has_solution get_forward_kin get_actual_tool_flange_pose pose_trans
pose_inv pose_add pose_sub pose_dist interpolate_pose to_num to_str str_cat str_len norm sqrt sin cos
tan asin acos atan atan2 pow log floor ceil d2r r2d binary_list_to_integer integer_to_binary_list
force_mode end_force_mode zero_ftsensor end_freedrive_mode end_teach_mode socket_open socket_close
socket_send_string socket_send_line socket_send_int socket_read_ascii_float socket_read_string
socket_read_binary_integer socket_read_byte_list socket_set_var socket_get_var write_output_integer_register
write_output_float_register write_output_boolean_register read_input_integer_register
read_input_float_register read_input_boolean_register rpc_factory kill run join enter_critical exit_critical
global local return break continue set_safety_mode_transition_hardness set_tool_digital_output_mode
is_steady is_within_safety_limits get_steptime get_controller_temp set_flag get_flag set_runstate_outputs
rtde_set_watchdog set_standard_digital_input_action set_configurable_digital_input_action
set_tool_digital_input_action set_gravity_compensation get_tcp_offset get_target_payload
""".split())


def parse_program(text: str, source: str) -> ParsedProgram:
    """The motion targets of a URScript file (see the module docstring)."""
    tree = parse(GRAMMAR, text if text.endswith("\n") else text + "\n", source, LANGUAGE)
    program = ParsedProgram(LANGUAGE, {source: text}, header={source: (0, "# ")})
    statements = [s for s in _statements(tree)]
    defined = {str(s.children[1]) for s in statements if is_tree(s, "block") and str(s.children[0]) == "def"
               and len(s.children) > 1 and is_token(s.children[1], "NAME")}
    assigned = {}
    for s in statements:
        if is_tree(s, "statement"):
            found = _assignment(s.children)
            if found is not None:
                assigned.setdefault(found[0], []).append(found[1])
    tool, tool_note = None, "no set_tcp in the program: the measured point is the TCP"
    targets = {}
    for s in statements:
        if not is_tree(s, "statement"):
            continue
        atoms = s.children
        first = atoms[0]
        line = first.line if is_token(first) else s.meta.line
        if is_token(first, "NAME") and len(atoms) >= 2 and is_tree(atoms[1], "group"):
            name = str(first)
            if name == "set_tcp":
                tool, tool_note = _tcp(atoms[1], assigned, text, source, line)
                continue
            if name in MOTIONS:
                _motion(program, targets, name, atoms[1], assigned, tool, tool_note, text, source)
                continue
            if name in OTHER_MOTIONS:
                program.unknown.append(f"{source}:{line}: {text_of(text, atoms)} (a {name}: not filtered)")
                continue
            if name not in BUILTINS and name not in defined:
                program.unknown.append(f"{source}:{line}: {text_of(text, atoms)} (a call of {name}, neither "
                                       "URScript's nor defined in the program: kept as written)")
    program.targets = list(targets.values())
    return program


def _statements(tree):
    """Every statement and block opener, depth first in the file's order."""
    for child in tree.children:
        if is_tree(child, "statement"):
            yield child
        elif is_tree(child, "block") or is_tree(child, "clause"):
            yield child
            yield from _statements(child)


def _assignment(atoms):
    """(variable, the literal node) of ``[global|local] name = literal``, else None."""
    if atoms and is_token(atoms[0], "NAME") and str(atoms[0]) in ("global", "local"):
        atoms = atoms[1:]
    if len(atoms) == 3 and is_token(atoms[0], "NAME") and is_token(atoms[1], "OP", "=") and \
            (is_tree(atoms[2], "pose") or is_tree(atoms[2], "list")):
        return str(atoms[0]), atoms[2]
    return None


def _literal(node, assigned, what: str):
    """(literal node, variable name, problem) of a motion's first argument."""
    if len(node) == 1 and (is_tree(node[0], "pose") or is_tree(node[0], "list")):
        return node[0], "", ""
    if len(node) == 1 and is_token(node[0], "NAME"):
        name = str(node[0])
        found = assigned.get(name, [])
        if len(found) == 1:
            return found[0], name, ""
        if not found:
            return None, name, f"{name} is not assigned a literal in the program"
        return None, name, f"{name} is assigned {len(found)} times"
    return None, "", f"its {what} is an expression, not a literal"


def _tcp(group, assigned, text, source, line):
    args = elements(group.children)
    literal, name, problem = _literal(args[0], assigned, "TCP") if args else (None, "", "no argument")
    if literal is None or not is_tree(literal, "pose"):
        return None, f"the TCP set at {source}:{line} ({text_of(text, args[0] if args else [])}) cannot be read " \
                     f"({problem or 'not a pose'}): the measured point is the TCP"
    numbers = numbers_of(literal.children)
    if numbers is None or len(numbers) != 6:
        return None, f"the TCP set at {source}:{line} is not six numbers: the measured point is the TCP"
    return _pose(numbers), f"the TCP set at {source}:{line}"


def _pose(numbers) -> np.ndarray:
    values = [n.value for n in numbers]
    return pin.SE3(pin.exp3(np.array(values[3:])), np.array(values[:3])).homogeneous


def _motion(program, targets, name, group, assigned, tool, tool_note, text, source):
    args = elements(group.children)
    first = args[0] if args else []
    literal, variable, problem = _literal(first, assigned, "target")
    where = first[0] if first else group
    line, column = line_column(text, start_of(where))
    key = id(literal) if literal is not None else (line, column)
    if key in targets:
        return
    target = ProgramTarget(source, line, column, name, variable, "joints", tool=tool, tool_note=tool_note,
                           frame=np.eye(4))
    targets[key] = target
    if literal is None:
        target.problem = f"{problem} ({text_of(text, first)})"
        return
    numbers = numbers_of(literal.children)
    if numbers is None or (is_tree(literal, "pose") and len(numbers) != 6):
        target.problem = "its literal is not six numbers" if is_tree(literal, "pose") else "its list is not all numbers"
        return
    if is_tree(literal, "pose"):
        target.kind, target.pose = "pose", _pose(numbers)
        target.write = lambda joints, pose, configuration: _write_pose(numbers, pose)
    else:
        set_joint_numbers(target, numbers)


def _write_pose(numbers, pose):
    """Edits writing ``pose`` (4, 4) into ``p[x, y, z, rx, ry, rz]``: metres and a rotation vector, the one
    nearest the original (a turn of pi may be written either way)."""
    old = np.array([n.value for n in numbers[3:]])
    vector = pin.log3(pose[:3, :3])
    angle = np.linalg.norm(vector)
    if angle > 1e-9:  # v and v (1 - 2 pi / |v|) are the same rotation
        other = vector * (1.0 - 2.0 * np.pi / angle)
        if np.linalg.norm(other - old) < np.linalg.norm(vector - old):
            vector = other
    values = [*pose[:3, 3], *vector]
    return [e for e in (n.edit(v, 9) for n, v in zip(numbers, values)) if e]
