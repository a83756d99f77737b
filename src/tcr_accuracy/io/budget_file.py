"""Error budgets from a user file (TOML or YAML), with the units written in the keys.

Example (TOML; YAML has the same structure)::

    name = "design review 3"

    [groups.link_length]          # one source per link, along the link
    distribution = "normal"
    std_mm = 0.2

    [groups.drive]                # one source per joint drive
    distribution = "normal"
    std_deg = 0.3                 # revolute joints
    std_mm = 0.25                 # prismatic joints

    [parameters."j3.dy"]          # any parameter of the error model by name
    distribution = "uniform"
    low_mm = -0.1
    high_mm = 0.1

    [parameters."j5.rx"]
    distribution = "truncnormal"
    std_deg = 0.05
    low_deg = -0.1
    high_deg = 0.1

    [clearance]                   # joint play (seed Table 4); alone, not with the above
    axial_std_mm = 0.2
    radial_std_mm = 0.5
    deflection_std_deg = 5.0

Groups: ``link_length``, ``drive``, ``axis_deflection`` (two tilts per revolute
joint), and the parameter groups ``placement``, ``base``, ``tool`` (one source per
component). Distribution fields: ``mean``, ``std`` (normal, truncnormal), ``low``,
``high`` (uniform, truncnormal), each with a unit suffix: lengths ``_m``, ``_mm``,
``_um``; angles ``_rad``, ``_mrad``, ``_deg``. A group holding both lengths and
angles (drive, placement, base, tool) takes both kinds of keys. Every problem is
reported as one line naming the file and the key.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..model.errors import (
    DISTRIBUTIONS,
    ErrorBudget,
    ErrorModel,
    ErrorSource,
    axis_deflection_directions,
    link_length_direction,
)
from ..exceptions import InputError
from ..input_files import MAX_NESTING, SIZE_LIMITS, parse_settings, read_input_text
from ..model.robot import REVOLUTE, RobotModel
from ..units import suffixes_of

LENGTH_UNITS = suffixes_of("m")
ANGLE_UNITS = suffixes_of("rad")
FIELDS = ("mean", "std", "low", "high")
SOURCE_GROUPS = ("link_length", "drive", "axis_deflection", "placement", "base", "tool")
CLEARANCE_KEYS = {"axial_std": LENGTH_UNITS, "radial_std": LENGTH_UNITS, "deflection_std": ANGLE_UNITS}


#: The largest magnitude a number of a settings file may have, in the unit its key names.
MAX_SETTING = 1e6


def read_table(path: Path) -> dict:
    """Parse a TOML (.toml) or YAML (.yaml/.yml) file into a dict; one-line errors."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".toml", ".yaml", ".yml"):
        raise InputError(f"{path}: unknown file type {suffix!r} (use .toml, .yaml or .yml)")
    text = read_input_text(path, "settings file", limit=SIZE_LIMITS["settings"])
    return parse_table(text, str(path), "toml" if suffix == ".toml" else "yaml")


def parse_table(text: str, source: str, kind: str = "yaml") -> dict:
    """TOML or YAML settings text to a dict whose keys are all strings, nested at most
    :data:`MAX_NESTING` deep (:func:`tcr_accuracy.input_files.parse_settings`); anything else is
    one InputError line naming ``source``."""
    data = parse_settings(text, source, kind)
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise InputError(f"{source}: expected a table of settings at the top level")
    _check_structure(data, source)
    return data


def _one_line(exc, limit: int = 300) -> str:
    text = " ".join(str(exc).split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _check_structure(data: dict, source: str) -> None:
    """Keys are strings, nesting is bounded (walked without recursion)."""
    stack = [(data, "", 1)]
    while stack:
        node, where, depth = stack.pop()
        if depth > MAX_NESTING:
            raise InputError(f"{source}: {where or 'top level'}: tables or lists nested more than "
                             f"{MAX_NESTING} deep")
        if isinstance(node, dict):
            for key, value in node.items():
                if not isinstance(key, str):
                    raise InputError(f"{source}: {where + '.' if where else ''}{_one_line(key, 60)}: keys must "
                                     f"be names, not {type(key).__name__} (quote it)")
                stack.append((value, f"{where}.{key}" if where else key, depth + 1))
        elif isinstance(node, list):
            stack.extend((value, f"{where}[{i}]", depth + 1) for i, value in enumerate(node))


def setting_number(raw, where: str, *, low: float = -MAX_SETTING, high: float = MAX_SETTING) -> float:
    """A number of a settings file: an int or float (not a bool, not text), finite, in [low, high]."""
    if isinstance(raw, bool) or not isinstance(raw, (int, float)):
        raise InputError(f"{where}: expected a number, got {_one_line(repr(raw), 60)}")
    value = float(raw) if abs(raw) < 1e308 else math.inf  # a huge YAML/TOML int overflows float()
    if not math.isfinite(value):
        raise InputError(f"{where}: expected a finite number, got {_one_line(repr(raw), 60)}")
    if not low <= value <= high:
        raise InputError(f"{where}: {value:g} is outside [{low:g}, {high:g}]")
    return value


def _unit_of(unit: str) -> dict:
    return LENGTH_UNITS if unit == "m" else ANGLE_UNITS


def _distribution_values(path: Path, where: str, spec, unit: str, strict: bool = True) -> dict:
    """Validated distribution settings for a parameter of SI unit ``unit`` ('m' or 'rad')."""
    if not isinstance(spec, dict):
        raise InputError(f"{path}: {where}: expected a table with distribution settings")
    dist = spec.get("distribution", "normal")
    if dist not in DISTRIBUTIONS:
        raise InputError(f"{path}: {where}.distribution: unknown distribution {dist!r} "
                         f"(use one of {', '.join(DISTRIBUTIONS)})")
    allowed = _unit_of(unit)
    values: dict = {}
    for key, raw in spec.items():
        if key == "distribution":
            continue
        field, _, suffix = key.rpartition("_")
        if field not in FIELDS:
            raise InputError(f"{path}: {where}.{key}: unknown key (use distribution and "
                             f"mean/std/low/high with a unit suffix such as _mm or _deg)")
        if suffix not in LENGTH_UNITS and suffix not in ANGLE_UNITS:
            raise InputError(f"{path}: {where}.{key}: unknown unit {suffix!r}")
        if suffix not in allowed:
            if strict:
                kind = "length" if unit == "m" else "angle"
                raise InputError(f"{path}: {where}.{key}: unit {suffix!r} does not fit a {kind} "
                                 f"(use {', '.join(allowed)})")
            continue  # the other kind of unit: in a mixed group it applies to other parameters
        if field in values:
            raise InputError(f"{path}: {where}.{key}: {field} given twice")
        raw = setting_number(raw, f"{path}: {where}.{key}")
        values[field] = raw * allowed[suffix]
        if field == "std" and raw < 0:
            raise InputError(f"{path}: {where}.{key}: spread must be >= 0, got {raw:g}")
    need = {"normal": ("std",), "uniform": ("low", "high"), "truncnormal": ("std", "low", "high")}[dist]
    missing = [f for f in need if f not in values]
    if missing:
        units = "/".join(allowed)
        raise InputError(f"{path}: {where}: {dist} needs {', '.join(f'{m}_<{units}>' for m in missing)} "
                         f"for {'lengths' if unit == 'm' else 'angles'}")
    if dist in ("uniform", "truncnormal") and not values["low"] < values["high"]:
        raise InputError(f"{path}: {where}: low must be below high")
    if dist == "truncnormal" and values["std"] <= 0:
        raise InputError(f"{path}: {where}: truncnormal needs std > 0")
    values["distribution"] = dist
    return values


def _source(name, group, direction, unit, values) -> ErrorSource:
    kwargs = {k: v for k, v in values.items() if k in FIELDS}
    return ErrorSource(name, group, direction, unit, distribution=values["distribution"], **kwargs)


def _group_sources(path, robot: RobotModel, em: ErrorModel, group: str, spec) -> list[ErrorSource]:
    where = f"groups.{group}"
    out: list[ErrorSource] = []

    def values_for(unit, strict=True):
        return _distribution_values(path, where, spec, unit, strict)

    if group == "link_length":
        vals = values_for("m")
        for j, name in enumerate(robot.joint_names):
            direction = link_length_direction(robot, j, em)
            if direction is not None:
                out.append(_source(f"{name} link length", group, direction, "m", vals))
    elif group == "axis_deflection":
        vals = values_for("rad")
        for j, name in enumerate(robot.joint_names):
            if robot.joint_kinds[j] == REVOLUTE:
                for label, direction in axis_deflection_directions(robot, j, em):
                    out.append(_source(f"{name} axis tilt {label}", group, direction, "rad", vals))
    else:  # drive, placement, base, tool: parameters of both units
        indices = em.group_indices(group)
        cache: dict = {}
        for i in indices:
            param = em.parameters[i]
            if param.unit not in cache:
                cache[param.unit] = values_for(param.unit, strict=False)
            direction = np.zeros(em.size)
            direction[i] = 1.0
            out.append(_source(param.name, group, direction, param.unit, cache[param.unit]))
    return out


def load_budget_file(path, robot: RobotModel):
    """An ErrorBudget (or a ClearanceModel for a [clearance] file) from a TOML/YAML file."""
    path = Path(path)
    data = read_table(path)
    known = {"name", "groups", "parameters", "clearance"}
    for key in data:
        if key not in known:
            raise InputError(f"{path}: {key}: unknown key (use name, groups, parameters, clearance)")
    em = ErrorModel(robot)
    name = str(data.get("name", path.stem))
    if "clearance" in data:
        if "groups" in data or "parameters" in data:
            raise InputError(f"{path}: clearance: cannot be combined with groups or parameters in one file")
        return _clearance(path, robot, em, data["clearance"], name)
    sources: list[ErrorSource] = []
    groups = data.get("groups", {})
    if not isinstance(groups, dict):
        raise InputError(f"{path}: groups: expected a table of groups")
    for group, spec in groups.items():
        if group not in SOURCE_GROUPS:
            raise InputError(f"{path}: groups.{group}: unknown group (use {', '.join(SOURCE_GROUPS)})")
        sources += _group_sources(path, robot, em, group, spec)
    params = data.get("parameters", {})
    if not isinstance(params, dict):
        raise InputError(f"{path}: parameters: expected a table of parameters")
    for pname, spec in params.items():
        if pname not in em.names:
            raise InputError(f"{path}: parameters.{pname}: unknown parameter (names look like "
                             f"{robot.joint_names[0]}.dx, {robot.joint_names[0]}.rz, "
                             f"{robot.joint_names[0]}.drive, base.dz, tool.rx)")
        i = em.index(pname)
        unit = em.parameters[i].unit
        direction = np.zeros(em.size)
        direction[i] = 1.0
        sources.append(_source(pname, em.parameters[i].group, direction, unit,
                               _distribution_values(path, f"parameters.{pname}", spec, unit)))
    if not sources:
        raise InputError(f"{path}: no error sources (add [groups.<group>] or [parameters.\"<name>\"] tables)")
    return ErrorBudget(em, sources, name=name)


def _clearance(path, robot, em, spec, name):
    from ..model.clearance import ClearanceModel

    if not isinstance(spec, dict):
        raise InputError(f"{path}: clearance: expected a table")
    spreads = {}
    for key, raw in spec.items():
        field, _, suffix = key.rpartition("_")
        if field not in CLEARANCE_KEYS:
            raise InputError(f"{path}: clearance.{key}: unknown key (use axial_std_mm, radial_std_mm, "
                             "deflection_std_deg or other unit suffixes)")
        units = CLEARANCE_KEYS[field]
        if suffix not in units:
            raise InputError(f"{path}: clearance.{key}: unit {suffix!r} does not fit (use {', '.join(units)})")
        spreads[field] = setting_number(raw, f"{path}: clearance.{key}", low=0.0) * units[suffix]
    return ClearanceModel.from_robot(robot, em, name=name, **spreads)
