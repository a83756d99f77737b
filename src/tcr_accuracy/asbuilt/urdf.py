"""An as-built (perturbed or calibrated) robot written back to URDF, for other tools.

Pinocchio's ``parentMjoint`` is the URDF ``<origin>`` of the joint, preceded by any fixed
joints between the parent moving joint and the joint's parent link: ``P = F * O``. A
perturbed placement ``P'`` therefore needs the new origin ``O' = O * (P^-1 P')``, whatever F
is; a joint zero offset is part of ``P'`` (``exp6(axis * offset)`` on the right), so the
joint's values mean what the controller's mean.

The robot's own frames stay where the maker put them: the TCP frame (``tool0``, REP 199's
flange) and every fixed frame keep their origins. The measured point (a reflector, a marker, a
tool tip) and the fitted error of the TCP frame become a frame of their own,
``<tool>_measured``, hung on the TCP frame by a fixed joint: ``toolMmeasured = exp6(xi_tool)``.
"""

from __future__ import annotations

from xml.etree import ElementTree

import numpy as np
import pinocchio as pin

from ..exceptions import InputError
from ..model.errors import ErrorModel
from ..model.robot import RobotModel
from ..model.urdf import parse_urdf_xml

#: Suffix of the frame the measured point gets (``tool0`` -> ``tool0_measured``).
MEASURED_SUFFIX = "_measured"


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
                  name: str | None = None, *, comment: str | None = None) -> tuple[str, str]:
    """URDF text of the robot with error vector x (n_params,) built in.

    Parameters
    ----------
    robot : RobotModel
        The nominal robot.
    x : ndarray of shape (n_params,)
        Error parameters [SI] in the layout of ``error_model``: joint placements and drive
        offsets go into the joints' origins, the base twist into the root joints', the TCP
        twist into the new measured frame.
    error_model : ErrorModel, optional
        Layout of x; built from the robot when omitted.
    name : str, optional
        The robot name written in the URDF; default the nominal URDF's.
    comment : str, optional
        Text of an XML comment at the top (what the URDF is, how accurate); ``--`` is replaced.

    Returns
    -------
    (urdf_text, measured_frame): the URDF, and the name of the measured frame in it
    (``<tool>_measured``, a child of the unchanged TCP frame).

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot("ur5")
    >>> x = tcr.ErrorModel(robot).zeros()
    >>> x[0] = 1e-4  # shoulder_pan_joint.dx: its placement 0.1 mm off
    >>> text, measured_frame = tcr.as_built_urdf(robot, x, name="ur5_as_built")
    >>> measured_frame, 'name="ur5_as_built"' in text
    ('tool0_measured', True)
    """
    error_model = error_model or ErrorModel(robot)
    root = parse_urdf_xml(robot.urdf_text, robot.name)
    if name:
        root.set("name", name)
    joints = {j.get("name"): j for j in root.findall("joint")}
    placements, tool = error_model.perturbed_placements(x)
    _set_joint_placements(root, robot, placements)
    measured = f"{robot.tool_frame}{MEASURED_SUFFIX}"
    links = {link.get("name") for link in root.findall("link")}
    if measured in links or measured in joints:
        raise InputError(f"{robot.name}: the URDF already has a {measured!r}; the measured frame needs that name")
    joint = ElementTree.SubElement(root, "joint", name=f"{measured}_joint", type="fixed")
    ElementTree.SubElement(joint, "parent", link=_link_of_frame(root, robot.tool_frame, links))
    ElementTree.SubElement(joint, "child", link=measured)
    _set_origin(ElementTree.SubElement(joint, "origin"), robot.tool_placement.inverse() * tool)
    ElementTree.SubElement(root, "link", name=measured)
    ElementTree.indent(root, space="  ")
    header = '<?xml version="1.0"?>\n'
    if comment:
        header += "<!-- " + comment.replace("--", "- -") + " -->\n"
    return header + ElementTree.tostring(root, encoding="unicode") + "\n", measured


def urdf_with_placements(robot: RobotModel, placements, tool: pin.SE3, *, comment: str | None = None) -> str:
    """URDF text of ``robot`` whose chain joints sit at ``placements`` and whose TCP frame at ``tool``:
    the robot's own (factory) kinematics written into its URDF, every other element unchanged.

    Parameters
    ----------
    robot : RobotModel
        The robot whose URDF is rewritten.
    placements : sequence of pin.SE3, one per chain joint
        The new ``parentMjoint`` at q = 0.
    tool : pin.SE3
        The new ``jointMtool``; the TCP frame must hang on a fixed joint to move (REP 199's ``tool0`` does).
    comment : str, optional
        An XML comment at the top.

    Returns
    -------
    str
    """
    root = parse_urdf_xml(robot.urdf_text, robot.name)
    _set_joint_placements(root, robot, placements)
    change = robot.tool_placement.inverse() * tool
    if np.abs(pin.log6(change).vector).max() > 1e-12:
        carrier = next((j for j in root.findall("joint") if j.find("child") is not None
                        and j.find("child").get("link") == robot.tool_frame), None)
        if carrier is None or carrier.get("type") != "fixed":
            raise InputError(f"{robot.name}: the TCP frame {robot.tool_frame} is no link on a fixed joint; its "
                             "placement cannot change in the URDF")
        origin, o = _origin_of(carrier)
        _set_origin(origin, o * change)
    ElementTree.indent(root, space="  ")
    header = '<?xml version="1.0"?>\n'
    if comment:
        header += "<!-- " + comment.replace("--", "- -") + " -->\n"
    return header + ElementTree.tostring(root, encoding="unicode") + "\n"


def _set_joint_placements(root: ElementTree.Element, robot: RobotModel, placements) -> None:
    """Each chain joint's ``<origin>`` in the URDF tree ``root`` rewritten so that its placement is the new one."""
    joints = {j.get("name"): j for j in root.findall("joint")}
    for nominal, new, joint_name in zip(robot.joint_placements, placements, robot.joint_names):
        element = joints.get(joint_name)
        if element is None:
            raise InputError(f"{robot.name}: joint {joint_name} of the model is not in its URDF")
        origin, o = _origin_of(element)
        _set_origin(origin, o * (nominal.inverse() * new))


def _link_of_frame(root: ElementTree.Element, frame: str, links: set) -> str:
    """The link whose frame is ``frame``: the link itself, or the child link of the joint of that name."""
    if frame in links:
        return frame
    for joint in root.findall("joint"):
        child = joint.find("child")
        if joint.get("name") == frame and child is not None:
            return child.get("link")
    raise InputError(f"the URDF has no link or joint named {frame!r} to hang the measured frame on")
