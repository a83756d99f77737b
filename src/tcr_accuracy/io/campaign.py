"""The campaign file: who and what a calibration report identifies, and the limits it is judged by.

A small YAML (or TOML) file given to ``tcr-accuracy report --campaign FILE`` and to the
``--out`` reports of ``diagnose``, ``iso9283 evaluate`` and ``compare``. Every key is optional;
what is not given reads "not stated" on the report's first page::

    title: Calibration of the cutter changer, TBM S-1234
    customer: Example Tunnelling Ltd., Hamburg
    robot:
      model: UR5                  # default: the robot's name in the results
      serial: 2018-301234
    instrument:
      name: API Radian laser tracker
      serial: R20-1234
      certificate: DAkkS D-K-15183-01-00, 2026-03-02
      mpe_um: [15, 6]             # maximum permissible error, A [um] + B [um/m] x distance (ISO 10360-10)
      radial_mpe_um: [10, 0.3]    # along the beam, where it differs from mpe_um (across it)
      position_mm: [0, 0, 0]      # the instrument in the measurements' frame (default: their origin)
    temperature_c: [19.5, 21.0]   # lowest and highest during the measurements [degC]
    payload_kg: 0                 # the load the robot carried while measured
    date: 2026-11-20              # when the robot was measured (default: the report's date)
    operator: J. Smith
    limits_mm:                    # the figures the result is judged against [mm]
      max: 0.30                   # TCP position error after calibration, held-out max
      rms: 0.10                   # ... held-out RMS
      mean: 0.08                  # ... held-out mean
      ap: 0.25                    # ISO 9283 pose accuracy AP_P, the largest pose
      rp: 0.05                    # ISO 9283 repeatability RP_l, the largest pose
    prepared_by: J. Smith         # names printed in the signature block
    checked_by: A. Jones

A key not listed here, a limit that is not a positive number of millimetres, or a temperature
range that is not two numbers, low then high, is one line naming the file and the key.
"""

from __future__ import annotations

import dataclasses
import datetime
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

from ..exceptions import InputError
from ..input_files import control_character
from .budget_file import read_table

#: The figures a limit may be stated for (the key under ``limits_mm``) and what each is.
LIMIT_FIGURES = {
    "mean": "TCP position error after calibration, held-out mean",
    "rms": "TCP position error after calibration, held-out RMS",
    "max": "TCP position error after calibration, held-out max",
    "ap": "ISO 9283 pose accuracy AP_P, the largest pose",
    "rp": "ISO 9283 repeatability RP_l, the largest pose",
}

#: The keys of the file: top-level text keys, and the keys of its two small tables.
TEXT_KEYS = ("title", "customer", "date", "operator", "prepared_by", "checked_by")
ROBOT_KEYS = ("model", "serial")
INSTRUMENT_KEYS = ("name", "serial", "certificate", "mpe_um", "radial_mpe_um", "position_mm")
KEYS = (*TEXT_KEYS, "robot", "instrument", "temperature_c", "payload_kg", "limits_mm")
#: The largest MPE terms a campaign may state: A [um], B [um/m] (a total station's is about 1000 + 1.5).
MAX_MPE_UM = (1e4, 1e3)
#: The farthest an instrument may stand from the measurements' origin [mm], and the heaviest payload [kg].
MAX_POSITION_MM, MAX_PAYLOAD_KG = 1e6, 1e6

#: The longest text a key may hold [characters] (a line of the first page, not a document).
MAX_TEXT = 300
#: Temperatures a campaign may state [degC].
TEMPERATURE_RANGE_C = (-60.0, 150.0)
#: The largest limit [mm] (beyond it a limit judges nothing).
MAX_LIMIT_MM = 1e4


@dataclass(frozen=True)
class CampaignFacts:
    """What the campaign file (and the flags beside it) say; empty strings where nothing is stated.

    Attributes
    ----------
    limits_mm : dict of str to float
        Limit [mm] per figure of :data:`LIMIT_FIGURES`.
    temperature_c : tuple of (float, float) or None
        Lowest and highest temperature during the measurements [degC].
    """

    title: str = ""
    customer: str = ""
    robot_model: str = ""
    robot_serial: str = ""
    instrument_name: str = ""
    instrument_serial: str = ""
    certificate: str = ""
    temperature_c: tuple | None = None
    date: str = ""
    operator: str = ""
    prepared_by: str = ""
    checked_by: str = ""
    limits_mm: dict = field(default_factory=dict)
    instrument_mpe_um: tuple | None = None  # (A [um], B [um/m]) across the beam (and along it unless radial)
    instrument_radial_mpe_um: tuple | None = None
    instrument_position_mm: tuple | None = None  # in the measurements' frame
    payload_kg: float | None = None

    def updated(self, **given) -> "CampaignFacts":
        """These facts with those of ``given`` that are not None (flags over the file);
        ``limits_mm`` is merged figure by figure."""
        given = {k: v for k, v in given.items() if v is not None}
        if "limits_mm" in given:
            given["limits_mm"] = {**self.limits_mm, **given["limits_mm"]}
        return dataclasses.replace(self, **given)


def read_campaign(path) -> CampaignFacts:
    """The campaign file at ``path`` (YAML or TOML, see the module docstring).

    Raises
    ------
    InputError
        One line naming the file and the key at fault.
    """
    source = str(path)
    doc = read_table(Path(path))
    unknown = [k for k in doc if k not in KEYS]
    if unknown:
        raise InputError(f"{source}: unknown key {unknown[0]!r} (keys: {', '.join(KEYS)})")
    robot = _table(doc, "robot", ROBOT_KEYS, source)
    instrument = _table(doc, "instrument", INSTRUMENT_KEYS, source)
    limits = _table(doc, "limits_mm", tuple(LIMIT_FIGURES), source)
    return CampaignFacts(
        **{k: _text(doc.get(k), k, source) for k in TEXT_KEYS if k != "date"},
        date=_date(doc.get("date"), source),
        robot_model=_text(robot.get("model"), "robot.model", source),
        robot_serial=_text(robot.get("serial"), "robot.serial", source),
        instrument_name=_text(instrument.get("name"), "instrument.name", source),
        instrument_serial=_text(instrument.get("serial"), "instrument.serial", source),
        certificate=_text(instrument.get("certificate"), "instrument.certificate", source),
        temperature_c=temperature_range(doc.get("temperature_c"), f"{source}: temperature_c"),
        instrument_mpe_um=_numbers(instrument.get("mpe_um"), 2, (0.0, 0.0), MAX_MPE_UM, f"{source}: instrument.mpe_um",
                                   "A [um] and B [um/m], e.g. [15, 6]"),
        instrument_radial_mpe_um=_numbers(instrument.get("radial_mpe_um"), 2, (0.0, 0.0), MAX_MPE_UM,
                                          f"{source}: instrument.radial_mpe_um", "A [um] and B [um/m]"),
        instrument_position_mm=_numbers(instrument.get("position_mm"), 3, (-MAX_POSITION_MM,) * 3,
                                        (MAX_POSITION_MM,) * 3, f"{source}: instrument.position_mm", "x, y, z [mm]"),
        payload_kg=None if doc.get("payload_kg") is None else _numbers(
            [doc["payload_kg"]], 1, (0.0,), (MAX_PAYLOAD_KG,), f"{source}: payload_kg", "a load [kg] >= 0")[0],
        limits_mm={k: limit_mm(v, f"{source}: limits_mm.{k}") for k, v in limits.items()},
    )


def _table(doc: dict, key: str, keys: tuple, source: str) -> dict:
    value = doc.get(key, {})
    if not isinstance(value, dict):
        raise InputError(f"{source}: {key}: expected a table with the keys {', '.join(keys)}")
    unknown = [k for k in value if k not in keys]
    if unknown:
        raise InputError(f"{source}: unknown key {key}.{unknown[0]} (keys of {key}: {', '.join(keys)})")
    return value


def _text(value, key: str, source: str) -> str:
    """A text value; a number or a date (YAML reads ``2026-11-20`` as one) as written. Anything
    else a YAML tag can make (``!!binary`` bytes, a ``!!set``, ``yes`` read as true) would print
    as Python's spelling of it on the first page, and a control character would go into the page
    as it is: both refused."""
    if value is None:
        return ""
    if isinstance(value, bool) or not isinstance(value, (str, int, float, datetime.date, datetime.time)):
        kind = {dict: "table", list: "list"}.get(type(value), type(value).__name__)
        raise InputError(f"{source}: {key}: expected text, got a {kind} ({value!r:.40})")
    text = " ".join(str(value).split())
    problem = text_problem(text)
    if problem is not None:
        raise InputError(f"{source}: {key}: {problem}")
    return text


def text_problem(text: str) -> str | None:
    """What keeps ``text`` off a line of the report's first page (a control or bidirectional-override
    character, more than :data:`MAX_TEXT` characters), or None: the one check of a text a campaign
    file gives and of a flag that gives the same fact (``--title``, ``--operator``, ...)."""
    control = control_character(text)
    if control is not None:
        return f"holds the control character U+{ord(control):04X}; write plain text"
    if len(text) > MAX_TEXT:
        return f"{len(text)} characters; at most {MAX_TEXT} fit a line of the report"
    return None


def _date(value, source: str) -> str:
    """The date as text; one written as a calendar date (``YYYY-MM-DD``, which YAML reads as a
    date only when it is one) must be a day of the calendar, not ``2026-13-45`` printed as given."""
    text = _text(value, "date", source)
    if re.fullmatch(r"\d{4}-\d{1,2}-\d{1,2}", text):
        try:
            datetime.date(*map(int, text.split("-")))
        except ValueError as err:
            raise InputError(f"{source}: date: {text} is not a day of the calendar ({err})") from None
    return text


def _numbers(value, count: int, low, high, where: str, want: str) -> tuple | None:
    """``count`` finite numbers within [low, high] each, as a tuple, or None; InputError naming ``where``."""
    if value is None:
        return None
    if not isinstance(value, (list, tuple)) or len(value) != count or any(
            isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) for v in value):
        raise InputError(f"{where}: {value!r:.60}: want {count} number{'s' if count > 1 else ''}: {want}")
    if any(not lo <= v <= hi for v, lo, hi in zip(value, low, high)):
        raise InputError(f"{where}: {list(value)}: out of range ({want}; each within {list(low)} to {list(high)})")
    if count == 2 and sum(value) <= 0:
        raise InputError(f"{where}: {list(value)}: A + B must be above 0 ({want})")
    return tuple(float(v) for v in value)


def limit_mm(value, where: str) -> float:
    """A limit [mm]: a positive finite number up to :data:`MAX_LIMIT_MM`; InputError naming ``where``."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
            or not 0 < value <= MAX_LIMIT_MM:
        raise InputError(f"{where}: {value!r}: want a limit in mm, a number > 0 and <= {MAX_LIMIT_MM:g}")
    return float(value)


def temperature_range(value, where: str) -> tuple | None:
    """``[low, high]`` [degC] as a tuple, or None; InputError naming ``where``."""
    if value is None:
        return None
    low, high = TEMPERATURE_RANGE_C
    if not isinstance(value, (list, tuple)) or len(value) != 2 or any(
            isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) for v in value):
        raise InputError(f"{where}: {value!r}: want two numbers [degC], the lowest and the highest, e.g. [19.5, 21]")
    if not (low <= value[0] <= value[1] <= high):
        raise InputError(f"{where}: {list(value)}: want low <= high, both within {low:g} to {high:g} degC")
    return float(value[0]), float(value[1])
