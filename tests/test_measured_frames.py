"""Several measured frames per row (both hands of a two-armed robot): shared parameters fitted
once; measured orientation in the fit.

The hidden truth is written down here by parameter name and each hand's positions are
made from it through that hand's own chain; the diagnosis sees only the CSV.
"""

import numpy as np
import pinocchio as pin
import pytest

from tcr_accuracy.cli import main
from tcr_accuracy.model.context import MeasurementContext
from tcr_accuracy.diagnosis.diagnose import diagnose
from tcr_accuracy.effects import make_effect, predict_positions
from tcr_accuracy.exceptions import InputError
from tcr_accuracy.io.measurements import measured_frames, parse_measurements, read_measurements
from tcr_accuracy.model.robot import robot_from_urdf_text


def _arm(side: str, y: float) -> str:
    inertia = 'ixx="1e-9" iyy="1e-9" izz="1e-9" ixy="0" ixz="0" iyz="0"'
    return f"""
  <link name="{side}1"><inertial><origin xyz="0.2 0 0"/><mass value="3"/><inertia {inertia}/></inertial></link>
  <link name="{side}2"><inertial><origin xyz="0.15 0 0"/><mass value="2"/><inertia {inertia}/></inertial></link>
  <link name="{side}_marker"/>
  <joint name="{side}a" type="revolute"><parent link="torso"/><child link="{side}1"/>
    <origin xyz="0 {y} 0.4" rpy="0.3 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="{side}b" type="revolute"><parent link="{side}1"/><child link="{side}2"/>
    <origin xyz="0.4 0 0"/><axis xyz="0 0 1"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="{side}_fix" type="fixed"><parent link="{side}2"/><child link="{side}_marker"/>
    <origin xyz="0.3 0.05 0.02"/></joint>"""


TWO_ARMS = f"""<?xml version="1.0"?>
<robot name="two_arms">
  <link name="base"/>
  <link name="torso"><inertial><origin xyz="0 0 0.2"/><mass value="5"/>
    <inertia ixx="1e-9" iyy="1e-9" izz="1e-9" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="t" type="revolute"><parent link="base"/><child link="torso"/>
    <origin xyz="0 0 0.5"/><axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  {_arm("right", -0.3)}
  {_arm("left", 0.3)}
</robot>
"""
JOINTS = ["t", "righta", "rightb", "lefta", "leftb"]
TRUTH = {
    "frames.base.dx": 0.012, "frames.base.dy": -0.02, "frames.base.dz": 0.008,
    "frames.base.rx": 0.01, "frames.base.ry": -0.004, "frames.base.rz": 0.02,
    "joint_offsets.righta": np.radians(0.2), "joint_offsets.rightb": np.radians(-0.3),
    "joint_offsets.lefta": np.radians(0.25), "joint_offsets.leftb": np.radians(0.15),
    "compliance.t": 4e-5, "compliance.righta": 6e-5, "compliance.lefta": 5e-5,
}
TOOL = {"right_marker": [0.002, -0.001, 0.0015], "left_marker": [-0.001, 0.002, 0.001]}


def _simulate(n: int, noise: float, seed: int) -> str:
    """CSV text: every joint, and both markers' positions in a tracker frame."""
    rng = np.random.default_rng(seed)
    q_all = rng.uniform(-1.0, 1.0, (n, len(JOINTS)))
    columns = [f"{j}_deg" for j in JOINTS]
    blocks = [np.degrees(q_all)]
    for frame in TOOL:
        robot = robot_from_urdf_text(TWO_ARMS, frame, name="two_arms")
        q = q_all[:, [JOINTS.index(j) for j in robot.joint_names]]
        outside = q_all[:, [JOINTS.index(j) for j in robot.outside_joint_names]]
        ctx = MeasurementContext(np.zeros(n), np.full(n, 20.0), np.zeros_like(q), outside_q=outside)
        effects, params = [], []
        for name in ("frames", "joint_offsets", "compliance"):
            effect = make_effect(name, robot)
            truth = {**TRUTH, **{f"frames.tool.{c}": v for c, v in zip(("dx", "dy", "dz"), TOOL[frame])}}
            effects.append(effect)
            params.append(np.array([truth.get(p, 0.0) for p in effect.parameter_names()]))
        position = predict_positions(robot, effects, params, q, ctx) + noise * rng.standard_normal((n, 3))
        columns += [f"{frame}.{a}_mm" for a in "xyz"]
        blocks.append(position * 1e3)
    table = np.concatenate(blocks, axis=1)
    return ",".join(columns) + "\n" + "\n".join(",".join(f"{v:.12g}" for v in row) for row in table) + "\n"


def _read(text: str):
    robots = [robot_from_urdf_text(TWO_ARMS, f, name="two_arms") for f in TOOL]
    return [(r, parse_measurements(text, r, frame=f, check_units=False)) for r, f in zip(robots, TOOL)]


def test_reading_one_frame_of_several():
    text = _simulate(20, 0.0, 1)
    parts = _read(text)
    assert [r.tool_frame for r, _ in parts] == ["right_marker", "left_marker"]
    right, left = parts[0][1], parts[1][1]
    assert right.joint_names == ["t", "righta", "rightb"] and right.outside_q.shape == (20, 2)
    assert not np.allclose(right.position, left.position)
    robot = parts[0][0]
    # the robot's TCP (what --tool names) is one of the measured frames: that one is read
    assert np.array_equal(parse_measurements(text, robot, check_units=False).position, right.position)
    elsewhere = robot_from_urdf_text(TWO_ARMS, "right1", name="two_arms")
    with pytest.raises(InputError, match="measures several frames .*tool=FRAME"):
        parse_measurements(text, elsewhere, check_units=False)
    with pytest.raises(InputError, match="no columns hand.x_mm"):
        parse_measurements(text, robot, frame="hand", check_units=False)
    bad = text.replace("right_marker.x_mm", "x_mm", 1)
    with pytest.raises(InputError, match="column x_mm next to per-frame columns"):
        parse_measurements(bad, robot, frame="left_marker", check_units=False)
    cell = text.splitlines()
    cell[3] = cell[3].rsplit(",", 1)[0] + ",abc"
    with pytest.raises(InputError, match=r"row 4, column left_marker.z_mm: 'abc' is not a number"):
        parse_measurements("\n".join(cell), robot, frame="right_marker", check_units=False)


def test_shared_parameters_are_fitted_once_and_agree_with_each_hand_alone():
    text = _simulate(150, 0.0, 2)
    parts = _read(text)
    both = diagnose(parts[0][0], parts, effects=["joint_offsets", "compliance"], folds=3, tracker_noise=1e-6)
    alone = [diagnose(r, m, effects=["joint_offsets", "compliance"], folds=3, tracker_noise=1e-6) for r, m in parts]
    assert both.frames_measured == ["right_marker", "left_marker"]
    assert both.steps[-1].heldout.rms < 1e-7  # noise-free: the model is exact
    fitted = {k: v for p in both.parameters.values() for k, v in p.items()}
    # one TCP offset per hand, one tracker frame for both
    assert {"frames.right_marker.dx", "frames.left_marker.dx", "frames.base.dx"} <= set(fitted)
    # (a TCP offset absorbs the offset of the last joint, which turns it: compare the rest)
    assert "joint_offsets.leftb" not in fitted and "joint_offsets.rightb" not in fitted
    for name, value in TRUTH.items():
        if name in fitted and not name.startswith("frames."):
            assert fitted[name] == pytest.approx(value, rel=1e-6), name
    assert "compliance.t" in fitted  # the torso, seen by both hands
    for single in alone:
        for name, value in single.parameters.get("compliance", {}).items():
            assert value == pytest.approx(fitted[name], rel=1e-6)


def test_two_hands_with_noise_through_the_command_line(tmp_path):
    path = tmp_path / "hands.csv"
    path.write_text(_simulate(200, 5e-5, 3))
    urdf = tmp_path / "two_arms.urdf"
    urdf.write_text(TWO_ARMS)
    assert measured_frames(path) == ["right_marker", "left_marker"]
    out = tmp_path / "d.json"
    code = main(["diagnose", str(path), "--robot", str(urdf), "--tool", "left_marker", "--effects",
                 "joint_offsets,compliance,geometry", "--folds", "4", "--noise-mm", "0.05", "--json", str(out),
                 "--quiet"])
    assert code == 0
    import json

    d = json.loads(out.read_text())
    assert d["frames_measured"] == ["left_marker", "right_marker"]  # --tool first
    assert d["primary_effect"] in ("compliance", "joint_offsets")
    for frame in ("left_marker", "right_marker"):
        assert d["heldout_by_frame"][frame]["rms_mm"] < 1.5 * 0.05 * np.sqrt(3)  # about the noise floor
    left = read_measurements(path, robot_from_urdf_text(TWO_ARMS, "left_marker", name="x"), frame="left_marker",
                             check_units=False)
    assert len(left) == 200


def test_measured_orientation_enters_the_fit(tool_changer):
    """A tilt of the last joint's axis does not move the TCP (it sits on that axis) but turns it:
    only a fit that uses the measured orientation can find it. The hidden robot on Pinocchio alone
    (tests/hidden_robot.py, no effect class): j6's placement turned -0.5 mrad about its y axis, j3's
    moved 0.2 mm along z, the TCP 1 mm off along x, the tracker 1.6 m away turned 35 deg; 0.02 mm
    and 2e-5 rad of noise per axis."""
    from dataclasses import replace

    from hidden_robot import HiddenRobot, fixed_tracker, in_tracker, measurement_csv, noisy, random_poses

    rng = np.random.default_rng(4)
    q = random_poses(tool_changer, 150, rng)
    tcp = tool_changer.tool_frame
    hidden = HiddenRobot(tool_changer, {"j6": np.array([0.0, 0.0, 0.0, 0.0, -5e-4, 0.0]),
                                        "j3": np.array([0.0, 0.0, 2e-4, 0.0, 0.0, 0.0])},
                         {tcp: np.array([1e-3, 0.0, 0.0])})
    rotation, position = hidden.placements(q, [tcp])[tcp]
    tracker = fixed_tracker()
    measured = noisy(rng, in_tracker(tracker, position), 2e-5)
    turned = [tracker.rotation @ r @ pin.exp3(rng.normal(0.0, 2e-5, 3)) for r in rotation]
    quaternion = np.array([[z.w, z.x, z.y, z.z] for z in (pin.Quaternion(r) for r in turned)])
    mset = parse_measurements(measurement_csv(tool_changer, q, {tcp: measured}, {}, per_frame=False), tool_changer)
    mset = replace(mset, quaternion=quaternion)
    with_orientation = diagnose(tool_changer, mset, effects=["geometry"], folds=3, tracker_noise=2e-5)
    assert with_orientation.parameters["geometry"]["geometry.j6.ry"] == pytest.approx(-5e-4, rel=0.02)
    # held-out orientation error at the orientation noise (2e-5 rad per axis)
    assert with_orientation.orientation["heldout_rms_deg"] < 2 * np.degrees(2e-5 * np.sqrt(3))
    assert any("orientation enters the fit" in note for note in with_orientation.notes)
    positions_only = diagnose(tool_changer, replace(mset, quaternion=None), effects=["geometry"], folds=3,
                              tracker_noise=2e-5)
    assert "geometry.j6.ry" not in positions_only.parameters["geometry"]
