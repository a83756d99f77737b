"""Units, stated once: SI inside, degrees and millimetres only at the edges.

The bottom of the package (imports nothing of it). Every table that turns a unit suffix
into an SI factor, or an SI value into what a report shows, lives here:

* :data:`SUFFIXES`: a key or column suffix (``_mm``, ``_deg``, ``_ppm_per_k``) -> its SI
  unit and the factor to SI; scenario files, budget files and CSV columns read it.
* :data:`JOINT_COLUMN_UNITS`, :data:`POSITION_UNITS`: the suffixes a joint or a position
  column may carry.
* :data:`DISPLAY_UNITS`, :func:`display_value`: an SI parameter value in the unit a
  report prints (rad -> deg, m -> mm, rad/Nm -> deg/kNm, ...).
"""

from __future__ import annotations

import math
import re

import numpy as np

REVOLUTE = "revolute"
PRISMATIC = "prismatic"

DEG = math.pi / 180.0

#: suffix -> (SI unit, factor to SI)
SUFFIXES: dict[str, tuple[str, float]] = {
    "m": ("m", 1.0), "mm": ("m", 1e-3), "um": ("m", 1e-6),
    "rad": ("rad", 1.0), "mrad": ("rad", 1e-3), "urad": ("rad", 1e-6),
    "deg": ("rad", math.pi / 180.0), "arcsec": ("rad", math.pi / 180.0 / 3600.0),
    "per_k": ("1/K", 1.0), "ppm_per_k": ("1/K", 1e-6), "ppm": ("1", 1e-6),
    "rad_per_nm": ("rad/Nm", 1.0), "urad_per_nm": ("rad/Nm", 1e-6),
    "deg_per_knm": ("rad/Nm", math.pi / 180.0 / 1000.0),
    "m_per_n": ("m/N", 1.0), "um_per_n": ("m/N", 1e-6), "mm_per_kn": ("m/N", 1e-6),
}


def suffixes_of(si_unit: str) -> dict[str, float]:
    """Every suffix of one SI unit with its factor: ``suffixes_of("m")`` -> {m: 1, mm: 1e-3, um: 1e-6}."""
    return {suffix: factor for suffix, (unit, factor) in SUFFIXES.items() if unit == si_unit}


def split_suffix(key: str) -> tuple[str, str | None]:
    """``'offsets_deg'`` -> ``('offsets', 'deg')``; the longest known suffix wins, None if none."""
    best = None
    for unit in SUFFIXES:
        if key.endswith("_" + unit) and (best is None or len(unit) > len(best)):
            best = unit
    if best is None:
        return key, None
    return key[: -len(best) - 1], best


#: Suffixes of a joint column, by joint kind -> factor to SI (rad or m).
JOINT_COLUMN_UNITS: dict[str, dict[str, float]] = {REVOLUTE: {"deg": DEG, "rad": 1.0},
                                                   PRISMATIC: {"mm": 1e-3, "m": 1.0}}
#: Suffixes of a measured position column -> factor to m.
POSITION_UNITS: dict[str, float] = {"mm": 1e-3, "m": 1.0}

#: Units a tracker export or a joint log may write in a header or a cell (``X [mm]``,
#: ``1234,5 in``) -> (SI unit, factor to SI): the suffixes above plus inch and foot.
IMPORT_UNITS: dict[str, tuple[str, float]] = {
    **{u: ("m", f) for u, f in suffixes_of("m").items()}, "in": ("m", 0.0254), "ft": ("m", 0.3048),
    **{u: ("rad", f) for u, f in suffixes_of("rad").items()}, "kg": ("kg", 1.0), "c": ("degC", 1.0),
}

#: What the edges show for a joint value of each kind: (unit label, factor from SI).
JOINT_DISPLAY: dict[str, tuple[str, float]] = {REVOLUTE: ("deg", 180.0 / math.pi), PRISMATIC: ("mm", 1000.0)}

#: SI parameter unit -> (display unit, factor) for reports and exported YAML.
DISPLAY_UNITS: dict[str, tuple[str, float]] = {
    "m": ("mm", 1e3),
    "rad": ("deg", 180.0 / math.pi),
    "rad/Nm": ("deg/kNm", 180.0 / math.pi * 1e3),
    "m/N": ("mm/kN", 1e6),
    "1/K": ("ppm/K", 1e6),
    "1": ("ppm", 1e6),
}


def display_value(value: float, unit: str) -> tuple[float, str]:
    """An SI parameter value in its display unit: (2e-4, "rad") -> (0.01146, "deg")."""
    label, factor = DISPLAY_UNITS.get(unit, (unit, 1.0))
    return float(value) * factor, label


#: A decimal number as people write it: ASCII digits, one optional sign, point and exponent.
#: Python's float() also takes ``1_5``, full-width digits, ``infinity`` and ``nan``; edges
#: that read user text go through :func:`parse_number` instead.
_NUMBER = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
_INTEGER = re.compile(r"[+-]?[0-9]+")
_ASCII_SPACE = " \t\r\n\f\v"


def parse_number(text: str, *, finite: bool = True) -> float:
    """User text to a float, strictly: ``'1.5e-3'`` yes; ``'1_5'``, ``'１５'``, ``'0x1p3'`` no.

    ``nan``, ``inf`` and ``-inf`` (any case), and a number too large for a float (``1e999``,
    read as inf), pass only with ``finite=False``.

    Raises
    ------
    ValueError
        The text is not such a number; the message says why.
    """
    text = text.strip(_ASCII_SPACE)
    if not finite and text.lower().lstrip("+-") in ("nan", "inf", "infinity"):
        return float(text)
    if not _NUMBER.fullmatch(text):
        raise ValueError(f"{text!r} is not a number")
    value = float(text)
    if finite and not math.isfinite(value):
        raise ValueError(f"{text!r} is too large for a number")
    return value


#: A character no cell of a number table holds (anything but ASCII digits, sign, point, exponent letter,
#: the comma between cells, the line break between rows, blanks around a cell)
_NOT_IN_NUMBER_TABLE = re.compile(r"[^0-9+\-.eE,\n \t]")


def parse_number_table(lines: list[str], n_columns: int) -> np.ndarray | None:
    """Lines of comma-separated cells to floats (n_lines, n_columns) at once, or None when some line
    has not ``n_columns`` cells or some cell is not a finite number as :func:`parse_number` reads
    one (the caller then reads the cells one by one to say which).

    Python's float() and :data:`_NUMBER` take the same cells once only ASCII digits, sign, point,
    exponent letter and blanks are left (float()'s other forms need underscores, other digits,
    letters of ``inf`` or ``nan``; its blanks are the ones stripped before :data:`_NUMBER` is
    matched): one search of the text for any other character, then numpy's float() of every cell,
    instead of a Python call per cell (10^5 rows of 17 columns: 0.8 s instead of 4 s).

    Parameters
    ----------
    lines : list of str, the rows (no line breaks in them)
    n_columns : int

    Returns
    -------
    ndarray of shape (len(lines), n_columns), or None
    """
    if not lines:
        return np.empty((0, n_columns))
    text = "\n".join(lines)
    if _NOT_IN_NUMBER_TABLE.search(text) or any(line.count(",") != n_columns - 1 for line in lines):
        return None
    try:
        values = np.array(text.replace("\n", ",").split(","), dtype=float)
    except ValueError:  # an empty cell, or one such as "1.2.3" or "e5"
        return None
    if not np.all(np.isfinite(values)):  # 1e999
        return None
    return values.reshape(len(lines), n_columns)


def parse_integer(text: str) -> int:
    """User text to an int, strictly (ASCII digits and an optional sign, as :func:`parse_number`)."""
    text = text.strip(_ASCII_SPACE)
    if not _INTEGER.fullmatch(text) or len(text) > 30:
        raise ValueError(f"{text!r} is not an integer")
    return int(text)
