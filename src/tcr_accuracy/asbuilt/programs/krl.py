"""KUKA KRL: a ``.src`` and its ``.dat``, their ``PTP``/``LIN`` targets (and the spline ``SPTP``, ``SLIN``, ``SPL``).

A target is the motion's first argument: an aggregate written inline, or a variable declared in
either file (``DECL E6POS XP1={X ..., Y ..., Z ..., A ..., B ..., C ..., S ..., T ...}``, ``E6AXIS``,
``POS``, ``FRAME``, ``AXIS``) or assigned one. Lengths in mm, angles in deg; A, B, C are the ZYX Euler
angles ``R = Rz(A) Ry(B) Rx(C)``; external axes (E1..E6) are kept as they are. Status and Turn name
the branch (:mod:`.configuration`).

The tool and the base are those in force where the target is used, in the files' order: ``$TOOL`` /
``$BASE`` assigned an aggregate, ``TOOL_DATA[n]`` / ``BASE_DATA[n]`` (or ``BAS(#TOOL, n)``, an inline
form's ``FDAT`` with ``TOOL_NO``/``BASE_NO``) when the files assign that entry. A tool whose data are
not in the files (they live in ``$config.dat``) leaves the measured point as the TCP, said; a base
whose data are not there leaves its Cartesian targets unfiltered. Base 0 and ``$NULLFRAME`` are the
robot's base (``$WORLD`` = ``$ROBROOT``).

Not filtered, and listed: relative motions (``PTP_REL``, ``LIN_REL``), circles (``CIRC``, ``SCIRC``), a
partial aggregate (its missing components are the robot's current ones), an array element, and calls
of routines that are neither KRL's nor defined in the files.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...model.kinematics import euler_zyx, rotation_from_euler_zyx
from .grammar import elements, is_token, is_tree, number_of, parse, start_of, text_of
from .targets import Configuration, NumberText, ParsedProgram, ProgramTarget, line_column, set_joint_numbers

LANGUAGE = "KRL"

_BLOCKS = {  # opener -> (its rule, the words between, the closer)
    "def": ("DEF", (), "END"), "deffct": ("DEFFCT", (), "ENDFCT"), "defdat": ("DEFDAT", (), "ENDDAT"),
    "if": ("IF", ("ELSE",), "ENDIF"), "for": ("FOR", (), "ENDFOR"), "while": ("WHILE", (), "ENDWHILE"),
    "loop": ("LOOP", (), "ENDLOOP"), "repeat": ("REPEAT", (), "UNTIL"),
    "switch": ("SWITCH", ("CASE", "DEFAULT"), "ENDSWITCH"), "spline": ("SPLINE", (), "ENDSPLINE"),
    "ptp_spline": ("PTP_SPLINE", (), "ENDSPLINE"), "skip": ("SKIP", (), "ENDSKIP"),
}


def _grammar() -> str:
    rules, terminals = [], set()
    for rule, (opener, middles, closer) in _BLOCKS.items():
        mid = f" ({' | '.join(f'{m} atom* _NL+ _item*' for m in middles)})*" if middles else ""
        scope = "_GLOBAL? " if rule in ("def", "deffct") else ""
        rules.append(f"{rule}: {scope}{opener} atom* _NL+ _item*{mid} {closer} atom* _NL*")
        terminals |= {opener, closer, *middles}
    keywords = "\n".join(f"{t}.2: /{t.lower()}\\b/i" for t in sorted(terminals))
    return r"""
start: _NL* _item*
_item: statement | """ + " | ".join(_BLOCKS) + r"""
statement: _GLOBAL? atom+ _NL+
""" + "\n".join(rules) + r"""
?atom: NAME | NUMBER | STRING | BITS | ENUM | OP | brace | bracket | group
brace: "{" _inner "}"
bracket: "[" _inner "]"
group: "(" _inner ")"
_inner: (atom | _NL)*
""" + keywords + r"""
_GLOBAL.2: /global\b/i
NAME: /\$?[A-Za-z_][A-Za-z0-9_$]*/
NUMBER: /(\d+\.\d*|\.\d+|\d+)([eE][-+]?\d+)?/
STRING: /"[^"\n]*"/
BITS: /'[BbHh][0-9A-Fa-f]+'/
ENUM: /#[A-Za-z_][A-Za-z0-9_]*/
OP: /==|<>|<=|>=|[-+*\/<>=:,.%!?@^|~]/
COMMENT: /;[^\n]*/
HEADER: /&[^\n]*/
_NL: /\r?\n/
%ignore /[ \t\f]+/
%ignore COMMENT
%ignore HEADER
"""


GRAMMAR = _grammar()

#: Motions whose targets are filtered (pose or joint targets), and those listed as not filtered.
MOTIONS = ("ptp", "lin", "sptp", "slin", "spl")
OTHER_MOTIONS = ("ptp_rel", "lin_rel", "circ", "circ_rel", "scirc", "sptp_rel", "slin_rel", "scirc_rel", "spl_rel")
POSE_TYPES = ("e6pos", "pos", "frame")
JOINT_TYPES = ("e6axis", "axis")
POSE_KEYS = ("x", "y", "z", "a", "b", "c")
JOINT_KEYS = ("a1", "a2", "a3", "a4", "a5", "a6")
#: Statements KRL itself knows (their first word); anything else that is called is listed.
KNOWN = frozenset("""
decl global public const int real bool char frame pos e6pos axis e6axis signal enum struc wait halt return exit
goto continue interrupt trigger brake resume pulse anin anout on_error_proceeding err_raise bas then else case
default time_block const_vel ext extfct imp lin ptp circ sptp slin scirc spl ptp_rel lin_rel circ_rel initmov
""".split())


def parse_program(files: dict) -> ParsedProgram:
    """The motion targets of a KRL program: its ``.src`` and/or ``.dat`` (file name -> text)."""
    program = ParsedProgram(LANGUAGE, dict(files))
    trees = {}
    for name, text in files.items():
        trees[name] = parse(GRAMMAR, text if text.endswith("\n") else text + "\n", name, LANGUAGE)
        program.header[name] = (_after_header_lines(text), "; ")
    statements = [(name, s) for name, tree in trees.items() for s in _statements(tree)]
    declared, tool_data, base_data, fdat, routines = {}, {}, {}, {}, set()
    for name, s in statements:
        if is_tree(s, "def") or is_tree(s, "deffct"):
            words = [str(a) for a in s.children if is_token(a, "NAME")]
            if words:
                routines.add(words[-1].lower() if is_tree(s, "deffct") else words[0].lower())
        if not is_tree(s, "statement"):
            continue
        found = _declaration(s.children)
        if found is not None:
            kind, variable, brace = found
            declared.setdefault(variable, []).append((kind, brace, name))
            continue
        data = _data_entry(s.children)
        if data is not None:
            table, index, brace = data
            (tool_data if table == "tool_data" else base_data)[index] = (brace, name, files[name])
    for variable, found in declared.items():
        if found[0][0] == "fdat":
            fdat[variable] = _fdat(found[0][1])
    tool = base = None
    tool_note, base_note = "no tool selected in the files: the measured point is the TCP", ""
    base = np.eye(4)
    targets = {}
    order = [(n, s) for n, s in statements if Path(n).suffix.lower() != ".dat"] or statements
    for name, s in order:
        if not is_tree(s, "statement"):
            continue
        text = files[name]
        atoms = s.children
        first = atoms[0]
        word = str(first).lower() if is_token(first, "NAME") else ""
        line = first.line if is_token(first) else s.meta.line
        selected = _selection(atoms)
        if selected is not None:
            what, value = selected
            if what in ("tool", "base"):
                frame, note = _frame_of(value, what, tool_data if what == "tool" else base_data, files, name, line)
                if what == "tool":
                    tool, tool_note = frame, note
                else:
                    base, base_note = frame, note
            elif what == "fdat" and value in fdat:
                tool_no, base_no = fdat[value]
                if tool_no is not None:
                    tool, tool_note = _frame_of(tool_no, "tool", tool_data, files, name, line)
                if base_no is not None:
                    base, base_note = _frame_of(base_no, "base", base_data, files, name, line)
            continue
        if word in MOTIONS and len(atoms) >= 2:
            _motion(program, targets, word.upper(), atoms[1], declared, tool, tool_note, base, base_note, files, name)
            continue
        if word in OTHER_MOTIONS:
            program.unknown.append(f"{name}:{line}: {text_of(text, atoms)} (a {word.upper()}: not filtered)")
            continue
        if _is_assignment(atoms) or word in KNOWN or word.startswith("$"):
            continue
        if word and word not in routines:
            program.unknown.append(f"{name}:{line}: {text_of(text, atoms)} (not KRL's, nor a routine of the files: "
                                   "kept as written)")
    program.targets = list(targets.values())
    for variable, found in declared.items():
        kind = found[0][0]
        used = any(t.name.lower() == variable for t in program.targets)
        if (kind in POSE_TYPES or kind in JOINT_TYPES) and not used:
            where = found[0][2]
            line = found[0][1].meta.line
            program.notes.append(f"{where}:{line}: {variable.upper()} is used by no motion of the files: kept as "
                                 "written")
    return program


def _after_header_lines(text: str) -> int:
    """The offset after the leading ``&`` lines (which must stay first in a KRL file)."""
    offset = 0
    for line in text.splitlines(keepends=True):
        if not line.startswith("&"):
            break
        offset += len(line)
    return offset


def _statements(tree):
    for child in tree.children:
        if is_tree(child, "statement"):
            yield child
        elif hasattr(child, "data"):
            yield child
            yield from _statements(child)


def _words(atoms) -> list[str]:
    return [str(a).lower() for a in atoms if is_token(a, "NAME")]


def _declaration(atoms):
    """(type, variable, brace) of ``[DECL] [GLOBAL] TYPE name = {...}``, or None."""
    words = []
    for k, atom in enumerate(atoms):
        if is_token(atom, "OP", "="):
            if k + 2 == len(atoms) and is_tree(atoms[k + 1], "brace") and len(words) >= 2:
                return words[-2], words[-1], atoms[k + 1]
            if k + 2 == len(atoms) and is_tree(atoms[k + 1], "brace") and len(words) == 1:
                return "", words[0], atoms[k + 1]  # an assignment of an aggregate
            return None
        if not is_token(atom, "NAME"):
            return None
        word = str(atom).lower()
        if word not in ("decl", "global", "public", "const"):
            words.append(word)
    return None


def _data_entry(atoms):
    """('tool_data' or 'base_data', n, brace) of ``TOOL_DATA[n]={...}``, or None."""
    if len(atoms) == 4 and is_token(atoms[0], "NAME") and str(atoms[0]).lower() in ("tool_data", "base_data") \
            and is_tree(atoms[1], "bracket") and is_token(atoms[2], "OP", "=") and is_tree(atoms[3], "brace"):
        index = _integer(atoms[1].children)
        if index is not None:
            return str(atoms[0]).lower(), index, atoms[3]
    return None


def _integer(children):
    if len(children) == 1 and is_token(children[0], "NUMBER") and "." not in str(children[0]):
        return int(str(children[0]))
    return None


def _selection(atoms):
    """What a statement selects: ('tool' | 'base', an index, a brace or '$nullframe'), ('fdat', name), or None."""
    if len(atoms) >= 3 and is_token(atoms[0], "NAME") and is_token(atoms[1], "OP", "="):
        target = str(atoms[0]).lower()
        value = atoms[2:]
        if target in ("$tool", "$base"):
            what = target[1:]
            if len(value) == 1 and is_tree(value[0], "brace"):
                return what, value[0]
            if len(value) == 1 and is_token(value[0], "NAME") and str(value[0]).lower() == "$nullframe":
                return what, 0
            if len(value) == 2 and is_token(value[0], "NAME") and str(value[0]).lower() == f"{what}_data" \
                    and is_tree(value[1], "bracket"):
                index = _integer(value[1].children)
                return what, ("?" if index is None else index)
            return what, "?"
        if target == "fdat_act" and len(value) == 1 and is_token(value[0], "NAME"):
            return "fdat", str(value[0]).lower()
    if len(atoms) == 2 and is_token(atoms[0], "NAME") and str(atoms[0]).lower() == "bas" and is_tree(atoms[1], "group"):
        args = elements(atoms[1].children)
        if len(args) == 2 and len(args[0]) == 1 and is_token(args[0][0], "ENUM") and \
                str(args[0][0]).lower() in ("#tool", "#base"):
            index = _integer(args[1])
            return str(args[0][0]).lower()[1:], ("?" if index is None else index)
    return None


def _is_assignment(atoms) -> bool:
    """``name = ...``, ``name[...] = ...`` or ``name.field = ...``."""
    k = 1
    while k < len(atoms) and (is_tree(atoms[k], "bracket") or is_token(atoms[k], "OP", ".") or
                              (is_token(atoms[k], "NAME") and k >= 2 and is_token(atoms[k - 1], "OP", "."))):
        k += 1
    return is_token(atoms[0], "NAME") and k < len(atoms) and is_token(atoms[k], "OP", "=")


def _components(brace):
    """({component: NumberText or other}, type prefix or '') of an aggregate ``{[TYPE:] K v, ...}``."""
    children = list(brace.children)
    prefix = ""
    if len(children) >= 2 and is_token(children[0], "NAME") and is_token(children[1], "OP", ":"):
        prefix, children = str(children[0]).lower(), children[2:]
    out = {}
    for element in elements(children):
        if not element or not is_token(element[0], "NAME"):
            continue
        key = str(element[0]).lower()
        value = element[1:]
        number = number_of(value)
        if number is None and len(value) == 1 and is_token(value[0], "BITS"):
            text = str(value[0])
            base = 2 if text[1] in "Bb" else 16
            number = NumberText(value[0].start_pos, value[0].end_pos, float(int(text[2:-1], base)), text)
        out[key] = number if number is not None else value
    return out, prefix


def _fdat(brace):
    components, _ = _components(brace)

    def index(key):
        value = components.get(key)
        return int(value.value) if isinstance(value, NumberText) else None

    return index("tool_no"), index("base_no")


def _pose_of(components) -> np.ndarray:
    values = [components[k].value for k in POSE_KEYS]
    out = np.eye(4)
    out[:3, :3] = rotation_from_euler_zyx(np.radians(values[3:]))[0]
    out[:3, 3] = np.array(values[:3]) * 1e-3
    return out


def _frame_of(value, what: str, table: dict, files, name, line):
    """(frame (4, 4) or None, note) of a tool or base selected by an index or an aggregate."""
    if is_tree(value, "brace"):
        components, _ = _components(value)
        if not all(isinstance(components.get(k), NumberText) for k in POSE_KEYS):
            return None, f"the ${what.upper()} set at {name}:{line} is not six numbers"
        return _pose_of(components), f"the ${what.upper()} set at {name}:{line}"
    if value == 0:
        return np.eye(4), ""
    if value == "?" or value not in table:
        data = f"{what.upper()}_DATA[{value}]" if value != "?" else f"the ${what.upper()} set at {name}:{line}"
        if what == "tool":
            return None, f"{data} is not in the given files ($config.dat holds it): the measured point is the TCP"
        return None, f"{data} is not in the given files ($config.dat holds it): the frame of its targets is unknown"
    brace, where, _ = table[value]
    components, _ = _components(brace)
    if not all(isinstance(components.get(k), NumberText) for k in POSE_KEYS):
        return None, f"{what.upper()}_DATA[{value}] in {where} is not six numbers"
    return _pose_of(components), f"{what.upper()}_DATA[{value}] ({where})"


def _motion(program, targets, instruction, argument, declared, tool, tool_note, base, base_note, files, name):
    text = files[name]
    variable = ""
    if is_tree(argument, "brace"):
        brace, kind, where, source = argument, "", name, text
    elif is_token(argument, "NAME"):
        variable = str(argument).lower()
        found = declared.get(variable, [])
        if len(found) != 1:
            line, column = line_column(text, start_of(argument))
            key = (name, line, column)
            if key not in targets:
                why = "is declared or assigned more than once" if found else "is not declared in the given files"
                targets[key] = ProgramTarget(name, line, column, instruction, str(argument), "pose",
                                             problem=f"{argument} {why}")
            return
        kind, brace, where = found[0]
        source = files[where]
    else:
        line, column = line_column(text, start_of(argument))
        targets[(name, line, column)] = ProgramTarget(name, line, column, instruction, "", "pose",
                                                      problem=f"its target is no aggregate nor a variable "
                                                              f"({text_of(text, [argument])})")
        return
    key = id(brace)
    line, column = line_column(source, brace.meta.start_pos)
    components, prefix = _components(brace)
    kind = kind or prefix
    if not kind:
        kind = "e6axis" if any(k in components for k in JOINT_KEYS) else "e6pos"
    label = variable.upper()
    if key in targets:
        previous = targets[key]
        if not previous.problem and (previous.tool_note != tool_note or previous.frame_note != base_note):
            previous.problem = f"used with two tools or bases ({previous.tool_note or 'flange'}; {tool_note or 'flange'})"
        return
    target = ProgramTarget(where, line, column, instruction, label, "joints", tool=tool, tool_note=tool_note)
    targets[key] = target
    if kind in JOINT_TYPES:
        numbers = [components.get(k) for k in JOINT_KEYS]
        if not all(isinstance(n, NumberText) for n in numbers):
            target.problem = "a partial axis aggregate (its missing axes are the robot's current ones)"
            return
        set_joint_numbers(target, numbers, scale=np.pi / 180.0, decimals=7)
        return
    if kind not in POSE_TYPES:
        target.problem = f"a {kind.upper()} is not a motion target"
        return
    target.kind = "pose"
    numbers = [components.get(k) for k in POSE_KEYS]
    if not all(isinstance(n, NumberText) for n in numbers):
        target.problem = "a partial aggregate (its missing components are the robot's current ones)"
        return
    target.pose = _pose_of(components)
    target.frame, target.frame_note = base, base_note
    status, turn = components.get("s"), components.get("t")
    if isinstance(status, NumberText) and isinstance(turn, NumberText):
        target.configuration = Configuration("kuka", (int(status.value), int(turn.value)))
    target.write = lambda joints, pose, configuration: _write_pose(numbers, turn, pose, configuration)


def _write_pose(numbers, turn, pose, configuration):
    """Edits writing ``pose`` (4, 4) as X, Y, Z [mm] and the ZYX Euler angles A, B, C [deg] nearest the
    original (each pose has two), and the Turn the corrected joints have, in the original's notation."""
    old = np.array([n.value for n in numbers[3:]])
    a, b, c = np.degrees(euler_zyx(pose[None, :3, :3])[0])
    candidates = [np.array([a, b, c]), np.array([a + 180.0, 180.0 - b, c + 180.0])]
    angles = min((_nearest_turn(v, old) for v in candidates), key=lambda v: float(np.abs(v - old).sum()))
    values = [*(pose[:3, 3] * 1e3), *angles]
    edits = [e for e in (n.edit(v, 6 if k < 3 else 7) for k, (n, v) in enumerate(zip(numbers, values))) if e]
    if configuration is not None and turn is not None and int(configuration.values[1]) != int(turn.value):
        edits.append((turn.start, turn.end, _bits_like(turn.text, int(configuration.values[1]))))
    return edits


def _nearest_turn(angles: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Each angle [deg] moved by whole turns to lie nearest the reference's."""
    return angles + 360.0 * np.round((reference - angles) / 360.0)


def _bits_like(original: str, value: int) -> str:
    """``value`` written as the original was: 'B..' binary (as many digits), 'H..' hex, or decimal."""
    if original.startswith("'") and original[1] in "Bb":
        return f"'{original[1]}{value:0{len(original) - 3}b}'"
    if original.startswith("'") and original[1] in "Hh":
        return f"'{original[1]}{value:X}'"
    return str(value)
