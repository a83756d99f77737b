"""Export an as-built (perturbed or calibrated) robot back to URDF, for other tools.

Pinocchio's ``parentMjoint`` is the URDF ``<origin>`` of the joint, preceded by any
fixed joints between the parent moving joint and the joint's parent link: ``P = F *
O``. A perturbed placement ``P'`` therefore needs the new origin ``O' = O * (P^-1 P')``,
whatever F is. The TCP frame is handled the same way through the fixed joint that
attaches it; when the TCP is the frame of a moving link, a fixed child link named
``<tool>_as_built`` is added and carries the TCP error.
"""

from __future__ import annotations

from xml.etree import ElementTree

import numpy as np
import pinocchio as pin

from .errors import ErrorModel
from ..exceptions import InputError
from .robot import RobotModel
from .urdf import parse_urdf_xml


def _origin_of(joint: ElementTree.Element) -> tuple[ElementTree.Element, pin.SE3]:
    origin = joint.find("origin")
    if origin is None:
        origin = ElementTree.SubElement(joint, "origin")
    xyz = np.array([float(v) for v in origin.get("xyz", "0 0 0").split()])
    rpy = np.array([float(v) for v in origin.get("rpy", "0 0 0").split()])
    return origin, pin.SE3(pin.rpy.rpyToMatrix(rpy), xyz)


def _set_origin(origin: ElementTree.Element, placement: pin.SE3) -> None:
    origin.set("xyz", " ".join(repr(float(v)) for v in placement.translation))
    origin.set("rpy", " ".join(repr(float(v)) for v in pin.rpy.matrixToRpy(placement.rotation)))


def as_built_urdf(robot: RobotModel, x: np.ndarray, error_model: ErrorModel | None = None,
                  name: str | None = None) -> tuple[str, str]:
    """URDF text of the robot with error vector x (n_params,) built in.

    Parameters
    ----------
    robot : RobotModel
        The nominal robot.
    x : ndarray of shape (n_params,)
        Error parameters [SI] in the layout of ``error_model``.
    error_model : ErrorModel, optional
        Layout of x; built from the robot when omitted.
    name : str, optional
        The robot name written in the URDF; default the nominal URDF's.

    Returns
    -------
    (urdf_text, tool_frame): the URDF, and the name of the TCP frame in it (the same
    as the robot's unless a ``<tool>_as_built`` link had to be added).
    """
    error_model = error_model or ErrorModel(robot)
    root = parse_urdf_xml(robot.urdf_text, robot.name)
    if name:
        root.set("name", name)
    joints = {j.get("name"): j for j in root.findall("joint")}
    placements, tool = error_model.perturbed_placements(x)
    for nominal, new, joint_name in zip(robot.joint_placements, placements, robot.joint_names):
        element = joints.get(joint_name)
        if element is None:
            raise InputError(f"{robot.name}: joint {joint_name} of the model is not in its URDF")
        origin, o = _origin_of(element)
        _set_origin(origin, o * (nominal.inverse() * new))
    delta_tool = robot.tool_placement.inverse() * tool
    tool_frame = robot.tool_frame
    attaching = _fixed_joint_for_frame(root, robot.tool_frame)
    if attaching is not None:
        origin, o = _origin_of(attaching)
        _set_origin(origin, o * delta_tool)
    elif not np.allclose(delta_tool.homogeneous, np.eye(4), atol=0.0, rtol=0.0):
        tool_frame = f"{robot.tool_frame}_as_built"
        joint = ElementTree.SubElement(root, "joint", name=f"{tool_frame}_joint", type="fixed")
        ElementTree.SubElement(joint, "parent", link=robot.tool_frame)
        ElementTree.SubElement(joint, "child", link=tool_frame)
        _set_origin(ElementTree.SubElement(joint, "origin"), delta_tool)
        ElementTree.SubElement(root, "link", name=tool_frame)
    ElementTree.indent(root, space="  ")
    text = '<?xml version="1.0"?>\n' + ElementTree.tostring(root, encoding="unicode") + "\n"
    return text, tool_frame


def _fixed_joint_for_frame(root: ElementTree.Element, frame: str) -> ElementTree.Element | None:
    """The fixed joint named ``frame`` or whose child link is ``frame``."""
    for joint in root.findall("joint"):
        if joint.get("type") != "fixed":
            continue
        child = joint.find("child")
        if joint.get("name") == frame or (child is not None and child.get("link") == frame):
            return joint
    return None
