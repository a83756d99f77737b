"""Each kind of result file and the type it is read as: the one reader's dispatch.

:data:`RESULT_TYPES` maps a kind (:data:`~tcr_accuracy.results.kinds.KINDS`) to its typed
result, each with ``to_dict``/``to_json`` and ``from_dict``/``from_json``; a new kind of result
is one line here (its keys in ``KINDS``, its schema in :func:`~tcr_accuracy.results.files.schema_of`).
:func:`read_result` reads any result file through the one reader and returns its typed result.
"""

from __future__ import annotations

from ..asbuilt.export_result import ExportResult
from ..diagnosis.compare import Comparison
from ..diagnosis.result import Diagnosis
from ..iso9283.result_file import IsoTestResult
from .consistency import check_robot
from .files import check_physics, read_result_document

#: kind -> the type its file is read as.
RESULT_TYPES = {
    "diagnosis": Diagnosis,
    "iso9283": IsoTestResult,
    "comparison": Comparison,
    "export": ExportResult,
}


def read_result(path, kind: str | None = None, *, robot=None, required=(), hint: str = ""):
    """The typed result of a result file (``diagnose --json``, ``iso9283 evaluate --json``,
    ``compare --json``, export's ``accuracy.json``, or what a script saved with ``to_json``), read
    through the one reader:
    the file checked whole before anything is built (its schema; its figures against each other;
    one copy of each number; its robot: the name and joints of what its ``robot_source`` loads,
    a diagnosis' parameters within their effects' physics on it).

    Parameters
    ----------
    path : str or Path
        The JSON file.
    kind : {"diagnosis", "iso9283", "comparison", "export"}, optional
        The kind expected (default: whichever the file is).
    robot : RobotModel, optional
        The robot to hold the result to; default the one its ``robot_source`` names (loaded
        here; a result that names none, or a URDF not on this machine, is held to nothing
        beyond itself).
    required : tuple of str, default=()
        Keys the caller needs besides those of every such result (``export`` needs a diagnosis'
        :data:`~tcr_accuracy.results.files.MODEL_KEYS`).
    hint : str, default=""
        What to give instead, said when the file is no JSON.

    Returns
    -------
    Diagnosis, IsoTestResult, Comparison or ExportResult
        As :data:`RESULT_TYPES` says for the file's kind.

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
    >>> fitted = tcr.diagnose(robot, measured, effects=["joint_offsets", "compliance"], folds=3)
    >>> path = tempfile.mkdtemp() + "/diagnosis.json"
    >>> _ = pathlib.Path(path).write_text(fitted.to_json())
    >>> loaded = tcr.read_result(path)
    >>> loaded.steps[-1].heldout.rms == fitted.steps[-1].heldout.rms, loaded.from_file
    (True, True)
    """
    found, doc = read_result_document(path, kind, hint=hint, required=required)
    if robot is None and doc.get("robot_source"):
        robot = _robot_of(doc, path)
    if robot is not None:
        check_robot(doc, robot, path)
        if found == "diagnosis":
            check_physics(doc, robot, path)
    return RESULT_TYPES[found].from_dict(doc, str(path))


def _robot_of(doc: dict, path):
    """The robot a result's ``robot_source`` (and ``tool_frame``) loads; InputError naming the key."""
    from ..exceptions import InputError
    from ..model.robot import load_robot

    from pathlib import Path

    from ..model.robot import BUILTIN_NAME, EXAMPLE_ROBOTS

    source = doc["robot_source"]
    if source != BUILTIN_NAME and source.lower() not in EXAMPLE_ROBOTS and not Path(source).exists():
        return None  # a URDF that is not on this machine: the result is held to nothing beyond itself
    try:
        robot = load_robot(source, doc.get("tool_frame") or None)
    except InputError as exc:
        raise InputError(f"{path}: $.robot_source: {exc}") from None
    if doc.get("kinematics") is None:
        return robot
    from ..asbuilt.factory_kinematics import robot_with_start

    return robot_with_start(robot, doc["kinematics"], str(path))  # the robot's own kinematics the result started from
