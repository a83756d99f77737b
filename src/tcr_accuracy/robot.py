"""Load a serial robot (URDF file, example-robot-data name, or the built-in
tool-changer) into a Pinocchio model plus a TCP frame.

Conventions, stated once:

* Joint values ("q") are one number per 1-DoF joint of the chain from the base to
  the TCP, in SI units: rad for revolute joints, m for prismatic ones. Joints of
  the URDF that do not carry the TCP (a gripper's fingers, another arm) are locked
  at zero and left out of the model.
* ``model.jointPlacements[j]`` is ``parentMjoint`` at q = 0; the TCP frame's
  placement is ``jointMtool``.
* Continuous joints are read as unbounded revolute joints.
"""

from __future__ import annotations

import math
import re
import sys
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from xml.etree import ElementTree

import numpy as np
import pinocchio as pin

from .exceptions import InputError
from .tool_changer import WORKING_POSE, tool_changer_urdf

REVOLUTE = "revolute"
PRISMATIC = "prismatic"

#: Robots of example-robot-data loadable by name: (URDF path under robots/, TCP frame).
EXAMPLE_ROBOTS: dict[str, tuple[str, str]] = {
    "ur3": ("ur_description/urdf/ur3_robot.urdf", "tool0"),
    "ur5": ("ur_description/urdf/ur5_robot.urdf", "tool0"),
    "ur10": ("ur_description/urdf/ur10_robot.urdf", "tool0"),
    "panda": ("panda_description/urdf/panda.urdf", "panda_hand_tcp"),
    "z1": ("z1_description/urdf/z1.urdf", "link06"),
    "xarm7": ("xarm_description/urdf/xarm7.urdf", "link7"),
}

BUILTIN_NAME = "tool_changer"


@dataclass
class RobotModel:
    """A serial chain from the base to a TCP frame.

    Attributes
    ----------
    model : pin.Model
        Pinocchio model holding only the joints that move the TCP. Never changed
        in place by this package: perturbations build a new ``RobotModel``.
    tool_frame : str
        Name of the TCP frame.
    name : str
        Short name for reports (file stem, example-robot-data name, ``tool_changer``).
    urdf_text : str
        The URDF the model was built from (kept for export and the viewer).
    urdf_path : Path or None
        Where the URDF came from, if a file.
    package_dirs : list of str
        Folders in which ``package://`` mesh paths are resolved.
    working_pose : ndarray of shape (n_joints,)
        A representative pose [rad, m] (the seed's pose for the tool-changer, zero otherwise).
    """

    model: pin.Model
    tool_frame: str
    name: str
    urdf_text: str
    urdf_path: Path | None = None
    package_dirs: list[str] = field(default_factory=list)
    working_pose: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.working_pose is None:
            self.working_pose = np.zeros(self.n_joints)

    # -- structure -------------------------------------------------------------------
    @property
    def tool_frame_id(self) -> int:
        return self.model.getFrameId(self.tool_frame)

    @property
    def n_joints(self) -> int:
        return self.model.njoints - 1

    @property
    def joint_names(self) -> list[str]:
        return list(self.model.names)[1:]

    @property
    def joint_kinds(self) -> list[str]:
        return [_joint_kind(self.model.joints[j]) for j in range(1, self.model.njoints)]

    @property
    def lower_limits(self) -> np.ndarray:
        """(n_joints,) lower joint limits [rad or m]; -inf where unbounded."""
        return self._limits(self.model.lowerPositionLimit)

    @property
    def upper_limits(self) -> np.ndarray:
        """(n_joints,) upper joint limits [rad or m]; +inf where unbounded."""
        return self._limits(self.model.upperPositionLimit)

    def _limits(self, pin_limits: np.ndarray) -> np.ndarray:
        out = np.empty(self.n_joints)
        for j in range(1, self.model.njoints):
            joint = self.model.joints[j]
            out[j - 1] = pin_limits[joint.idx_q] if joint.nq == 1 else math.nan
        # URDF limits of continuous joints are meaningless: pin stores +-max float
        out[~np.isfinite(out) | (np.abs(out) > 1e30)] = math.nan
        return out

    @property
    def motion_axes(self) -> np.ndarray:
        """(n_joints, 6) joint motion twists (v, w) in each joint's own frame.

        A revolute joint about unit axis a has (0, a); a prismatic one (a, 0).
        """
        data = self.model.createData()
        q0 = pin.neutral(self.model)
        pin.computeJointJacobians(self.model, data, q0)
        axes = np.empty((self.n_joints, 6))
        for j in range(1, self.model.njoints):
            jac = pin.getJointJacobian(self.model, data, j, pin.LOCAL)
            axes[j - 1] = jac[:, self.model.joints[j].idx_v]
        return axes

    @property
    def joint_placements(self) -> list[pin.SE3]:
        """Nominal ``parentMjoint`` for each joint (copies)."""
        return [pin.SE3(self.model.jointPlacements[j]) for j in range(1, self.model.njoints)]

    @property
    def tool_placement(self) -> pin.SE3:
        """``jointMtool``: the TCP frame in its parent joint's frame (a copy)."""
        return pin.SE3(self.model.frames[self.tool_frame_id].placement)

    # -- joint values ----------------------------------------------------------------
    def to_pinocchio_q(self, q: np.ndarray) -> np.ndarray:
        """Joint values (n_joints,) [rad, m] to Pinocchio's configuration vector (nq,)."""
        q = np.asarray(q, dtype=float)
        out = pin.neutral(self.model)
        for j in range(1, self.model.njoints):
            joint = self.model.joints[j]
            if joint.nq == 1:
                out[joint.idx_q] = q[j - 1]
            else:  # unbounded revolute stored as (cos, sin)
                out[joint.idx_q] = math.cos(q[j - 1])
                out[joint.idx_q + 1] = math.sin(q[j - 1])
        return out

    def check_joint_values(self, q: np.ndarray, *, source: str = "--q") -> np.ndarray:
        """Validate joint values (n_joints,) [SI]: count and finiteness raise, limits warn."""
        q = np.asarray(q, dtype=float)
        if q.shape != (self.n_joints,):
            raise InputError(
                f"{source}: expected {self.n_joints} joint values "
                f"({', '.join(self.joint_names)}), got {q.size}"
            )
        bad = ~np.isfinite(q)
        if bad.any():
            name = self.joint_names[int(np.argmax(bad))]
            raise InputError(f"{source}: joint {name} has a non-finite value ({q[bad][0]})")
        lo, hi = self.lower_limits, self.upper_limits
        outside = (q < lo) | (q > hi)  # NaN limits compare False: unbounded
        for j in np.flatnonzero(outside):
            unit = self.display_units[j]
            scale = self.display_scale[j]
            warnings.warn(
                f"{source}: joint {self.joint_names[j]} = {q[j] * scale:.6g} {unit} is outside "
                f"its limits [{lo[j] * scale:.6g}, {hi[j] * scale:.6g}] {unit}",
                JointLimitWarning,
                stacklevel=2,
            )
        return q

    @property
    def display_units(self) -> list[str]:
        """Units used at the edges: 'deg' for revolute joints, 'mm' for prismatic ones."""
        return ["deg" if k == REVOLUTE else "mm" for k in self.joint_kinds]

    @property
    def display_scale(self) -> np.ndarray:
        """(n_joints,) factors from SI joint values to display units."""
        return np.array([180.0 / math.pi if k == REVOLUTE else 1000.0 for k in self.joint_kinds])

    # -- copies ----------------------------------------------------------------------
    def with_model(self, model: pin.Model, name: str | None = None) -> "RobotModel":
        """A new RobotModel sharing everything but the Pinocchio model."""
        return RobotModel(
            model=model,
            tool_frame=self.tool_frame,
            name=name or self.name,
            urdf_text=self.urdf_text,
            urdf_path=self.urdf_path,
            package_dirs=list(self.package_dirs),
            working_pose=np.array(self.working_pose),
        )


class JointLimitWarning(UserWarning):
    """A joint value lies outside the URDF limits (the analysis still runs)."""


def _joint_kind(joint: pin.JointModel) -> str:
    short = joint.shortname()
    if short.startswith("JointModelR"):
        return REVOLUTE
    if short.startswith("JointModelP"):
        return PRISMATIC
    raise InputError(
        f"joint type {short} is not supported: tcr-accuracy handles serial chains of "
        "revolute, continuous and prismatic joints"
    )


def example_robot_data_dir() -> Path:
    """The ``share`` folder of the example-robot-data wheel (holds robots/...)."""
    for entry in sys.path:
        candidate = Path(entry) / "cmeel.prefix" / "share"
        if (candidate / "example-robot-data" / "robots").is_dir():
            return candidate
    raise InputError(
        "example-robot-data is not installed: pip install example-robot-data"
    )


_ENTITY = re.compile(r"<!\s*(ENTITY|DOCTYPE)", re.IGNORECASE)
MAX_URDF_BYTES = 50 * 1024 * 1024


def read_urdf_text(path: Path) -> str:
    """Read a URDF file, refusing DTDs and entities (no entity expansion, ever)."""
    try:
        size = path.stat().st_size
    except OSError as exc:
        raise InputError(f"{path}: cannot read URDF ({exc.strerror})") from None
    if size > MAX_URDF_BYTES:
        raise InputError(f"{path}: URDF is {size} bytes, larger than the {MAX_URDF_BYTES} allowed")
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read URDF as UTF-8 text ({exc})") from None
    return text


def parse_urdf_xml(text: str, source: str) -> ElementTree.Element:
    """Parse URDF text into an element tree, with one clear line on failure."""
    match = _ENTITY.search(text)
    if match:
        line = text.count("\n", 0, match.start()) + 1
        raise InputError(
            f"{source}: line {line}: URDF declares a DTD or entity (<!{match.group(1)}); "
            "entity expansion is refused"
        )
    try:
        root = ElementTree.fromstring(text)
    except ElementTree.ParseError as exc:
        raise InputError(f"{source}: URDF does not parse as XML ({exc})") from None
    if root.tag != "robot":
        raise InputError(f"{source}: root element is <{root.tag}>, a URDF needs <robot>")
    return root


def load_robot(source: str | Path | None = None, tool: str | None = None) -> RobotModel:
    """Load a robot and its TCP frame.

    Parameters
    ----------
    source : str or Path, optional
        A URDF file path, the name of an example-robot-data robot (see
        ``EXAMPLE_ROBOTS``), or ``None``/``"tool_changer"`` for the built-in
        shield-machine tool-changer.
    tool : str, optional
        TCP frame name. Defaults: ``tool`` for the tool-changer, the table entry
        for named robots, and for a URDF file the single leaf link of the tree.

    Raises
    ------
    InputError
        The URDF does not exist or parse, the frame is unknown, or a joint kind is
        not supported.
    """
    package_dirs: list[str] = []
    urdf_path: Path | None = None
    working_pose = None
    if source is None or str(source) == BUILTIN_NAME:
        text = tool_changer_urdf()
        name = BUILTIN_NAME
        tool = tool or "tool"
        working_pose = WORKING_POSE.copy()
        label = "built-in tool_changer"
    elif Path(source).is_file():
        urdf_path = Path(source).resolve()
        text = read_urdf_text(urdf_path)
        name = urdf_path.stem
        package_dirs = [str(urdf_path.parent), str(urdf_path.parent.parent)]
        label = str(source)
        if urdf_path.stem == "tool_changer":
            working_pose = WORKING_POSE.copy()
    elif str(source).lower() in EXAMPLE_ROBOTS:
        share = example_robot_data_dir()
        rel, default_tool = EXAMPLE_ROBOTS[str(source).lower()]
        urdf_path = share / "example-robot-data" / "robots" / rel
        text = read_urdf_text(urdf_path)
        name = str(source).lower()
        tool = tool or default_tool
        package_dirs = [str(share)]
        label = f"{name} ({urdf_path})"
    else:
        raise InputError(
            f"--robot {source}: no such file, and not a known robot name "
            f"(known: {BUILTIN_NAME}, {', '.join(EXAMPLE_ROBOTS)})"
        )
    return robot_from_urdf_text(
        text, tool, name=name, source=label, urdf_path=urdf_path,
        package_dirs=package_dirs, working_pose=working_pose,
    )


def robot_from_urdf_text(
    text: str,
    tool: str | None,
    *,
    name: str = "robot",
    source: str = "<urdf>",
    urdf_path: Path | None = None,
    package_dirs: list[str] | None = None,
    working_pose: np.ndarray | None = None,
) -> RobotModel:
    """Build a :class:`RobotModel` from URDF text (see :func:`load_robot`)."""
    root = parse_urdf_xml(text, source)
    if tool is None:
        tool = _single_leaf_link(root, source)
    try:
        full = pin.buildModelFromXML(text)
    except Exception as exc:  # pinocchio raises plain RuntimeError/ValueError
        raise InputError(f"{source}: Pinocchio cannot build a model from this URDF ({exc})") from None
    if not full.existFrame(tool):
        names = sorted({f.name for f in full.frames if f.name != "universe"})
        raise InputError(
            f"--tool {tool}: no such frame in {source} (frames: {', '.join(names)})"
        )
    frame = full.frames[full.getFrameId(tool)]
    chain = set(full.supports[frame.parentJoint])
    locked = [j for j in range(1, full.njoints) if j not in chain]
    if locked:
        model = pin.buildReducedModel(full, locked, pin.neutral(full))
    else:
        model = full
    if model.njoints <= 1:
        raise InputError(f"--tool {tool}: no joint moves this frame in {source}")
    for j in range(1, model.njoints):
        _joint_kind(model.joints[j])  # raises for unsupported kinds
    robot = RobotModel(
        model=model,
        tool_frame=tool,
        name=name,
        urdf_text=text,
        urdf_path=urdf_path,
        package_dirs=list(package_dirs or []),
        working_pose=working_pose,
    )
    return robot


def _single_leaf_link(root: ElementTree.Element, source: str) -> str:
    links = [link.get("name") for link in root.findall("link")]
    parents = {joint.find("parent").get("link") for joint in root.findall("joint")
               if joint.find("parent") is not None}
    leaves = [link for link in links if link not in parents]
    if len(leaves) != 1:
        raise InputError(
            f"{source}: give the TCP frame with --tool (leaf links: {', '.join(leaves) or 'none'})"
        )
    return leaves[0]
