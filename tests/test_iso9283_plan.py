"""iso9283 plan as a robot must run it: every pose and corner above the mounting plane (or the floor
or box given), no revolute joint more than half a turn from home, no body below the mounting plane,
free of self-collision, the cycles in the standard's order and the test conditions in the file.

The checks read the plan's CSV and redo the kinematics with Pinocchio and the collision queries
with coal here (a box under the floor, coal.distance between bodies), not with the planner's code."""

import json
from itertools import combinations

import numpy as np
import pinocchio as pin
import pytest

from tcr_accuracy.iso9283.plan import plan_iso_cube
from tcr_accuracy.iso9283.reach import Workspace
from tcr_accuracy.model.robot import load_robot

from conftest import pinocchio_kinematics
from conftest import run_command as run


def _full_q(robot, q):
    qf = pin.neutral(robot.full_model)
    for name, v in zip(robot.joint_names, q):
        qf[robot.full_model.joints[robot.full_model.getJointId(name)].idx_q] = v
    return qf


def _geometry(robot):
    return pin.buildGeomFromUrdfString(robot.full_model, robot.urdf_text, pin.GeometryType.COLLISION,
                                       package_dirs=robot.package_dirs)


def _body_troubles(robot, geom, q, design_contacts, floor=0.0):
    """(self-collisions beyond the design contacts, bodies reaching below z = floor) at chain joints q:
    coal.distance between every pair of bodies on non-adjacent joints, and between every body not
    fixed to the base and a 100 m slab whose top face is the floor."""
    model, data = robot.full_model, robot.full_model.createData()
    gdata = geom.createData()
    pin.updateGeometryPlacements(model, data, geom, gdata, _full_q(robot, q))
    slab = pin.coal.Box(100.0, 100.0, 1.0)
    slab_at = pin.coal.Transform3s(np.eye(3), np.array([0.0, 0.0, floor - 0.5]))
    contacts, below = set(), []
    placements = [pin.coal.Transform3s(m.rotation, m.translation) for m in gdata.oMg]
    for i, j in combinations(range(geom.ngeoms), 2):
        a, b = geom.geometryObjects[i], geom.geometryObjects[j]
        if a.parentJoint == b.parentJoint or model.parents[a.parentJoint] == b.parentJoint \
                or model.parents[b.parentJoint] == a.parentJoint:
            continue
        result = pin.coal.DistanceResult()
        if pin.coal.distance(a.geometry, placements[i], b.geometry, placements[j], pin.coal.DistanceRequest(),
                             result) <= 0:
            contacts.add((a.name, b.name))
    for i, body in enumerate(geom.geometryObjects):
        if body.parentJoint == 0:
            continue  # the base stands on the mounting plane
        result = pin.coal.DistanceResult()
        if pin.coal.distance(body.geometry, placements[i], slab, slab_at, pin.coal.DistanceRequest(), result) <= 0:
            below.append(body.name)
    return contacts - design_contacts, below


def _tcp(robot, q):
    data, placement = pinocchio_kinematics(robot, q)
    return placement.translation.copy(), [data.oMi[j].translation[2] for j in range(1, robot.model.njoints)]


def _plan_rows(path, robot):
    lines = [line for line in path.read_text().splitlines() if not line.startswith("#")]
    head = lines[0].split(",")
    rows = [dict(zip(head, line.split(","))) for line in lines[1:]]
    q = np.array([[float(r[f"{n}_{u}"]) for n, u in zip(robot.joint_names, robot.display_units)] for r in rows])
    return rows, q / robot.display_scale


#: The makers' ready poses [deg], written out: the UR's upright home (PolyScope), Franka's ready pose.
READY_DEG = {"ur5": [0, -90, 0, -90, 0, 0], "ur10": [0, -90, 0, -90, 0, 0], "panda": [0, -45, 0, -135, 0, 90, 45]}


@pytest.mark.parametrize("name", ["ur5", "ur10", "panda", "tool_changer"])
def test_plan_keeps_above_the_mounting_plane_near_home_and_free_of_collision(name, tmp_path, capsys):
    code, out, err = run(["iso9283", "plan", "--robot", name, "--cycles", "3", "--out", str(tmp_path / "plan.csv"),
                          "--json", str(tmp_path / "plan.json")], capsys)
    assert code == 0, err
    robot = load_robot(name)
    rows, q = _plan_rows(tmp_path / "plan.csv", robot)
    payload = json.loads((tmp_path / "plan.json").read_text())
    # the default home: the maker's ready pose (the UR upright, Franka's ready pose), else the reference pose
    home = np.radians(READY_DEG[name]) if name in READY_DEG else robot.working_pose
    np.testing.assert_allclose(np.asarray(payload["home_display"]) / robot.display_scale, home, atol=1e-12)
    revolute = np.array([k == "revolute" for k in robot.joint_kinds])
    assert np.degrees(np.abs(q - home)[:, revolute]).max() <= 180.0 + 1e-6
    lo, hi = robot.joint_bounds(np.inf)
    assert np.all(q >= lo - 1e-9) and np.all(q <= hi + 1e-9)
    # the CSV's joints reach its targets, all above the mounting plane, with the joint origins above it too
    for row, qk in zip(rows, q):
        tcp, origins = _tcp(robot, qk)
        target = np.array([float(row[f"target_{a}_mm"]) for a in "xyz"]) * 1e-3
        assert np.linalg.norm(tcp - target) < 1e-6
        assert tcp[2] >= 0.0
        if name == "tool_changer":
            assert min(origins) >= 0.0
    # the cube's corners (where the paths run) too, and no body below the plane, no self-collision
    plan = plan_iso_cube(robot, np.random.default_rng(0))
    np.testing.assert_allclose(plan.q[0], q[4], atol=1e-7)  # the same plan as the command's (P1 ends cycle 1)
    corners = plan.centre + plan.size / 2 * np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])
    assert corners[:, 2].min() >= 0.0
    assert np.degrees(np.abs(plan.corner_q - home)[:, revolute]).max() <= 180.0 + 1e-6
    if name != "tool_changer":
        geom = _geometry(robot)
        design, _ = _body_troubles(robot, geom, home, set())
        for qk in np.vstack([plan.q, plan.corner_q]):
            contacts, below = _body_troubles(robot, geom, qk, design)
            assert not contacts and not below, (contacts, below)
        # the queries are not blind: somewhere in the joint space they find contacts and bodies below
        found = [_body_troubles(robot, geom, qk, design)
                 for qk in np.random.default_rng(1).uniform(*robot.joint_bounds(np.pi), (40, robot.n_joints))]
        assert any(c for c, _ in found) and any(b for _, b in found)


def test_the_cycles_start_at_p1_and_the_conditions_are_blocks_of_the_file(tmp_path, capsys):
    code, out, err = run(["iso9283", "plan", "--robot", "ur5", "--cycles", "2", "--out", str(tmp_path / "plan.csv")],
                         capsys)
    assert code == 0, err
    robot = load_robot("ur5")
    rows, _ = _plan_rows(tmp_path / "plan.csv", robot)
    # the standard's conditions: rated load (5 kg for a UR5) at 100, 50, 10 % speed, then 10 % load at 100 %
    blocks = [(float(r["load_pct"]), float(r["speed_pct"]), float(r["payload_kg"])) for r in rows]
    assert list(dict.fromkeys(blocks)) == [(100, 100, 5.0), (100, 50, 5.0), (100, 10, 5.0), (10, 100, 0.5)]
    for k in range(4):
        block = rows[10 * k:10 * (k + 1)]
        assert [r["pose_id"] for r in block] == ["P5", "P4", "P3", "P2", "P1"] * 2
        assert [r["cycle"] for r in block] == ["1"] * 5 + ["2"] * 5
    comments = [line for line in (tmp_path / "plan.csv").read_text().splitlines() if line.startswith("# condition")]
    assert len(comments) == 4 and all("start at P1" in c for c in comments)
    assert "10 % rated load (0.5 kg), 100 % rated speed" in out


def test_a_floor_and_a_box_and_a_home_are_kept(tmp_path, capsys):
    home = [90, -90, 90, -90, -90, 0]
    code, out, err = run(["iso9283", "plan", "--robot", "ur10", "--floor-mm", "200", "--box", "-1500", "1500",
                          "0", "1500", "-500", "1500", "--home", *map(str, home), "--cycles", "1", "--conditions",
                          "100/100", "--out", str(tmp_path / "plan.csv")], capsys)
    assert code == 0, err
    robot = load_robot("ur10")
    rows, q = _plan_rows(tmp_path / "plan.csv", robot)
    targets = np.array([[float(r[f"target_{a}_mm"]) for a in "xyz"] for r in rows])
    assert targets[:, 2].min() >= 200.0 and targets[:, 1].min() >= 0.0
    assert np.degrees(np.abs(q - np.radians(home))).max() <= 180.0 + 1e-6


@pytest.mark.parametrize("argv, words", [
    (["--cube-centre-mm", "400", "100", "300", "--cube-size-mm", "1e-9"], "--cube-size-mm 1e-9: want a number >= 10"),
    (["--cube-centre-mm", "400", "100", "40", "--cube-size-mm", "200"], "below the floor"),
    (["--home", "0", "0"], "--home: expected 6 joint values"),
    (["--conditions", "100/0"], "want LOAD/SPEED"),
    (["--box", "0", "100", "0", "100", "-300", "-100"], "the box lies below the floor"),
])
def test_plans_no_one_should_run_are_refused(argv, words, tmp_path, capsys):
    code, out, err = run(["iso9283", "plan", "--robot", "ur5", *argv, "--out", str(tmp_path / "plan.csv")], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1 and words in err, err
    assert not (tmp_path / "plan.csv").exists()


def test_a_given_cube_under_the_floor_is_named(tmp_path):
    with pytest.raises(Exception, match="outside the workspace"):
        plan_iso_cube(load_robot("ur5"), np.random.default_rng(0), centre=[0.4, 0.1, 0.04], size=0.2,
                      workspace=Workspace(floor=0.0))


def _rpy_by_hand(roll, pitch, yaw):
    """R = Rz(yaw) Ry(pitch) Rx(roll) [rad], written out (the URDF's rpy)."""
    cr, sr, cp, sp, cy, sy = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return rz @ ry @ rx


def test_the_tool_orientation_and_the_trackers_line_of_sight_are_kept(tmp_path, capsys):
    """--tool-rpy: every pose holds that TCP orientation (Pinocchio's forward kinematics here);
    --tracker-mm: no collision body on the beam to P1..P5 (coal capsules built here) and each pose's
    distance from the tracker written; a tracker inside the robot's base sees nothing: refused."""
    rpy, tracker = (180.0, 0.0, 90.0), np.array([1500.0, -1200.0, 600.0])
    code, out, err = run(["iso9283", "plan", "--robot", "ur5", "--tool-rpy", *map(str, rpy), "--tracker-mm",
                          *map(str, tracker), "--cycles", "1", "--conditions", "100/100", "--out",
                          str(tmp_path / "plan.csv"), "--json", str(tmp_path / "plan.json")], capsys)
    assert code == 0, err
    robot = load_robot("ur5")
    rows, q = _plan_rows(tmp_path / "plan.csv", robot)
    wanted = _rpy_by_hand(*np.radians(rpy))
    for qk in q:
        _, placement = pinocchio_kinematics(robot, qk)
        np.testing.assert_allclose(placement.rotation, wanted, atol=1e-6)
    payload = json.loads((tmp_path / "plan.json").read_text())
    geom = _geometry(robot)
    model, data = robot.full_model, robot.full_model.createData()
    for pose in payload["poses"]:
        target = np.array(pose["target_mm"]) * 1e-3
        assert pose["tracker_distance_mm"] == pytest.approx(np.linalg.norm(target * 1e3 - tracker), abs=1e-6)
        qk = np.asarray(pose["q_display"]) / robot.display_scale
        gdata = geom.createData()
        pin.updateGeometryPlacements(model, data, geom, gdata, _full_q(robot, qk))
        start = tracker * 1e-3
        end = target + (start - target) * 0.025 / np.linalg.norm(start - target)  # the reflector's 25 mm
        axis = (end - start) / np.linalg.norm(end - start)
        beam = pin.coal.Capsule(1e-3, float(np.linalg.norm(end - start)))
        at = pin.coal.Transform3s(pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), axis).matrix(),
                                  0.5 * (start + end))
        for body, placement in zip(geom.geometryObjects, gdata.oMg):
            hit = pin.coal.collide(beam, at, body.geometry, pin.coal.Transform3s(placement.rotation,
                                                                                 placement.translation),
                                   pin.coal.CollisionRequest(), pin.coal.CollisionResult())
            assert not hit, (pose["pose_id"], body.name)
    assert "sees every measured pose" in out and "mm from the tracker" in out
    code, out, err = run(["iso9283", "plan", "--robot", "ur5", "--tracker-mm", "0", "0", "40", "--cycles", "1",
                          "--conditions", "100/100", "--out", str(tmp_path / "hidden.csv")], capsys)
    assert code == 2 and "in sight of the tracker" in err and not (tmp_path / "hidden.csv").exists(), err
