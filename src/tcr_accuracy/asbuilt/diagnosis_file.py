"""The calibrated model in a ``diagnose --json`` result, read strictly.

``export`` reads the keys ``robot_source``, ``tool_frame``, ``effect_parameters``,
``effect_options`` and ``tracker_transform``, and where they are there the measurement files
(``measurement_files``, else ``measurements``) and the final step's k-fold held-out figures.
Every value is checked as :mod:`tcr_accuracy.effects.file_values` and
:func:`~tcr_accuracy.asbuilt.model_file.tracker_matrix` say; the first one at fault is one
:class:`~tcr_accuracy.exceptions.InputError` line naming the file and the key.
"""

from __future__ import annotations

import json
from pathlib import Path

from ..effects.file_values import file_number
from ..exceptions import InputError
from ..model.robot import load_robot
from .model import AsBuiltModel
from .model_file import tracker_matrix

#: Largest diagnosis JSON read [bytes].
MAX_BYTES = 200_000_000
REQUIRED = ("effect_parameters", "robot_source", "tool_frame", "tracker_transform")


def parse_diagnosis_json(text: str, source: str) -> dict:
    """The JSON object of a ``diagnose --json`` result with the keys export needs."""
    try:
        data = json.loads(text)
    except RecursionError:
        raise InputError(f"{source}: nested too deep to be a diagnosis") from None
    except ValueError as exc:
        raise InputError(f"{source}: not JSON ({exc})") from None
    if not isinstance(data, dict):
        raise InputError(f"{source}: not a diagnosis (a JSON object was expected)")
    for key in REQUIRED:
        if key not in data:
            raise InputError(f"{source}: key {key!r} is missing; write the JSON with 'tcr-accuracy diagnose "
                             "MEASUREMENTS.csv --json FILE' of this version")
    return data


def read_diagnosis_json(path) -> dict:
    """:func:`parse_diagnosis_json` of a file (a regular file of at most :data:`MAX_BYTES`)."""
    path = Path(path)
    try:
        if not path.is_file():
            raise InputError(f"{path}: {'no such file' if not path.exists() else 'not a regular file'}")
        if path.stat().st_size > MAX_BYTES:
            raise InputError(f"{path}: {path.stat().st_size / 1e6:.0f} MB is more than a diagnosis")
        text = path.read_bytes().decode("utf-8-sig")
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror or exc})") from None
    except UnicodeDecodeError as exc:
        raise InputError(f"{path}: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    return parse_diagnosis_json(text, str(path))


def model_from_diagnosis(data: dict, source: str) -> AsBuiltModel:
    """The full model a diagnosis JSON holds, every value checked."""
    robot_source, tool = data["robot_source"], data["tool_frame"]
    for key, value in (("robot_source", robot_source), ("tool_frame", tool)):
        if not isinstance(value, str) or not value or len(value) > 4096:
            raise InputError(f"{source}: {key}: {value!r} is not a robot name, path or frame name")
    parameters, options = data["effect_parameters"], data.get("effect_options") or {}
    for key, value in (("effect_parameters", parameters), ("effect_options", options)):
        if not isinstance(value, dict) or not all(isinstance(v, dict) or v is None for v in value.values()):
            raise InputError(f"{source}: {key}: must map effect names to {{name: value}}")
    tracker = tracker_matrix(data["tracker_transform"], f"{source}: tracker_transform")
    robot = load_robot(None if robot_source == "tool_changer" else robot_source, tool)
    return AsBuiltModel(robot, {str(e): dict(p or {}) for e, p in parameters.items()}, robot_source, tracker,
                        {str(e): dict(o or {}) for e, o in options.items()}, source=source,
                        source_keys=("effect_parameters", "effect_options"))


def measurement_files(data: dict, source: str) -> list[str]:
    """The measurement files the diagnosis was fitted to, as it recorded them (may be relative)."""
    files = data.get("measurement_files")
    if files is None:
        text = data.get("measurements")
        files = [] if not isinstance(text, str) or not text else text.split(", ")
    if not isinstance(files, list) or not all(isinstance(f, str) and f for f in files):
        raise InputError(f"{source}: measurement_files: must be a list of file names")
    return files


def kfold_figures(data: dict, source: str) -> dict | None:
    """The final model's k-fold held-out mean, RMS and max [m] (None where the JSON has none)."""
    steps = data.get("steps")
    if not isinstance(steps, list) or not steps or not isinstance(steps[-1], dict):
        return None
    last = steps[-1]
    try:
        figures = {k: file_number(last.get(f"heldout_{k}_mm"), f"{source}: steps[-1].heldout_{k}_mm") * 1e-3
                   for k in ("mean", "rms", "max")}
    except InputError:
        return None
    folds, n = data.get("folds"), data.get("n_measurements")
    figures.update(folds=folds if isinstance(folds, int) else "", n=n if isinstance(n, int) else 0)
    return figures
