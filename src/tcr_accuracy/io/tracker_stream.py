"""A tracker's stream of a moving TCP: time-stamped positions, read and checked.

The stream of a path test (``tcr-accuracy iso9283 evaluate --path``) is a CSV with one reading
per row:

==========================  ===============================================================
column                      meaning
==========================  ===============================================================
``time_s``                  time of the reading [s] (any origin), increasing within a cycle
``x_mm, y_mm, z_mm``        the measured point in the instrument's frame (or ``x_m`` ...)
``qw, qx, qy, qz``          optional orientation (read, not used by the path figures)
``path``                    optional: which commanded path (``line``, ``circle_large`` ...)
``speed_pct``               optional: its speed in % of the rated path speed
``cycle``                   optional: which run of the path (labels: ``1``, ``C03`` ...)
==========================  ===============================================================

Lines starting with ``#`` are comments; messages name the file, row (line) and column. Values
are converted to SI at once. A whole number written as a label is its digits (``1.0`` = ``1``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..exceptions import InputError
from ..input_files import csv_cells
from ..units import POSITION_UNITS
from .measurements import (MAX_POSITION_M, MAX_TIME_S, QUATERNION_COLUMNS, _check_range, _header, label_cell,
                           number_cell, read_user_text)

#: The labels of a stream's rows.
STREAM_LABELS = ("path", "cycle")


@dataclass(frozen=True)
class TrackerStream:
    """Time-stamped readings of a moving point, SI units.

    Attributes
    ----------
    time_s : ndarray of shape (N,)
        Time of each reading [s].
    position : ndarray of shape (N, 3)
        The point in the instrument's frame [m].
    labels : dict of str to ndarray of shape (N,)
        ``path`` and ``cycle`` as text (object arrays), those the file has.
    speed_pct : ndarray of shape (N,) or None
        The commanded speed in % of the rated path speed, when the file says it.
    rows : ndarray of shape (N,)
        Line of each reading in the file.
    source : str
    position_columns : tuple of (list of str, str)
        The position columns and their unit, as written.
    """

    time_s: np.ndarray
    position: np.ndarray
    labels: dict
    speed_pct: np.ndarray | None
    rows: np.ndarray
    source: str
    position_columns: tuple

    def __len__(self) -> int:
        return len(self.time_s)


def read_tracker_stream(path: str | Path) -> TrackerStream:
    """Read and check a tracker stream CSV (see the module docstring).

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    TrackerStream

    Raises
    ------
    InputError
        Naming the file, row and column at fault.

    Examples
    --------
    >>> import pathlib
    >>> import tempfile
    >>> import tcr_accuracy as tcr
    >>> path = tempfile.mkdtemp() + "/stream.csv"
    >>> rows = [f"{0.001 * k:.3f},{1000 + 0.1 * k:.3f},200.000,300.000" for k in range(100)]
    >>> _ = pathlib.Path(path).write_text("time_s,x_mm,y_mm,z_mm\\n" + "\\n".join(rows) + "\\n")
    >>> stream = tcr.read_tracker_stream(path)
    >>> len(stream.time_s), float(stream.position[1, 0])  # [s], [m]
    (100, 1.0001)
    """
    path = Path(path)
    source = str(path)
    lines, header, header_line = _header(read_user_text(path, "tracker stream"), source)
    units = [u for u in POSITION_UNITS if any(f"{a}_{u}" in header for a in "xyz")]
    allowed = {"time_s", "speed_pct", *STREAM_LABELS, *QUATERNION_COLUMNS,
               *(f"{a}_{u}" for u in POSITION_UNITS for a in "xyz")}
    for c, name in enumerate(header):
        if name not in allowed:
            raise InputError(f"{source}: row {header_line}: unknown column {name!r} in a tracker stream (allowed: "
                             f"time_s, x_mm, y_mm, z_mm or x_m, y_m, z_m, qw..qz, path, speed_pct, cycle)")
        if header.index(name) != c:
            raise InputError(f"{source}: row {header_line}: column {name} appears twice in the header")
    if len(units) != 1:
        raise InputError(f"{source}: row {header_line}: " + ("position columns mix units; use one" if units else
                                                            "missing position columns x_mm, y_mm, z_mm (or x_m ...)"))
    cols = [f"{a}_{units[0]}" for a in "xyz"]
    missing = [c for c in ["time_s", *cols] if c not in header]
    if missing:
        raise InputError(f"{source}: row {header_line}: missing column {', '.join(missing)}")
    numeric = [c for c, name in enumerate(header) if name not in STREAM_LABELS]
    values = np.empty((len(lines) - 1, len(header)))
    labels = {name: [] for name in STREAM_LABELS if name in header}
    rows = np.empty(len(lines) - 1, dtype=int)
    for k, (line_no, line) in enumerate(lines[1:]):
        cells = csv_cells(line, source, line_no)
        if len(cells) != len(header):
            raise InputError(f"{source}: row {line_no}: {len(cells)} cells, the header has {len(header)} columns")
        for c in numeric:
            values[k, c] = number_cell(cells[c].strip(), source, line_no, header[c])
        for name in labels:
            labels[name].append(label_cell(cells[header.index(name)].strip(), source, line_no, name))
        rows[k] = line_no
    if len(rows) < 2:
        raise InputError(f"{source}: {len(rows)} readings; a path is a stream of many")
    time_s = values[:, header.index("time_s")]
    _check_range(source, rows, "time_s", time_s, MAX_TIME_S, "s", 1.0, "s")
    position = values[:, [header.index(c) for c in cols]] * POSITION_UNITS[units[0]]
    for k, c in enumerate(cols):
        _check_range(source, rows, c, position[:, k], MAX_POSITION_M, "m", 1.0 / POSITION_UNITS[units[0]], units[0])
    speed = values[:, header.index("speed_pct")] if "speed_pct" in header else None
    if speed is not None and not np.all((speed > 0) & (speed <= 100)):
        r = int(np.argmax(~((speed > 0) & (speed <= 100))))
        raise InputError(f"{source}: row {rows[r]}, column speed_pct: {speed[r]:g} is not a speed in (0, 100] %")
    return TrackerStream(time_s=time_s, position=position,
                         labels={k: np.array(v, dtype=object) for k, v in labels.items()}, speed_pct=speed,
                         rows=rows, source=source, position_columns=(cols, units[0]))


__all__ = ["STREAM_LABELS", "TrackerStream", "read_tracker_stream"]
