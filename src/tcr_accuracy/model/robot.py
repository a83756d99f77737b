"""Load a serial robot (URDF file, example-robot-data name, or the built-in
tool-changer) into a Pinocchio model plus a TCP frame.

Conventions, stated once:

* Joint values ("q") are one number per 1-DoF joint of the chain from the base to
  the TCP, in SI units: rad for revolute joints, m for prismatic ones. Joints of
  the URDF that do not carry the TCP (a gripper's fingers, another arm, a head) are
  left out of the kinematic chain (``model``) but kept in ``full_model``, where their
  masses load the chain: gravity torques are computed on the whole tree, with those
  joints at measured values (:class:`~tcr_accuracy.model.context.MeasurementContext`'s
  ``outside_q``) or at their neutral value.
* ``model.jointPlacements[j]`` is ``parentMjoint`` at q = 0; the TCP frame's
  placement is ``jointMtool``.
* Continuous joints are read as unbounded revolute joints; their limits are NaN.
* URDF allows a link and a joint of the same name (``torso_0`` the link and
  ``torso_0`` the joint); frames are therefore looked up with their type, links first.
* A URDF ``<mimic>`` joint stays an ordinary joint of the model (so its offset can
  be fitted like any other); where its value is not given, it follows its rule
  ``q = multiplier * q_source + offset`` (:attr:`RobotModel.mimic`).

One concept, the robot (:class:`RobotModel` and the loading that builds it: URDF, example-robot-data
or the built-in tool-changer, chain and mimic rules), and so one module above 500 lines.
"""

from __future__ import annotations

import math
import re
import sys
import warnings
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np
import pinocchio as pin

from ..exceptions import FixedFrameError, InputError
from .tool_changer import DISC_CUTTER_MASS, WORKING_POSE, tool_changer_urdf
from ..units import JOINT_DISPLAY, PRISMATIC, REVOLUTE  # noqa: F401 - PRISMATIC: part of this module's vocabulary
from .mesh_resources import check_mesh_references
from .ros_packages import (find_packages, given_package_dirs, mesh_places, missing_mesh_message, package_of,
                           ros_package_path, urdf_with_located_meshes)
from .urdf import (
    MAX_CHAIN_JOINTS,
    check_mesh_paths,
    check_urdf,
    find_frame,
    joint_kind,
    mimic_rules,
    parse_urdf_xml,
    read_urdf_text,
    one_line,
    quiet_native_stderr,
    reduce_model,
    single_leaf_link,
)

#: Robots of example-robot-data loadable by name: (URDF path under robots/, TCP frame).
EXAMPLE_ROBOTS: dict[str, tuple[str, str]] = {
    "ur3": ("ur_description/urdf/ur3_robot.urdf", "tool0"),
    "ur5": ("ur_description/urdf/ur5_robot.urdf", "tool0"),
    "ur10": ("ur_description/urdf/ur10_robot.urdf", "tool0"),
    "panda": ("panda_description/urdf/panda.urdf", "panda_hand_tcp"),
    "z1": ("z1_description/urdf/z1.urdf", "link06"),
    "xarm7": ("xarm_description/urdf/xarm7.urdf", "link7"),
    "kinova": ("kinova_description/robots/kinova.urdf", "j2s6s200_end_effector"),
}

BUILTIN_NAME = "tool_changer"


@dataclass
class RobotModel:
    """A serial chain from the base to a TCP frame, inside the robot's whole kinematic tree.

    Attributes
    ----------
    model : pin.Model
        Pinocchio model holding only the joints that move the TCP (the other joints
        locked at their neutral value). Never changed in place by this package:
        perturbations build a new ``RobotModel``.
    tool_frame : str
        Name of the TCP frame.
    name : str
        Short name for reports (the URDF's robot name, example-robot-data name, ``tool_changer``).
    urdf_text : str
        The URDF the model was built from (kept for export and the viewer).
    urdf_path : Path or None
        Where the URDF came from, if a file.
    package_dirs : list of str
        Folders in which ``package://NAME/...`` mesh paths are looked for as ``DIR/NAME/...``
        when NAME is not in ``packages`` (``--package-dir`` folders, then the URDF's folder and
        the one above it, or example-robot-data's ``share`` folder).
    packages : dict of str to str
        The folder of each ROS package the URDF's meshes name that was found (in
        ``--package-dir`` folders, ``ROS_PACKAGE_PATH`` or around the URDF; see
        :mod:`tcr_accuracy.model.ros_packages`).
    working_pose : ndarray of shape (n_joints,)
        A representative pose [rad, m] (the seed's pose for the tool-changer; otherwise zero for
        every joint whose limits hold zero and the middle of its range for the others, see
        :func:`default_working_pose`).
    full_model : pin.Model or None
        Every joint of the URDF (None: the same as ``model``). Gravity uses it.
    chain_joint_ids : tuple of int
        ``full_model`` joint index of each chain joint, in chain order.
    tool_frame_id : int
        Index of the TCP frame in ``model.frames`` (found by name and type).
    mimic : dict of str to Mimic
        URDF ``<mimic>`` rules, by joint name (chain or outside joints).
    payload_kg : float or None
        The payload an analysis assumes by default [kg] (the 150 kg disc cutter of the
        tool-changer); None: a fifth of the moving links' mass (:attr:`typical_payload_kg`).
    robot_source : str or None
        How :func:`load_robot` loads this robot again: ``tool_changer``, an example-robot-data
        name (``ur5``) or the URDF's absolute path; None for a robot built otherwise (from URDF
        text, or a perturbed copy), which a result file cannot name.
    mounting_plane_z : float or None
        The plane the robot stands on [m], base frame z: random poses keep the TCP and the joints on
        or above it (0: an arm bolted to a floor or a table by its base); None for the tool-changer,
        which works below its base inside the cutterhead.
    kinematics : dict or None
        Where the robot's own (factory) kinematics came from, when they replace the URDF's: the
        file's name, its format and SHA-256, and the joint and TCP-frame placements it gave
        (``file``, ``format``, ``sha256``, ``placements``; :mod:`tcr_accuracy.asbuilt.factory_kinematics`).
        None: the URDF's own (the catalogue's) kinematics.

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot("ur5")
    >>> robot.n_joints, robot.tool_frame, robot.robot_source
    (6, 'tool0', 'ur5')
    >>> robot.joint_names[:2]
    ['shoulder_pan_joint', 'shoulder_lift_joint']
    """

    model: pin.Model
    tool_frame: str
    name: str
    urdf_text: str
    urdf_path: Path | None = None
    package_dirs: list[str] = field(default_factory=list)
    packages: dict = field(default_factory=dict)
    working_pose: np.ndarray | None = None
    full_model: pin.Model | None = None
    chain_joint_ids: tuple = ()
    tool_frame_id: int = -1
    mimic: dict = field(default_factory=dict)
    payload_kg: float | None = None
    robot_source: str | None = None
    mounting_plane_z: float | None = 0.0
    kinematics: dict | None = None

    def __post_init__(self) -> None:
        if self.working_pose is None:
            self.working_pose = default_working_pose(self.lower_limits, self.upper_limits)
        if self.full_model is None:
            self.full_model = self.model
            self.chain_joint_ids = tuple(range(1, self.model.njoints))
        if self.tool_frame_id < 0:
            self.tool_frame_id = find_frame(self.model, self.tool_frame)

    def __repr__(self) -> str:
        source = f", urdf={Path(self.urdf_path).name!r}" if self.urdf_path is not None else ""
        return f"RobotModel({self.name!r}, {self.n_joints} joints, tool_frame={self.tool_frame!r}{source})"

    # -- structure (the model never changes in place, so these are computed once) -----
    @property
    def n_joints(self) -> int:
        return self.model.njoints - 1

    @cached_property
    def joint_names(self) -> list[str]:
        return list(self.model.names)[1:]

    @cached_property
    def joint_kinds(self) -> list[str]:
        return [joint_kind(self.model.joints[j]) for j in range(1, self.model.njoints)]

    @cached_property
    def outside_joint_names(self) -> list[str]:
        """1-DoF joints of the URDF that do not move the TCP (full-model order)."""
        chain = set(self.chain_joint_ids)
        full = self.full_model
        return [full.names[j] for j in range(1, full.njoints) if j not in chain and full.joints[j].nv == 1]

    @cached_property
    def outside_joint_kinds(self) -> list[str]:
        full = self.full_model
        return [joint_kind(full.joints[full.getJointId(n)]) for n in self.outside_joint_names]

    @property
    def lower_limits(self) -> np.ndarray:
        """(n_joints,) lower joint limits [rad or m]; NaN where unbounded."""
        return self._limits(self.model.lowerPositionLimit)

    @property
    def upper_limits(self) -> np.ndarray:
        """(n_joints,) upper joint limits [rad or m]; NaN where unbounded."""
        return self._limits(self.model.upperPositionLimit)

    def joint_bounds(self, unbounded: float = math.pi) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper), each (n_joints,) [rad or m], with +-``unbounded`` where a joint has no limit."""
        lo, hi = self.lower_limits, self.upper_limits
        return np.where(np.isnan(lo), -unbounded, lo), np.where(np.isnan(hi), unbounded, hi)

    def _limits(self, pin_limits: np.ndarray) -> np.ndarray:
        out = np.empty(self.n_joints)
        for j in range(1, self.model.njoints):
            joint = self.model.joints[j]
            out[j - 1] = pin_limits[joint.idx_q] if joint.nq == 1 else math.nan
        # URDF limits of continuous joints are meaningless: pin stores +-max float
        out[~np.isfinite(out) | (np.abs(out) > 1e30)] = math.nan
        return out

    @cached_property
    def motion_axes(self) -> np.ndarray:
        """(n_joints, 6) joint motion twists (v, w) in each joint's own frame.

        A revolute joint about unit axis a has (0, a); a prismatic one (a, 0).
        """
        data = self.model.createData()
        q0 = pin.neutral(self.model)
        pin.computeJointJacobians(self.model, data, q0)
        axes = np.empty((self.n_joints, 6))
        for j in range(1, self.model.njoints):
            # (6, nv); eigenpy hands a one-joint model's (6, 1) back as a vector: shaped again
            jac = np.asarray(pin.getJointJacobian(self.model, data, j, pin.LOCAL)).reshape(6, -1)
            axes[j - 1] = jac[:, self.model.joints[j].idx_v]
        axes.setflags(write=False)
        return axes

    def joint_axis(self, j: int) -> np.ndarray:
        """(3,) unit axis of chain joint j in its own frame (rotation axis or sliding direction)."""
        motion = self.motion_axes[j]
        return motion[3:] if self.joint_kinds[j] == REVOLUTE else motion[:3]

    def axis_perpendiculars(self, j: int) -> tuple[np.ndarray, np.ndarray]:
        """Two unit vectors across joint j's axis, (u, v) with u x v = axis, in the joint's frame.

        Coordinate axes when the joint axis is one (z -> (x, y), x -> (y, z), y -> (z, x)),
        so parameters named after them read naturally.
        """
        axis = self.joint_axis(j)
        k = int(np.argmax(np.abs(axis)))
        if abs(abs(axis[k]) - 1.0) < 1e-12:
            sign = math.copysign(1.0, axis[k])
            u = np.eye(3)[(k + 1) % 3]
            return u, sign * np.eye(3)[(k + 2) % 3]
        helper = np.eye(3)[int(np.argmin(np.abs(axis)))]
        u = np.cross(helper, axis)
        u /= np.linalg.norm(u)
        return u, np.cross(axis, u)

    @property
    def joint_placements(self) -> list[pin.SE3]:
        """Nominal ``parentMjoint`` for each joint (copies)."""
        return [pin.SE3(self.model.jointPlacements[j]) for j in range(1, self.model.njoints)]

    @property
    def tool_placement(self) -> pin.SE3:
        """``jointMtool``: the TCP frame in its parent joint's frame (a copy)."""
        return pin.SE3(self.model.frames[self.tool_frame_id].placement)

    @cached_property
    def typical_payload_kg(self) -> float:
        """The payload an analysis assumes by default [kg]: ``payload_kg`` if the robot has one
        (the tool-changer's disc cutter), else a fifth of the moving links' mass."""
        if self.payload_kg is not None:
            return float(self.payload_kg)
        return 0.2 * sum(self.model.inertias[j].mass for j in range(1, self.model.njoints))

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

    def full_configurations(self, q: np.ndarray, outside_q: np.ndarray | None = None) -> np.ndarray:
        """``full_model`` configurations (N, nq_full) from chain joints q (N, n_joints) [SI] and
        the outside joints' values (N, n_outside) (None: neutral, or the mimic rule)."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        full = self.full_model
        out = np.tile(pin.neutral(full), (q.shape[0], 1))
        values = dict(zip(self.chain_joint_ids, q.T))
        names = self.outside_joint_names
        if outside_q is not None:
            outside_q = np.atleast_2d(np.asarray(outside_q, dtype=float))
            for k, name in enumerate(names):
                values[full.getJointId(name)] = outside_q[:, k]
        else:
            for name in names:
                rule = self.mimic.get(name)
                if rule is not None and rule.joint in self.joint_names:
                    source = q[:, self.joint_names.index(rule.joint)]
                    values[full.getJointId(name)] = rule.multiplier * source + rule.offset
        for jid, column in values.items():
            joint = full.joints[jid]
            if joint.nq == 1:
                out[:, joint.idx_q] = column
            else:
                out[:, joint.idx_q] = np.cos(column)
                out[:, joint.idx_q + 1] = np.sin(column)
        return out

    def follow_mimic(self, q: np.ndarray) -> np.ndarray:
        """A copy of joint values q (N, n_joints) [SI] in which every chain joint with a URDF
        ``<mimic>`` rule on another chain joint takes the value its rule gives
        (``multiplier * q_source + offset``), as the real robot would."""
        q = np.array(q, dtype=float, copy=True)
        for j, name in enumerate(self.joint_names):
            rule = self.mimic.get(name)
            if rule is not None and rule.joint in self.joint_names:
                q[..., j] = rule.multiplier * q[..., self.joint_names.index(rule.joint)] + rule.offset
        return q

    def within_limits(self, q: np.ndarray) -> np.ndarray:
        """(N,) whether each row of joint values q (N, n_joints) [SI] is within the joint limits
        (an unbounded side, NaN, holds every value)."""
        with np.errstate(invalid="ignore"):
            outside = (q < self.lower_limits - 1e-12) | (q > self.upper_limits + 1e-12)
        return ~outside.any(axis=-1)

    @property
    def has_chain_mimic(self) -> bool:
        """Whether a chain joint follows another chain joint by a ``<mimic>`` rule."""
        return any(rule.joint in self.joint_names for name, rule in self.mimic.items() if name in self.joint_names)

    def check_joint_values(self, q: np.ndarray, *, source: str = "q") -> np.ndarray:
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
        return [JOINT_DISPLAY[k][0] for k in self.joint_kinds]

    @property
    def display_scale(self) -> np.ndarray:
        """(n_joints,) factors from SI joint values to display units."""
        return np.array([JOINT_DISPLAY[k][1] for k in self.joint_kinds])

    # -- visuals -----------------------------------------------------------------------
    @property
    def urdf_source(self) -> str:
        """The URDF file's path, or the robot's name when it has no file, for messages."""
        return str(self.urdf_path) if self.urdf_path is not None else self.name

    def mesh_roots(self) -> list[str]:
        """The folders meshes and the files they reference may come from: the URDF's folder,
        the package folders (``package_dirs``) and the ROS packages found (``packages``)."""
        roots = ([str(self.urdf_path.parent)] if self.urdf_path is not None else []) + list(self.package_dirs)
        return list(dict.fromkeys(roots + [str(p) for p in self.packages.values()]))

    def mesh_places(self, kinds=("visual", "collision")) -> list:
        """Where each mesh of the URDF's ``<visual>`` and/or ``<collision>`` elements points
        (:class:`~tcr_accuracy.model.ros_packages.MeshPlace`, ``path`` None when it is missing)."""
        return mesh_places(parse_urdf_xml(self.urdf_text, self.urdf_source), kinds,
                           self.urdf_path.parent if self.urdf_path is not None else None,
                           self.package_dirs, self.packages)

    def missing_meshes(self, kinds=("visual", "collision")) -> list:
        """The meshes of :meth:`mesh_places` that are found nowhere."""
        return [place for place in self.mesh_places(kinds) if place.path is None]

    def missing_mesh_message(self) -> str | None:
        """One line on the missing meshes and how to provide them, or None when none is missing."""
        missing = self.missing_meshes()
        return missing_mesh_message(self.urdf_source, missing, self.packages) if missing else None

    def geometry_model(self, kind: str = "visual") -> pin.GeometryModel:
        """Pinocchio's ``GeometryModel`` of the URDF's ``<visual>`` or ``<collision>`` elements
        (``kind``) on ``full_model``, each mesh read from the file :meth:`mesh_places` found; an
        element whose mesh is missing is left out (kinematics never needs it). Built once per
        robot and kind (as Pinocchio's ``RobotWrapper`` builds its models once): the URDF and
        its meshes are read on the first call only.

        Raises
        ------
        InputError
            The geometry cannot be read, or (visuals, which views embed) a mesh or a file it
            references (a COLLADA image, an OBJ's material library and its textures) lies outside
            the URDF's folder and the package folders.
        """
        cache = self.__dict__.setdefault("_geometry_models", {})
        if kind not in cache:
            cache[kind] = self._build_geometry_model(kind)
        return cache[kind]

    def _build_geometry_model(self, kind: str) -> pin.GeometryModel:
        roots, source = self.mesh_roots(), self.urdf_source
        root = parse_urdf_xml(self.urdf_text, source)
        places = mesh_places(root, (kind,), self.urdf_path.parent if self.urdf_path is not None else None,
                             self.package_dirs, self.packages)
        if kind == "visual":
            check_mesh_paths(places, source, roots)  # the file each mesh is read from, before anything reads it
            for place in places:
                if place.path is not None:
                    check_mesh_references(place.path, roots, source, place.name)
        text = urdf_with_located_meshes(root, kind, places) if places else self.urdf_text
        geometry_type = pin.GeometryType.VISUAL if kind == "visual" else pin.GeometryType.COLLISION
        with quiet_native_stderr() as said:
            try:
                return pin.buildGeomFromUrdfString(self.full_model, text, geometry_type,
                                                   package_dirs=list(self.package_dirs))
            except Exception as exc:  # pinocchio raises plain RuntimeError/ValueError
                raise InputError(f"{self.name}: cannot read the URDF's {kind} geometry "
                                 f"({one_line(said() or exc)})") from None

    def visual_model(self) -> pin.GeometryModel:
        """Pinocchio's visual ``GeometryModel`` attached to ``model``'s joints (bodies of the
        locked joints at their neutral pose; those whose mesh is missing left out, see
        :meth:`geometry_model`).

        Raises
        ------
        InputError
            See :meth:`geometry_model`.
        """
        cache = self.__dict__.setdefault("_geometry_models", {})
        if "visual_reduced" not in cache:
            geometry = self.geometry_model("visual")
            chain = set(self.chain_joint_ids)
            locked = [j for j in range(1, self.full_model.njoints) if j not in chain]
            cache["visual_reduced"] = geometry if not locked else reduce_model(self.full_model, locked, geometry)[1]
        return cache["visual_reduced"]

    # -- copies ----------------------------------------------------------------------
    def with_model(self, model: pin.Model, name: str | None = None) -> "RobotModel":
        """A new RobotModel sharing everything but the (chain) Pinocchio model."""
        return RobotModel(
            model=model,
            tool_frame=self.tool_frame,
            name=name or self.name,
            urdf_text=self.urdf_text,
            urdf_path=self.urdf_path,
            package_dirs=list(self.package_dirs),
            packages=dict(self.packages),
            working_pose=np.array(self.working_pose),
            full_model=self.full_model,
            chain_joint_ids=self.chain_joint_ids,
            tool_frame_id=self.tool_frame_id,
            mimic=dict(self.mimic),
            payload_kg=self.payload_kg,
            mounting_plane_z=self.mounting_plane_z,
            kinematics=self.kinematics,
        )


class JointLimitWarning(UserWarning):
    """A joint value lies outside the URDF limits (the analysis still runs)."""


class MissingMeshWarning(UserWarning):
    """A mesh the URDF names is found nowhere (kinematics runs; views draw a skeleton)."""

    #: The parameter of :func:`load_robot` that provides it (the command line words it as its flag).
    parameter = "package_dirs"


def urdf_robot_name(text: str) -> str | None:
    """The ``name`` of a URDF's ``<robot>`` element, or None when the text does not say.

    Read from the text alone, with no XML parser (the URDF reader, which refuses entity
    tricks, parses it afterwards and reports any fault).
    """
    match = re.search(r"<robot\b[^>]*?\bname\s*=\s*(\"([^\"<>&]*)\"|'([^'<>&]*)')", text)
    if match is None:
        return None
    return (match.group(2) if match.group(2) is not None else match.group(3)).strip() or None


def default_working_pose(lower, upper) -> np.ndarray:
    """Joint values [rad, m] for a robot without a named working pose: zero where the limits
    hold it, else the middle of the joint's range (the Panda's joint 4 lives in
    [-176, -4] deg), so that the default pose is one the robot can take.

    Parameters
    ----------
    lower, upper : array-like of shape (n_joints,)
        Limits [rad, m]; NaN for an unbounded side.
    """
    lower = np.asarray(lower, dtype=float)
    upper = np.asarray(upper, dtype=float)
    q = np.zeros(lower.shape)
    outside = (lower > 0) | (upper < 0)  # NaN compares False: an unbounded side holds zero
    both = outside & np.isfinite(lower) & np.isfinite(upper)
    q[both] = 0.5 * (lower[both] + upper[both])
    only_low = outside & ~both & (lower > 0)
    q[only_low] = lower[only_low]
    only_high = outside & ~both & (upper < 0)
    q[only_high] = upper[only_high]
    return q


def example_robot_data_dir() -> Path:
    """The ``share`` folder of the example-robot-data wheel (holds robots/...)."""
    for entry in sys.path:
        candidate = Path(entry) / "cmeel.prefix" / "share"
        if (candidate / "example-robot-data" / "robots").is_dir():
            return candidate
    raise InputError(
        "example-robot-data is not installed: pip install example-robot-data"
    )


def load_robot(source: str | Path | None = None, tool: str | None = None, *,
               package_dirs: list | None = None) -> RobotModel:
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
    package_dirs : list of str or Path, optional
        Folders holding the ROS packages that ``package://NAME/...`` meshes name (each a
        package, a folder with ``DIR/NAME``, or one with packages below it); searched before
        ``ROS_PACKAGE_PATH``. Default: the command line's ``--package-dir`` folders
        (:func:`tcr_accuracy.model.ros_packages.package_dirs_given`).

    A mesh found nowhere is no error (kinematics does not need it): a
    :class:`MissingMeshWarning` says which and how to provide it, once, and views draw the
    link as a skeleton.

    Returns
    -------
    RobotModel
        The chain from the base to the TCP frame.

    Raises
    ------
    InputError
        The URDF does not exist or parse, the frame is unknown, or a joint kind is
        not supported.

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> tcr.load_robot("ur5")
    RobotModel('ur5', 6 joints, tool_frame='tool0', urdf='ur5_robot.urdf')
    """
    given = [str(d) for d in (given_package_dirs() if package_dirs is None else package_dirs)]
    package_dirs = []
    urdf_path: Path | None = None
    working_pose = None
    payload_kg = None
    if source is None or str(source) == BUILTIN_NAME:
        text = tool_changer_urdf()
        name = BUILTIN_NAME
        tool = tool or "tool"
        working_pose = WORKING_POSE.copy()
        payload_kg = DISC_CUTTER_MASS
        label = "built-in tool_changer"
        loaded_from = BUILTIN_NAME
    elif Path(source).is_file():
        urdf_path = Path(source).resolve()
        text = read_urdf_text(urdf_path)
        name = urdf_robot_name(text) or urdf_path.stem  # what the URDF calls itself, as for named robots
        package_dirs = given + [str(urdf_path.parent), str(urdf_path.parent.parent)]
        if "package://example-robot-data/" in text:
            # an as-built URDF exported from a named robot keeps its meshes' package:// names;
            # that package is installed with this tool (example-robot-data), so it resolves here
            package_dirs.append(str(example_robot_data_dir()))
        label = str(source)
        loaded_from = str(urdf_path)
        if urdf_path.stem == BUILTIN_NAME or name.startswith(BUILTIN_NAME):  # a variant, its as-built model
            working_pose = WORKING_POSE.copy()
            payload_kg = DISC_CUTTER_MASS
    elif str(source).lower() in EXAMPLE_ROBOTS:
        share = example_robot_data_dir()
        rel, default_tool = EXAMPLE_ROBOTS[str(source).lower()]
        urdf_path = share / "example-robot-data" / "robots" / rel
        text = read_urdf_text(urdf_path)
        name = str(source).lower()
        tool = tool or default_tool
        package_dirs = given + [str(share)]
        label = f"{name} ({urdf_path})"
        loaded_from = name
    elif Path(source).exists():
        what = "a folder" if Path(source).is_dir() else "not a regular file (a device or a pipe)"
        raise InputError(f"source={source}: {what}; give a URDF file or a known robot name "
                         f"({BUILTIN_NAME}, {', '.join(EXAMPLE_ROBOTS)})", parameter="source", value=source)
    else:
        raise InputError(
            f"source={source}: no such file, and not a known robot name "
            f"(known: {BUILTIN_NAME}, {', '.join(EXAMPLE_ROBOTS)})", parameter="source", value=source
        )
    robot = robot_from_urdf_text(
        text, tool, name=name, source=label, urdf_path=urdf_path,
        package_dirs=package_dirs, working_pose=working_pose, payload_kg=payload_kg,
    )
    robot.robot_source = loaded_from
    if urdf_path is not None and "package://" in text:
        names = {package_of(place.name) for place in robot.mesh_places()} - {None}
        robot.packages = {name: str(folder) for name, folder in
                          find_packages(names, given + ros_package_path(), urdf_path.parent).items()}
    if working_pose is not None:  # the tool-changer (or its as-built variant) works below its base, in the cutterhead
        robot.mounting_plane_z = None
    if urdf_path is not None:
        message = robot.missing_mesh_message()
        if message:
            warnings.warn(message, MissingMeshWarning)  # one place: shown once a run
    return robot


def robot_from_urdf_text(
    text: str,
    tool: str | None,
    *,
    name: str = "robot",
    source: str = "<urdf>",
    urdf_path: Path | None = None,
    package_dirs: list[str] | None = None,
    working_pose: np.ndarray | None = None,
    payload_kg: float | None = None,
) -> RobotModel:
    """Build a :class:`RobotModel` from URDF text (see :func:`load_robot`)."""
    root = parse_urdf_xml(text, source)
    check_urdf(root, source)
    if tool is None:
        tool = single_leaf_link(root, source)
    with quiet_native_stderr() as said:  # urdfdom writes its complaints to fd 2, several lines each
        try:
            full = pin.buildModelFromXML(text)
        except Exception as exc:  # pinocchio raises plain RuntimeError/ValueError
            first = said()
            raise InputError(f"{source}: Pinocchio cannot build a model from this URDF "
                             f"({one_line(first or exc)})") from None
    frame_id = find_frame(full, tool, source)
    frame = full.frames[frame_id]
    chain = set(full.supports[frame.parentJoint])
    locked = [j for j in range(1, full.njoints) if j not in chain]
    model = reduce_model(full, locked) if locked else full
    if model.njoints <= 1:
        data = full.createData()
        pin.framesForwardKinematics(full, data, pin.neutral(full))
        raise FixedFrameError(f"tool={tool}: no joint moves this frame in {source}", tool,
                              data.oMf[frame_id].translation.copy())
    if model.njoints - 1 > MAX_CHAIN_JOINTS:
        raise InputError(f"tool={tool}: {model.njoints - 1} joints move this frame in {source}, more than the "
                         f"{MAX_CHAIN_JOINTS} of a serial chain tcr-accuracy models", parameter="tool", value=tool)
    for j in range(1, model.njoints):
        joint_kind(model.joints[j], f"{source}: joint {one_line(model.names[j])}")  # raises for unsupported kinds
    tool_frame_id = next(i for i, f in enumerate(model.frames) if f.name == tool and f.type == frame.type)
    robot = RobotModel(
        model=model,
        tool_frame=tool,
        name=name,
        urdf_text=text,
        urdf_path=urdf_path,
        package_dirs=list(package_dirs or []),
        working_pose=working_pose,
        full_model=full,
        chain_joint_ids=tuple(full.getJointId(n) for n in list(model.names)[1:]),
        tool_frame_id=tool_frame_id,
        mimic=mimic_rules(root, source),
        payload_kg=payload_kg,
    )
    return robot
