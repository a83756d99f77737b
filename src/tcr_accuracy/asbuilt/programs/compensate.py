"""Every motion target of a program through the compensation filter, and the program written back.

For each target, in the order the program first uses them:

* **the TCP**: the tool the program's tool data give where they can be read (URScript's ``set_tcp``,
  KRL's ``$TOOL``/``TOOL_DATA``, RAPID's ``tooldata``), on the robot's TCP frame (the controller's
  flange: REP 199's ``tool0``); else the measured point, said in the notes. The controller's model is
  the nominal robot with that tool; the full model is the calibrated one with that tool on its own
  flange (:func:`model_with_tool`).
* **joint targets** are the joints the controller would command; **pose targets** are the TCP's pose in
  the program's frame (the controller's base frame: the URDF's ``base`` frame where it has one, REP
  199's, else its root; a KRL base or a RAPID work object where its data can be read). Their joints are
  the controller's inverse kinematics of the pose on the branch the program's configuration names
  (KRL Status and Turn, RAPID ``confdata``; :mod:`.configuration`), else from the joints of the target
  before it (URScript's controller takes the solution nearest its current joints).
* the joints go through :func:`~tcr_accuracy.asbuilt.compensation_filter.filter_joint_targets` (the full
  model, at the campaign's end state and the given payload): the corrected joints put the full model's
  TCP on the controller's TCP at the target joints. A pose target is written back as the controller's
  forward kinematics of the corrected joints, in its own frame, its configuration recomputed: Turn
  bits and quadrants follow the corrected joints; a corrected target whose branch (Status, ``cfx``)
  changes would be reached another way by the controller and is refused.

A target that cannot be filtered (no inverse kinematics, outside the limits, a singularity, an
unknown frame, an expression) is written as it was and listed with its reason.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pinocchio as pin

from ...exceptions import InputError
from ...model.context import MeasurementContext
from ...model.errors import ErrorModel
from ...model.kinematics import tcp_poses
from ..compensation_filter import filter_joint_targets
from ..model import AsBuiltModel
from .configuration import ArmGeometry
from .targets import Configuration, ParsedProgram, ProgramTarget, apply_edits

#: Inverse kinematics of a pose target: tolerances [m, rad] and the random starts tried when the first
#: (the target before it) does not reach the branch asked.
IK_TOLERANCE = 1e-11
IK_STARTS = 48
#: Most targets and unknown constructs listed in a file's header.
HEADER_LIST = 30


@dataclass(frozen=True)
class TargetResult:
    """What became of one target.

    label : ``movel p1 at prog.script:12``; file, line, column : where its literal is
    kind : "joints" or "pose"
    status : "filtered", or "not filtered" (written as it was)
    reason : why not ("" when filtered)
    tcp : which TCP was used: the program's tool data it was read from, or why the measured point was
    error_before_m, error_after_m : the full model's miss of the target with the command as written and as
        filtered [m] (None where not computed)
    """

    label: str
    file: str
    line: int
    column: int
    kind: str
    status: str
    reason: str
    tcp: str
    error_before_m: float | None = None
    error_after_m: float | None = None
    measured_point: bool = False


@dataclass(frozen=True)
class FilteredProgram:
    """A program filtered through the calibrated model.

    language : the program's language; texts : file name -> its filtered text
    targets : one TargetResult per target, in the program's order
    unknown : constructs kept as written without being understood ("file:line: what (why)")
    notes : what was assumed (an unknown tool: the measured point)
    """

    language: str
    texts: dict
    targets: tuple
    unknown: tuple
    notes: tuple

    @property
    def not_filtered(self) -> list[TargetResult]:
        return [t for t in self.targets if t.status != "filtered"]


def model_with_tool(model: AsBuiltModel, tool: np.ndarray | None) -> AsBuiltModel:
    """The calibrated model whose TCP is ``tool`` (4, 4) on the robot's TCP frame (its fitted measured
    point dropped: the flange as built carries the tool), or ``model`` itself for None."""
    if tool is None:
        return model
    robot = model.robot
    em = ErrorModel(robot)
    x = em.zeros()
    x[em.tool_slice] = pin.log6(pin.SE3(np.asarray(tool, dtype=float))).vector
    parameters = {e: ({k: v for k, v in p.items() if not str(k).startswith("frames.tool.")} if e == "frames"
                      else dict(p)) for e, p in model.parameters.items()}
    return replace(model, robot=em.perturbed_robot(x, name=robot.name), parameters=parameters)


def controller_base(robot) -> np.ndarray:
    """(4, 4) rootMbase: the controller's base frame in the robot's root, the URDF's frame ``base`` fixed to
    the root where there is one (REP 199; ur_description turns it 180 deg about z), else the root."""
    model = robot.model
    for frame in model.frames:
        if frame.name == "base" and frame.parentJoint == 0:
            return frame.placement.homogeneous
    return np.eye(4)


def filter_parsed(model: AsBuiltModel, program: ParsedProgram, *, threshold: float = 1e-7, payload_kg: float = 0.0,
                  header: list[str] | None = None, random_state=0) -> FilteredProgram:
    """Every target of a parsed program through the compensation filter (see the module docstring).

    Parameters
    ----------
    model : AsBuiltModel
        The full calibrated model.
    program : ParsedProgram
        From a language's parser.
    threshold : float, default=1e-7
        Stop correcting a target when the full model's miss is below this [m].
    payload_kg : float, default=0.0
        The load the targets are reached with [kg].
    header : list of str, optional
        Lines of the header comment (what was done, with which model, when); the targets not filtered and
        the constructs not understood are listed after them.
    random_state : int, default=0
        Seeds the inverse kinematics' extra starts.

    Returns
    -------
    FilteredProgram
    """
    robot = model.robot
    rng = np.random.default_rng(random_state)
    root_base = controller_base(robot)
    geometry = None
    results: dict[int, TargetResult] = {}
    solved: dict[int, np.ndarray] = {}
    models: dict[bytes, AsBuiltModel] = {}
    seed = np.array(robot.working_pose, dtype=float)
    for k, target in enumerate(program.targets):
        tcp = _tcp(target)
        if target.problem:
            results[k] = _refused(target, target.problem, tcp)
            continue
        key = b"" if target.tool is None else np.asarray(target.tool, dtype=float).tobytes()
        if key not in models:
            models[key] = model_with_tool(model, target.tool)
        controller = models[key].measured_point_robot()
        if target.kind == "joints":
            q = np.asarray(target.joints, dtype=float)
            if q.shape != (robot.n_joints,):
                results[k] = _refused(target, f"{q.size} joint values for a robot of {robot.n_joints} joints", tcp)
                continue
            if not robot.within_limits(q[None])[0]:
                results[k] = _refused(target, "outside the joint limits", tcp)
                continue
        else:
            if target.frame is None:
                results[k] = _refused(target, target.frame_note or "its frame cannot be read", tcp)
                continue
            if target.configuration is not None and geometry is None:
                geometry = ArmGeometry(robot)
            pose = root_base @ target.frame @ target.pose
            q, why = _solve(controller, pose, seed, target.configuration, geometry, rng)
            if q is None:
                results[k] = _refused(target, why, tcp)
                continue
        solved[k] = q
        seed = q
    edits: dict[str, list] = {name: [] for name in program.texts}
    by_model: dict[bytes, list[int]] = {}
    for k in solved:
        target = program.targets[k]
        by_model.setdefault(b"" if target.tool is None else np.asarray(target.tool, dtype=float).tobytes(),
                            []).append(k)
    for key, rows in by_model.items():
        tooled = models[key]
        q = np.array([solved[k] for k in rows])
        context = MeasurementContext.defaults(len(rows), robot.n_joints, payload_kg=payload_kg)
        filtered = filter_joint_targets(tooled, q, context, threshold=threshold)
        controller = tooled.measured_point_robot()
        for i, k in enumerate(rows):
            target = program.targets[k]
            tcp = _tcp(target)
            before = float(filtered.error_before[i])
            if not filtered.solved[i]:
                results[k] = _refused(target, str(filtered.status[i]), tcp, before)
                continue
            command = filtered.command_q[i]
            if np.array_equal(command, q[i]):  # nothing to correct (already within the threshold): as written
                results[k] = TargetResult(target.label(), target.file, target.line, target.column, target.kind,
                                          "filtered", "", tcp, before, float(filtered.error_after[i]),
                                          target.tool is None)
                continue
            if target.kind == "joints":
                changes = target.write(command, None, None)
            else:
                frame = root_base @ target.frame
                pose = np.linalg.inv(frame) @ tcp_poses_homogeneous(controller, command)
                configuration, why = _new_configuration(target.configuration, geometry, command)
                if configuration is None and target.configuration is not None:
                    results[k] = _refused(target, why, tcp, before)
                    continue
                changes = target.write(None, pose, configuration)
            edits[target.file].extend(changes)
            results[k] = TargetResult(target.label(), target.file, target.line, target.column, target.kind, "filtered",
                                      "", tcp, before, float(filtered.error_after[i]), target.tool is None)
    ordered = tuple(results[k] for k in range(len(program.targets)))
    texts = {}
    for name, text in program.texts.items():
        new = apply_edits(text, edits[name])
        if header is not None:
            new = _with_header(new, program, name, header, ordered)
        texts[name] = new
    return FilteredProgram(program.language, texts, ordered, tuple(program.unknown), tuple(program.notes))


def tcp_poses_homogeneous(robot, q) -> np.ndarray:
    """(4, 4) base_M_tcp of ``robot`` at joints q (n,)."""
    pose = tcp_poses(robot, np.asarray(q, dtype=float)[None])
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = pose.rotation[0], pose.position[0]
    return out


def _tcp(target: ProgramTarget) -> str:
    return target.tool_note or ("the program's tool data" if target.tool is not None else "the measured point")


def _refused(target: ProgramTarget, reason: str, tcp: str, before: float | None = None) -> TargetResult:
    return TargetResult(target.label(), target.file, target.line, target.column, target.kind, "not filtered", reason,
                        tcp, before, None, target.tool is None)


def _solve(controller, pose: np.ndarray, seed: np.ndarray, wanted: Configuration | None, geometry, rng):
    """(joints, "") of the controller's inverse kinematics of ``pose`` (4, 4) on the branch ``wanted`` names
    (nearest ``seed`` among them), or (None, why)."""
    from ...analysis.sampling import inverse_kinematics

    orientation = "exact" if controller.n_joints >= 6 else "best_effort"

    def attempt(starts):
        n = len(starts)
        ik = inverse_kinematics(controller, np.repeat(pose[None, :3, 3], n, 0), np.repeat(pose[None, :3, :3], n, 0),
                                starts, tol_position=IK_TOLERANCE, tol_rotation=IK_TOLERANCE, max_iter=400,
                                orientation=orientation)
        return [q for q, ok in zip(ik.q, ik.success) if ok]

    def matching(found):
        return [q for q in found if wanted is None or geometry.matches(wanted.kind, q, _given(wanted))]

    found = matching(attempt(seed[None]))
    if not found:
        lo, hi = controller.joint_bounds(np.pi)
        starts = np.vstack([controller.working_pose, rng.uniform(lo, hi, (IK_STARTS, controller.n_joints))])
        found = matching(attempt(starts))
    if not found:
        said = "" if wanted is None else f" in the configuration given ({_said(wanted)})"
        return None, f"no inverse kinematics{said}"
    return min(found, key=lambda q: float(np.abs(q - seed).sum())), ""


def _given(wanted: Configuration) -> tuple:
    """The part of a configuration that names the branch: KUKA's Status bits 0-2 and Turn bits 0-5."""
    if wanted.kind == "kuka":
        status, turn = wanted.values
        return int(status) & 0b111, int(turn) & 0b111111
    return tuple(int(v) for v in wanted.values)


def _configuration(kind: str, geometry: ArmGeometry, q) -> tuple:
    return geometry.kuka(q) if kind == "kuka" else geometry.abb(q)


def _said(configuration: Configuration) -> str:
    if configuration.kind == "kuka":
        return f"S {configuration.values[0]}, T {configuration.values[1]}"
    return "confdata [" + ", ".join(str(v) for v in configuration.values) + "]"


def _new_configuration(given: Configuration | None, geometry, q):
    """(the configuration to write for the corrected joints, "") or (None, why) when the branch changed."""
    if given is None:
        return None, ""
    new = _configuration(given.kind, geometry, q)
    if geometry.matches(given.kind, q, _given(given)):  # on the branch given (a boundary's either side included)
        return given, ""
    if given.kind == "kuka":
        status, turn = given.values
        if new[0] != int(status) & 0b111:
            return None, (f"the correction crosses a branch boundary (Status {int(status) & 0b111} -> {new[0]}): the "
                          "controller would reach it another way")
        return Configuration("kuka", (status, (int(turn) & ~0b111111) | new[1])), ""
    if new[3] != int(given.values[3]):
        return None, (f"the correction crosses a branch boundary (cfx {given.values[3]} -> {new[3]}): the controller "
                      "would reach it another way")
    return Configuration("abb", new), ""


def _with_header(text: str, program: ParsedProgram, name: str, header: list[str], results) -> str:
    offset, prefix = program.header.get(name, (0, "# "))
    lines = list(header)
    mine = [r for r in results if r.file == name]
    refused = [r for r in mine if r.status != "filtered"]
    changed = sum(1 for r in mine if r.status == "filtered")
    lines.append(f"{changed} of {len(mine)} motion targets in this file filtered"
                 + (f"; {len(refused)} written as they were:" if refused else "."))
    lines += [f"  {r.label}: {r.reason}" for r in refused[:HEADER_LIST]]
    if len(refused) > HEADER_LIST:
        lines.append(f"  ... and {len(refused) - HEADER_LIST} more")
    assumed = list(dict.fromkeys(r.tcp for r in mine if r.measured_point))
    if assumed:
        lines.append("The TCP is the measured point (the calibration's) where the program's tool cannot be read:")
        lines += [f"  {note}" for note in assumed[:HEADER_LIST]]
    unknown = [u for u in program.unknown if u.startswith(f"{name}:")]
    if unknown:
        lines.append("Kept as written without being understood:")
        lines += [f"  {u}" for u in unknown[:HEADER_LIST]]
        if len(unknown) > HEADER_LIST:
            lines.append(f"  ... and {len(unknown) - HEADER_LIST} more")
    newline = "\r\n" if "\r\n" in text[:2000] else "\n"
    block = "".join(f"{prefix}{_one_line(line)}{newline}" for line in lines)
    return text[:offset] + block + text[offset:]


def _one_line(line: str) -> str:
    """A header line with no line break in it (a comment ends at the line's end)."""
    return " ".join(str(line).split()) if str(line).strip() else ""


def check_language_robot(program: ParsedProgram, robot) -> None:
    """Refuse a program whose targets do not fit the robot: joint targets of another number of joints."""
    for target in program.targets:
        if target.kind == "joints" and target.joints is not None and len(target.joints) != robot.n_joints:
            raise InputError(f"{target.where}: {len(target.joints)} joint values, but {robot.name} has "
                             f"{robot.n_joints} joints ({', '.join(robot.joint_names)})")
