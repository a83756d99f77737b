"""Simulated robots for issue 28, their measurements written by a forward model here, on Pinocchio alone.

Each builder returns a :class:`Scenario`: the robot, the measurement CSV text (and the URDF
where the robot needs extra frames), the hidden truth, the instrument's noise per axis [m].
The data are made without the project's effect classes (nothing here imports
``tcr_accuracy.effects``, ``analysis.simulate`` or a scenario file): data written by the
classes the diagnosis fits would cancel the classes' own mistakes. What is taken from the
package: loading a robot (:func:`tcr_accuracy.load_robot`, its ``full_model``,
``full_configurations``, joint names and display units) and nothing that models an error.

Sign conventions, used everywhere below:

* ``g(q) = pin.computeGeneralizedGravity(model, data, q)`` is the torque [Nm] (force [N] on a
  prismatic joint) the drives apply to HOLD the arm still: the gradient of the potential energy
  dV/dq. Gravity pushes each joint by ``-g`` (downhill).
* An elastic joint sags with gravity: ``delta = -C g`` with ``C > 0`` [rad/Nm, m/N].
* A controller that over-compensates gravity leaves each joint against it: ``delta = +k g``,
  ``k > 0`` (its feed-forward ``(1 + e) C g`` where the joint gives ``C g``: ``k = e C``).
* The payload is a point mass at the TCP frame's origin, added to the inertia of the link the
  TCP is fixed to.
* Error screws ``xi = (v, w)``, linear part first as ``pin.log6``, applied on the right of the
  joint's placement in its parent: ``M_j <- M_j * exp6(xi_j)``.
* An encoder offset ``o_j`` puts the real joint at ``q_cmd + o_j``.
* The tracker reads ``p_tracker = R p_base + t`` (``trackerMbase``) plus Gaussian noise, the
  same standard deviation on each axis.

Every builder is deterministic in its ``seed``. SI inside; mm and deg only in the CSV. The forward
model itself (:class:`HiddenRobot`), the draws and the CSV writer are in tests/hidden_robot.py.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from tcr_accuracy.model.robot import RobotModel, load_robot, robot_from_urdf_text

from hidden_robot import (DEG, MM, HiddenRobot, Scenario, approach_directions, geometric_errors, hidden_free,
                          in_tracker, measurement_csv, noisy, random_poses, reference_heldout, rms, tracker_frame,
                          truth_frame, truth_geometry)


# ---------------------------------------------------------------------------------------
# (a) a controller that over-compensates gravity
# ---------------------------------------------------------------------------------------
def build_gravity_overcompensation(seed: int = 0, n: int = 300, noise_mm: float = 0.015,
                                   tcp_rms_mm: float = 1.0) -> Scenario:
    """The tool-changer carrying its 150 kg disc cutter (a point mass at the TCP) in about 60 % of
    the poses, whose controller over-compensates gravity: every joint ends AGAINST the torque it
    carries, ``delta_j = +k_j g_j`` (k > 0), sized to move the TCP by ``tcp_rms_mm`` RMS; plus
    encoder offsets, joint placement errors and the tracker's frame; ``noise_mm`` per axis."""
    robot = load_robot()
    rng = np.random.default_rng([seed, 1])
    tcp = robot.tool_frame
    q = random_poses(robot, n, rng)
    payload = np.where(rng.random(n) < 0.6, robot.payload_kg, 0.0)
    offsets, placements = geometric_errors(robot, rng, offset_deg=0.01, offset_mm=0.05, placement_mm=0.05,
                                           placement_deg=0.003)
    hidden = HiddenRobot(robot, placements)
    q_set = q + offsets  # where the encoders' zeros put the joints
    # first order: the torque at the undeflected pose (a 1 mm deflection changes it by ~1e-3)
    g = hidden.holding_torque(q_set, payload)
    # k_j = e C_j: each joint's compliance C_j inversely proportional to the torque (force) its
    # drive is rated for (the URDF's effort limit: gears are sized for their load), within
    # +-30 % joint to joint; e sets the size
    rated = np.array([robot.model.effortLimit[robot.model.joints[j].idx_v] for j in range(1, robot.model.njoints)])
    profile = rng.uniform(0.7, 1.3, robot.n_joints) / rated
    undeflected = hidden.positions(q_set, [tcp])[tcp]
    scale = 1e-4
    for _ in range(4):  # nearly linear in the scale: a few rescalings reach the size asked
        moved = rms(hidden.positions(q_set + scale * profile * g, [tcp])[tcp] - undeflected)
        scale *= tcp_rms_mm * MM / moved
    gain = scale * profile
    q_real = q_set + gain * g
    deflected = hidden.positions(q_real, [tcp])[tcp]
    frame = tracker_frame(rng)
    noise = noise_mm * MM
    measured = {tcp: noisy(rng, in_tracker(frame, deflected), noise)}
    context = {"payload_kg": payload}
    truth = {"scenario": "a", "robot": robot.name,
             "mechanism": "gravity compensation over-correcting: delta = +k g(q), k > 0 (against gravity)",
             "gain_si": dict(zip(robot.joint_names, gain.tolist())), "gain_units": "rad/Nm; m/N (j4)",
             "deflection_tcp_rms_m": rms(deflected - undeflected),
             "payload_kg": float(robot.payload_kg), "payload_share": float(np.mean(payload > 0)),
             "geometric_tcp_rms_m": rms(undeflected - hidden_free(robot).positions(q, [tcp])[tcp]),
             **truth_geometry(robot, offsets, placements), "tracker": truth_frame(frame), "noise_m": noise}
    return Scenario("a_gravity_overcompensation", robot,
                    measurement_csv(robot, q, measured, context, per_frame=False,
                                    comment="issue 28 (a): tool-changer, gravity over-compensated"),
                    truth, noise, q, measured, context)


# ---------------------------------------------------------------------------------------
# (b) joints that end ahead of their motion
# ---------------------------------------------------------------------------------------
def build_lead_direction(seed: int = 0, n: int = 400, noise_mm: float = 0.015) -> Scenario:
    """A 7-axis arm (panda) whose joints end 0.1-0.3 deg AHEAD of their motion:
    ``q_real = q_cmd + a_j dir_j`` with ``a_j`` in [0.1, 0.3] deg and ``dir_j`` the direction the
    joint moved in from the previous pose (a dead band would leave it behind: ``- b dir``); plus
    encoder offsets, joint placement errors and the tracker's frame."""
    robot = load_robot("panda")
    rng = np.random.default_rng([seed, 2])
    tcp = robot.tool_frame
    q = random_poses(robot, n, rng)
    direction = approach_directions(q, robot.working_pose)
    lead = rng.uniform(0.1, 0.3, robot.n_joints) * DEG
    offsets, placements = geometric_errors(robot, rng, offset_deg=0.02, offset_mm=0.0, placement_mm=0.05,
                                           placement_deg=0.005)
    hidden = HiddenRobot(robot, placements)
    q_real = q + offsets + lead * direction
    positions = hidden.positions(q_real, [tcp])[tcp]
    frame = tracker_frame(rng, 2.5)
    noise = noise_mm * MM
    measured = {tcp: noisy(rng, in_tracker(frame, positions), noise)}
    context = {"direction": direction}
    without_lead = hidden.positions(q + offsets, [tcp])[tcp]
    truth = {"scenario": "b", "robot": robot.name,
             "mechanism": "joints ahead of their motion: q_real = q_cmd + a dir, a > 0 (lost-motion compensation "
                          "set too high)",
             "lead_rad": dict(zip(robot.joint_names, lead.tolist())),
             "lead_tcp_rms_m": rms(positions - without_lead),
             **truth_geometry(robot, offsets, placements), "tracker": truth_frame(frame), "noise_m": noise}
    return Scenario("b_lead_direction", robot,
                    measurement_csv(robot, q, measured, context, per_frame=False,
                                    comment="issue 28 (b): panda, joints ahead of their motion"),
                    truth, noise, q, measured, context, robot_arg="panda")


# ---------------------------------------------------------------------------------------
# (c) a tracker whose length scale follows the temperature
# ---------------------------------------------------------------------------------------
def campaign_temperatures(rng: np.random.Generator, n: int, days=(19.5, 26.5, 16.0, 23.0)) -> np.ndarray:
    """(n,) temperatures [degC]: one block of rows per day, in this order (not monotonic: the
    temperature does not follow the measurement order), each day warming by 2.5 K over its
    rows, within 15-28 degC."""
    blocks = np.array_split(np.arange(n), len(days))
    base = np.asarray(days) + rng.uniform(-0.3, 0.3, len(days))
    out = np.empty(n)
    for rows, start in zip(blocks, base):
        out[rows] = start + np.linspace(-1.0, 1.5, len(rows))
    return np.clip(out, 15.0, 28.0)


def build_tracker_scale(seed: int = 0, n: int = 400, noise_mm: float = 0.015, scale_per_k: float = 1.5e-4,
                        reference_c: float = 20.0) -> Scenario:
    """A UR10 measured at 15-28 degC by a tracker whose length scale follows the temperature:
    every position is scaled about the TRACKER's origin by ``1 + s (T - T0)``, s = 1.5e-4 /K
    (4-10 x any metal's expansion, e.g. a weather station's wrong reading); the arm itself does
    not expand. Plus encoder offsets and joint placement errors."""
    robot = load_robot("ur10")
    rng = np.random.default_rng([seed, 3])
    tcp = robot.tool_frame
    q = random_poses(robot, n, rng)
    temperature = campaign_temperatures(rng, n)
    offsets, placements = geometric_errors(robot, rng, offset_deg=0.02, offset_mm=0.0, placement_mm=0.05,
                                           placement_deg=0.005)
    hidden = HiddenRobot(robot, placements)
    positions = hidden.positions(q + offsets, [tcp])[tcp]
    frame = tracker_frame(rng, 2.5)
    noise = noise_mm * MM
    factor = 1.0 + scale_per_k * (temperature - reference_c)
    true_tracker = in_tracker(frame, positions)
    measured = {tcp: noisy(rng, factor[:, None] * true_tracker, noise)}
    context = {"temperature_c": temperature}
    truth = {"scenario": "c", "robot": robot.name,
             "mechanism": "instrument length scale with temperature about the tracker's origin",
             "scale_per_k": scale_per_k, "reference_c": reference_c,
             "scale_tcp_rms_m": rms((factor[:, None] - 1.0) * true_tracker),
             **truth_geometry(robot, offsets, placements), "tracker": truth_frame(frame), "noise_m": noise}
    return Scenario("c_tracker_scale", robot,
                    measurement_csv(robot, q, measured, context, per_frame=False,
                                    comment="issue 28 (c): UR10, tracker scale 1.5e-4/K"),
                    truth, noise, q, measured, context, robot_arg="ur10")


# ---------------------------------------------------------------------------------------
# (d) a base joint swept in measurement order, and a warm-up drift
# ---------------------------------------------------------------------------------------
def build_sweep_drift(seed: int = 0, n: int = 300, noise_mm: float = 0.015, with_time: bool = True,
                      tau_s: float = 1800.0) -> Scenario:
    """A UR10 whose base joint is swept from -165 to +165 deg in measurement order (the other
    joints random), warming up as it is measured: the encoder offsets of the shoulder and the
    elbow and the base's pose drift as ``A (1 - exp(-t / tau))`` (tau 30 min over a ~3 h
    campaign; the base's drift includes a yaw, which over the sweep looks like a scale on the
    base joint); plus static encoder offsets, joint placement errors and the tracker's frame.
    ``with_time``: the CSV has a ``time_s`` column; else the measurement order only (the same
    data either way)."""
    robot = load_robot("ur10")
    rng = np.random.default_rng([seed, 4])
    tcp = robot.tool_frame
    q = random_poses(robot, n, rng)
    q[:, 0] = np.linspace(-165.0, 165.0, n) * DEG + rng.uniform(-1.0, 1.0, n) * DEG
    time_s = np.cumsum(rng.uniform(25.0, 45.0, n))
    warm = 1.0 - np.exp(-time_s / tau_s)
    drift_offsets = np.zeros(robot.n_joints)
    drift_offsets[1:3] = rng.choice([-1.0, 1.0], 2) * np.array([0.02, 0.015]) * DEG
    # base twist (v [m], w [rad]) at the end of the warm-up, applied on the left: the base moves
    base_drift = np.concatenate([[0.03 * MM, -0.02 * MM, 0.06 * MM], np.array([0.001, -0.001, 0.008]) * DEG])
    offsets, placements = geometric_errors(robot, rng, offset_deg=0.02, offset_mm=0.0, placement_mm=0.05,
                                           placement_deg=0.005)
    hidden = HiddenRobot(robot, placements)
    cold = hidden.positions(q + offsets, [tcp])[tcp]
    moved = hidden.positions(q + offsets + warm[:, None] * drift_offsets, [tcp])[tcp]
    positions = np.array([pin.exp6(w * base_drift).act(p) for w, p in zip(warm, moved)])
    frame = tracker_frame(rng, 2.5)
    noise = noise_mm * MM
    measured = {tcp: noisy(rng, in_tracker(frame, positions), noise)}
    context = {"time_s": time_s} if with_time else {}
    truth = {"scenario": "d", "robot": robot.name,
             "mechanism": "warm-up drift A (1 - exp(-t / tau)) of two encoder offsets and the base; base joint "
                          "swept in measurement order",
             "tau_s": tau_s, "time_s": time_s.tolist(),
             "drift_offsets_rad": dict(zip(robot.joint_names, drift_offsets.tolist())),
             "base_drift_twist_m_rad": base_drift.tolist(),
             "drift_tcp_rms_m": rms(positions - cold),
             **truth_geometry(robot, offsets, placements), "tracker": truth_frame(frame), "noise_m": noise}
    name = "d_sweep_drift_time" if with_time else "d_sweep_drift_order"
    return Scenario(name, robot,
                    measurement_csv(robot, q, measured, context, per_frame=False,
                                    comment="issue 28 (d): UR10, base joint swept in order, warm-up drift"),
                    truth, noise, q, measured, context, robot_arg="ur10")


# ---------------------------------------------------------------------------------------
# (e) 36 poses of single-joint sweeps, three reflectors on the flange
# ---------------------------------------------------------------------------------------
#: Three reflectors on the tool-changer's end effector [m], in its link frame (j6 turns about z):
#: 99 mm apart from one another, all off the j6 axis.
REFLECTORS = {"smr_1": (0.07, 0.10, 0.0), "smr_2": (0.0, 0.10, 0.07), "smr_3": (0.0, 0.17, 0.0)}


def urdf_with_reflectors(text: str, parent_link: str, reflectors: dict) -> str:
    """The URDF with one fixed link per reflector, at its position [m] in ``parent_link``."""
    extra = "".join(f'  <link name="{name}"/>\n'
                    f'  <joint name="{name}_mount" type="fixed"><parent link="{parent_link}"/>'
                    f'<child link="{name}"/><origin xyz="{x} {y} {z}" rpy="0 0 0"/></joint>\n'
                    for name, (x, y, z) in reflectors.items())
    head, tail = text.rsplit("</robot>", 1)
    return head + extra + "</robot>" + tail


def single_joint_sweeps(robot: RobotModel, home: np.ndarray, values: int = 6, share: float = 0.35) -> np.ndarray:
    """(n_joints * values, n_joints) joint values: each joint swept alone from ``home``, over
    ``2 share`` of its range centred on home (moved inside the limits where it would leave them),
    never at the home value itself (the grid point nearest home is left out; with no point near
    home, the one farthest from it)."""
    lo, hi = robot.joint_bounds()
    rows = []
    for j in range(robot.n_joints):
        span = share * (hi[j] - lo[j])
        centre = min(max(home[j], lo[j] + span), hi[j] - span)
        grid = centre + span * np.linspace(-1.0, 1.0, values + 1)
        distance = np.abs(grid - home[j])
        gap = grid[1] - grid[0]
        drop = int(np.argmin(distance)) if distance.min() < gap / 2 else int(np.argmax(distance))
        for value in np.delete(grid, drop):
            row = home.copy()
            row[j] = value
            rows.append(row)
    return np.array(rows)


def _frames_columns(rotations: dict, positions: dict) -> np.ndarray:
    """(3 N F, 6 + 3 F) first-order motion of the measured points per tracker-frame twist (v, w)
    and per offset of each frame in its own axes: the 'frames' model a calibration starts with."""
    frames = list(positions)
    blocks = []
    for k, f in enumerate(frames):
        p, r = positions[f], rotations[f]
        n = len(p)
        cols = np.zeros((n, 3, 6 + 3 * len(frames)))
        cols[:, :, :3] = np.eye(3)
        cols[:, :, 3:6] = -np.array([pin.skew(x) for x in p])  # w x p
        cols[:, :, 6 + 3 * k:9 + 3 * k] = r
        blocks.append(cols.reshape(3 * n, -1))
    return np.vstack(blocks)


def _residual_after(columns: np.ndarray, motion: np.ndarray) -> np.ndarray:
    """What of ``motion`` (3 N F,) the columns' least-squares fit leaves."""
    return motion - columns @ np.linalg.lstsq(columns, motion, rcond=None)[0]


def build_sweeps_three_reflectors(seed: int = 0, noise_mm: float = 0.025, payload_kg: float = 165.0,
                                  before_mm: float = 0.8, after_offsets_mm: float = 0.4) -> Scenario:
    """The tool-changer carrying 165 kg, measured in 36 poses of single-joint sweeps (each joint
    alone from the working pose, 6 values) with three reflectors on its end effector (three
    measured frames per row, ``smr_k.x_mm`` ...), ``noise_mm`` per axis; only geometric errors:
    encoder offsets and joint placement errors. Sized so that the tracker frame and the
    reflector offsets leave ``before_mm`` held-out RMS (:func:`reference_heldout`, 6 folds) and
    the joint offsets about ``after_offsets_mm / before_mm`` of it. The payload is in the CSV
    but loads no compliance: the truth is geometric."""
    base = load_robot()
    text = urdf_with_reflectors(base.urdf_text, "end_effector", REFLECTORS)
    frames = list(REFLECTORS)
    robot = robot_from_urdf_text(text, frames[0], name="tool_changer", working_pose=base.working_pose,
                                 payload_kg=payload_kg)
    rng = np.random.default_rng([seed, 5])
    q = single_joint_sweeps(robot, base.working_pose)
    offsets, placements = _sized_geometry(robot, q, frames, rng, before_mm * MM, after_offsets_mm * MM)
    frame = tracker_frame(rng, 3.0)
    noise = noise_mm * MM
    draws = {f: noise * rng.standard_normal((len(q), 3)) for f in frames}

    def scenario(factor: float) -> Scenario:
        hidden = HiddenRobot(robot, {k: factor * xi for k, xi in placements.items()})
        real = hidden.positions(q + factor * offsets, frames)
        measured = {f: in_tracker(frame, real[f]) + draws[f] for f in frames}
        context = {"payload_kg": np.full(len(q), payload_kg)}
        truth = {"scenario": "e", "robot": "tool_changer with three reflectors",
                 "mechanism": "geometric errors only: encoder offsets and joint placement errors",
                 "reflectors_m": {k: list(v) for k, v in REFLECTORS.items()}, "payload_kg": payload_kg,
                 **truth_geometry(robot, factor * offsets, {k: factor * xi for k, xi in placements.items()}),
                 "tracker": truth_frame(frame), "noise_m": noise}
        return Scenario("e_sweeps_three_reflectors", robot,
                        measurement_csv(robot, q, measured, context, per_frame=True,
                                        comment="issue 28 (e): tool-changer, 165 kg, single-joint sweeps, three "
                                                "reflectors"),
                        truth, noise, q, measured, context, urdf_text=text, frames=frames)

    # the sizing is in-sample and first order; 36 poses put the held-out error well above it
    first = scenario(1.0)
    result = scenario(before_mm * MM / reference_heldout(first)[1])
    result.truth["reference_heldout_m"] = {"frames": reference_heldout(result)[1],
                                           "frames+joint_offsets": reference_heldout(result, (1, 2, 3, 4))[1]}
    return result


def _sized_geometry(robot: RobotModel, q: np.ndarray, frames: list, rng: np.random.Generator, before: float,
                    after: float) -> tuple[np.ndarray, dict]:
    """Encoder offsets (n_joints,) and placement errors ``{joint: (6,)}`` [SI], sized to first
    order so that a fit of the tracker frame and each reflector's offset leaves ``before`` [m] RMS
    per point, and one that adds every encoder offset ``after``: the offsets' share is what the
    offsets take, the placements' what they cannot (drawn again where that alone exceeds ``before``)."""
    nominal = hidden_free(robot).placements(q, frames)
    points = {f: p for f, (_, p) in nominal.items()}
    stacked = np.concatenate([points[f].ravel() for f in frames])
    n_points = len(q) * len(frames)

    def motion(hidden, dq):
        moved = hidden.positions(q + dq, frames)
        return np.concatenate([moved[f].ravel() for f in frames]) - stacked

    frames_cols = _frames_columns({f: r for f, (r, _) in nominal.items()}, points)
    offset_cols = np.stack([motion(hidden_free(robot), np.eye(robot.n_joints)[j] * 1e-6) / 1e-6
                            for j in range(robot.n_joints)], axis=1)
    for _ in range(50):
        unit_offsets, unit_placements = geometric_errors(robot, rng, offset_deg=0.05, offset_mm=0.1,
                                                         placement_mm=0.1, placement_deg=0.01)
        by_placements = motion(HiddenRobot(robot, unit_placements), 0.0)
        b = after / rms(_residual_after(np.hstack([frames_cols, offset_cols]), by_placements).reshape(-1, 3))
        u = _residual_after(frames_cols, motion(hidden_free(robot), unit_offsets))
        v = b * _residual_after(frames_cols, by_placements)
        uv, uu, vv = u @ v, u @ u, v @ v
        if vv < 0.5 * n_points * before ** 2:
            a = (-uv + math.sqrt(uv * uv - uu * (vv - n_points * before ** 2))) / uu
            return a * unit_offsets, {k: b * xi for k, xi in unit_placements.items()}
    raise RuntimeError("no draw of placement errors leaves the offsets their share")


# ---------------------------------------------------------------------------------------
# (f) null data
# ---------------------------------------------------------------------------------------
def build_null(seed: int = 0, robot_name: str = "tool_changer", n: int = 200, noise_mm: float = 0.015,
               tcp_offset_mm: float = 10.0) -> Scenario:
    """Nothing but the tracker's frame, a TCP offset (the reflector not where the URDF's TCP is,
    ``tcp_offset_mm`` per axis) and the tracker's noise."""
    robot = load_robot(None if robot_name == "tool_changer" else robot_name)
    rng = np.random.default_rng([seed, 6, len(robot_name)])
    tcp = robot.tool_frame
    q = random_poses(robot, n, rng)
    offset = rng.normal(0.0, tcp_offset_mm * MM, 3)
    hidden = HiddenRobot(robot, frame_offsets={tcp: offset})
    frame = tracker_frame(rng, 3.0)
    noise = noise_mm * MM
    measured = {tcp: noisy(rng, in_tracker(frame, hidden.positions(q, [tcp])[tcp]), noise)}
    truth = {"scenario": "f", "robot": robot.name, "mechanism": "none: tracker frame, TCP offset, noise",
             "tcp_offset_m": offset.tolist(), "tracker": truth_frame(frame), "noise_m": noise}
    return Scenario(f"f_null_{robot.name}", robot,
                    measurement_csv(robot, q, measured, {}, per_frame=False,
                                    comment=f"issue 28 (f): {robot.name}, null data"),
                    truth, noise, q, measured, {}, robot_arg=None if robot_name == "tool_changer" else robot_name)


def _builder(function, **fixed):
    def build(seed: int = 0) -> Scenario:
        return function(seed, **fixed)
    build.__doc__ = function.__doc__
    return build


#: scenario name -> builder(seed)
BUILDERS = {
    "a_gravity_overcompensation": build_gravity_overcompensation,
    "b_lead_direction": build_lead_direction,
    "c_tracker_scale": build_tracker_scale,
    "d_sweep_drift_time": _builder(build_sweep_drift, with_time=True),
    "d_sweep_drift_order": _builder(build_sweep_drift, with_time=False),
    "e_sweeps_three_reflectors": build_sweeps_three_reflectors,
    "f_null_tool_changer": _builder(build_null, robot_name="tool_changer"),
    "f_null_ur5": _builder(build_null, robot_name="ur5"),
}
