"""The forward model behind tests/independent_truths.py: the real robot on Pinocchio alone.

:class:`HiddenRobot` is the URDF's whole tree with hidden joint placement errors, measured-frame
offsets and a point payload; the draws (poses, the tracker's frame, geometric errors), the CSV a
user would give (the package's writer has no ``time_s`` nor ``<frame>.x_mm`` columns) and an
independent reference fit (tracker frame, reflector offsets, encoder offsets, by scipy) are
shared by the builders. Nothing here imports ``tcr_accuracy.effects``, ``analysis.simulate`` or
a scenario file. The sign conventions are stated in tests/independent_truths.py; here:
``g(q) = pin.computeGeneralizedGravity`` is what holds the arm, error screws ``xi = (v, w)``
act as ``M_j <- M_j * exp6(xi_j)``, the tracker reads ``R p + t``. SI units.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin

from tcr_accuracy.model.robot import RobotModel

MM = 1e-3
DEG = math.pi / 180.0


# ---------------------------------------------------------------------------------------
# What a builder returns
# ---------------------------------------------------------------------------------------
@dataclass
class Scenario:
    """One simulated measurement campaign.

    Attributes
    ----------
    name : str
        Scenario key (``a_gravity_overcompensation`` ...).
    robot : RobotModel
        The nominal robot (TCP: the first measured frame).
    csv_text : str
        The measurement CSV as a user would give it to ``tcr-accuracy diagnose``.
    truth : dict
        The hidden robot and instrument, SI, units in the keys.
    noise_m : float
        The instrument's noise, standard deviation per axis [m].
    q : ndarray of shape (N, n_joints)
        Commanded joint values [rad, m] (the CSV's, before rounding).
    measured : dict of str to ndarray of shape (N, 3)
        Measured position of each measured frame in the tracker frame [m].
    context : dict of str to ndarray
        ``payload_kg`` (N,), ``temperature_c`` (N,), ``time_s`` (N,), ``direction`` (N, n_joints),
        whichever the campaign has.
    robot_arg : str or None
        What ``--robot`` takes: an example-robot-data name, None for the built-in tool-changer;
        ignored where ``urdf_text`` is set (the URDF file written next to the CSV is given).
    urdf_text : str or None
        A URDF to write next to the CSV (robots with extra measured frames).
    frames : list of str
        The measured frames, in column order (one: the TCP, plain ``x_mm`` columns).
    """

    name: str
    robot: RobotModel
    csv_text: str
    truth: dict
    noise_m: float
    q: np.ndarray
    measured: dict
    context: dict
    robot_arg: str | None = None
    urdf_text: str | None = None
    frames: list = field(default_factory=list)

    def write(self, folder: Path) -> tuple[Path, list[str]]:
        """Write the CSV (and the URDF) into ``folder``.

        Returns
        -------
        (Path, list of str)
            The CSV's path and the ``--robot ... [--tool ...]`` arguments of ``diagnose``.
        """
        folder = Path(folder)
        csv_path = folder / f"{self.name}.csv"
        csv_path.write_text(self.csv_text)
        if self.urdf_text is not None:
            urdf = folder / f"{self.name}.urdf"
            urdf.write_text(self.urdf_text)
            return csv_path, ["--robot", str(urdf), "--tool", self.frames[0]]
        return csv_path, [] if self.robot_arg is None else ["--robot", self.robot_arg]


# ---------------------------------------------------------------------------------------
# The hidden robot: the URDF's whole tree with its placement errors, frame offsets, payload
# ---------------------------------------------------------------------------------------
def frame_id(model: pin.Model, name: str) -> int:
    """Index of the frame named ``name`` (the link's BODY frame where a joint shares the name)."""
    ids = [i for i, f in enumerate(model.frames) if f.name == name]
    if not ids:
        raise KeyError(name)
    return next((i for i in ids if model.frames[i].type == pin.FrameType.BODY), ids[0])


@dataclass
class HiddenRobot:
    """The real robot behind the measurements.

    Attributes
    ----------
    robot : RobotModel
        The nominal robot (its ``full_model``: every joint and link mass of the URDF).
    placement_errors : dict of str to ndarray of shape (6,)
        Error screw ``(v [m], w [rad])`` of each joint's placement in its parent, by joint name.
    frame_offsets : dict of str to ndarray of shape (3,)
        Displacement [m] of a measured frame in its own axes (a reflector not where the URDF has it).
    """

    robot: RobotModel
    placement_errors: dict = field(default_factory=dict)
    frame_offsets: dict = field(default_factory=dict)

    def model(self, payload_kg: float = 0.0) -> pin.Model:
        """A copy of the full model with the errors built in and a point payload [kg] at the TCP."""
        model = pin.Model(self.robot.full_model)
        if payload_kg:
            tcp = model.frames[frame_id(model, self.robot.tool_frame)]
            point = pin.Inertia(float(payload_kg), np.zeros(3), np.zeros((3, 3)))
            model.inertias[tcp.parentJoint] = model.inertias[tcp.parentJoint] + tcp.placement.act(point)
        for name, xi in self.placement_errors.items():
            j = model.getJointId(name)
            model.jointPlacements[j] = model.jointPlacements[j] * pin.exp6(np.asarray(xi, dtype=float))
        for name, offset in self.frame_offsets.items():
            fid = frame_id(model, name)
            frame = model.frames[fid]
            frame.placement = frame.placement * pin.SE3(np.eye(3), np.asarray(offset, dtype=float))
            model.frames[fid] = frame
        return model

    def placements(self, q: np.ndarray, frames: list[str]) -> dict:
        """Rotation (N, 3, 3) and position (N, 3) [m] in the base frame of each named frame,
        ``{frame: (R, p)}``, at joint values q (N, n_joints) [rad, m] (the real joints, not the
        commanded ones)."""
        model = self.model()
        data = model.createData()
        ids = [frame_id(model, f) for f in frames]
        out = {f: (np.empty((len(q), 3, 3)), np.empty((len(q), 3))) for f in frames}
        for i, config in enumerate(self.robot.full_configurations(q)):
            pin.framesForwardKinematics(model, data, config)
            for f, fid in zip(frames, ids):
                out[f][0][i] = data.oMf[fid].rotation
                out[f][1][i] = data.oMf[fid].translation
        return out

    def positions(self, q: np.ndarray, frames: list[str]) -> dict:
        """Position [m] in the base frame of each named frame, ``{frame: (N, 3)}`` (see :meth:`placements`)."""
        return {f: p for f, (_, p) in self.placements(q, frames).items()}

    def holding_torque(self, q: np.ndarray, payload_kg: np.ndarray) -> np.ndarray:
        """g(q): the torque [Nm] (force [N]) that holds each chain joint, (N, n_joints), with the
        payload of each row (N,) [kg] at the TCP; gravity pushes the joints by minus this."""
        payload = np.broadcast_to(np.asarray(payload_kg, dtype=float), (len(q),))
        out = np.empty(q.shape)
        configs = self.robot.full_configurations(q)
        for mass in np.unique(payload):
            model = self.model(mass)
            data = model.createData()
            rows = np.flatnonzero(payload == mass)
            idx_v = [model.joints[j].idx_v for j in self.robot.chain_joint_ids]
            for i in rows:
                out[i] = pin.computeGeneralizedGravity(model, data, configs[i])[idx_v]
        return out


# ---------------------------------------------------------------------------------------
# Draws shared by the builders
# ---------------------------------------------------------------------------------------
def random_poses(robot: RobotModel, n: int, rng: np.random.Generator, span: float = math.pi) -> np.ndarray:
    """(n, n_joints) joint values [rad, m] uniform within the limits, revolute joints within +-span."""
    lo = np.where(np.isnan(robot.lower_limits), -span, np.maximum(robot.lower_limits, -span))
    hi = np.where(np.isnan(robot.upper_limits), span, np.minimum(robot.upper_limits, span))
    return rng.uniform(lo, hi, size=(n, robot.n_joints))


def tracker_frame(rng: np.random.Generator, distance_m: float = 3.0) -> pin.SE3:
    """``trackerMbase``: a tracker standing ``distance_m`` from the robot, levelled within ~1 deg,
    looking from any side."""
    rotation = pin.rpy.rpyToMatrix(rng.normal(0.0, 0.015), rng.normal(0.0, 0.015), rng.uniform(-math.pi, math.pi))
    heading = rng.uniform(-math.pi, math.pi)
    translation = np.array([distance_m * math.cos(heading), distance_m * math.sin(heading), rng.uniform(-0.8, 0.2)])
    return pin.SE3(rotation, translation)


def geometric_errors(robot: RobotModel, rng: np.random.Generator, *, offset_deg: float, offset_mm: float,
                     placement_mm: float, placement_deg: float) -> tuple[np.ndarray, dict]:
    """Encoder offsets (n_joints,) [rad, m] and joint placement error screws ``{joint: (6,)}``
    [m, rad], normal with the given standard deviations."""
    revolute = np.array([k == "revolute" for k in robot.joint_kinds])
    offsets = rng.normal(size=robot.n_joints) * np.where(revolute, offset_deg * DEG, offset_mm * MM)
    placements = {name: np.concatenate([rng.normal(0.0, placement_mm * MM, 3),
                                        rng.normal(0.0, placement_deg * DEG, 3)])
                  for name in robot.joint_names}
    return offsets, placements


def fixed_tracker() -> pin.SE3:
    """``trackerMbase`` of the tests that fix it: 1.6 m from the robot (1.25, -0.83, -0.41 m),
    turned 35 deg about the vertical."""
    return pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, math.radians(35.0)), np.array([1.25, -0.83, -0.41]))


def in_tracker(frame: pin.SE3, positions: np.ndarray) -> np.ndarray:
    """(N, 3) base-frame positions [m] as the tracker sees them: R p + t."""
    return positions @ frame.rotation.T + frame.translation


def rms(a: np.ndarray) -> float:
    """RMS length of the rows of a (N, 3) array (or RMS of a vector)."""
    a = np.asarray(a, dtype=float)
    return float(np.sqrt(np.mean(np.sum(a * a, axis=-1)))) if a.ndim == 2 else float(np.sqrt(np.mean(a * a)))


def approach_directions(q: np.ndarray, start: np.ndarray) -> np.ndarray:
    """(N, n_joints) +1/-1: the direction each joint moved in to reach each row from the row
    before (the first from ``start``); a joint that did not move keeps its last direction."""
    previous = np.vstack([start, q[:-1]])
    step = np.sign(q - previous)
    out = np.empty_like(step)
    last = np.ones(q.shape[1])
    for i, row in enumerate(step):
        last = np.where(row != 0, row, last)
        out[i] = last
    return out


def truth_frame(frame: pin.SE3) -> dict:
    return {"rotation": frame.rotation.tolist(), "translation_m": frame.translation.tolist()}


def truth_geometry(robot: RobotModel, offsets: np.ndarray, placements: dict) -> dict:
    return {"joint_offsets_si": dict(zip(robot.joint_names, offsets.tolist())),
            "placement_errors_m_rad": {k: np.asarray(v).tolist() for k, v in placements.items()}}


# ---------------------------------------------------------------------------------------
# The CSV, as a user's file: the package's writer has no time_s nor <frame>.x_mm columns
# ---------------------------------------------------------------------------------------
def measurement_csv(robot: RobotModel, q: np.ndarray, measured: dict, context: dict, *, per_frame: bool,
                    comment: str = "") -> str:
    """CSV text: joint columns in deg/mm, positions in mm (``x_mm`` or ``<frame>.x_mm``), then the
    context columns present in ``context`` (``payload_kg``, ``temperature_c``, ``time_s``,
    ``direction`` as ``<joint>_dir``)."""
    header = [f"{n}_{u}" for n, u in zip(robot.joint_names, robot.display_units)]
    blocks = [q * robot.display_scale]
    formats = ["{:.9f}"] * robot.n_joints
    for frame, position in measured.items():
        header += [f"{frame}.{a}_mm" if per_frame else f"{a}_mm" for a in "xyz"]
        blocks.append(position / MM)
        formats += ["{:.6f}"] * 3
    for key, fmt in (("payload_kg", "{:.1f}"), ("temperature_c", "{:.3f}"), ("time_s", "{:.3f}")):
        if key in context:
            header.append(key)
            blocks.append(np.asarray(context[key], dtype=float)[:, None])
            formats.append(fmt)
    if "direction" in context:
        header += [f"{n}_dir" for n in robot.joint_names]
        blocks.append(context["direction"])
        formats += ["{:+.0f}"] * robot.n_joints
    table = np.hstack(blocks)
    lines = [f"# {line}" for line in comment.splitlines()] + [",".join(header)]
    lines += [",".join(f.format(v) for f, v in zip(formats, row)) for row in table]
    return "\n".join(lines) + "\n"


def noisy(rng: np.random.Generator, positions: np.ndarray, noise_m: float) -> np.ndarray:
    return positions + noise_m * rng.standard_normal(positions.shape)


def hidden_free(robot: RobotModel) -> HiddenRobot:
    """The nominal robot as a :class:`HiddenRobot` (no error)."""
    return HiddenRobot(robot)


# ---------------------------------------------------------------------------------------
# An independent reference fit: tracker frame, reflector offsets, optionally joint offsets
# ---------------------------------------------------------------------------------------
def _tracker_start(model_points: np.ndarray, measured: np.ndarray) -> pin.SE3:
    """Kabsch (scipy's ``Rotation.align_vectors``): the rigid frame that best maps the model's
    points (N, 3) onto the measured ones."""
    from scipy.spatial.transform import Rotation

    centre_m, centre_p = measured.mean(axis=0), model_points.mean(axis=0)
    rotation = Rotation.align_vectors(measured - centre_m, model_points - centre_p)[0].as_matrix()
    return pin.SE3(rotation, centre_m - rotation @ centre_p)


def reference_fit(scenario: Scenario, joints: tuple = (), rows: np.ndarray | None = None):
    """Fit the tracker frame, each measured frame's offset (in its own axes) and the encoder
    offsets of ``joints`` (chain indices) to the scenario's measured positions of ``rows``, by
    scipy's Levenberg-Marquardt on the exact kinematics (Pinocchio, nominal URDF).

    Returns
    -------
    callable
        ``predict(rows) -> {frame: (n, 3)}``: the fitted model's positions in the tracker frame [m].
    """
    from scipy.optimize import least_squares
    from scipy.spatial.transform import Rotation

    robot, q, frames = scenario.robot, scenario.q, list(scenario.measured)
    rows = np.arange(len(q)) if rows is None else np.asarray(rows)
    joints = list(joints)
    start = _tracker_start(hidden_free(robot).positions(q[rows], frames[:1])[frames[0]],
                           scenario.measured[frames[0]][rows])

    def predict(x, at):
        rotation = Rotation.from_rotvec(x[:3]).as_matrix() @ start.rotation
        offsets = {f: x[6 + 3 * k:9 + 3 * k] for k, f in enumerate(frames)}
        dq = np.zeros(robot.n_joints)
        dq[joints] = x[6 + 3 * len(frames):]
        moved = HiddenRobot(robot, frame_offsets=offsets).positions(q[at] + dq, frames)
        return {f: moved[f] @ rotation.T + start.translation + x[3:6] for f in frames}

    def residual(x):
        predicted = predict(x, rows)
        return np.concatenate([(predicted[f] - scenario.measured[f][rows]).ravel() for f in frames])

    x = least_squares(residual, np.zeros(6 + 3 * len(frames) + len(joints)), method="lm").x
    return lambda at: predict(x, np.asarray(at))


def reference_heldout(scenario: Scenario, joints: tuple = (), folds: int = 6, seed: int = 0) -> tuple[float, float]:
    """(in-sample RMS, k-fold held-out RMS) [m] of the 3D error per measured point of
    :func:`reference_fit` (folds of rows drawn with ``seed``)."""
    n = len(scenario.q)
    frames = list(scenario.measured)

    def errors(predicted, rows):
        return np.concatenate([predicted[f] - scenario.measured[f][rows] for f in frames])

    everything = np.arange(n)
    train = rms(errors(reference_fit(scenario, joints)(everything), everything))
    held = []
    for test in np.array_split(np.random.default_rng(seed).permutation(n), folds):
        fitted = reference_fit(scenario, joints, np.setdiff1d(everything, test))
        held.append(errors(fitted(test), test))
    return train, rms(np.concatenate(held))


# ---------------------------------------------------------------------------------------
# A robot with a tracker, for prediction and compensation: geometry, encoder offsets, compliance
# ---------------------------------------------------------------------------------------
@dataclass
class TrackedRobot:
    """A real robot for the prediction and compensation tests, on Pinocchio alone.

    The TCP the tracker sees at commanded q is the hidden robot's (joint placement errors, a
    TCP offset) at ``q + offsets + dq(q)``, plus isotropic noise of std ``noise_m`` [m] per
    axis, in the robot's base frame. ``dq = -compliance * g(q)``: each joint gives way to
    gravity (``g`` the holding torque of :meth:`HiddenRobot.holding_torque`, the payload a
    point mass at the TCP), the sign of a real elastic joint. Stiffness is the robot's: it
    stays when the payload changes (:meth:`with_payload`).

    Attributes
    ----------
    hidden : HiddenRobot
    offsets : ndarray of shape (n_joints,)
        Encoder offsets [rad, m].
    compliance : ndarray of shape (n_joints,)
        [rad/(N m), m/N].
    payload_kg, noise_m : float
    rng : numpy.random.Generator
        The tracker's noise stream.
    """

    hidden: HiddenRobot
    offsets: np.ndarray
    compliance: np.ndarray
    payload_kg: float
    noise_m: float
    rng: np.random.Generator

    @property
    def robot(self) -> RobotModel:
        return self.hidden.robot

    def with_payload(self, payload_kg: float) -> "TrackedRobot":
        return TrackedRobot(self.hidden, self.offsets, self.compliance, payload_kg, self.noise_m, self.rng)

    def joint_deflection(self, q: np.ndarray) -> np.ndarray:
        """(N, n_joints) gravity deflection at commanded q [rad, m]."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        if not np.any(self.compliance):
            return np.zeros_like(q)
        return -self.compliance * self.hidden.holding_torque(q, self.payload_kg)

    def true_positions(self, q: np.ndarray) -> np.ndarray:
        """(N, 3) noise-free TCP positions in the base frame [m]."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        tcp = self.robot.tool_frame
        return self.hidden.positions(q + self.offsets + self.joint_deflection(q), [tcp])[tcp]

    def true_errors(self, q: np.ndarray) -> np.ndarray:
        """(N, 3) real minus nominal TCP position, noise-free [m] (the nominal by Pinocchio too)."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        tcp = self.robot.tool_frame
        return self.true_positions(q) - hidden_free(self.robot).positions(q, [tcp])[tcp]

    def measure(self, q: np.ndarray) -> np.ndarray:
        """(N, 3) TCP positions as the tracker reports them [m]."""
        return noisy(self.rng, self.true_positions(q), self.noise_m)


def draw_tracked_robot(robot: RobotModel, rng: np.random.Generator, *, payload_kg: float = 150.0,
                       placement_mm: float = 0.2, placement_deg: float = 0.2e-3 / DEG,
                       offset_deg: float = 0.5e-3 / DEG, deflection_rad: float = 1e-3,
                       noise_m: float = 2e-5) -> TrackedRobot:
    """A random :class:`TrackedRobot` of plausible size: placement errors of ``placement_mm`` /
    ``placement_deg`` on every joint, encoder offsets of ``offset_deg`` (prismatic: 0.2 x that in
    mm), a TCP offset of ``placement_mm`` per axis, and joint compliances that turn a loaded joint
    by about ``deflection_rad`` (x U(0.5, 1.5); prismatic: 0.1 x that in m) under its RMS holding
    torque over random poses with the payload."""
    offsets, placements = geometric_errors(robot, rng, offset_deg=offset_deg, offset_mm=0.2 * offset_deg * DEG / MM,
                                           placement_mm=placement_mm, placement_deg=placement_deg)
    tcp_offset = rng.normal(0.0, placement_mm * MM, 3)
    hidden = HiddenRobot(robot, placements, {robot.tool_frame: tcp_offset})
    g = hidden.holding_torque(random_poses(robot, 64, rng), payload_kg)
    spread = np.sqrt(np.mean(g**2, axis=0))
    revolute = np.array([k == "revolute" for k in robot.joint_kinds])
    scale = np.where(revolute, deflection_rad, 0.1 * deflection_rad) * rng.uniform(0.5, 1.5, robot.n_joints)
    compliance = np.where(spread > 1e-6 * max(spread.max(), 1e-12), scale / np.maximum(spread, 1e-300), 0.0)
    return TrackedRobot(hidden, offsets, compliance, payload_kg, noise_m, rng)
