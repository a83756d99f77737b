"""The kinematics calibration file of Universal Robots' ROS 2 driver, for a calibrated UR arm.

``ur_calibration`` extracts a UR controller's factory calibration into a YAML file that
``ur_description`` (``urdf/ur_macro.xacro``, through ``urdf/inc/ur_common.xacro``) reads as
``kinematics_parameters_file``::

    kinematics:
      shoulder:  {x: .., y: .., z: .., roll: .., pitch: .., yaw: ..}
      upper_arm: {...}
      forearm:   {...}
      wrist_1:   {...}
      wrist_2:   {...}
      wrist_3:   {...}
      hash: calib_...

Each entry is the ``<origin xyz="x y z" rpy="roll pitch yaw"/>`` of one joint (shoulder_pan ...
wrist_3), from the parent link to the child link, every joint turning about its own z; the chain
starts at ``base_link_inertia`` (``base_link`` turned 180 deg about z) and ends at
``wrist_3_link``, from which the xacro hangs ``flange`` (rpy 0, -90, -90 deg) and ``tool0`` (rpy
90, 0, 90 deg). ``rpy`` is URDF's: ``R = Rz(yaw) Ry(pitch) Rx(roll)``. ``hash`` names the
calibration; the driver compares it with the controller's and logs a mismatch, which is
expected here: this file carries a calibration the controller does not know.

The file is read off the calibrated robot (example-robot-data's frames): each UR link frame is
rigidly attached to the same body as the example-robot-data joint frame, by a constant transform
taken from the nominal robot, so the as-built origins are ``L_(i-1)^-1 L_i`` at q = 0 with
``L_i = J_i C_i``. Joint zero offsets are in the origins (a turn about the joint's own z
commutes with the joint). The measured point is no part of the file: the controller takes it as
its TCP (written beside it).
"""

from __future__ import annotations

import hashlib

import numpy as np
import pinocchio as pin

from ..exceptions import InputError
from ..model.robot import RobotModel
from .maker_dh import PUBLISHED

#: The file's entries, one per joint in chain order.
LINKS = ("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3")
#: Fixed transforms of ur_description: base_link -> base_link_inertia, wrist_3_link -> tool0.
BASE_LINK_INERTIA = pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, np.pi), np.zeros(3))
WRIST_3_TO_TOOL0 = (pin.SE3(pin.rpy.rpyToMatrix(0.0, -np.pi / 2, -np.pi / 2), np.zeros(3))
                    * pin.SE3(pin.rpy.rpyToMatrix(np.pi / 2, 0.0, np.pi / 2), np.zeros(3)))


def is_ur(source: str, robot: RobotModel) -> bool:
    """Whether ``robot`` (loaded as ``source``) is a UR arm measured at ``tool0``."""
    return (str(source).lower() in ("ur3", "ur5", "ur10") and robot.n_joints == 6 and robot.tool_frame == "tool0")


def nominal_origins(source: str) -> list[pin.SE3]:
    """The six joint origins of ur_description for the maker's published DH (what ur_calibration
    writes for an uncalibrated arm): shoulder ``Tz(d1)``, then ``Tx(a_k) Rx(alpha_k) Tz(d_k+1)``."""
    rows = PUBLISHED[str(source).lower()].rows
    origins = [pin.SE3(np.eye(3), np.array([0.0, 0.0, rows[0][2]]))]
    for k in range(1, 6):
        a, alpha, _, _ = rows[k - 1]
        previous = pin.SE3(pin.rpy.rpyToMatrix(alpha, 0.0, 0.0), np.array([a, 0.0, 0.0]))
        origins.append(previous * pin.SE3(np.eye(3), np.array([0.0, 0.0, rows[k][2]])))
    return origins


def ur_kinematics(as_built: RobotModel, nominal: RobotModel, source: str) -> dict:
    """The ``kinematics`` document of the calibrated arm (ur_description's format).

    Parameters
    ----------
    as_built : RobotModel
        The calibrated chain (example-robot-data's frames, the URDF's geometry).
    nominal : RobotModel
        The nominal robot of example-robot-data (``source``), or the robot's own kinematics on its
        URDF (the catalogue's URDF then says how each UR link rides its body).
    source : str
        ``ur3``, ``ur5`` or ``ur10``.

    Returns
    -------
    dict
        ``{"kinematics": {shoulder: {x, y, z, roll, pitch, yaw}, ..., "hash": ...}}`` [m, rad].
    """
    if not is_ur(source, nominal):
        raise InputError(f"UR calibration file: {source} is not a UR3, UR5 or UR10 measured at tool0")
    ur_links = _link_frames(nominal_origins(source))
    catalogue = nominal
    if nominal.kinematics:  # each UR link rides its body as the catalogue's URDF has it, whatever the start
        from ..model.robot import load_robot

        catalogue = load_robot(source, nominal.tool_frame)
    bodies_nominal, bodies = _joint_frames(catalogue), _joint_frames(as_built)
    attach = [b.inverse() * u for b, u in zip(bodies_nominal, ur_links[1:])]  # constant per body
    frames = [ur_links[0]] + [b * c for b, c in zip(bodies, attach)]
    entries = {}
    for name, parent, child in zip(LINKS, frames[:-1], frames[1:]):
        origin = parent.inverse() * child
        roll, pitch, yaw = pin.rpy.matrixToRpy(origin.rotation)
        entries[name] = {"x": float(origin.translation[0]), "y": float(origin.translation[1]),
                         "z": float(origin.translation[2]), "roll": float(roll), "pitch": float(pitch),
                         "yaw": float(yaw)}
    digest = hashlib.sha256(repr(sorted((k, sorted(v.items())) for k, v in entries.items())).encode()).hexdigest()
    entries["hash"] = f"calib_tcr_accuracy_{int(digest[:15], 16)}"
    return {"kinematics": entries}


#: The keys of each entry of the file, and the largest translation an entry may hold [m] (a plain
#: DH calibration of a UR puts a few origins hundreds of metres away; 1 km is no robot).
ENTRY_KEYS = ("x", "y", "z", "roll", "pitch", "yaw")
MAX_ORIGIN_M = 1000.0


def read_ur_calibration(text: str, source) -> dict:
    """The ``kinematics`` document of a UR ROS 2 driver calibration file (what ``ur_calibration``
    extracts from a controller, and what :func:`ur_kinematics` writes), every value checked.

    Parameters
    ----------
    text : str
        The YAML text (comments and a ``hash`` allowed; other keys refused).
    source : str or Path
        Names the file in messages.

    Returns
    -------
    dict
        ``{"kinematics": {shoulder: {x, y, z, roll, pitch, yaw}, ..., "hash": str}}`` [m, rad],
        as :func:`tool0_poses` reads it.

    Raises
    ------
    InputError
        One line naming the file and the key at fault.
    """
    from ..effects.file_values import file_number
    from ..input_files import parse_settings

    doc = parse_settings(text, source, "yaml")
    if not isinstance(doc, dict) or "kinematics" not in doc:
        raise InputError(f"{source}: no 'kinematics' mapping: not a UR calibration file (ur_calibration's, or "
                         "the ur_calibration.yaml export writes)")
    extra = sorted(str(k) for k in doc if k != "kinematics")
    if extra:
        raise InputError(f"{source}: key {extra[0]!r} is not part of a UR calibration file (only 'kinematics')")
    entries = doc["kinematics"]
    if not isinstance(entries, dict):
        raise InputError(f"{source}: kinematics: must map {', '.join(LINKS)} to their origins")
    unknown = sorted(str(k) for k in entries if k not in (*LINKS, "hash"))
    if unknown:
        raise InputError(f"{source}: kinematics.{unknown[0]}: not a joint of a UR arm (its entries: "
                         f"{', '.join(LINKS)}, hash)")
    out = {}
    for name in LINKS:
        entry = entries.get(name)
        if not isinstance(entry, dict):
            raise InputError(f"{source}: kinematics.{name}: missing, or not a mapping of {', '.join(ENTRY_KEYS)}")
        bad = sorted(str(k) for k in entry if k not in ENTRY_KEYS)
        if bad:
            raise InputError(f"{source}: kinematics.{name}.{bad[0]}: not one of {', '.join(ENTRY_KEYS)}")
        values = {}
        for key in ENTRY_KEYS:
            if key not in entry:
                raise InputError(f"{source}: kinematics.{name}.{key}: missing")
            values[key] = file_number(entry[key], f"{source}: kinematics.{name}.{key}")
            limit = MAX_ORIGIN_M if key in "xyz" else 4 * np.pi
            if abs(values[key]) > limit:
                unit = "m" if key in "xyz" else "rad"
                raise InputError(f"{source}: kinematics.{name}.{key}: {values[key]:g} {unit} is beyond {limit:g} "
                                 f"{unit}: no robot's joint origin")
        out[name] = values
    if "hash" in entries:
        if not isinstance(entries["hash"], str) or len(entries["hash"]) > 200:
            raise InputError(f"{source}: kinematics.hash: must be a short text")
        out["hash"] = entries["hash"]
    return {"kinematics": out}


def tool0_poses(document: dict, q) -> np.ndarray:
    """(N, 4, 4) ``base_link_M_tool0`` of the chain a kinematics document describes, at joints q
    (N, 6) [rad]: the xacro's joints, ``origin * Rz(q)`` each, between its fixed frames."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    entries = document["kinematics"]
    origins = [pin.SE3(pin.rpy.rpyToMatrix(*(entries[n][k] for k in ("roll", "pitch", "yaw"))),
                       np.array([entries[n][k] for k in ("x", "y", "z")], dtype=float)) for n in LINKS]
    out = np.empty((len(q), 4, 4))
    for i, values in enumerate(q):
        pose = BASE_LINK_INERTIA
        for origin, value in zip(origins, values):
            pose = pose * origin * pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, value), np.zeros(3))
        out[i] = (pose * WRIST_3_TO_TOOL0).homogeneous
    return out


def _link_frames(origins: list[pin.SE3]) -> list[pin.SE3]:
    """base_link_inertia and the six UR link frames at q = 0, in base_link."""
    frames = [BASE_LINK_INERTIA]
    for origin in origins:
        frames.append(frames[-1] * origin)
    return frames


def _joint_frames(robot: RobotModel) -> list[pin.SE3]:
    """oMi of the six joints at q = 0."""
    data = robot.model.createData()
    pin.forwardKinematics(robot.model, data, robot.to_pinocchio_q(np.zeros(robot.n_joints)))
    return [data.oMi[j + 1].copy() for j in range(robot.n_joints)]
