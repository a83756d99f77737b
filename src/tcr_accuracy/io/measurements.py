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

import csv
import io
import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..model.context import REFERENCE_TEMPERATURE_C, MeasurementContext
from ..exceptions import InputError
from ..input_files import SIZE_LIMITS, read_input_text
from .measurement_checks import MeasurementWarning, check_duplicates, check_position_units, warn_outside_limits
from ..model.robot import RobotModel
from ..units import JOINT_COLUMN_UNITS as _JOINT_UNITS
from ..units import JOINT_DISPLAY
from ..units import POSITION_UNITS as _POSITION_UNITS
from ..units import REVOLUTE, parse_number

#: Largest |quaternion norm - 1| accepted before normalising.
QUATERNION_TOLERANCE = 1e-3

QUATERNION_COLUMNS = ("qw", "qx", "qy", "qz")
CONTEXT_COLUMNS = ("payload_kg", "temperature_c", "time_s")
#: columns whose cells are labels, not numbers
LABEL_COLUMNS = ("session",)
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
#: Labels a pose or path test adds to a row (ISO 9283, ``iso9283 plan``): accepted, carried, not used by a fit.
ANNOTATION_COLUMNS = ("pose_id", "cycle", "approach", "load_pct", "speed_pct", "target_x_mm", "target_y_mm",
                      "target_z_mm", "path", "speed_mm_s", "s_mm")
#: The annotations that are names, not numbers (``P1``, ``S01.P1``, ``+x``, ``line``): kept as text.
TEXT_ANNOTATIONS = ("pose_id", "cycle", "approach", "path")
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
# Containers
# ---------------------------------------------------------------------------------------
@dataclass
class MeasurementSet:
    """Measurements of one robot, SI units.

    Attributes
    ----------
    joint_names : list of str
        Joint order of ``q`` (the robot's).
    q : ndarray of shape (N, n_joints)
        Commanded joint values [rad, m].
    position : ndarray of shape (N, 3)
        Measured TCP position in the measurement (tracker) frame [m].
    quaternion : ndarray of shape (N, 4) or None
        Measured TCP orientation (w, x, y, z), unit norm; None when not measured.
    payload_kg : ndarray of shape (N,) or None
        Payload [kg]; None when the file has no ``payload_kg`` column.
    temperature_c : ndarray of shape (N,) or None
        Temperature [degC]; None when the file has no ``temperature_c`` column.
    direction : ndarray of shape (N, n_joints) or None
        Approach directions +1/-1, 0 for joints without a ``<joint>_dir`` column;
        None when the file has no direction column at all.
    outside_q : ndarray of shape (N, n_outside) or None
        Values [rad, m] of the robot's joints that do not move the TCP
        (``robot.outside_joint_names``: another arm, a head), for the gravity torques;
        None when the file has none of their columns and no mimic rule sets them.
    annotations : dict of str to ndarray of shape (N,), or None
        The file's :data:`ANNOTATION_COLUMNS` by column name: the :data:`TEXT_ANNOTATIONS`
        as names (object arrays of str, a whole number as its digits: see
        :func:`canonical_label`), the others as numbers (the name carries the unit:
        ``target_x_mm``); None when it has none.
    source : str
        Where the rows came from (file path or a label).
    rows : ndarray of shape (N,)
        Row (line) number of each measurement in the source file.
    session : ndarray of shape (N,) of str, or None
        Session label of each row (one tracker frame each); None: one session.
    time_s : ndarray of shape (N,) or None
        Time of each measurement [s]; None when the file has no ``time_s`` column.
    """

    joint_names: list[str]
    q: np.ndarray
    position: np.ndarray
    quaternion: np.ndarray | None = None
    payload_kg: np.ndarray | None = None
    temperature_c: np.ndarray | None = None
    direction: np.ndarray | None = None
    source: str = "<memory>"
    rows: np.ndarray | None = None
    outside_q: np.ndarray | None = None
    session: np.ndarray | None = None
    time_s: np.ndarray | None = None
    annotations: dict | None = None

    def __post_init__(self) -> None:
        self.q = np.atleast_2d(np.asarray(self.q, dtype=float))
        self.position = np.atleast_2d(np.asarray(self.position, dtype=float))
        if self.rows is None:
            self.rows = np.arange(2, 2 + self.q.shape[0])

    def __len__(self) -> int:
        return self.q.shape[0]

    def __repr__(self) -> str:
        measured = [k for k in ("quaternion", "payload_kg", "temperature_c", "direction", "outside_q", "time_s")
                    if getattr(self, k) is not None]
        sessions = f", {len(self.session_labels)} sessions" if self.session is not None else ""
        source = self.source if len(self.source) <= 60 else self.source[:57] + "..."
        return (f"MeasurementSet({len(self)} rows x {self.q.shape[1]} joints, source={source!r}"
                f"{sessions}, context columns: {', '.join(measured) or 'none'})")

    @property
    def context(self) -> MeasurementContext:
        """The per-row context (payload, temperature, approach directions, other joints, session),
        with defaults where a column is absent: no payload, the reference temperature, no direction."""
        return self.make_context()

    def make_context(self, reference_temperature_c: float = REFERENCE_TEMPERATURE_C,
                     rng: np.random.Generator | None = None) -> MeasurementContext:
        """The per-row context with another reference temperature [degC] where the file has none,
        or a generator for the effects that draw random numbers (``rng``)."""
        n, nj = self.q.shape
        return MeasurementContext(
            payload_kg=self.payload_kg.copy() if self.payload_kg is not None else np.zeros(n),
            temperature_c=(self.temperature_c.copy() if self.temperature_c is not None
                           else np.full(n, float(reference_temperature_c))),
            direction=self.direction.copy() if self.direction is not None else np.zeros((n, nj)),
            rng=rng,
            outside_q=None if self.outside_q is None else self.outside_q.copy(),
            session=self.session_index(),
            time_s=None if self.time_s is None else np.asarray(self.time_s, dtype=float).copy(),
        )

    @property
    def session_labels(self) -> list[str]:
        """The sessions' labels in order of first appearance ([] without a session column)."""
        return [] if self.session is None else list(dict.fromkeys(self.session.tolist()))

    def session_index(self) -> np.ndarray | None:
        """(N,) int: each row's session, numbered in order of first appearance (None: one session)."""
        if self.session is None:
            return None
        number = {label: k for k, label in enumerate(self.session_labels)}
        return np.array([number[label] for label in self.session.tolist()], dtype=int)

    def subset(self, rows) -> "MeasurementSet":
        """The measurements of some rows (index array or boolean mask), e.g. a fold."""
        def pick(a):
            return None if a is None else a[rows]

        return replace(self, q=self.q[rows], position=self.position[rows],
                       quaternion=pick(self.quaternion), payload_kg=pick(self.payload_kg),
                       temperature_c=pick(self.temperature_c), direction=pick(self.direction),
                       rows=self.rows[rows], outside_q=pick(self.outside_q), session=pick(self.session),
                       time_s=pick(self.time_s),
                       annotations=None if self.annotations is None else
                       {k: v[rows] for k, v in self.annotations.items()})


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
    >>> measured = tcr.read_measurements("examples/measured.csv", robot)  # doctest: +SKIP
    >>> measured.context.payload_kg.shape  # doctest: +SKIP
    (200,)
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
    return lines, [h.strip() for h in next(csv.reader(io.StringIO(header_text)))], header_line


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
    values = np.empty((len(lines) - 1, n_cols))
    rows = np.empty(len(lines) - 1, dtype=int)
    label_columns = {c: name for c, name in enumerate(header) if name in LABEL_COLUMNS + TEXT_ANNOTATIONS}
    labels = {name: [] for name in label_columns.values()}
    codes = {name: {} for name in label_columns.values()}
    for k, (line_no, line) in enumerate(lines[1:]):
        cells = next(csv.reader(io.StringIO(line)))
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
        rows[k] = line_no
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


# ---------------------------------------------------------------------------------------
# Writing
# ---------------------------------------------------------------------------------------
def measurement_columns(robot: RobotModel, mset: MeasurementSet, unit: str = "mm") -> list[str]:
    """Header of the CSV :func:`format_measurements` writes."""
    if unit not in ("mm", "m"):
        raise InputError(f"unit {unit!r}: use 'mm' (deg, mm columns) or 'm' (rad, m columns)")
    joint_unit = {REVOLUTE: "deg" if unit == "mm" else "rad", "prismatic": unit}
    cols = [f"{n}_{joint_unit[k]}" for n, k in zip(robot.joint_names, robot.joint_kinds)]
    if mset.outside_q is not None:
        cols += [f"{n}_{joint_unit[k]}" for n, k in zip(robot.outside_joint_names, robot.outside_joint_kinds)]
    cols += [f"{a}_{unit}" for a in "xyz"]
    if mset.quaternion is not None:
        cols += list(QUATERNION_COLUMNS)
    if mset.payload_kg is not None:
        cols.append("payload_kg")
    if mset.temperature_c is not None:
        cols.append("temperature_c")
    if mset.direction is not None:
        cols += [f"{n}_dir" for j, n in enumerate(robot.joint_names) if np.any(mset.direction[:, j] != 0)]
    return cols + _annotation_columns(mset)


def _annotation_columns(mset: MeasurementSet) -> list[str]:
    return [c for c in ANNOTATION_COLUMNS if mset.annotations and c in mset.annotations]


def format_measurements(robot: RobotModel, mset: MeasurementSet, unit: str = "mm",
                        comment: str | None = None) -> str:
    """CSV text of a measurement set, joints in deg/mm (unit "mm") or rad/m (unit "m")."""
    cols = measurement_columns(robot, mset, unit)
    if list(mset.joint_names) != list(robot.joint_names):
        raise InputError(f"measurement set joints {mset.joint_names} are not the robot's {robot.joint_names}")
    factor = 1e3 if unit == "mm" else 1.0
    joint_scale = robot.display_scale if unit == "mm" else np.ones(robot.n_joints)
    blocks = [mset.q * joint_scale]
    if mset.outside_q is not None:
        outside_scale = (np.array([JOINT_DISPLAY[k][1] for k in robot.outside_joint_kinds]) if unit == "mm"
                         else np.ones(len(robot.outside_joint_names)))
        blocks.append(mset.outside_q * outside_scale)
    blocks.append(mset.position * factor)
    if mset.quaternion is not None:
        blocks.append(mset.quaternion)
    if mset.payload_kg is not None:
        blocks.append(mset.payload_kg[:, None])
    if mset.temperature_c is not None:
        blocks.append(mset.temperature_c[:, None])
    if mset.direction is not None:
        used = [j for j in range(robot.n_joints) if np.any(mset.direction[:, j] != 0)]
        blocks.append(mset.direction[:, used])
    labels = _annotation_columns(mset)
    numbers = [c for c in labels if c not in TEXT_ANNOTATIONS]
    table = np.concatenate(blocks + [np.stack([np.asarray(mset.annotations[c], dtype=float) for c in numbers], axis=1)]
                           if numbers else blocks, axis=1)
    if not np.all(np.isfinite(table)):
        raise InputError("measurement set has non-finite values; nothing written")
    names = [[_label_cell(mset.annotations[c][k]) if c in TEXT_ANNOTATIONS else None for c in labels]
             for k in range(len(table))]
    out = io.StringIO()
    if comment:
        for line in comment.splitlines():
            out.write(f"# {line}\n")
    out.write(",".join(cols) + "\n")
    n_values = len(cols) - len(labels) - sum(c.endswith("_dir") for c in cols)
    n_dirs = len(cols) - len(labels)
    for row, text in zip(table, names):
        cells = [format(v, ".12g") for v in row[:n_values]]
        cells += [f"{int(v):+d}" for v in row[n_values:n_dirs]]
        given = iter(format(v, ".12g") for v in row[n_dirs:])
        cells += [next(given) if name is None else name for name in text]
        out.write(",".join(cells) + "\n")
    return out.getvalue()


def _label_cell(value) -> str:
    """A text annotation as a CSV cell (quoted when it holds a comma or a quote)."""
    text = str(value)
    return f'"{text.replace(chr(34), chr(34) * 2)}"' if ("," in text or '"' in text) else text


def join_sessions(sets: list[MeasurementSet], labels: list[str]) -> MeasurementSet:
    """Several measurement sets of one robot as one, each its own session (its label, or
    ``<label>:<session>`` where a set has a session column already); columns one set has and
    another lacks take their defaults (no payload, the reference temperature, no direction)."""
    if len(sets) == 1:
        return sets[0]
    session = np.concatenate([np.array([f"{label}:{v}" for v in s.session], dtype=object) if s.session is not None
                              else np.full(len(s), label, dtype=object) for s, label in zip(sets, labels)])

    def joined(attr, fill):
        values = [getattr(s, attr) for s in sets]
        if all(v is None for v in values):
            return None
        return np.concatenate([v if v is not None else fill(s) for v, s in zip(values, sets)])

    nj = sets[0].q.shape[1]
    return MeasurementSet(
        joint_names=list(sets[0].joint_names), q=np.concatenate([s.q for s in sets]),
        position=np.concatenate([s.position for s in sets]),
        quaternion=joined("quaternion", lambda s: np.tile([1.0, 0.0, 0.0, 0.0], (len(s), 1))),
        payload_kg=joined("payload_kg", lambda s: np.zeros(len(s))),
        temperature_c=joined("temperature_c", lambda s: np.full(len(s), REFERENCE_TEMPERATURE_C)),
        direction=joined("direction", lambda s: np.zeros((len(s), nj))),
        source=", ".join(s.source for s in sets), rows=np.concatenate([s.rows for s in sets]),
        outside_q=joined("outside_q", lambda s: np.zeros((len(s), next(
            o.outside_q.shape[1] for o in sets if o.outside_q is not None)))),
        session=session, time_s=joined("time_s", lambda s: np.full(len(s), np.nan)),
    )


__all__ = [
    "ANNOTATION_COLUMNS", "MeasurementContext", "MeasurementSet", "MeasurementWarning", "REFERENCE_TEMPERATURE_C",
    "allowed_columns", "format_measurements", "join_sessions", "measured_frames", "measurement_columns",
    "parse_measurements", "read_measurements", "read_user_text",
]
