"""The robot's own kinematics as the start: a UR's factory calibration, a DH or MDH table.

Every Universal Robots arm leaves the factory with its own kinematics, which ``ur_calibration``
extracts into the ROS 2 driver's YAML (the file :mod:`tcr_accuracy.asbuilt.ur_calibration` reads and
writes); other makers, and an earlier ``export``, give a DH or MDH table. A diagnosis against the
catalogue's URDF finds those factory deltas again as "geometry", and an export then writes a
calibration relative to the wrong start. Given such a file, the nominal robot *is* the robot's own
kinematics: the diagnosis, the exported forms and the compensation filter are relative to it.

**How the file becomes the robot.** The file gives the TCP frame's pose as a function of the joints
(the UR xacro's chain, :func:`~tcr_accuracy.asbuilt.ur_calibration.tool0_poses`; the product of the
table's rows, :meth:`~tcr_accuracy.asbuilt.dh.DhTable.tcp`). The robot's URDF keeps its links,
meshes, masses and frames; its joint placements and TCP frame are fitted to that function at
:data:`N_POSES` joint configurations (every parameter of
:class:`~tcr_accuracy.model.errors.ErrorModel` the poses determine, Gauss-Newton from the URDF's
own: :func:`~tcr_accuracy.asbuilt.refit.fit_to_poses`), written into the URDF
(:func:`~tcr_accuracy.asbuilt.urdf.urdf_with_placements`) and checked at as many other
configurations to :data:`EXPRESSED_M` and :data:`EXPRESSED_RAD`. A file whose TCP lies more than
:data:`ANOTHER_ROBOT_M` (or :data:`ANOTHER_ROBOT_RAD`) from the URDF's anywhere is another robot's
(a UR10's file for a UR5): refused.

**What a result keeps.** The robot carries a record of its start (:attr:`RobotModel.kinematics
<tcr_accuracy.model.robot.RobotModel>`: the file's name, format and SHA-256, and the placements
it gave); ``diagnose --json`` and the model file write it, and :func:`robot_with_start` rebuilds the
same robot from it when ``export`` or ``load_as_built`` read them back.

A DH or MDH table is read in the form ``export`` writes ``dh.csv``/``mdh.csv`` (the ``*_as_built``
columns when there are, else the first ones; lengths in mm, angles in deg), its base and tool
transforms from ``<name>_base_tool.csv`` beside it when there is one, else those of the robot's own
table (or its maker's published one) that put it nearest the URDF; DH or MDH is the convention
that does.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pinocchio as pin

from ..exceptions import InputError
from ..input_files import SIZE_LIMITS, csv_cells, read_input_text
from ..model.errors import ErrorModel
from ..model.kinematics import tcp_poses
from ..model.robot import RobotModel, robot_from_urdf_text
from .dh import DhTable, NoDhForm, dh_table, mdh_table
from .refit import fit_to_poses
from .urdf import urdf_with_placements

#: Joint configurations the fit uses, and as many others it is checked at.
N_POSES = 60
#: Farthest the file's TCP may lie from the URDF's [m] / turn from it [rad] and be this robot's.
ANOTHER_ROBOT_M = 0.05
ANOTHER_ROBOT_RAD = float(np.radians(5.0))
#: Largest miss of the rewritten URDF from the file's kinematics [m] / [rad].
EXPRESSED_M = 1e-9
EXPRESSED_RAD = 1e-9
#: The formats, as a result names them.
UR_FORMAT = "UR ROS 2 driver calibration"
TABLE_COLUMNS = ("a_mm", "alpha_deg", "d_mm", "theta_deg", "beta_deg")
#: Largest value a table's cell may hold [mm or deg].
MAX_TABLE_VALUE = 1e9


def with_factory_kinematics(robot: RobotModel, path) -> RobotModel:
    """``robot`` with the kinematics of the file ``path`` as its own (see the module docstring).

    Parameters
    ----------
    robot : RobotModel
        The robot as its URDF has it (the catalogue's kinematics).
    path : str or Path
        A UR ROS 2 driver calibration YAML, or a DH/MDH table CSV as ``export`` writes them.

    Returns
    -------
    RobotModel
        The same robot (name, links, meshes, masses, TCP frame) with the file's kinematics, and
        ``kinematics`` recording them.

    Raises
    ------
    InputError
        The file cannot be read, is neither format, or is another robot's; one line naming it.
    """
    text = read_input_text(path, "kinematics file", limit=SIZE_LIMITS["settings"])
    lines = [line.strip() for line in text.splitlines() if line.strip() and not line.lstrip().startswith("#")]
    if lines and lines[0].split(",")[0].strip().lower() == "joint":
        fk, form = _table_kinematics(text, path, robot)
    else:
        fk, form = _ur_kinematics(text, path, robot), UR_FORMAT
    record = {"file": Path(path).name, "format": form, "sha256": hashlib.sha256(text.encode()).hexdigest()}
    return _rewritten(robot, fk, record, str(path))


def robot_with_start(robot: RobotModel, record, source: str) -> RobotModel:
    """``robot`` rebuilt on the start a result recorded (its ``kinematics``: a diagnosis JSON's or a
    model file's), every value checked; ``source`` names the result in messages. None: ``robot``."""
    if record is None:
        return robot
    where = f"{source}: kinematics"
    if not isinstance(record, dict) or not all(isinstance(record.get(k), str) and 0 < len(record[k]) <= 4096
                                               for k in ("file", "format", "sha256")):
        raise InputError(f"{where}: must name the file, its format and its sha256")
    placements = record.get("placements")
    if not isinstance(placements, dict) or set(placements) != {"joints", "tool"} or \
            not isinstance(placements["joints"], dict):
        raise InputError(f"{where}.placements: must hold 'joints' (joint -> x, y, z, roll, pitch, yaw) and 'tool'")
    joints = placements["joints"]
    if list(joints) != list(robot.joint_names):
        raise InputError(f"{where}.placements.joints: names {', '.join(map(str, joints))}, not the joints of "
                         f"{robot.name} ({', '.join(robot.joint_names)})")
    chain = [_placement(joints[name], f"{where}.placements.joints.{name}") for name in robot.joint_names]
    tool = _placement(placements["tool"], f"{where}.placements.tool")
    rebuilt = _robot_from_placements(robot, chain, tool, source)
    q = _configurations(robot, 0)
    _check_same_robot(robot, tcp_poses(rebuilt, q), q, where)
    rebuilt.robot_source = robot.robot_source
    rebuilt.kinematics = {**record, "placements": {"joints": dict(joints), "tool": list(placements["tool"])}}
    return rebuilt


def start_label(robot: RobotModel) -> str:
    """Words for what the robot's nominal kinematics are: 'the factory kinematics of FILE (format)' or
    'the URDF's kinematics'."""
    record = robot.kinematics
    if not record:
        return "the URDF's kinematics"
    return f"the factory kinematics of {record['file']} ({record['format']}, sha256 {record['sha256'][:12]})"


# ---------------------------------------------------------------------------------------
# The file's kinematics, as a function of the joints
# ---------------------------------------------------------------------------------------
def _ur_kinematics(text: str, path, robot: RobotModel):
    from .ur_calibration import read_ur_calibration, tool0_poses

    document = read_ur_calibration(text, path)
    if robot.n_joints != 6 or any(kind != "revolute" for kind in robot.joint_kinds):
        raise InputError(f"{path}: a UR calibration file describes a 6-joint UR arm; {robot.name} has "
                         f"{robot.n_joints} joints ({', '.join(robot.joint_kinds)})")
    tool0_tcp = _tool0_to_tcp(robot, path)
    return lambda q: tool0_poses(document, q) @ tool0_tcp


def _tool0_to_tcp(robot: RobotModel, path) -> np.ndarray:
    """(4, 4) ``tool0`` to the robot's TCP frame (identity when the TCP frame is ``tool0``): both must
    hang on the last joint."""
    if robot.tool_frame == "tool0":
        return np.eye(4)
    model = robot.model
    if not model.existFrame("tool0"):
        raise InputError(f"{path}: a UR calibration file ends at tool0; {robot.name} has no frame tool0")
    tool0 = model.frames[model.getFrameId("tool0")]
    tcp = model.frames[robot.tool_frame_id]
    if tool0.parentJoint != tcp.parentJoint:
        raise InputError(f"{path}: a UR calibration file ends at tool0; the TCP frame {robot.tool_frame} does not "
                         "move with it")
    return (tool0.placement.inverse() * tcp.placement).homogeneous


def _table_kinematics(text: str, path, robot: RobotModel):
    """The table's TCP function and its format ('DH table' or 'MDH table'): the convention and base and
    tool transforms that put it nearest the URDF (see the module docstring)."""
    joints, variable, params, suffix = _table_rows(text, path, robot)
    sidecar = _base_tool(path, suffix)
    q = _configurations(robot, 0)
    nominal = tcp_poses(robot, q)
    best = None
    for convention, build in (("DH", dh_table), ("MDH", mdh_table)):
        for base, tool in ([sidecar] if sidecar is not None else _base_tool_candidates(robot, convention, build)):
            table = DhTable.from_rows(convention, joints, variable, params, base, tool)
            poses = np.array([table.tcp(v) for v in q])
            miss = float(np.linalg.norm(poses[:, :3, 3] - nominal.position, axis=1).max())
            if best is None or miss < best[0]:
                best = (miss, table)
    table = best[1]
    return (lambda values: np.array([table.tcp(v) for v in np.atleast_2d(values)])), f"{table.convention} table"


def _table_rows(text: str, path, robot: RobotModel):
    lines = [(k + 1, line) for k, line in enumerate(text.splitlines()) if line.strip()]
    header = [c.strip() for c in csv_cells(lines[0][1], path, lines[0][0])]
    suffix = "_as_built" if all(f"{c}_as_built" in header for c in TABLE_COLUMNS) else ""
    wanted = ["joint", "variable"] + [f"{c}{suffix}" for c in TABLE_COLUMNS]
    missing = [c for c in wanted if c not in header and c != "beta_deg"]
    if missing:
        raise InputError(f"{path}: row {lines[0][0]}: column {missing[0]} is missing (a DH/MDH table as export writes "
                         f"it: {', '.join(wanted)})")
    rows = lines[1:]
    if len(rows) != robot.n_joints:
        raise InputError(f"{path}: {len(rows)} joint rows, but {robot.name} has {robot.n_joints} joints "
                         f"({', '.join(robot.joint_names)})")
    joints, variable, params = [], [], []
    scale = [1e-3, np.pi / 180.0, 1e-3, np.pi / 180.0, np.pi / 180.0]
    from ..units import parse_number

    for (row, line), name, kind in zip(rows, robot.joint_names, robot.joint_kinds):
        cells = [c.strip() for c in csv_cells(line, path, row)]
        if len(cells) != len(header):
            raise InputError(f"{path}: row {row}: {len(cells)} cells, the header has {len(header)}")
        cell = dict(zip(header, cells))
        if cell["joint"] != name:
            raise InputError(f"{path}: row {row}: joint {cell['joint']!r}, but joint {len(joints) + 1} of "
                             f"{robot.name} is {name}: a table of another robot, or in another order")
        expected = "d" if kind == "prismatic" else "theta"
        if cell["variable"] != expected:
            raise InputError(f"{path}: row {row}: variable {cell['variable']!r}, but {name} is {kind} ({expected})")
        values = []
        for column, factor in zip(TABLE_COLUMNS, scale):
            key = f"{column}{suffix}"
            try:
                value = parse_number(cell.get(key, "0") or "0")
            except ValueError as exc:
                raise InputError(f"{path}: row {row}: column {key}: {exc}") from None
            if abs(value) > MAX_TABLE_VALUE:  # a plain table's far common normal may lie kilometres away
                raise InputError(f"{path}: row {row}: column {key}: {value:g} is beyond any table's "
                                 f"(at most {MAX_TABLE_VALUE:g})")
            values.append(value * factor)
        joints.append(name)
        variable.append(expected)
        params.append(values)
    return joints, variable, np.array(params), suffix


def _base_tool(path, suffix: str):
    """(base (4, 4), tool (4, 4)) from ``<name>_base_tool.csv`` beside the table, or None when there is none."""
    path = Path(path)
    side = path.with_name(f"{path.stem}_base_tool{path.suffix}")
    if not side.is_file():
        return None
    from ..units import parse_number

    text = read_input_text(side, "kinematics file", limit=SIZE_LIMITS["settings"])
    lines = [(k + 1, line) for k, line in enumerate(text.splitlines()) if line.strip()]
    header = [c.strip() for c in csv_cells(lines[0][1], side, lines[0][0])] if lines else []
    columns = ["frame", "model", "x_mm", "y_mm", "z_mm", "roll_deg", "pitch_deg", "yaw_deg"]
    if header != columns:
        raise InputError(f"{side}: the header is not {','.join(columns)} (as export writes it)")
    model = "as_built" if suffix else "nominal"
    found = {}
    for row, line in lines[1:]:
        cells = [c.strip() for c in csv_cells(line, side, row)]
        if len(cells) != len(columns) or cells[1] != model:
            continue
        try:
            x, y, z, roll, pitch, yaw = (parse_number(c) for c in cells[2:])
        except ValueError as exc:
            raise InputError(f"{side}: row {row}: {exc}") from None
        found[cells[0]] = pin.SE3(pin.rpy.rpyToMatrix(*np.radians([roll, pitch, yaw])),
                                  np.array([x, y, z]) * 1e-3).homogeneous
    if set(found) != {"base_to_frame0", "last_frame_to_tcp"}:
        raise InputError(f"{side}: needs the rows base_to_frame0 and last_frame_to_tcp of the model {model}")
    return found["base_to_frame0"], found["last_frame_to_tcp"]


def _base_tool_candidates(robot: RobotModel, convention: str, build):
    """Base and tool transforms a table of ``robot`` in ``convention`` may have: its own table's, and
    its maker's published table's."""
    from .maker_dh import published_table

    out = []
    try:
        own = build(robot)
        out.append((own.base, own.tool))
    except NoDhForm:
        pass
    maker = published_table(robot.name, robot)
    if maker is not None and maker[0].convention == convention:
        out.append((maker[1].base, maker[1].tool))
    return out or [(np.eye(4), np.eye(4))]


# ---------------------------------------------------------------------------------------
# The robot rewritten
# ---------------------------------------------------------------------------------------
def _configurations(robot: RobotModel, seed: int) -> np.ndarray:
    """(N_POSES, n_joints): the working pose and joint values drawn within the limits (+-pi unbounded)."""
    lo, hi = robot.joint_bounds(np.pi)
    draws = np.random.default_rng(seed).uniform(lo, hi, (N_POSES - 1, robot.n_joints))
    return np.vstack([robot.working_pose, draws])


def _check_same_robot(robot: RobotModel, poses, q, where: str) -> None:
    nominal = tcp_poses(robot, q)
    miss = np.linalg.norm(poses.position - nominal.position, axis=1)
    turn = np.linalg.norm([pin.log3(a.T @ b) for a, b in zip(nominal.rotation, poses.rotation)], axis=1)
    if miss.max() > ANOTHER_ROBOT_M or turn.max() > ANOTHER_ROBOT_RAD:
        raise InputError(f"{where}: its TCP lies up to {miss.max() * 1e3:.4g} mm and {np.degrees(turn.max()):.3g} deg "
                         f"from {robot.name}'s (at most {ANOTHER_ROBOT_M * 1e3:g} mm and "
                         f"{np.degrees(ANOTHER_ROBOT_RAD):g} deg for a robot's own kinematics): the kinematics of "
                         "another robot?")


def _rewritten(robot: RobotModel, fk, record: dict, source: str) -> RobotModel:
    """``robot`` with its placements fitted to ``fk`` (q (N, n) -> (N, 4, 4) TCP poses), checked."""
    from ..model.kinematics import TcpPoses

    q = _configurations(robot, 0)
    target = np.asarray(fk(q), dtype=float)
    if target.shape != (len(q), 4, 4) or not np.all(np.isfinite(target)):
        raise InputError(f"{source}: its kinematics give no finite TCP pose")
    _check_same_robot(robot, TcpPoses(target[:, :3, 3], target[:, :3, :3]), q, source)
    x = fit_to_poses(robot, q, target[:, :3, 3], target[:, :3, :3])
    placements, tool = ErrorModel(robot).perturbed_placements(x)
    rebuilt = _robot_from_placements(robot, placements, tool, source)
    check = _configurations(robot, 1)
    expected, got = np.asarray(fk(check), dtype=float), tcp_poses(rebuilt, check)
    miss = np.linalg.norm(got.position - expected[:, :3, 3], axis=1).max()
    turn = max(np.linalg.norm(pin.log3(a.T @ b)) for a, b in zip(expected[:, :3, :3], got.rotation))
    if miss > EXPRESSED_M or turn > EXPRESSED_RAD:
        raise InputError(f"{source}: the URDF of {robot.name} cannot carry these kinematics (its joints placed as "
                         f"near as they go miss them by {miss * 1e3:.3g} mm and {np.degrees(turn):.3g} deg): a chain "
                         "of other joints")
    rebuilt.robot_source = robot.robot_source  # load_robot(robot_source) and these placements give it again
    rebuilt.kinematics = {**record, "placements": {
        "joints": {name: _six(p) for name, p in zip(robot.joint_names, rebuilt.joint_placements)},
        "tool": _six(rebuilt.tool_placement)}}
    return rebuilt


def _robot_from_placements(robot: RobotModel, placements, tool, source: str) -> RobotModel:
    text = urdf_with_placements(robot, placements, tool)
    rebuilt = robot_from_urdf_text(text, robot.tool_frame, name=robot.name, source=source, urdf_path=robot.urdf_path,
                                   package_dirs=list(robot.package_dirs), working_pose=np.array(robot.working_pose),
                                   payload_kg=robot.payload_kg)
    rebuilt.packages = dict(robot.packages)
    rebuilt.mounting_plane_z = robot.mounting_plane_z
    return rebuilt


def _six(placement: pin.SE3) -> list[float]:
    """[x, y, z, roll, pitch, yaw] of a placement [m, rad] (URDF's rpy)."""
    return [float(v) for v in (*placement.translation, *pin.rpy.matrixToRpy(placement.rotation))]


def _placement(values, where: str) -> pin.SE3:
    from ..effects.file_values import file_number

    if not isinstance(values, list) or len(values) != 6:
        raise InputError(f"{where}: must be 6 numbers (x, y, z [m], roll, pitch, yaw [rad])")
    numbers = [file_number(v, f"{where}[{k}]") for k, v in enumerate(values)]
    if max(abs(v) for v in numbers[:3]) > 1000.0 or max(abs(v) for v in numbers[3:]) > 4 * np.pi:
        raise InputError(f"{where}: beyond 1 km or 4 pi rad: no robot's joint placement")
    return pin.SE3(pin.rpy.rpyToMatrix(*numbers[3:]), np.array(numbers[:3]))
