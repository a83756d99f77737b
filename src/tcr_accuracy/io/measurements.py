"""Measurement CSV: commanded joint values, measured TCP position (and orientation), context.

One row per measurement. Columns (header names, any order):

==========================  ===============================================================
column                      meaning
==========================  ===============================================================
``<joint>_deg|_rad``        commanded value of a revolute joint (every joint of the chain)
``<joint>_mm|_m``           commanded value of a prismatic joint
``x_mm, y_mm, z_mm``        measured TCP position in the tracker frame (or ``x_m, y_m, z_m``)
``qw, qx, qy, qz``          optional measured TCP orientation (unit quaternion, all four)
``payload_kg``              optional payload at the TCP [kg] (absent: 0)
``temperature_c``           optional temperature of the arm [degC] (absent: reference, 20)
``<joint>_dir``             optional approach direction of a joint: +1 or -1
``session``                 optional label of the measurement session (tracker station,
                            day) a row belongs to: each session has its own tracker frame
``time_s``                  optional time of the measurement [s] (any origin): the time
                            axis of the tracker's drift seen by base references
``pose_id``, ``cycle``,     optional labels of a pose test (``tcr-accuracy iso9283 plan``
``approach``,               writes them): which commanded pose, which cycle, which
``load_pct``,               approach direction (names or numbers: ``P1``, ``S01.P1``, ``+x``),
``speed_pct``,              the test condition (% of the rated load and speed), the
``target_x_mm`` ...         commanded TCP in the base frame [mm]; of a commanded path
``path``, ``speed_mm_s``,   (``iso9283 plan --path``): which path, its speed [mm/s] and the
``s_mm``                    arc length of the point [mm];
                            carried through (:attr:`MeasurementSet.annotations`), ignored
                            by every analysis but ``iso9283 evaluate``
==========================  ===============================================================

Lines starting with ``#`` are comments. Row numbers in messages are the file's line
numbers, as a spreadsheet shows them (the header is row 1 when there is no comment).
Everything read is converted to SI at once; :class:`MeasurementSet` holds SI only.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..model.context import REFERENCE_TEMPERATURE_C, MeasurementContext
from ..exceptions import InputError
from ..input_files import SIZE_LIMITS, csv_cells, read_input_text
from .measurement_checks import (MeasurementWarning, check_duplicates, check_position_units, warn_constant_time,
                                 warn_outside_limits)
from .measurement_set import (ANNOTATION_COLUMNS, CONTEXT_COLUMNS, LABEL_COLUMNS, QUATERNION_COLUMNS,
                              TEXT_ANNOTATIONS, MeasurementSet, join_sessions)
# the CSV's writer, named here too for the callers that read and write it
from .measurement_text import format_measurements, measurement_columns
from ..model.robot import RobotModel
from ..units import JOINT_COLUMN_UNITS as _JOINT_UNITS
from ..units import POSITION_UNITS as _POSITION_UNITS
from ..units import REVOLUTE, parse_number_table, parse_number

#: Largest |quaternion norm - 1| accepted before normalising.
QUATERNION_TOLERANCE = 1e-3

#: The largest magnitudes a measurement CSV's values may have, as the settings files' are bounded:
#: beyond them a value is a typo (1e300 overflowed the analyses into a silent 'frames only').
MAX_JOINT_SI = 1e4          # [rad] or [m]: the URDF's own bound on angles and lengths
MAX_POSITION_M = 1e3        # [m]: a tracker sees a kilometre at most
MAX_PAYLOAD_KG = 1e6
MAX_TEMPERATURE_C = 1e3     # an arm at 1000 degC has melted
MAX_TIME_S = 1e11           # [s]: a Unix time stamp is 1.8e9


def _check_range(source, rows, column: str, values_si, bound: float, si_unit: str, to_shown: float,
                 shown_unit: str) -> None:
    """Refuse the first value of ``column`` whose magnitude exceeds ``bound`` (SI), in the file's unit."""
    bad = np.flatnonzero(np.abs(values_si) > bound)
    if len(bad):
        r = bad[0]
        raise InputError(f"{source}: row {rows[r]}, column {column}: {values_si[r] * to_shown:g} {shown_unit} is "
                         f"beyond the {bound * to_shown:g} {shown_unit} a measurement may have")
#: A label written as a whole number within this magnitude is that integer's digits ("1.0" -> "1").
_EXACT_INTEGER = 2.0 ** 53


def number_cell(cell: str, source: str, row: int, column: str) -> float:
    """A CSV cell (stripped) as a finite number, or InputError naming the file, row and column.
    Strict: ``1_5`` and full-width digits are no numbers."""
    try:
        value = parse_number(cell, finite=False)
    except ValueError:
        what = "an empty cell" if not cell else f"{cell!r} is not a number"
        raise InputError(f"{source}: row {row}, column {column}: {what}") from None
    if not math.isfinite(value):
        raise InputError(f"{source}: row {row}, column {column}: non-finite value {cell!r}")
    return value


def label_cell(cell: str, source: str, row: int, column: str, what: str = "label", canonical: bool = True) -> str:
    """A CSV cell (stripped) as a label: printable ASCII, not empty (else InputError naming the file, row
    and column), a whole number written as its digits when ``canonical`` (:func:`canonical_label`)."""
    if not cell or not cell.isprintable() or not cell.isascii():
        raise InputError(f"{source}: row {row}, column {column}: a {what} must be printable ASCII, got {cell!r}")
    return canonical_label(cell) if canonical else cell


def canonical_label(cell: str) -> str:
    """A label cell as a name: a whole number is written as its digits (``1.0``, ``+1`` and ``1``
    name one pose), any other text is kept as written.

    Parameters
    ----------
    cell : str
        The cell, stripped.

    Returns
    -------
    str
    """
    try:
        value = parse_number(cell)
    except ValueError:
        return cell
    if value == int(value) and abs(value) < _EXACT_INTEGER:
        return str(int(value))
    return cell


# ---------------------------------------------------------------------------------------
# Reading
# ---------------------------------------------------------------------------------------
def _all_joints(robot: RobotModel) -> list[tuple[str, str]]:
    """(name, kind) of every joint a row may give: the chain's, then those outside it."""
    return (list(zip(robot.joint_names, robot.joint_kinds))
            + list(zip(robot.outside_joint_names, robot.outside_joint_kinds)))


def allowed_columns(robot: RobotModel) -> list[str]:
    """Every column name a measurement file for this robot may have.

    Columns of joints that do not move the TCP (another arm, a head) are allowed: a joint
    log has every joint, and their masses load the chain (gravity torques).
    """
    cols = []
    for name, kind in _all_joints(robot):
        cols += [f"{name}_{u}" for u in _JOINT_UNITS[kind]]
    cols += [f"{a}_{u}" for u in _POSITION_UNITS for a in "xyz"]
    cols += list(QUATERNION_COLUMNS) + list(CONTEXT_COLUMNS) + list(LABEL_COLUMNS)
    cols += [f"{name}_dir" for name, _ in _all_joints(robot)]
    return cols + list(ANNOTATION_COLUMNS)


def read_measurements(path: str | Path, robot: RobotModel, *, min_rows: int = 1,
                      require_position: bool = True, check_units: bool = True,
                      frame: str | None = None, repeats_allowed: bool = False) -> MeasurementSet:
    """Read and validate a measurement CSV (see the module docstring for the columns).

    Parameters
    ----------
    path : str or Path
    robot : RobotModel
        Names the joint columns and gives the nominal kinematics for the unit check.
    min_rows : int
        Fewest measurements the caller needs (e.g. the number of parameters to fit).
    require_position : bool
        False to read a pose list (joint columns and context only), e.g. ``simulate --poses``.
    check_units : bool
        Compare the spread of the measured positions with that of the nominal model's
        TCP at the same joint values, to catch a file in metres labelled mm (or the
        reverse) and joint values in the wrong unit.
    frame : str, optional
        For a file measuring several frames per row (``<frame>.x_mm`` ... columns, see
        :func:`measured_frames`): the one to read; the robot's TCP must be that frame.
    repeats_allowed : bool
        Rows may repeat one another (poses to predict or compensate); otherwise an exact copy
        of a row is an error and a repeated pose a warning.

    Returns
    -------
    MeasurementSet
        The rows in SI units, with the context columns the file has.

    Raises
    ------
    InputError
        Naming the file, row and column at fault.

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot()
    >>> measured = tcr.read_measurements("examples/measured.csv", robot)
    >>> measured.q.shape, measured.context.payload_kg.shape  # [rad, m], [kg]
    ((200, 6), (200,))
    """
    path = Path(path)
    text = read_user_text(path, "measurement file")
    return parse_measurements(text, robot, source=str(path), min_rows=min_rows,
                              require_position=require_position, check_units=check_units, frame=frame,
                              repeats_allowed=repeats_allowed)


def read_user_text(path: Path, what: str) -> str:
    """A user's UTF-8 table (a byte-order mark is dropped), or one InputError line: through the
    package's one opener (:func:`tcr_accuracy.input_files.read_input_text`: a regular file of at
    most the size bound of a table)."""
    return read_input_text(path, what, limit=SIZE_LIMITS["table"])


#: Column suffixes a measured frame's columns carry after ``<frame>.``
FRAME_COLUMNS = tuple(f"{a}_{u}" for u in _POSITION_UNITS for a in "xyz") + QUATERNION_COLUMNS


def _frame_of(column: str) -> str | None:
    """``right_marker.x_mm`` -> ``right_marker``; None for any other column."""
    prefix, dot, rest = column.rpartition(".")
    return prefix if dot and prefix and rest in FRAME_COLUMNS else None


def _header(text: str, source: str) -> tuple[list[tuple[int, str]], list[str], int]:
    lines = [(i + 1, line) for i, line in enumerate(text.splitlines())
             if line.strip() and not line.lstrip().startswith("#")]
    if not lines:
        raise InputError(f"{source}: empty measurement file (no header row)")
    header_line, header_text = lines[0]
    if ";" in header_text and "," not in header_text:
        raise InputError(f"{source}: row {header_line}: columns are separated by ';'; "
                         "a measurement CSV uses commas (and '.' for decimals)")
    return lines, [h.strip() for h in csv_cells(header_text, source, header_line)], header_line


def measured_frames(path: str | Path) -> list[str]:
    """Frames a measurement file measures as ``<frame>.x_mm ...`` columns (empty: the TCP's ``x_mm``)."""
    text = read_user_text(Path(path), "measurement file")
    _, header, _ = _header(text, str(path))
    return list(dict.fromkeys(f for f in map(_frame_of, header) if f is not None))


def parse_measurements(text: str, robot: RobotModel, *, source: str = "<text>", min_rows: int = 1,
                       require_position: bool = True, check_units: bool = True,
                       frame: str | None = None, repeats_allowed: bool = False) -> MeasurementSet:
    """:func:`read_measurements` on CSV text already in memory."""
    lines, header, header_line = _header(text, source)
    # a file may measure several frames per row: <frame>.x_mm ...; read one of them
    frames = list(dict.fromkeys(f for f in map(_frame_of, header) if f is not None))
    if frames:
        plain = [h for h in header if h in FRAME_COLUMNS]
        if plain:
            raise InputError(f"{source}: row {header_line}: column {plain[0]} next to per-frame columns "
                             f"({frames[0]}.x_mm ...); name every measured frame's columns <frame>.x_mm")
        if frame is None and robot.tool_frame in frames:  # the robot's TCP is a measured frame (--tool): read it
            frame = robot.tool_frame
        if frame is None and len(frames) > 1:
            raise InputError(f"{source}: measures several frames ({', '.join(frames)}); choose the one to read "
                             f"with tool=FRAME (only diagnose reads them together)", parameter="tool")
        if frame is None:
            raise InputError(f"{source}: columns {frames[0]}.x_mm ...: measures frame {frames[0]}, not the robot's "
                             f"TCP frame {robot.tool_frame}; give tool={frames[0]}", parameter="tool",
                             value=robot.tool_frame)
        if frame not in frames:
            raise InputError(f"{source}: no columns {frame}.x_mm ... (frames measured: {', '.join(frames)})")
    logical = [h if _frame_of(h) is None else (h.rpartition(".")[2] if _frame_of(h) == frame else "")
               for h in header]
    columns = _resolve_columns(header, robot, source, header_line, require_position, logical)
    shown, header = header, logical  # messages name the file's columns; the reading uses their meaning

    n_cols = len(header)
    label_columns = {c: name for c, name in enumerate(header) if name in LABEL_COLUMNS + TEXT_ANNOTATIONS}
    values, rows, labels = _cells(lines, source, shown, label_columns)
    if len(rows) < min_rows:
        raise InputError(f"{source}: {len(rows)} measurement rows, at least {min_rows} are needed")

    def column(name):
        return values[:, header.index(name)]

    # joints: the chain's into q, the others into outside_q (gravity only); a joint
    # without a column but with a URDF <mimic> rule follows its source joint
    si: dict[str, np.ndarray] = {}
    kinds = dict(_all_joints(robot))
    for name, col, unit in columns["joints"] + [(n, c, u) for _, n, c, u in columns["outside"]]:
        if col is None:
            continue
        raw = column(col)
        if kinds[name] == REVOLUTE and unit == "rad":
            bad = np.flatnonzero(np.abs(raw) > 2 * math.pi + 1e-9)
            if len(bad) and (name not in robot.joint_names
                             or np.isfinite(robot.lower_limits[robot.joint_names.index(name)])):
                r = bad[0]
                raise InputError(
                    f"{source}: row {rows[r]}, column {col}: {raw[r]:g} rad is more than a full turn; "
                    f"if the column holds degrees, name it {name}_deg"
                )
        si[name] = raw * _JOINT_UNITS[kinds[name]][unit]
        _check_range(source, rows, col, si[name], MAX_JOINT_SI, "m" if kinds[name] != REVOLUTE else "rad",
                     1.0 / _JOINT_UNITS[kinds[name]][unit], unit)
    for name in [n for n, _ in _all_joints(robot) if n not in si and n in robot.mimic]:
        rule = robot.mimic[name]
        if rule.joint in si:
            si[name] = rule.multiplier * si[rule.joint] + rule.offset
    q = np.stack([si[name] for name in robot.joint_names], axis=1)
    warn_outside_limits(robot, q, rows, columns["joints"], source)
    outside_q = None
    if any(name in si for name in robot.outside_joint_names):
        outside_q = np.stack([si.get(name, np.zeros(len(rows))) for name in robot.outside_joint_names], axis=1)

    position = None
    if columns["position"] is not None:
        cols, unit = columns["position"]
        position = np.stack([column(c) for c in cols], axis=1) * _POSITION_UNITS[unit]
        for k, c in enumerate(cols):
            _check_range(source, rows, c, position[:, k], MAX_POSITION_M, "m", 1.0 / _POSITION_UNITS[unit], unit)
    quaternion = None
    if columns["quaternion"]:
        quaternion = np.stack([column(c) for c in QUATERNION_COLUMNS], axis=1)
        norms = np.linalg.norm(quaternion, axis=1)
        bad = np.flatnonzero(np.abs(norms - 1.0) > QUATERNION_TOLERANCE)
        if len(bad):
            r = bad[0]
            raise InputError(
                f"{source}: row {rows[r]}, columns qw,qx,qy,qz: quaternion norm is {norms[r]:.6g}, "
                f"not 1 (within {QUATERNION_TOLERANCE:g})"
            )
        quaternion = quaternion / norms[:, None]
    payload = column("payload_kg") if "payload_kg" in header else None
    if payload is not None:
        _check_range(source, rows, "payload_kg", np.maximum(payload, 0.0), MAX_PAYLOAD_KG, "kg", 1.0, "kg")
    if "temperature_c" in header:
        _check_range(source, rows, "temperature_c", np.maximum(column("temperature_c"), 0.0), MAX_TEMPERATURE_C,
                     "degC", 1.0, "degC")
    if payload is not None and (payload < 0).any():
        r = int(np.argmax(payload < 0))
        raise InputError(f"{source}: row {rows[r]}, column payload_kg: negative payload {payload[r]:g} kg")
    temperature = column("temperature_c") if "temperature_c" in header else None
    if temperature is not None and (temperature < -273.15).any():
        r = int(np.argmax(temperature < -273.15))
        raise InputError(f"{source}: row {rows[r]}, column temperature_c: {temperature[r]:g} degC is below "
                         "absolute zero")
    direction = None
    if columns["directions"]:
        direction = np.zeros((len(rows), robot.n_joints))
        for j, col in columns["directions"]:
            raw = column(col)
            bad = np.flatnonzero((raw != 1.0) & (raw != -1.0))
            if len(bad):
                r = bad[0]
                raise InputError(f"{source}: row {rows[r]}, column {col}: approach direction must be "
                                 f"+1 or -1, got {raw[r]:g}")
            direction[:, j] = raw

    time_s = column("time_s") if "time_s" in header else None
    if time_s is not None:
        _check_range(source, rows, "time_s", time_s, MAX_TIME_S, "s", 1.0, "s")
        if not repeats_allowed:  # measurements, whose time the drift reads
            warn_constant_time(time_s, rows, source)
    session = np.array(labels["session"], dtype=object) if "session" in labels else None
    annotations = {name: np.array(labels[name], dtype=object) if name in TEXT_ANNOTATIONS else column(name)
                   for name in ANNOTATION_COLUMNS if name in header} or None
    mset = MeasurementSet(
        joint_names=list(robot.joint_names), q=q,
        position=position if position is not None else np.full((len(rows), 3), np.nan),
        quaternion=quaternion, payload_kg=payload, temperature_c=temperature, direction=direction,
        source=source, rows=rows, outside_q=outside_q, session=session, time_s=time_s, annotations=annotations,
    )
    if not repeats_allowed:  # measurements, not poses to predict or compensate (asked twice legitimately)
        check_duplicates(mset, values, header, source, CONTEXT_COLUMNS)
    if check_units and position is not None:
        check_position_units(mset, robot, columns, source)
    return mset


def _cells(lines, source: str, shown: list, label_columns: dict) -> tuple[np.ndarray, np.ndarray, dict]:
    """The body's cells: (values (n_rows, n_cols) [as written], the rows' line numbers (n_rows,), the label
    columns' labels by name). A label column's value is 0 (a session) or its label's index (a text
    annotation, so that rows differing only in it differ).

    Numbers only (no label column): read whole (:func:`~tcr_accuracy.units.parse_number_table`,
    which takes no text the csv module would read otherwise: no quote, no NUL). Otherwise, or where
    that finds a line of the wrong length or a cell that is no finite number, the lines are read one
    cell at a time, whose messages name the file, row and column of the first bad cell."""
    body = lines[1:]
    n_cols = len(shown)
    rows = np.array([line_no for line_no, _ in body], dtype=int)
    values = None if label_columns else parse_number_table([line for _, line in body], n_cols)
    if values is not None:
        return values, rows, {}
    values = np.empty((len(body), n_cols))
    labels = {name: [] for name in label_columns.values()}
    codes = {name: {} for name in label_columns.values()}
    for k, (line_no, line) in enumerate(body):
        cells = csv_cells(line, source, line_no)
        if len(cells) != n_cols:
            raise InputError(f"{source}: row {line_no}: {len(cells)} cells, the header has {n_cols} columns")
        for c, cell in enumerate(cells):
            cell = cell.strip()
            if c in label_columns:
                name = label_columns[c]
                if name in LABEL_COLUMNS:
                    labels[name].append(label_cell(cell, source, line_no, shown[c], "session label", canonical=False))
                    values[k, c] = 0.0
                    continue
                labels[name].append(label_cell(cell, source, line_no, shown[c]))
                # a text annotation's number: its label's index, so that rows differing only in it differ
                values[k, c] = float(codes[name].setdefault(labels[name][-1], len(codes[name])))
                continue
            values[k, c] = number_cell(cell, source, line_no, shown[c])
    return values, rows, labels


def _resolve_columns(header, robot, source, line_no, require_position, logical):
    allowed = allowed_columns(robot)
    seen = set()
    for c, (name, meaning) in enumerate(zip(header, logical)):
        if not name:
            raise InputError(f"{source}: row {line_no}, column {c + 1}: empty column name in the header")
        if name in seen:
            raise InputError(f"{source}: row {line_no}: column {name} appears twice in the header")
        if not meaning:  # another measured frame's column: read and checked, not used here
            continue
        seen.add(meaning)
        name = meaning
        if name not in allowed:
            raise InputError(f"{source}: row {line_no}: unknown column {name!r}; allowed columns for "
                             f"{robot.name}: {', '.join(allowed)}")
    def given(name, kind):
        present = [u for u in _JOINT_UNITS[kind] if f"{name}_{u}" in seen]
        if len(present) > 1:
            raise InputError(f"{source}: row {line_no}: joint {name} is given twice "
                             f"({', '.join(f'{name}_{u}' for u in present)}); keep one")
        return present[0] if present else None

    units_given = {name: given(name, kind) for name, kind in _all_joints(robot)}
    joints = []
    for name, kind in zip(robot.joint_names, robot.joint_kinds):
        unit = units_given[name]
        if unit is None:
            rule = robot.mimic.get(name)
            if rule is not None and units_given.get(rule.joint) is not None:
                joints.append((name, None, None))  # follows its <mimic> source
                continue
            options = " or ".join(f"{name}_{u}" for u in _JOINT_UNITS[kind])
            hint = f" (its <mimic> source {rule.joint} has no column either)" if rule is not None else ""
            raise InputError(f"{source}: row {line_no}: missing joint column {options} "
                             f"({kind} joint {name}){hint}")
        joints.append((name, f"{name}_{unit}", unit))
    outside = [(k, name, f"{name}_{units_given[name]}", units_given[name])
               for k, name in enumerate(robot.outside_joint_names) if units_given[name] is not None]
    position = None
    units = [u for u in _POSITION_UNITS if any(f"{a}_{u}" in seen for a in "xyz")]
    if len(units) > 1:
        mixed = [f"{a}_{u}" for a in "xyz" for u in units if f"{a}_{u}" in seen]
        raise InputError(f"{source}: row {line_no}: position columns mix units ({', '.join(mixed)}); use one unit")
    if units:
        missing = [f"{a}_{units[0]}" for a in "xyz" if f"{a}_{units[0]}" not in seen]
        if missing:
            raise InputError(f"{source}: row {line_no}: missing position column {', '.join(missing)}")
        position = ([f"{a}_{units[0]}" for a in "xyz"], units[0])
    elif require_position:
        raise InputError(f"{source}: row {line_no}: missing position columns x_mm, y_mm, z_mm (or x_m, y_m, z_m)")
    quats = [c for c in QUATERNION_COLUMNS if c in seen]
    if quats and len(quats) != 4:
        missing = [c for c in QUATERNION_COLUMNS if c not in seen]
        raise InputError(f"{source}: row {line_no}: orientation needs all of qw, qx, qy, qz; "
                         f"missing {', '.join(missing)}")
    # directions of joints outside the chain are allowed (a joint log has them) and not used
    directions = [(j, f"{name}_dir") for j, name in enumerate(robot.joint_names) if f"{name}_dir" in seen]
    return {"joints": joints, "outside": outside, "position": position, "quaternion": bool(quats),
            "directions": directions}


__all__ = [
    "ANNOTATION_COLUMNS", "MeasurementContext", "MeasurementSet", "MeasurementWarning", "REFERENCE_TEMPERATURE_C",
    "allowed_columns", "format_measurements", "join_sessions", "measured_frames", "measurement_columns",
    "parse_measurements", "read_measurements", "read_user_text",
]
