"""The one file format of the whole calibrated model, written and read back.

``tcr-accuracy export`` (``as_built.yaml``) and ``tcr-accuracy diagnose --as-built-urdf FILE``
(``FILE.effects.yaml``) write the same format; :func:`load_as_built` reads it. The format is
written down in ``docs/as-built-format.md`` for other tools. In short (SI units)::

    format: tcr-accuracy as-built model 3
    robot: ur5                       # the nominal robot's name
    robot_source: ur5                # example-robot-data name, tool_changer, or a URDF's absolute path
    tool_frame: tool0                # the nominal TCP frame the chain ends at
    effects:                         # every fitted effect: parameter -> value [SI]
      joint_offsets: {joint_offsets.shoulder_pan_joint: 1.2e-05, ...}
      ...
    options: {cyclic: {max_order: 30}, ...}   # each effect's options (may be empty)
    trackerMbase: [[...4 rows...]]            # or null: p_tracker = trackerMbase @ p_base [m]

and, not needed to rebuild the model: ``units``, ``note``, ``state``, ``urdf`` and
``urdf_measured_frame`` (the URDF written with it), ``accuracy`` (what each exported form
reaches), ``uncertainty``, ``joint_functions``, ``measured_frames``, ``selected_effects``.

Reading is strict (one :class:`~tcr_accuracy.exceptions.InputError` line naming the file and
key): YAML's 1.1 shortcuts that turn text into numbers (``yes``, ``0x10``, ``1:30``, ``010``,
dates) stay text and are refused as numbers; every value is checked as
:mod:`tcr_accuracy.effects.file_values` says; the tracker frame must be a rigid 4 x 4 transform.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..exceptions import InputError
from ..input_files import parse_settings, read_input_text
from ..effects.file_values import file_number
from ..model.robot import load_robot
from .model import AsBuiltModel

#: Format tag written (and the ones read).
FORMAT = "tcr-accuracy as-built model 3"
READABLE = (FORMAT, "tcr-accuracy as-built model 2", "tcr-accuracy as-built model 1")
#: The tracker frame's key, and the one formats 1 and 2 wrote it under (still read).
TRACKER_KEY, OLD_TRACKER_KEY = "trackerMbase", "tracker_from_base"
#: Keys a file may carry; the first four are required.
REQUIRED = ("format", "robot_source", "tool_frame", "effects")
INFORMATIONAL = ("robot", "units", "note", "left_out", "state", "urdf", "urdf_measured_frame", "urdf_tool_frame", "accuracy",
                 "uncertainty", "uncertainty_note", "joint_functions", "joint_functions_note", "measured_frames",
                 "chain_in_urdf", "selected_effects")
KEYS = REQUIRED + ("options", TRACKER_KEY, OLD_TRACKER_KEY, "kinematics") + INFORMATIONAL
#: Largest model file read [bytes] (a cyclic model of a 20-joint robot is under 1 MB).
MAX_BYTES = 20_000_000
#: Largest translation of the tracker frame [m] and how far from a rotation its matrix may be.
TRACKER_MAX_M = 1000.0
RIGID_TOL = 1e-6
UNITS = "SI (m, rad, rad/Nm, m/N, 1/K)"
STATE = ("tcp_poses(q, context) at each row's context (a row without the campaign's time at its start); the "
         "exported forms, held-out figures and the compensation filter take new poses at the campaign's end "
         "(AsBuiltModel.state_context)")


def model_document(model: AsBuiltModel, **extra) -> dict:
    """The file's document of ``model`` (plain types, SI), with informational keys from ``extra``.

    Parameters
    ----------
    model : AsBuiltModel
    **extra
        Any of :data:`INFORMATIONAL` (e.g. ``urdf``, ``urdf_measured_frame``, ``accuracy``).

    Returns
    -------
    dict
    """
    unknown = sorted(set(extra) - set(INFORMATIONAL))
    if unknown:
        raise InputError(f"as-built model file: {unknown[0]!r} is not a key of the format")
    doc = {
        "format": FORMAT,
        "robot": model.robot.name,
        "robot_source": model.robot_source,
        "tool_frame": model.robot.tool_frame,
        "units": UNITS,
        "note": "tcp_poses = the nominal robot with these effects; the frames' base twist is the tracker's and is "
                "left out (trackerMbase: p_tracker = trackerMbase @ p_base)",
        "left_out": left_out(model),
        "state": STATE,
        "effects": {e: {k: float(v) for k, v in p.items() if not (e == "frames" and str(k).startswith("frames.base."))}
                    for e, p in model.parameters.items()},
        "options": {e: _plain(o) for e, o in model.options.items() if o},
        TRACKER_KEY: None if model.trackerMbase is None else [[float(v) for v in row] for row in model.trackerMbase],
    }
    if model.robot.kinematics:  # the nominal robot is the robot's own kinematics, not its URDF's
        doc["kinematics"] = _plain(model.robot.kinematics)
    doc.update(extra)
    return doc


def left_out(model: AsBuiltModel) -> str:
    """What the file leaves out of the model's parameters, in words: the tracker frame's base twist
    (``frames.base.*``, folded into ``trackerMbase``), which ``tcp_poses`` does not use."""
    base = sorted(n for n in model.parameters.get("frames", {}) if str(n).startswith("frames.base."))
    if not base:
        return "nothing"
    total = sum(len(p) for p in model.parameters.values())
    return (f"{len(base)} parameters of the tracker frame ({', '.join(base)}): part of the measurement setup, not "
            f"of the robot; trackerMbase holds them with the frame; the file keeps {total - len(base)} of the "
            f"{total} parameters of the model")


def model_yaml(document: dict) -> str:
    """YAML text of a document (keys in order, floats to full precision)."""
    import yaml

    return yaml.safe_dump(document, sort_keys=False, allow_unicode=True)


def _plain(value):
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


# ---------------------------------------------------------------------------------------
# Reading
# ---------------------------------------------------------------------------------------
def load_as_built(path) -> AsBuiltModel:
    """The calibrated robot written by ``tcr-accuracy export`` or ``diagnose --as-built-urdf``,
    whose :meth:`AsBuiltModel.tcp_poses` include the non-geometric effects.

    Parameters
    ----------
    path : str or Path
        The model file (``as_built.yaml``, ``X.effects.yaml``), or the ``.urdf`` written with it.

    Returns
    -------
    AsBuiltModel
        The nominal robot and every effect with its fitted parameters [SI].

    Raises
    ------
    InputError
        One line naming the file and the key at fault.

    Examples
    --------
    >>> import pathlib
    >>> import tempfile
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot()
    >>> measured = tcr.read_measurements("examples/measured.csv", robot)
    >>> d = tcr.diagnose(robot, measured, effects=["joint_offsets"], folds=3)
    >>> export = tcr.build_export(tcr.AsBuiltModel.from_diagnosis(robot, d), measured)
    >>> path = tempfile.mkdtemp() + "/as_built.yaml"
    >>> _ = pathlib.Path(path).write_text(export.model_text())
    >>> tcr.load_as_built(path)
    AsBuiltModel('tool_changer', effects [frames, joint_offsets], 9 parameters, with tracker frame)
    """
    path = Path(path)
    if path.suffix.lower() == ".urdf":
        candidates = [path.with_suffix(".yaml"), path.with_suffix(".effects.yaml")]
        path = next((c for c in candidates if c.is_file()), candidates[0])
    return read_model_document(read_input_text(path, "as-built model written by tcr-accuracy export",
                                               limit=MAX_BYTES), str(path))


def read_model_document(text: str, source: str) -> AsBuiltModel:
    """The model of a file's text (see :func:`load_as_built`); ``source`` names it in messages."""
    doc = parse_settings(text, source, "yaml")  # YAML 1.2's numbers, no aliases, no key twice
    if isinstance(doc, dict) and doc.get("format") not in READABLE and {"steps", "parameters"} <= set(doc):
        raise InputError(f"{source}: a diagnosis, not an as-built model: read it with tcr_accuracy.read_result and "
                         "build its model with AsBuiltModel.from_diagnosis(robot, diagnosis)")
    if not isinstance(doc, dict) or doc.get("format") not in READABLE:
        raise InputError(f"{source}: not an as-built model written by tcr-accuracy (no 'format: {FORMAT}')")
    for key in REQUIRED:
        if key not in doc:
            raise InputError(f"{source}: key {key!r} is missing")
    for key in doc:
        if key not in KEYS:
            raise InputError(f"{source}: key {key!r} is not part of the format (keys: {', '.join(KEYS)})")
    if TRACKER_KEY in doc and OLD_TRACKER_KEY in doc:
        raise InputError(f"{source}: {TRACKER_KEY} and {OLD_TRACKER_KEY}: the tracker frame is given twice (formats "
                         f"1 and 2 wrote {OLD_TRACKER_KEY}, format 3 {TRACKER_KEY}); give it once")
    key = OLD_TRACKER_KEY if OLD_TRACKER_KEY in doc else TRACKER_KEY
    model = model_from_values(source, ("effects", "options"), doc["robot_source"], doc["tool_frame"],
                              doc["effects"], doc.get("options"), doc.get(key), key,
                              kinematics=doc.get("kinematics"))
    if "robot" in doc and doc["robot"] != model.robot.name:
        raise InputError(f"{source}: robot: {doc['robot']!r}, but robot_source {doc['robot_source']!r} loads "
                         f"{model.robot.name!r}: the model of one robot named as another's")
    return model


def model_from_values(source: str, keys: tuple, robot_source, tool_frame, parameters, options, tracker,
                      tracker_key: str, *, kinematics=None) -> AsBuiltModel:
    """The model of values read from a file (a model file's or a diagnosis JSON's), each checked;
    ``keys`` names the parameters' and the options' mappings in that file, ``tracker_key`` the
    tracker frame's; ``kinematics`` the robot's own kinematics the file was fitted from
    (:func:`~tcr_accuracy.asbuilt.factory_kinematics.robot_with_start`), None: the URDF's."""
    for key, value in (("robot_source", robot_source), ("tool_frame", tool_frame)):
        if not isinstance(value, str) or not value or len(value) > 4096:
            raise InputError(f"{source}: {key}: {value!r} is not a robot name, path or frame name")
    options = options or {}
    for key, value in zip(keys, (parameters, options)):
        if not isinstance(value, dict) or not all(isinstance(v, dict) or v is None for v in value.values()):
            raise InputError(f"{source}: {key}: must map effect names to {{name: value}}")
    tracker = tracker_matrix(tracker, f"{source}: {tracker_key}")
    robot = load_robot(None if robot_source == "tool_changer" else robot_source, tool_frame)
    if kinematics is not None:
        from .factory_kinematics import robot_with_start

        robot = robot_with_start(robot, kinematics, source)
    return AsBuiltModel(robot, {str(e): dict(p or {}) for e, p in parameters.items()}, robot_source, tracker,
                        {str(e): dict(o or {}) for e, o in options.items()}, source=source, source_keys=keys)


def tracker_matrix(value, where: str) -> np.ndarray | None:
    """A 4 x 4 rigid transform (rows of numbers, a rotation within 1e-6, the last row 0 0 0 1,
    the translation within 1 km) or None; InputError naming ``where`` otherwise."""
    if value is None:
        return None
    if not isinstance(value, list) or len(value) != 4 or not all(isinstance(r, list) and len(r) == 4 for r in value):
        raise InputError(f"{where}: must be 4 rows of 4 numbers")
    matrix = np.array([[file_number(v, f"{where}[{i}][{j}]") for j, v in enumerate(row)]
                       for i, row in enumerate(value)])
    rotation = matrix[:3, :3]
    if (np.abs(matrix[3] - [0.0, 0.0, 0.0, 1.0]).max() > 0 or np.abs(rotation.T @ rotation - np.eye(3)).max() > RIGID_TOL
            or np.linalg.det(rotation) <= 0):
        raise InputError(f"{where}: not a rigid transform (a rotation and a translation, last row 0 0 0 1)")
    if np.linalg.norm(matrix[:3, 3]) > TRACKER_MAX_M:
        raise InputError(f"{where}: the tracker {np.linalg.norm(matrix[:3, 3]):.3g} m from the robot's base "
                         f"(at most {TRACKER_MAX_M:g} m)")
    return matrix
