"""ISO 9283 pose test: the figures against the standard's formulas written out here, the planned
cube against its geometry, IK, limits and an independent collision query, and the CLI."""

import json
import math
from itertools import combinations

import numpy as np
import pinocchio as pin
import pytest

from tcr_accuracy.cli import main
from tcr_accuracy.io.measurements import read_measurements
from tcr_accuracy.model.robot import load_robot

from conftest import tool_changer_tcp_by_hand
from conftest import run_command as run

#: Five distinct tool-changer poses [deg, deg, deg, mm, deg, deg] standing in for P1..P5.
POSES_DISPLAY = np.array([
    [10, 20, -10, 200, -20, 0],
    [-30, 35, 5, 300, 10, 20],
    [45, 10, -25, 100, -35, -15],
    [80, 25, 15, 400, 5, 40],
    [-60, 5, -5, 250, -10, -30],
], dtype=float)


def _q_si(display):
    q = np.radians(display)
    q[3] = display[3] * 1e-3
    return q


def _skew_log(rotation):
    """Rotation vector of a rotation matrix, written out: angle from the trace, axis from the skew part."""
    angle = math.acos(max(-1.0, min(1.0, (np.trace(rotation) - 1.0) / 2.0)))
    if angle < 1e-12:
        return np.zeros(3)
    w = np.array([rotation[2, 1] - rotation[1, 2], rotation[0, 2] - rotation[2, 0], rotation[1, 0] - rotation[0, 1]])
    return w * angle / (2.0 * math.sin(angle))


def _small_rotation(v):
    """exp of the rotation vector v, written out (Rodrigues)."""
    angle = np.linalg.norm(v)
    k = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]]) / angle
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


def _quaternion(rotation):
    """(w, x, y, z) of a rotation matrix (trace method; the test rotations are near the TCP's, w > 0)."""
    w = math.sqrt(max(0.0, 1.0 + np.trace(rotation))) / 2.0
    return np.array([w, (rotation[2, 1] - rotation[1, 2]) / (4 * w), (rotation[0, 2] - rotation[2, 0]) / (4 * w),
                     (rotation[1, 0] - rotation[0, 1]) / (4 * w)])


def _repeat_data(rng, counts=(30, 30, 30, 30, 12), orientation=True):
    """Readings in the base frame [mm]: known barycentre offsets and spreads per pose, cycles in order."""
    bias_mm = rng.normal(0, 0.3, (5, 3))
    spread_mm = np.array([0.02, 0.05, 0.01, 0.08, 0.03])
    rows = []
    for cycle in range(1, max(counts) + 1):
        for k in (4, 3, 2, 1, 0):  # P5..P1
            if cycle > counts[k]:
                continue
            m = tool_changer_tcp_by_hand(_q_si(POSES_DISPLAY[k]))
            p = m[:3, 3] * 1e3 + bias_mm[k] + rng.normal(0, spread_mm[k], 3)
            rot = m[:3, :3] @ _small_rotation(rng.normal(0, 2e-4, 3) + 1e-3 * (k + 1))
            rows.append((k + 1, cycle, p, rot, m))
    return rows


def _write(path, rows, orientation=True, approach=None):
    head = "j1_deg,j2_deg,j3_deg,j4_mm,j5_deg,j6_deg,x_mm,y_mm,z_mm" + (",qw,qx,qy,qz" if orientation else "") + \
        ",pose_id,cycle" + (",approach" if approach is not None else "")
    lines = [head]
    for i, (pid, cycle, p, rot, _) in enumerate(rows):
        cells = [repr(float(v)) for v in POSES_DISPLAY[pid - 1]] + [repr(float(v)) for v in p]
        if orientation:
            cells += [repr(float(v)) for v in _quaternion(rot)]
        cells += [str(pid), str(cycle)] + ([str(approach[i])] if approach is not None else [])
        lines.append(",".join(cells))
    path.write_text("\n".join(lines) + "\n")


def test_evaluate_reproduces_the_standard_formulas_written_out(tmp_path, capsys):
    rows = _repeat_data(np.random.default_rng(7))
    _write(tmp_path / "meas.csv", rows)
    code, out, err = run(["iso9283", "evaluate", str(tmp_path / "meas.csv"), "--frame", "base",
                          "--json", str(tmp_path / "iso.json")], capsys)
    assert code == 0, err
    got = {p["pose_id"]: p for p in json.loads((tmp_path / "iso.json").read_text())["poses"]}
    assert sorted(got) == [1, 2, 3, 4, 5]
    for pid in range(1, 6):
        mine = [r for r in rows if r[0] == pid]
        n = len(mine)
        commanded = mine[0][4][:3, 3] * 1e3
        xs = [r[2] for r in mine]
        bar = [sum(p[a] for p in xs) / n for a in range(3)]
        ap = [bar[a] - commanded[a] for a in range(3)]
        ap_p = math.sqrt(sum(v * v for v in ap))
        l = [math.sqrt(sum((p[a] - bar[a]) ** 2 for a in range(3))) for p in xs]
        l_mean = sum(l) / n
        s_l = math.sqrt(sum((v - l_mean) ** 2 for v in l) / (n - 1))
        rp = l_mean + 3 * s_l
        g = got[pid]
        assert g["n"] == n
        assert g["ap_mm"] == pytest.approx(ap_p, abs=1e-9)
        assert [g["ap_x_mm"], g["ap_y_mm"], g["ap_z_mm"]] == pytest.approx(ap, abs=1e-9)
        assert g["rp_mm"] == pytest.approx(rp, abs=1e-9)
        # orientation: a, b, c = rotation vector of R_measured R_commanded^T about the base axes
        dev = [np.degrees(_skew_log(r[3] @ r[4][:3, :3].T)) for r in mine]
        for a, axis in enumerate("abc"):
            mean = sum(d[a] for d in dev) / n
            std = math.sqrt(sum((d[a] - mean) ** 2 for d in dev) / (n - 1))
            assert g[f"ap_{axis}_deg"] == pytest.approx(mean, abs=1e-9)
            assert g[f"rp_{axis}_deg"] == pytest.approx(3 * std, abs=1e-9)
    # distance accuracy between every pair of poses over the cycles they share
    got_d = {(d["pose_a"], d["pose_b"]): d for d in json.loads((tmp_path / "iso.json").read_text())["distances"]}
    assert len(got_d) == 10
    for a, b in combinations(range(1, 6), 2):
        by_cycle_a = {r[1]: r for r in rows if r[0] == a}
        by_cycle_b = {r[1]: r for r in rows if r[0] == b}
        common = sorted(set(by_cycle_a) & set(by_cycle_b))
        d = [math.dist(by_cycle_a[c][2], by_cycle_b[c][2]) for c in common]
        d_c = math.dist(by_cycle_a[common[0]][4][:3, 3] * 1e3, by_cycle_b[common[0]][4][:3, 3] * 1e3)
        mean = sum(d) / len(d)
        assert got_d[(a, b)]["n"] == len(common)
        assert got_d[(a, b)]["ad_mm"] == pytest.approx(mean - d_c, abs=1e-9)
        assert got_d[(a, b)]["rd_mm"] == pytest.approx(3 * math.sqrt(sum((v - mean) ** 2 for v in d) / (len(d) - 1)),
                                                       abs=1e-9)
    assert "P5" in out and "AP_P" in out and "RP_l" in out


def test_multi_directional_variation_is_the_largest_distance_between_approach_barycentres(tmp_path, capsys):
    rng = np.random.default_rng(3)
    rows = _repeat_data(rng, counts=(30,) * 5)
    approach = [1 + (r[1] % 3) for r in rows]  # three approach directions, 10 cycles each
    shift = {1: np.zeros(3), 2: np.array([0.05, 0.0, 0.0]), 3: np.array([0.0, -0.02, 0.03])}
    rows = [(pid, c, p + shift[h], rot, m) for (pid, c, p, rot, m), h in zip(rows, approach)]
    _write(tmp_path / "meas.csv", rows, orientation=False, approach=approach)
    code, out, err = run(["iso9283", "evaluate", str(tmp_path / "meas.csv"), "--frame", "base", "--json",
                          str(tmp_path / "iso.json")], capsys)
    assert code == 0, err
    payload = json.loads((tmp_path / "iso.json").read_text())
    assert len(payload["poses"]) == 15  # per pose and approach
    vap = {d["pose_id"]: d["vap_mm"] for d in payload["directional"]}
    for pid in range(1, 6):
        bars = {h: np.mean([r[2] for r, a in zip(rows, approach) if r[0] == pid and a == h], axis=0)
                for h in (1, 2, 3)}
        expected = max(math.dist(bars[h], bars[k]) for h, k in combinations((1, 2, 3), 2))
        assert vap[pid] == pytest.approx(expected, abs=1e-9)


def _rigid(rng):
    axis = rng.normal(size=3)
    return _small_rotation(axis / np.linalg.norm(axis) * 0.7), np.array([1500.0, -800.0, 300.0])


def test_fitted_frame_keeps_repeatability_and_a_calibration_frame_keeps_accuracy(tmp_path, capsys):
    """RP does not depend on the frame (a rigid motion keeps distances); a frame fitted on other
    poses of the same session (with a reflector offset from the TCP) gives back the base-frame AP."""
    rng = np.random.default_rng(11)
    rotation, translation = _rigid(rng)
    offset_mm = np.array([12.0, -7.0, 40.0])  # the reflector in the TCP frame
    rows = _repeat_data(rng, orientation=False)
    _write(tmp_path / "base.csv", [(pid, c, p + m[:3, :3] @ offset_mm, rot, m) for pid, c, p, rot, m in rows],
           orientation=False)
    _write(tmp_path / "tracker.csv", [(pid, c, rotation @ (p + m[:3, :3] @ offset_mm) + translation, rot, m)
                                      for pid, c, p, rot, m in rows], orientation=False)
    cal = ["j1_deg,j2_deg,j3_deg,j4_mm,j5_deg,j6_deg,x_mm,y_mm,z_mm"]
    for display in rng.uniform([-170, -50, -40, 0, -80, -170], [170, 60, 40, 500, 80, 170], (40, 6)):
        m = tool_changer_tcp_by_hand(_q_si(display))
        p = rotation @ (m[:3, 3] * 1e3 + m[:3, :3] @ offset_mm) + translation
        cal.append(",".join(repr(float(v)) for v in [*display, *p]))
    (tmp_path / "cal.csv").write_text("\n".join(cal) + "\n")
    results = {}
    for name, extra in [("fit", []), ("given", ["--frame-from", str(tmp_path / "cal.csv")])]:
        code, out, err = run(["iso9283", "evaluate", str(tmp_path / "tracker.csv"), "--json",
                              str(tmp_path / f"{name}.json"), *extra], capsys)
        assert code == 0, err
        results[name] = {p["pose_id"]: p for p in json.loads((tmp_path / f"{name}.json").read_text())["poses"]}
    for pid in range(1, 6):
        mine = [r for r in rows if r[0] == pid]
        bar = np.mean([r[2] for r in mine], axis=0)
        expected_ap = np.linalg.norm(bar - mine[0][4][:3, 3] * 1e3)  # the bias drawn, with its noise mean
        l = [np.linalg.norm(r[2] - bar) for r in mine]
        expected_rp = np.mean(l) + 3 * np.std(l, ddof=1)
        assert results["fit"][pid]["rp_mm"] == pytest.approx(expected_rp, abs=1e-9)
        assert results["given"][pid]["rp_mm"] == pytest.approx(expected_rp, abs=1e-9)
        assert results["given"][pid]["ap_mm"] == pytest.approx(expected_ap, abs=1e-6)
    # fitted on the test's own five barycentres, the frame takes up part of the bias: AP shrinks
    assert max(results["fit"][p]["ap_mm"] for p in results["fit"]) < max(results["given"][p]["ap_mm"]
                                                                         for p in results["given"])


# ---------------------------------------------------------------------------------------
# plan
# ---------------------------------------------------------------------------------------
def _independent_collisions(robot, q):
    """Pairs of collision bodies in contact at chain joints q, from the URDF read again here:
    bodies on non-adjacent links, pairs touching at the working pose left out."""
    full = robot.full_model
    geom = pin.buildGeomFromUrdfString(full, robot.urdf_text, pin.GeometryType.COLLISION,
                                       package_dirs=robot.package_dirs)
    data = full.createData()

    def contacts(config):
        qf = pin.neutral(full)
        for name, v in zip(robot.joint_names, config):
            qf[full.joints[full.getJointId(name)].idx_q] = v
        gdata = geom.createData()
        pin.updateGeometryPlacements(full, data, geom, gdata, qf)
        found = set()
        for i, j in combinations(range(geom.ngeoms), 2):
            a, b = geom.geometryObjects[i], geom.geometryObjects[j]
            if a.parentJoint == b.parentJoint or full.parents[a.parentJoint] == b.parentJoint \
                    or full.parents[b.parentJoint] == a.parentJoint:
                continue
            req, res = pin.coal.CollisionRequest(), pin.coal.CollisionResult()
            if pin.coal.collide(a.geometry, gdata.oMg[i], b.geometry, gdata.oMg[j], req, res):
                found.add((a.name, b.name))
        return found

    design = contacts(robot.working_pose)
    return [contacts(row) - design for row in np.atleast_2d(q)]


@pytest.mark.parametrize("name", ["tool_changer", "ur10", "panda"])
def test_plan_poses_are_on_the_iso_plane_reachable_within_limits_and_collision_free(name):
    from tcr_accuracy.iso9283.plan import plan_iso_cube

    robot = load_robot(name)
    plan = plan_iso_cube(robot, np.random.default_rng(0))
    c, s = plan.centre, plan.size
    assert s > 0.2  # a useful cube: 200 mm at least for these arms
    corners = [c + s / 2 * np.array(sign) for sign in ([-1, -1, -1], [1, -1, -1], [1, 1, 1], [-1, 1, 1])]
    diagonal = s * math.sqrt(3)
    np.testing.assert_allclose(plan.positions[0], c, atol=1e-12)
    for k in range(4):
        p = plan.positions[k + 1]
        assert np.linalg.norm(p - corners[k]) == pytest.approx(0.1 * diagonal, abs=1e-12)
        assert np.linalg.norm(np.cross(p - corners[k], c - corners[k])) < 1e-12  # on the corner's diagonal
    # the joints reach the targets (Pinocchio's own forward kinematics on the URDF model)
    data = robot.model.createData()
    for q, target in zip(plan.q, plan.positions):
        pin.framesForwardKinematics(robot.model, data, robot.to_pinocchio_q(q))
        assert np.linalg.norm(data.oMf[robot.tool_frame_id].translation - target) < 1e-6
    lo, hi = robot.lower_limits, robot.upper_limits
    assert np.all(plan.q >= np.where(np.isnan(lo), -np.inf, lo) - 1e-12)
    assert np.all(plan.q <= np.where(np.isnan(hi), np.inf, hi) + 1e-12)
    cube = c + s / 2 * np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])
    for q, target in zip(plan.corner_q, cube):
        pin.framesForwardKinematics(robot.model, data, robot.to_pinocchio_q(q))
        assert np.linalg.norm(data.oMf[robot.tool_frame_id].translation - target) < 1e-6
    if name == "tool_changer":
        assert "no collision geometry" in plan.collision
    else:
        assert plan.collision.startswith("checked")
        assert plan.orientation == "exact"
        np.testing.assert_allclose(plan.rotation, np.broadcast_to(plan.rotation[0], (5, 3, 3)), atol=1e-6)
        assert not any(_independent_collisions(robot, np.vstack([plan.q, plan.corner_q])))
        # the query is not blind: it finds contacts somewhere in the joint space
        lo_b, hi_b = robot.joint_bounds(np.pi)
        assert any(_independent_collisions(robot, np.random.default_rng(1).uniform(lo_b, hi_b, (60, robot.n_joints))))


def test_a_given_cube_is_planned_and_one_out_of_reach_is_refused(tmp_path, capsys):
    code, out, err = run(["iso9283", "plan", "--robot", "ur5", "--cube-centre-mm", "400", "100", "300",
                          "--cube-size-mm", "200", "--cycles", "3", "--out", str(tmp_path / "plan.csv"),
                          "--json", str(tmp_path / "plan.json")], capsys)
    assert code == 0, err
    payload = json.loads((tmp_path / "plan.json").read_text())
    assert payload["cube_centre_mm"] == pytest.approx([400, 100, 300]) and payload["cube_size_mm"] == 200
    assert payload["poses"][1]["target_mm"] == pytest.approx([300 + 20, 0 + 20, 200 + 20])  # 20 % towards P1
    code, out, err = run(["iso9283", "plan", "--robot", "ur5", "--cube-centre-mm", "400", "100", "300",
                          "--cube-size-mm", "2000", "--out", str(tmp_path / "far.csv")], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "not reachable" in err


def test_plan_simulate_evaluate_round_trip(tmp_path, capsys):
    """The plan's CSV runs through simulate (labels carried) and evaluate; a perfect robot seen
    from a tracker frame with a reflector offset, without noise, has AP = RP = 0 once the frame is fitted."""
    plan, meas = tmp_path / "plan.csv", tmp_path / "meas.csv"
    code, out, err = run(["iso9283", "plan", "--cycles", "4", "--conditions", "100/100", "--out", str(plan)], capsys)
    assert code == 0, err
    header = [line for line in plan.read_text().splitlines() if not line.startswith("#")]
    assert header[0].endswith("payload_kg,pose_id,cycle,load_pct,speed_pct,target_x_mm,target_y_mm,target_z_mm")
    assert [r.split(",")[7] for r in header[1:6]] == ["P5", "P4", "P3", "P2", "P1"] and len(header) == 21
    assert {r.split(",")[6] for r in header[1:]} == {"150"}  # the disc cutter, the rated load
    scenario = tmp_path / "frames.yaml"
    scenario.write_text("effects:\n  frames:\n    base_mm: {dx: 1250.0, dy: -830.0, dz: -410.0}\n"
                        "    base_deg: {rz: 35.0, rx: 2.0}\n    tool_mm: {dx: 0.8, dy: -0.5, dz: 1.2}\n")
    for noise, ap_max, rp_range in [("0", 1e-5, (0, 1e-5)), ("0.02", 0.1, (0.02, 0.2))]:
        code, out, err = run(["simulate", "--poses", str(plan), "--scenario", str(scenario), "--noise-mm", noise,
                              "--out", str(meas), "--quiet"], capsys)
        assert code == 0, err
        assert "pose_id" in meas.read_text().splitlines()[0]
        code, out, err = run(["iso9283", "evaluate", str(meas), "--json", "-"], capsys)
        assert code == 0, err
        poses = json.loads(out)["poses"]
        assert [p["pose_id"] for p in poses] == ["P1", "P2", "P3", "P4", "P5"] and all(p["n"] == 4 for p in poses)
        assert max(p["ap_mm"] for p in poses) < ap_max
        assert all(rp_range[0] <= p["rp_mm"] < rp_range[1] for p in poses)


def test_other_commands_read_a_pose_test_file_and_ignore_its_labels(tmp_path):
    rows = _repeat_data(np.random.default_rng(5), counts=(4,) * 5, orientation=False)
    _write(tmp_path / "with.csv", rows, orientation=False)
    text = (tmp_path / "with.csv").read_text().splitlines()
    (tmp_path / "without.csv").write_text("\n".join(",".join(line.split(",")[:9]) for line in text) + "\n")
    robot = load_robot()
    with pytest.warns(UserWarning, match="repeated pose"):
        plain = read_measurements(tmp_path / "without.csv", robot)
    labelled = read_measurements(tmp_path / "with.csv", robot)  # a pose test repeats on purpose: no warning
    np.testing.assert_array_equal(labelled.q, plain.q)
    np.testing.assert_array_equal(labelled.position, plain.position)
    assert plain.annotations is None
    assert labelled.subset([0, 5]).annotations["pose_id"].tolist() == [str(rows[0][0]), str(rows[5][0])]


@pytest.mark.parametrize("edit, words", [
    (lambda lines: [",".join(line.split(",")[:-2]) for line in lines[:1]]
     + [",".join(line.split(",")[:-2]).replace("0.0,", f"{i}.5,", 1) for i, line in enumerate(lines[1:])],
     "no pose_id column, and no two readings at the same joint values"),
    (lambda lines: lines[:2] + [lines[2].replace(lines[2].split(",")[1], "%r" % (float(lines[2].split(",")[1]) + 0.1), 1)]
     + lines[3:], "commanded with other joint values"),
    (lambda lines: lines[:3] + [lines[3].replace(lines[3].split(",")[6], "nan", 1)] + lines[4:],
     "row 4, column x_mm: non-finite"),
])
def test_bad_pose_test_files_are_one_line_and_exit_code_2(edit, words, tmp_path, capsys):
    rows = _repeat_data(np.random.default_rng(5), counts=(4,) * 5, orientation=False)
    _write(tmp_path / "meas.csv", rows, orientation=False)
    lines = (tmp_path / "meas.csv").read_text().splitlines()
    (tmp_path / "bad.csv").write_text("\n".join(edit(lines)) + "\n")
    code, out, err = run(["iso9283", "evaluate", str(tmp_path / "bad.csv")], capsys)
    assert code == 2
    assert len(err.strip().splitlines()) == 1 and str(tmp_path / "bad.csv") in err and words in err


def test_model_compensation_shrinks_the_accuracy_figures(tmp_path, capsys):
    """A diagnosis-style JSON with the hidden joint offsets removes them: AP after ~ AP of a robot without them."""
    rows = _repeat_data(np.random.default_rng(2), counts=(5,) * 5, orientation=False)
    offsets = np.radians([0.0, 0.05, -0.04, 0.0, 0.06, 0.0])
    shifted = []
    for pid, c, p, rot, m in rows:
        q = _q_si(POSES_DISPLAY[pid - 1])
        moved = tool_changer_tcp_by_hand(q + offsets)[:3, 3] * 1e3 - m[:3, 3] * 1e3
        shifted.append((pid, c, p + moved, rot, m))
    _write(tmp_path / "meas.csv", shifted, orientation=False)
    names = ["j1", "j2", "j3", "j4", "j5", "j6"]
    model = {"robot": "tool_changer", "parameters": {"joint_offsets": {
        f"joint_offsets.{n}": float(v) for n, v in zip(names, offsets)}}}
    (tmp_path / "model.json").write_text(json.dumps(model))
    code, out, err = run(["iso9283", "evaluate", str(tmp_path / "meas.csv"), "--frame", "base", "--model",
                          str(tmp_path / "model.json"), "--json", str(tmp_path / "iso.json")], capsys)
    assert code == 0, err
    payload = json.loads((tmp_path / "iso.json").read_text())
    for before, after, pid in zip(payload["poses"], payload["compensated"]["poses"], range(1, 6)):
        bar = np.mean([r[2] for r in rows if r[0] == pid], axis=0)
        without = np.linalg.norm(bar - rows[[r[0] for r in rows].index(pid)][4][:3, 3] * 1e3)
        assert after["ap_mm"] == pytest.approx(without, abs=1e-6)
        assert after["rp_mm"] == pytest.approx(before["rp_mm"], abs=1e-9)
    assert "after compensation" in out


def _evaluate_json(path, capsys, *extra):
    code, out, err = run(["iso9283", "evaluate", str(path), "--frame", "base", "--json", "-", *extra], capsys)
    assert code == 0, err
    return json.loads(out)


def test_without_pose_id_the_readings_are_grouped_by_their_joint_values(tmp_path, capsys):
    """Real pose tests often come as a tracker export joined to a joint log, without labels: the
    readings at the same joints are one pose, and every figure is the labelled file's."""
    rows = _repeat_data(np.random.default_rng(11), counts=(6, 5, 4, 6, 5), orientation=False)
    order = np.random.default_rng(1).permutation(len(rows))  # visits interleaved, not pose by pose
    rows = [rows[i] for i in order]
    _write(tmp_path / "labelled.csv", rows, orientation=False)
    lines = (tmp_path / "labelled.csv").read_text().splitlines()
    (tmp_path / "bare.csv").write_text("\n".join(",".join(line.split(",")[:-2]) for line in lines) + "\n")
    labelled, bare = _evaluate_json(tmp_path / "labelled.csv", capsys), _evaluate_json(tmp_path / "bare.csv", capsys)
    # the grouped ids are in order of first visit: map them through the first reading of each pose
    first_visit = list(dict.fromkeys(pid for pid, *_ in rows))
    by_label = {p["pose_id"]: p for p in labelled["poses"]}
    assert len(bare["poses"]) == 5
    for p in bare["poses"]:
        twin = by_label[first_visit[p["pose_id"] - 1]]
        assert p["n"] == twin["n"]
        for key in ("ap_mm", "ap_x_mm", "ap_y_mm", "ap_z_mm", "rp_mm"):
            assert p[key] == pytest.approx(twin[key], abs=1e-9)
    code, out, err = run(["iso9283", "evaluate", str(tmp_path / "bare.csv"), "--frame", "base"], capsys)
    assert "no pose_id column: the readings grouped by their joint values" in out and "into 5 poses" in out


def test_encoder_scatter_of_the_joint_values_is_one_pose_and_said(tmp_path, capsys):
    """Joint values logged from the encoders scatter by a few counts about the commanded ones:
    still one pose (commanded joints = their mean), the figures move by what that mean moves
    the TCP (micrometres), and a note says so; a pose whose joints differ by 0.1 deg is refused."""
    rows = _repeat_data(np.random.default_rng(12), counts=(5,) * 5, orientation=False)
    _write(tmp_path / "clean.csv", rows, orientation=False)
    rng = np.random.default_rng(3)
    lines = (tmp_path / "clean.csv").read_text().splitlines()
    noisy = [lines[0]]
    for line in lines[1:]:
        cells = line.split(",")
        for j in (0, 1, 2, 4, 5):  # the revolute joints, in deg: +-0.001 deg (17 urad)
            cells[j] = repr(float(cells[j]) + rng.uniform(-1e-3, 1e-3))
        noisy.append(",".join(cells))
    (tmp_path / "noisy.csv").write_text("\n".join(noisy) + "\n")
    clean, scattered = _evaluate_json(tmp_path / "clean.csv", capsys), _evaluate_json(tmp_path / "noisy.csv", capsys)
    for a, b in zip(clean["poses"], scattered["poses"]):
        assert a["pose_id"] == b["pose_id"] and a["n"] == b["n"]
        assert abs(a["ap_mm"] - b["ap_mm"]) < 0.05  # 17 urad at under 2.5 m of reach
        assert a["rp_mm"] == pytest.approx(b["rp_mm"], abs=1e-12)  # RP does not depend on the commanded pose
    code, out, err = run(["iso9283", "evaluate", str(tmp_path / "noisy.csv"), "--frame", "base"], capsys)
    assert "scatter by up to" in out and "taken as their mean" in out
