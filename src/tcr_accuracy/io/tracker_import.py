"""Tracker exports and joint logs in, the measurement CSV out (``tcr-accuracy import``).

A laser tracker (Leica, FARO, API) or a motion-capture system (Vicon) exports its points
as delimited text in its own dialect: semicolons or tabs, decimal commas, a few lines of
metadata above the header, the unit in the header (``X [mm]``, ``Y (m)``, ``Z_in``) or in
each cell (``1234,56 mm``), a timestamp per point. The robot controller logs its joints
with timestamps of its own. This module reads both, maps their columns onto the
measurement CSV's (:mod:`tcr_accuracy.io.measurements`), and joins each tracker point to
the joint-log sample nearest in time, within a tolerance. Points without a sample that
close are returned, never dropped silently.

Column maps name the target column (a measurement-CSV column with its unit, or ``time_s``
for the timestamp) and the source column as the file's header spells it::

    {"x_mm": "Point X", "y_mm": "Point Y", "z_mm": "Point Z", "time_s": "Timestamp"}

Without a map, columns named like the targets pass through, and the tracker's position and
time columns are found by their names (``X``, ``Point X``, ``X [mm]``, ``time``,
``timestamp``, ...). A value's unit, when the header or cell gives one, is converted to the
target's; without one, the value is taken in the target's unit. Timestamps are seconds, or
dates and times of day (``2026-11-23 10:15:02,125``, ``10:15:02.125``): both files must use
the same kind.
"""

from __future__ import annotations

import bisect
import math
import re
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path

from ..exceptions import InputError
from ..units import IMPORT_UNITS, parse_number

TIME = "time_s"
#: Header names (lower case, unit removed) taken as the timestamp column when no map names it.
TIME_NAMES = ("time_s", "time", "t", "timestamp", "stamp", "date/time", "datetime", "zeit", "t_s")
AXES = ("x", "y", "z")
_UNIT_IN_HEADER = re.compile(r"^(?P<base>.*?)\s*(?:\[(?P<b>[^\]]+)\]|\((?P<p>[^)]+)\)|/\s*(?P<s>\w+))\s*$")
_NUMBER = re.compile(r"^(?P<number>[+-]?(?:\d+(?:[.,]\d*)?|[.,]\d+)(?:[eE][+-]?\d+)?)\s*(?P<unit>[A-Za-z]+)?$",
                     re.ASCII)
_TIME_OF_DAY = re.compile(r"^(?P<h>\d{1,2}):(?P<m>\d{2}):(?P<s>\d{2}(?:[.,]\d+)?)$", re.ASCII)
#: Units a timestamp column's header may name ('Time [ms]', 'time_us'), as factors to seconds.
TIME_UNITS = {"s": 1.0, "sec": 1.0, "ms": 1e-3, "us": 1e-6, "\u00b5s": 1e-6, "ns": 1e-9, "min": 60.0, "h": 3600.0}
DAY_S = 86400.0


@dataclass
class Table:
    """A delimited file as read: header cells, data rows (cells as text) and their line numbers."""

    path: Path
    header: list[str]
    rows: list[list[str]]
    lines: list[int]
    delimiter: str
    decimal_comma: bool

    def column(self, name: str) -> int:
        try:
            return self.header.index(name)
        except ValueError:
            raise InputError(f"{self.path}: no column {name!r} (the header has: "
                             f"{', '.join(repr(h) for h in self.header)})") from None


@dataclass
class Unjoined:
    """A tracker point with no joint-log sample within the tolerance."""

    line: int            # its line in the tracker file
    time: str            # its timestamp as written
    nearest_s: float     # the time to the nearest joint-log sample [s] (inf: the log is empty)


@dataclass
class ImportResult:
    """The measurement CSV's columns and rows (display units, as text), and what was left out."""

    columns: list[str]
    rows: list[list[str]] = field(default_factory=list)
    unjoined: list[Unjoined] = field(default_factory=list)
    n_tracker_rows: int = 0
    tracker: Table | None = None
    log: Table | None = None

    def csv_text(self, comment: str | None = None) -> str:
        lines = [f"# {line}" for line in (comment or "").splitlines()]
        lines.append(",".join(self.columns))
        lines += [",".join(row) for row in self.rows]
        return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------------------
# Reading delimited text
# ---------------------------------------------------------------------------------------
#: The most cells a line of a tracker export or joint log may have (an export has tens of columns;
#: a line of 80 million one-character cells took gigabytes and minutes before its header was found).
MAX_COLUMNS = 10_000


def _split(line: str, delimiter: str, source, row: int) -> list[str]:
    from ..input_files import csv_cells

    if line.count(delimiter) >= MAX_COLUMNS:  # counted before the line is split
        raise InputError(f"{source}: row {row}: {line.count(delimiter) + 1} cells; a tracker export or joint log has "
                         f"at most {MAX_COLUMNS} columns")
    return [cell.strip() for cell in csv_cells(line, source, row, delimiter)]


def _normal(name: str) -> str:
    """A header name without its unit, in lower case: 'Point X [mm]', 'point_x_mm' -> 'point x'."""
    match = _UNIT_IN_HEADER.match(name.strip())
    base = match["base"] if match else name.strip()
    head, _, suffix = base.rpartition("_")
    if match is None and head and suffix.lower() in IMPORT_UNITS:
        base = head
    return " ".join(base.replace("_", " ").split()).lower()


def header_unit(name: str) -> str | None:
    """The unit a header names: 'X [mm]', 'X (m)', 'X / in', 'x_mm' -> 'mm', 'm', 'in', 'mm'."""
    match = _UNIT_IN_HEADER.match(name.strip())
    if match:
        unit = (match["b"] or match["p"] or match["s"]).strip().lower()
        return unit if unit in IMPORT_UNITS else None
    base, _, suffix = name.strip().rpartition("_")
    return suffix.lower() if base and suffix.lower() in IMPORT_UNITS else None


def _decode(data: bytes) -> str:
    """A file's text: UTF-16 with its byte-order mark (Windows tools export it), UTF-8 (with or
    without a mark), else latin-1 (older exports)."""
    if data.startswith((b"\xff\xfe", b"\xfe\xff")):
        try:
            return data.decode("utf-16")
        except UnicodeDecodeError:
            pass
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        return data.decode("latin-1")


def read_table(path, wanted: list[str] | None = None, *, header_test=None) -> Table:
    """Read a delimited file whose header is the first line that names every ``wanted``
    column (or passes ``header_test(cells)``); lines above it (an export's metadata),
    empty lines and lines starting with ``#`` are skipped.

    The delimiter is the header's ``;``, tab or ``,`` (in that order of preference); decimal
    commas are recognised when the delimiter is not a comma.
    """
    path = Path(path)
    from ..input_files import SIZE_LIMITS, read_input_bytes

    text = _decode(read_input_bytes(path, "tracker or joint log file", limit=SIZE_LIMITS["table"]))
    # lines end at a newline only: str.splitlines() would also end one at U+2028, U+0085 (a
    # latin-1 byte 0x85) or a form feed inside a cell, and every row number after it would be off
    lines = [line.removesuffix("\r") for line in text.split("\n")]
    for i, line in enumerate(lines):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        delimiter = ";" if ";" in line else "\t" if "\t" in line else ","
        cells = _split(line, delimiter, path, i + 1)
        found = all(w in cells for w in wanted) if wanted else bool(header_test and header_test(cells))
        if not found:
            continue
        rows, numbers, misfit = [], [], False
        for k in range(i + 1, len(lines)):
            if not lines[k].strip() or lines[k].lstrip().startswith("#"):
                continue
            row = _split(lines[k], delimiter, path, k + 1)
            if len(row) != len(cells):
                if not rows:  # a metadata line that names the columns ("Columns: X;Y;Z"): the header is below
                    misfit = True
                    break
                raise InputError(f"{path}: row {k + 1}: {len(row)} cells for the header's {len(cells)} "
                                 f"(delimiter {delimiter!r}, header on row {i + 1})")
            rows.append(row)
            numbers.append(k + 1)
        if misfit:
            continue
        if not rows:
            raise InputError(f"{path}: no data rows below the header on row {i + 1}")
        decimal_comma = delimiter != "," and any(re.match(r"^[+-]?\d+,\d+", c) for r in rows for c in r)
        return Table(path, cells, rows, numbers, delimiter, decimal_comma)
    if wanted:
        raise InputError(f"{path}: no header line names the columns {', '.join(repr(w) for w in wanted)}")
    raise InputError(f"{path}: no header line found (expected the names of the columns to import)")


def parse_value(table: Table, row: int, col: int, target_unit: str | None) -> float:
    """The cell as a number in ``target_unit`` (its unit from the cell or the header, if any)."""
    cell = table.rows[row][col]
    where = f"{table.path}: row {table.lines[row]}, column {table.header[col]!r}"
    match = _NUMBER.match(cell.replace("\u2212", "-"))
    if not match:
        raise InputError(f"{where}: {cell!r} is not a number")
    number = match["number"]
    if table.decimal_comma:
        number = number.replace(",", ".")
    elif "," in number:
        raise InputError(f"{where}: {cell!r} has a decimal comma in a comma-separated file")
    value = float(number)
    if not math.isfinite(value):
        raise InputError(f"{where}: {cell!r} is not finite")
    unit = (match["unit"] or "").lower() or header_unit(table.header[col])
    if unit is not None and unit not in IMPORT_UNITS:
        raise InputError(f"{where}: unknown unit {unit!r} (known: {', '.join(IMPORT_UNITS)})")
    if unit is None or target_unit is None or unit == target_unit:
        return value
    (kind, factor), (target_kind, target_factor) = IMPORT_UNITS[unit], IMPORT_UNITS[target_unit]
    if kind != target_kind:
        raise InputError(f"{where}: a value in {unit} cannot fill a column in {target_unit}")
    return value * factor / target_factor


def _time_factor(table: Table, col: int) -> float:
    """Seconds per unit of a timestamp column, from its header ('Time [ms]' -> 0.001; none: 1)."""
    name = table.header[col].strip()
    match = _UNIT_IN_HEADER.match(name)
    unit = (match["b"] or match["p"] or match["s"]).strip() if match else None
    if unit is None:
        base, _, suffix = name.rpartition("_")
        unit = suffix if base and suffix.lower() in TIME_UNITS else None
    if unit is None:
        return 1.0
    if unit.lower() not in TIME_UNITS and unit not in TIME_UNITS:
        raise InputError(f"{table.path}: column {name!r}: unit {unit!r} is not a unit of time "
                         f"(known: {', '.join(TIME_UNITS)})")
    return TIME_UNITS.get(unit, TIME_UNITS.get(unit.lower(), 1.0))


def parse_time(table: Table, row: int, col: int) -> tuple[float, str]:
    """A timestamp in seconds and its kind ('seconds' or 'clock': a date and/or time of day)."""
    cell = table.rows[row][col].strip()
    where = f"{table.path}: row {table.lines[row]}, column {table.header[col]!r}"
    text = cell.replace(",", ".") if table.decimal_comma or ":" in cell else cell
    try:
        value = parse_number(text.removesuffix("s").strip())  # plain ASCII: no '1_000', no Arabic digits
    except ValueError:
        value = math.nan
    if math.isfinite(value):
        return value * _time_factor(table, col), "seconds"
    match = _TIME_OF_DAY.match(text)
    if match:
        h, m, sec = int(match["h"]), int(match["m"]), float(match["s"])
        if h > 23 or m > 59 or sec >= 60:
            raise InputError(f"{where}: {cell!r} is not a time of day (hours 0-23, minutes and seconds 0-59)")
        return h * 3600 + m * 60 + sec, "clock"
    try:
        stamp = datetime.fromisoformat(text.replace("/", "-"))
    except ValueError:
        raise InputError(f"{where}: {cell!r} is not a time (seconds, hh:mm:ss.fff or a date and time)") from None
    if stamp.tzinfo is not None:
        return stamp.timestamp(), "clock"
    seconds = (stamp - datetime(stamp.year, stamp.month, stamp.day)).total_seconds()
    return stamp.toordinal() * 86400.0 + seconds, "clock"


# ---------------------------------------------------------------------------------------
# Column maps
# ---------------------------------------------------------------------------------------
def target_unit(target: str) -> str | None:
    """'x_mm' -> 'mm', 'j2_deg' -> 'deg', 'time_s' -> None (times are parsed on their own)."""
    if target == TIME:
        return None
    _, _, suffix = target.rpartition("_")
    return suffix if suffix in IMPORT_UNITS else None


def _axis_columns(header: list[str], axis: str) -> list[str]:
    """Header cells that name a position along ``axis``: 'X', 'Point X', 'X [mm]', 'Dev X'."""
    return [h for h in header if _normal(h) == axis or _normal(h).endswith(" " + axis)]


def _auto_tracker_map(header: list[str]) -> dict[str, str]:
    """Position and time columns found by name: 'X', 'Point X', 'X [mm]', 'Meas. X (m)', 'Time'."""
    found: dict[str, str] = {}
    for axis in AXES:
        hits = _axis_columns(header, axis)
        if len(hits) == 1:
            unit = header_unit(hits[0])
            found[f"{axis}_{'m' if unit == 'm' else 'mm'}"] = hits[0]
    times = [h for h in header if _normal(h) in TIME_NAMES or h.strip().lower() in TIME_NAMES]
    if len(times) == 1:
        found[TIME] = times[0]
    return found


def _auto_log_map(header: list[str]) -> dict[str, str]:
    times = [h for h in header if _normal(h) in TIME_NAMES or h.strip().lower() in TIME_NAMES]
    found = {TIME: times[0]} if len(times) == 1 else {}
    for h in header:  # columns named like the measurement CSV's pass through
        if h not in times and (target_unit(h) is not None or h in ("payload_kg", "temperature_c")
                               or h.endswith("_dir")):
            found[h] = h
    return found


def _columns(table: Table, mapping: dict[str, str], what: str) -> list[tuple[str, int]]:
    """(target, column index) of each entry of ``mapping``; ``what``: the map's parameter name."""
    out = []
    for target, source in mapping.items():
        if source not in table.header:
            raise InputError(f"{table.path}: {what}[\"{target}\"]={source!r}: no such column (the header has: "
                             f"{', '.join(repr(h) for h in table.header)})", parameter=what, value=mapping)
        out.append((target, table.header.index(source)))
    return out


# ---------------------------------------------------------------------------------------
# The import
# ---------------------------------------------------------------------------------------
def _format(value: float) -> str:
    return f"{value:.10g}"


def _cell(table: Table, row: int, col: int, target: str) -> str:
    if target.endswith("_dir"):
        value = parse_value(table, row, col, None)
        if value not in (-1.0, 1.0) or not re.fullmatch(r"\s*[+-]?1([.,]0*)?\s*", table.rows[row][col]):
            raise InputError(f"{table.path}: row {table.lines[row]}, column {table.header[col]!r}: "
                             f"a direction is +1 or -1, got {table.rows[row][col]!r}")
        return "+1" if value > 0 else "-1"
    return _format(parse_value(table, row, col, target_unit(target)))


def _nearest(times: list[float], t: float, wraps: bool) -> tuple[int | None, float]:
    """(index into the sorted ``times`` nearest to ``t``, |gap| [s]); with ``wraps``, times of day
    are on a 24 h circle."""
    best, gap = None, math.inf
    for shift in ((-DAY_S, 0.0, DAY_S) if wraps else (0.0,)):
        k = bisect.bisect_left(times, t + shift)
        for i in (k - 1, k):
            if 0 <= i < len(times) and abs(times[i] - t - shift) < gap:
                best, gap = i, abs(times[i] - t - shift)
    return best, gap


def _refuse_simultaneous_samples(log: Table, order: list[int], times: list[float], cols: list[int],
                                 time_col: int) -> None:
    """Two joint-log samples at one time with different joint values: which one a tracker point
    was taken at cannot be told (one would be picked silently)."""
    for i in range(len(order) - 1):
        a, b = order[i], order[i + 1]
        if times[i] == times[i + 1] and [log.rows[a][c] for c in cols] != [log.rows[b][c] for c in cols]:
            raise InputError(f"{log.path}: rows {log.lines[a]} and {log.lines[b]} have the same time "
                             f"{log.rows[a][time_col]!r} but different joint values: which one a tracker point "
                             "was taken at cannot be told; remove one")


def import_tracker(tracker_path, tracker_map: dict[str, str] | None = None, log_path=None,
                   log_map: dict[str, str] | None = None, tolerance_s: float = 0.05) -> ImportResult:
    """Read a tracker export (and a joint log) into measurement-CSV rows.

    Parameters
    ----------
    tracker_path : path
        The tracker's export (points, optionally their timestamps and joint columns).
    tracker_map, log_map : dict of target -> source column, optional
        See the module docstring; the tracker's needs the positions (found by name when
        absent), and a timestamp (``time_s``) when a joint log is given.
    log_path : path, optional
        The robot's joint log: a timestamp and the joint columns (``<joint>_<unit>``, or
        mapped), optionally ``payload_kg``, ``temperature_c``, ``<joint>_dir``.
    tolerance_s : float
        Largest |tracker time - joint-log time| that joins a point to a log sample [s].

    Returns
    -------
    ImportResult
        The joined rows in display units (deg, mm as the targets name them), and the
        tracker points that found no log sample within the tolerance.
    """
    if not (math.isfinite(tolerance_s) and tolerance_s >= 0):
        raise InputError(f"tolerance_s={tolerance_s:g}: must be a number >= 0", parameter="tolerance_s",
                         value=tolerance_s)
    wanted = list(tracker_map.values()) if tracker_map else None
    tracker = read_table(tracker_path, wanted, header_test=lambda cells: all(_axis_columns(cells, a) for a in AXES))
    mapping = dict(tracker_map or {})
    auto = _auto_tracker_map(tracker.header)
    for axis in AXES:
        if not any(t in mapping for t in (f"{axis}_mm", f"{axis}_m")):
            key = next((k for k in (f"{axis}_mm", f"{axis}_m") if k in auto), None)
            hits = _axis_columns(tracker.header, axis)
            if key is None and len(hits) > 1:
                raise InputError(f"{tracker.path}: columns {', '.join(repr(h) for h in hits)} could each be the "
                                 f"{axis} position: name one with tracker_map[\"{axis}_mm\"]=\"HEADER\"",
                                 parameter="tracker_map", value=tracker_map)
            if key is None:
                raise InputError(f"{tracker.path}: no column for the {axis} position: name it with "
                                 f"tracker_map[\"{axis}_mm\"]=\"HEADER\" (the header has: "
                                 f"{', '.join(repr(h) for h in tracker.header)})", parameter="tracker_map",
                                 value=tracker_map)
            mapping[key] = auto[key]
    if log_path is not None and TIME not in mapping:
        if TIME not in auto:
            raise InputError(f"{tracker.path}: no timestamp column to join the joint log on: name it with "
                             f"tracker_map[\"time_s\"]=\"HEADER\"", parameter="tracker_map", value=tracker_map)
        mapping[TIME] = auto[TIME]
    tracker_cols = [(t, c) for t, c in _columns(tracker, mapping, "tracker_map") if t != TIME]
    columns = [t for t, _ in tracker_cols]
    result = ImportResult(columns=[], n_tracker_rows=len(tracker.rows), tracker=tracker)

    # the tracker's time and session labels travel into the measurement CSV: without them a drift is
    # fitted on the row order and every station shares one tracker frame (the diagnosis reads both)
    time_col = tracker.column(mapping[TIME] if TIME in mapping else auto[TIME]) if TIME in mapping or TIME in auto \
        else None
    session_col = _session_column(tracker, set(mapping.values()))
    carried = ([TIME] if time_col is not None else []) + (["session"] if session_col is not None else [])
    clock = _Unwrapped()

    def context(r: int) -> list[str]:
        cells = [] if time_col is None else [_seconds(clock(*parse_time(tracker, r, time_col)))]
        return cells + ([] if session_col is None else [_label(tracker, r, session_col)])

    if log_path is None:  # joint and context columns of the tracker file itself pass through
        used = set(mapping.values())
        first = {h: i for i, h in reversed(list(enumerate(tracker.header)))}  # header.index(h), once per column
        tracker_cols += [(t, first[h]) for t, h in _auto_log_map(tracker.header).items()
                         if t != TIME and t not in mapping and h not in used and t.split("_")[0] not in AXES]
        columns = [t for t, _ in tracker_cols]
        result.columns = columns + carried
        result.rows = [[_cell(tracker, r, c, t) for t, c in tracker_cols] + context(r)
                       for r in range(len(tracker.rows))]
        return result

    log_wanted = list(log_map.values()) if log_map else None
    log = read_table(log_path, log_wanted, header_test=lambda cells: TIME in _auto_log_map(cells))
    result.log = log
    log_mapping = dict(log_map or {})
    if TIME not in log_mapping:
        auto_log = _auto_log_map(log.header)
        if TIME not in auto_log:
            raise InputError(f"{log.path}: no timestamp column: name it with log_map[\"time_s\"]=\"HEADER\"",
                             parameter="log_map", value=log_map)
        log_mapping[TIME] = auto_log[TIME]
    if not [t for t in log_mapping if t != TIME]:
        log_mapping.update({k: v for k, v in _auto_log_map(log.header).items() if k != TIME})
    log_cols = [(t, c) for t, c in _columns(log, log_mapping, "log_map") if t != TIME]
    if not log_cols:
        raise InputError(f"{log.path}: no joint columns: name them like the measurement CSV (j1_deg, ...) "
                         "or map them with log_map[\"j1_deg\"]=\"HEADER\"", parameter="log_map", value=log_map)
    both = set(columns) & {t for t, _ in log_cols}
    if both:
        raise InputError(f"{', '.join(sorted(both))}: given by both the tracker file and the joint log")

    log_time_col = log.column(log_mapping[TIME])
    stamps = [parse_time(log, r, log_time_col) for r in range(len(log.rows))]
    kinds = {kind for _, kind in stamps}
    order = sorted(range(len(log.rows)), key=lambda r: stamps[r][0])
    times = [stamps[r][0] for r in order]
    _refuse_simultaneous_samples(log, order, times, [c for _, c in log_cols], log_time_col)
    # times of day without a date (hh:mm:ss) wrap at midnight: 23:59:59.99 is 20 ms before 00:00:00.01
    wraps = kinds == {"clock"} and all(0.0 <= x < DAY_S for x in times)
    tracker_time_col = tracker.column(mapping[TIME])
    result.columns = [t for t, _ in log_cols] + columns + carried
    for r in range(len(tracker.rows)):
        t, kind = parse_time(tracker, r, tracker_time_col)
        if kinds and kind not in kinds:
            raise InputError(f"{tracker.path}: row {tracker.lines[r]}: the tracker's time {tracker.rows[r][tracker_time_col]!r} "
                             f"is a {'clock time' if kind == 'clock' else 'number of seconds'}, the joint log's "
                             f"are {'clock times' if 'clock' in kinds else 'seconds'}: use one kind in both files")
        best, gap = _nearest(times, t, wraps and 0.0 <= t < DAY_S)
        if gap > tolerance_s:
            result.unjoined.append(Unjoined(tracker.lines[r], tracker.rows[r][tracker_time_col], gap))
            continue
        log_row = order[best]
        result.rows.append([_cell(log, log_row, c, t_) for t_, c in log_cols]
                           + [_cell(tracker, r, c, t_) for t_, c in tracker_cols] + context(r))
    return result


class _Unwrapped:
    """Times of day read in row order, carried past midnight (23:59:59 then 00:00:01 is 2 s later)."""

    def __init__(self) -> None:
        self.last, self.days = None, 0

    def __call__(self, t: float, kind: str) -> float:
        if kind == "clock" and 0.0 <= t < DAY_S:
            if self.last is not None and t + self.days * DAY_S < self.last - DAY_S / 2:
                self.days += 1
            t += self.days * DAY_S
            self.last = t
        return t


def _seconds(t: float) -> str:
    return f"{t:.6f}".rstrip("0").rstrip(".")


def _session_column(table: Table, used: set[str]) -> int | None:
    """The column of the rows' session labels (a header ``session``, any case), unless a map took it."""
    hits = [i for i, h in enumerate(table.header) if h.strip().lower() == "session" and h not in used]
    return hits[0] if hits else None


def _label(table: Table, row: int, col: int) -> str:
    cell = table.rows[row][col].strip()
    if not cell or not cell.isprintable() or any(c in cell for c in ',"\''):
        raise InputError(f"{table.path}: row {table.lines[row]}, column {table.header[col]!r}: a session label is "
                         f"printable text without commas or quotes, got {cell!r}")
    return cell
