"""Poses a robot can reach: ``plan-poses`` and ``simulate`` keep to the joint limits and
``<mimic>`` rules, leave out self-colliding configurations, keep to a task box and to the
tracker's line of sight, and refuse candidate rows the robot cannot take.

The judge of every kept pose is built here from the URDF, not through the package: the
kinematic model with ``pin.buildModelFromUrdf``, the collision bodies with
``pin.buildGeomFromUrdf`` and coal, with the pairs left out that
:mod:`tcr_accuracy.analysis.collision` documents (bodies on one joint or on a parent and
its child joint; UR10 has no SRDF and no body pair in contact at its working pose).
"""

from __future__ import annotations

import csv
import math
import xml.etree.ElementTree as ElementTree

import coal
import numpy as np
import pinocchio as pin
import pytest

from conftest import REPO, run_command
from tcr_accuracy.model.robot import load_robot

UR10_JOINTS = ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint",
               "wrist_3_joint"]
BOX_MM = (-600.0, 600.0, -600.0, 600.0, 0.0, 900.0)


class IndependentUr10:
    """UR10's kinematics and collision bodies straight from its URDF file."""

    def __init__(self):
        robot = load_robot("ur10")  # only for where the files are
        path, package_dirs = str(robot.urdf_path), list(robot.package_dirs)
        self.model = pin.buildModelFromUrdf(path)
        self.geometry = pin.buildGeomFromUrdf(self.model, path, pin.GeometryType.COLLISION,
                                              package_dirs=package_dirs)
        self.geometry.addAllCollisionPairs()
        for pair in list(self.geometry.collisionPairs):
            a = self.geometry.geometryObjects[pair.first].parentJoint
            b = self.geometry.geometryObjects[pair.second].parentJoint
            if a == b or self.model.parents[a] == b or self.model.parents[b] == a:
                self.geometry.removeCollisionPair(pair)
        self.tool = self.model.getFrameId("tool0")
        root = ElementTree.parse(path).getroot()
        limits = {j.get("name"): j.find("limit") for j in root.findall("joint")}
        self.lower = np.array([float(limits[n].get("lower")) for n in UR10_JOINTS])
        self.upper = np.array([float(limits[n].get("upper")) for n in UR10_JOINTS])

    def configuration(self, q_rad):
        full = pin.neutral(self.model)
        for name, value in zip(UR10_JOINTS, q_rad):
            full[self.model.joints[self.model.getJointId(name)].idx_q] = value
        return full

    def colliding(self, q_rad) -> list:
        data, geometry_data = self.model.createData(), self.geometry.createData()
        pin.computeCollisions(self.model, data, self.geometry, geometry_data, self.configuration(q_rad), False)
        return [k for k, r in enumerate(geometry_data.collisionResults) if r.isCollision()]

    def tcp(self, q_rad) -> np.ndarray:
        data = self.model.createData()
        pin.framesForwardKinematics(self.model, data, self.configuration(q_rad))
        return data.oMf[self.tool].translation.copy()

    def bodies_on_segment(self, q_rad, start, end, radius=1e-3) -> list:
        """Names of the bodies a capsule from start to end touches (coal.distance <= 0)."""
        data, geometry_data = self.model.createData(), self.geometry.createData()
        pin.forwardKinematics(self.model, data, self.configuration(q_rad))
        pin.updateGeometryPlacements(self.model, data, self.geometry, geometry_data)
        axis = (end - start) / np.linalg.norm(end - start)
        # a rotation taking z onto the axis, by Rodrigues about z x axis
        v, c = np.cross([0.0, 0.0, 1.0], axis), axis[2]
        vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
        rotation = np.eye(3) + vx + vx @ vx / (1.0 + c)
        beam = coal.Capsule(radius, float(np.linalg.norm(end - start)))
        beam_tf = coal.Transform3s(rotation, 0.5 * (start + end))
        hit = []
        for body, placement in zip(self.geometry.geometryObjects, geometry_data.oMg):
            result = coal.DistanceResult()
            distance = coal.distance(beam, beam_tf, body.geometry,
                                     coal.Transform3s(placement.rotation, placement.translation),
                                     coal.DistanceRequest(), result)
            if distance <= 0.0:
                hit.append(body.name)
        return hit


@pytest.fixture(scope="module")
def ur10_files():
    return IndependentUr10()


@pytest.fixture(scope="module")
def ur10_measured(tmp_path_factory):
    path = tmp_path_factory.mktemp("ur10") / "ur10_60.csv"
    from tcr_accuracy.cli import main

    assert main(["simulate", "--robot", "ur10", "--random", "--n", "60", "--seed", "2", "--out", str(path),
                 "--quiet"]) == 0
    return path


def read_joint_rows(path, names, units):
    """(N, n) joint values [rad, m] of a CSV written in deg / mm."""
    rows = list(csv.DictReader(line for line in path.read_text().splitlines() if not line.startswith("#")))
    scale = [math.pi / 180.0 if u == "deg" else 1e-3 for u in units]
    return np.array([[float(row[f"{n}_{u}"]) * s for n, u, s in zip(names, units, scale)] for row in rows])


# ---------------------------------------------------------------------------------------
# plan-poses on UR10 (collision meshes) and on the tool-changer (none)
# ---------------------------------------------------------------------------------------
def test_ur10_planned_poses_are_within_limits_free_of_self_collision_and_in_the_box(
        ur10_measured, ur10_files, tmp_path, capsys):
    out = tmp_path / "next.csv"
    code, stdout, err = run_command(["plan-poses", str(ur10_measured), "--robot", "ur10", "-k", "12",
                                     "--effects", "joint_offsets,geometry", "--n-candidates", "800",
                                     "--box", *map(str, BOX_MM), "--out", str(out)], capsys)
    assert code == 0, err
    q = read_joint_rows(out, UR10_JOINTS, ["deg"] * 6)
    assert q.shape == (12, 6)
    assert np.all((q >= ur10_files.lower - 1e-9) & (q <= ur10_files.upper + 1e-9))
    assert [ur10_files.colliding(row) for row in q] == [[]] * 12
    box = np.array(BOX_MM).reshape(3, 2) * 1e-3
    for row in q:
        p = ur10_files.tcp(row)
        assert np.all((p >= box[:, 0]) & (p <= box[:, 1])), p
    line = next(t for t in stdout.splitlines() if t.startswith("candidates:"))
    assert "free of self-collision" in line and "in self-collision" in line  # some were rejected, and counted
    assert "TCP in the box x [-600, 600] y [-600, 600] z [0, 900] mm" in line


def test_ur10_random_poses_often_collide_so_the_filter_matters(ur10_files):
    """The check above could not pass by luck: uniform draws within UR10's limits collide often."""
    rng = np.random.default_rng(0)
    q = rng.uniform(ur10_files.lower, ur10_files.upper, size=(300, 6))
    colliding = sum(bool(ur10_files.colliding(row)) for row in q)
    assert colliding > 20  # about 15 % of them


def test_tool_changer_plan_says_self_collision_is_unchecked_and_keeps_the_limits(tmp_path, capsys):
    urdf = (REPO / "robots" / "tool_changer.urdf").read_text()
    assert "<collision" not in urdf  # nothing to check against: the output must say so
    root = ElementTree.fromstring(urdf)
    movable = [j for j in root.findall("joint") if j.get("type") in ("revolute", "prismatic")]
    names = [j.get("name") for j in movable]
    units = ["deg" if j.get("type") == "revolute" else "mm" for j in movable]
    lower = np.array([float(j.find("limit").get("lower")) for j in movable])
    upper = np.array([float(j.find("limit").get("upper")) for j in movable])
    measured = tmp_path / "m.csv"
    assert run_command(["simulate", "--scenario", str(REPO / "examples" / "scenario_compliance.yaml"), "--n", "40",
                        "--seed", "2", "--out", str(measured), "--quiet"], capsys)[0] == 0
    out = tmp_path / "next.csv"
    code, stdout, err = run_command(["plan-poses", str(measured), "-k", "10", "--effects", "joint_offsets",
                                     "--n-candidates", "500", "--out", str(out)], capsys)
    assert code == 0, err
    q = read_joint_rows(out, names, units)
    assert q.shape == (10, 6)
    assert np.all((q >= lower - 1e-9) & (q <= upper + 1e-9))
    unchecked = [t for t in stdout.splitlines() if "not checked" in t]
    assert unchecked == ["candidates: 500 random, within the joint limits; self-collision not checked: the URDF "
                         "of tool_changer has no collision geometry"]


def test_simulate_ur10_random_poses_are_free_of_self_collision(ur10_measured, ur10_files):
    q = read_joint_rows(ur10_measured, UR10_JOINTS, ["deg"] * 6)
    assert len(q) == 60
    assert [ur10_files.colliding(row) for row in q] == [[]] * 60


def test_simulate_says_when_self_collision_is_unchecked(tmp_path, capsys):
    code, stdout, err = run_command(["simulate", "--random", "--n", "20", "--out", str(tmp_path / "s.csv")], capsys)
    assert code == 0, err
    assert ("poses: random, within the joint limits; self-collision not checked: the URDF of tool_changer has "
            "no collision geometry") in stdout.splitlines()


# ---------------------------------------------------------------------------------------
# The tracker's line of sight
# ---------------------------------------------------------------------------------------
def test_a_reflector_hidden_behind_the_robots_base_is_rejected(ur10_files):
    from tcr_accuracy.analysis.reachable import REFLECTOR_CLEARANCE_M, PoseFilter

    robot = load_robot("ur10")
    q = np.zeros(6)  # arm stretched along +x, the flange facing +y
    assert ur10_files.colliding(q) == []
    p = ur10_files.tcp(q)
    shoulder = np.array([0.0, 0.0, 0.127])  # on the base's axis, inside the shoulder body
    behind = shoulder + 1.5 * (shoulder - p) / np.linalg.norm(shoulder - p)  # the base between it and the TCP
    in_front = p + np.array([0.3, 2.0, 0.5])  # facing the flange, nothing between
    for tracker, seen in ((behind, False), (in_front, True)):
        end = p + (tracker - p) * REFLECTOR_CLEARANCE_M / np.linalg.norm(tracker - p)
        blocking = ur10_files.bodies_on_segment(q, tracker, end)
        assert (not blocking) == seen, blocking
        if not seen:
            assert "shoulder_link_0" in blocking or "base_link_0" in blocking
        assert PoseFilter.for_robot(robot, tracker=tracker).in_sight(q[None]).tolist() == [seen]


def test_plan_poses_with_a_tracker_keeps_poses_it_sees(ur10_measured, ur10_files, tmp_path, capsys):
    from tcr_accuracy.analysis.reachable import REFLECTOR_CLEARANCE_M

    tracker_mm = (2500.0, -500.0, 800.0)
    out = tmp_path / "seen.csv"
    code, stdout, err = run_command(["plan-poses", str(ur10_measured), "--robot", "ur10", "-k", "8",
                                     "--effects", "joint_offsets", "--n-candidates", "400",
                                     "--tracker-mm", *map(str, tracker_mm), "--out", str(out)], capsys)
    assert code == 0, err
    assert "hidden from the tracker" in stdout  # some candidates were, and were counted
    tracker = np.array(tracker_mm) * 1e-3
    for row in read_joint_rows(out, UR10_JOINTS, ["deg"] * 6):
        p = ur10_files.tcp(row)
        end = p + (tracker - p) * REFLECTOR_CLEARANCE_M / np.linalg.norm(tracker - p)
        assert ur10_files.bodies_on_segment(row, tracker, end) == []


# ---------------------------------------------------------------------------------------
# Too few candidates; candidate files the robot cannot follow
# ---------------------------------------------------------------------------------------
def test_a_box_out_of_reach_leaves_no_candidate_exit_2(ur10_measured, tmp_path, capsys):
    out = tmp_path / "p.csv"
    code, stdout, err = run_command(["plan-poses", str(ur10_measured), "--robot", "ur10", "-k", "3",
                                     "--effects", "joint_offsets", "--n-candidates", "100",
                                     "--box", "5000", "6000", "0", "100", "0", "100", "--out", str(out)], capsys)
    assert code == 2 and stdout == ""
    assert len(err.strip().splitlines()) == 1
    assert "no candidate left" in err and "with the TCP outside the box" in err
    assert not out.exists()


def test_few_survivors_are_said_with_the_counts(ur10_measured, ur10_files, tmp_path, capsys):
    candidates = tmp_path / "cand.csv"
    reachable = [np.radians([10, -60, 60, 0, 90, 0]), np.radians([-20, -90, 100, -30, 90, 0])]
    colliding = np.radians([0, 0, 180, 0, 0, 0])  # the forearm folded back onto the upper arm
    assert [ur10_files.colliding(q) for q in reachable] == [[], []] and ur10_files.colliding(colliding)
    rows = [*reachable, colliding]
    candidates.write_text(",".join(f"{n}_deg" for n in UR10_JOINTS) + "\n"
                          + "".join(",".join(f"{v:.6f}" for v in np.degrees(q)) + "\n" for q in rows))
    out = tmp_path / "p.csv"
    code, stdout, err = run_command(["plan-poses", str(ur10_measured), "--robot", "ur10", "-k", "3",
                                     "--effects", "joint_offsets", "--candidates", str(candidates),
                                     "--out", str(out)], capsys)
    assert code == 0, err
    assert f"only 2 candidates (from {candidates}) survive (3 given: 1 in self-collision): planning 2 poses " \
           "instead of 3" in stdout
    assert len(read_joint_rows(out, UR10_JOINTS, ["deg"] * 6)) == 2


def test_a_candidate_row_outside_the_limits_is_refused_naming_it(ur10_measured, tmp_path, capsys):
    candidates = tmp_path / "cand.csv"
    candidates.write_text("# from a task\n" + ",".join(f"{n}_deg" for n in UR10_JOINTS) + "\n"
                          "10,-60,60,0,90,0\n10,-60,200,0,90,0\n")  # elbow_joint within +-180 deg
    out = tmp_path / "p.csv"
    code, stdout, err = run_command(["plan-poses", str(ur10_measured), "--robot", "ur10", "-k", "1",
                                     "--effects", "joint_offsets", "--candidates", str(candidates),
                                     "--out", str(out)], capsys)
    assert code == 2 and stdout == ""
    assert err.strip().splitlines() == [f"tcr-accuracy plan-poses: error: {candidates}: row 4: joint elbow_joint = "
                                        "200 deg is outside its limits [-180, 180] deg; a candidate must be a pose "
                                        "the robot can take (1 such row(s))"]
    assert not out.exists()


MIMIC_URDF = """<robot name="mim"><link name="base"/><link name="l1"/><link name="l2"/><link name="l3"/>
<link name="tool"/>
<joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0 0.3"/><axis xyz="0 0 1"/>
  <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
<joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0 0 0.3"/><axis xyz="1 0 0"/>
  <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
<joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/><origin xyz="0 0.4 0"/><axis xyz="1 0 0"/>
  <limit lower="-2.2" upper="2.2" effort="1" velocity="1"/><mimic joint="j2" multiplier="-1" offset="0.1"/></joint>
<joint name="jt" type="fixed"><parent link="l3"/><child link="tool"/><origin xyz="0 0.3 0"/></joint>
</robot>"""


def test_a_candidate_row_off_its_mimic_rule_is_refused_naming_it(tmp_path, capsys):
    urdf = tmp_path / "mim.urdf"
    urdf.write_text(MIMIC_URDF)
    measured = tmp_path / "m.csv"
    assert run_command(["simulate", "--robot", str(urdf), "--tool", "tool", "--random", "--n", "30", "--seed", "1",
                        "--out", str(measured), "--quiet"], capsys)[0] == 0
    j2, follows = 30.0, -30.0 + math.degrees(0.1)  # j3 = -1 x j2 + 0.1 rad
    candidates = tmp_path / "cand.csv"
    candidates.write_text(f"j1_deg,j2_deg,j3_deg\n0,{j2},{follows:.6f}\n5,{j2},{follows + 3:.6f}\n")
    code, stdout, err = run_command(["plan-poses", str(measured), "--robot", str(urdf), "--tool", "tool", "-k", "1",
                                     "--effects", "joint_offsets", "--candidates", str(candidates),
                                     "--out", str(tmp_path / "p.csv")], capsys)
    assert code == 2 and stdout == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and f"{candidates}: row 3: joint j3 = {follows + 3:.6g} deg breaks its <mimic> rule" \
        in lines[0]
    candidates.write_text(f"j1_deg,j2_deg,j3_deg\n0,{j2},{follows:.6f}\n5,{j2},{follows:.6f}\n")
    code, stdout, err = run_command(["plan-poses", str(measured), "--robot", str(urdf), "--tool", "tool", "-k", "1",
                                     "--effects", "joint_offsets", "--candidates", str(candidates),
                                     "--out", str(tmp_path / "p.csv")], capsys)
    assert code == 0, err
