"""The calibrated model in a ``diagnose --json`` result, read strictly.

``export`` reads the keys ``robot_source``, ``tool_frame``, ``effect_parameters``,
``effect_options`` and ``trackerMbase`` (``tracker_transform`` in files of 0.1), and where they are there the measurement files
(``measurement_files``, else ``measurements``) and the final step's k-fold held-out figures.
Every value is checked as :mod:`tcr_accuracy.effects.file_values` and
:func:`~tcr_accuracy.asbuilt.model_file.tracker_matrix` say; the first one at fault is one
:class:`~tcr_accuracy.exceptions.InputError` line naming the file and the key.
"""

from __future__ import annotations


from ..effects.file_values import file_number
from ..exceptions import InputError
from ..input_files import parse_json, read_input_text
from .model import AsBuiltModel
from .model_file import model_from_values

#: Largest diagnosis JSON read [bytes].
MAX_BYTES = 200_000_000
REQUIRED = ("effect_parameters", "robot_source", "tool_frame", "trackerMbase")


def parse_diagnosis_json(text: str, source: str) -> dict:
    """The JSON object of a ``diagnose --json`` result with the keys export needs."""
    data = parse_json(text, source, "give the JSON that tcr-accuracy diagnose wrote")
    if not isinstance(data, dict):
        raise InputError(f"{source}: not a diagnosis (a JSON object was expected)")
    for key in REQUIRED:
        if key not in data:
            raise InputError(f"{source}: key {key!r} is missing; write the JSON with tcr-accuracy diagnose of "
                             "this version")
    return data


def read_diagnosis_json(path) -> dict:
    """:func:`parse_diagnosis_json` of a file (a regular file of at most :data:`MAX_BYTES`)."""
    return parse_diagnosis_json(read_input_text(path, "diagnosis", limit=MAX_BYTES), str(path))


def model_from_diagnosis(data: dict, source: str) -> AsBuiltModel:
    """The full model a diagnosis JSON holds, every value checked."""
    return model_from_values(source, ("effect_parameters", "effect_options"), data["robot_source"],
                             data["tool_frame"], data["effect_parameters"], data.get("effect_options"),
                             data.get("trackerMbase", data.get("tracker_transform")), "trackerMbase",
                             kinematics=data.get("kinematics"))


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
