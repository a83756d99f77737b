"""ISO 9283 figures a person can act on: AP in the robot's base frame by default where a frame source
is given, said "relative" on every line where the frame could only be fitted on the test's own poses;
a series where most poses are read once, evaluated; the test planned, simulated and evaluated from a
script with public names only.

The robots' errors are written out here on Pinocchio (joint placements perturbed by error screws),
not with the project's effect classes; the expected figures are the standard's formulas on raw
numpy (AP = |barycentre of the attained positions - command position|, RP = l̄ + 3 S_l)."""

import dataclasses
import json
import re

import numpy as np
import pinocchio as pin
import pytest

import tcr_accuracy as tcr
from tcr_accuracy.exceptions import InputError

from conftest import run_command as run

#: The UR5's given test cube [mm] (a cube the robot serves, as `iso9283 plan` finds near it).
UR5_CUBE = ("-130", "-440", "320", "380")


def _perturbed(robot, rng, zero_deg=0.1, link_mm=0.5, tilt_deg=0.05):
    """A copy of the robot's Pinocchio model whose joints are off as a real arm's are: the zeros of
    shoulder_lift .. wrist_2 (rotation about each joint's axis, z in the UR URDF), and the elbow's and
    wrist_1's placements (the upper arm's and the forearm's lengths, offsets and tilts). Left out:
    the first placement (a base-frame error) and the last (a TCP offset), which no measurement of the
    TCP tells apart from the instrument's frame and the reflector's offset."""
    model = robot.model.copy()
    for j in (2, 3, 4, 5):
        xi = np.zeros(6)
        if j in (3, 4):
            xi[:3] = rng.normal(0.0, link_mm * 1e-3, 3)
            xi[3:5] = rng.normal(0.0, np.radians(tilt_deg), 2)
        xi[5] = rng.normal(0.0, np.radians(zero_deg))
        model.jointPlacements[j] = model.jointPlacements[j] * pin.exp6(pin.Motion(xi[:3], xi[3:]))
    return model


def _fk(robot, model, q):
    """(N, 3) TCP positions [m] of a Pinocchio model at chain joints q (N, n_joints) (the UR's chain is the model's)."""
    data, frame = model.createData(), model.getFrameId(robot.tool_frame)
    out = []
    for row in np.atleast_2d(q):
        pin.framesForwardKinematics(model, data, row)
        out.append(data.oMf[frame].translation.copy())
    return np.array(out)


def _plan_rows(path):
    lines = [line for line in path.read_text().splitlines() if not line.startswith("#")]
    head = lines[0].split(",")
    return head, [line.split(",") for line in lines[1:]]


def _write(path, head, cells, positions):
    lines = [",".join(head + ["x_mm", "y_mm", "z_mm"])]
    lines += [",".join(list(c) + [repr(float(v)) for v in p * 1e3]) for c, p in zip(cells, positions)]
    path.write_text("\n".join(lines) + "\n")


def _ap_by_hand(pose_of, positions, command):
    """pose -> AP_P [mm]: |mean of its positions - its command|, written out."""
    out = {}
    for pose in sorted(set(pose_of)):
        rows = [i for i, p in enumerate(pose_of) if p == pose]
        out[pose] = float(np.sqrt(np.sum((positions[rows].mean(axis=0) - command[pose]) ** 2)) * 1e3)
    return out


@pytest.fixture(scope="module")
def ur5_test(tmp_path_factory):
    """The UR5's planned test (10 cycles), measured on the perturbed arm: in its base frame, in a
    tracker's frame, and a calibration set of 200 poses of the same session in the tracker's frame."""
    folder = tmp_path_factory.mktemp("ur5")
    plan = folder / "plan.csv"
    code = _main(["iso9283", "plan", "--robot", "ur5", "--cube-centre-mm", *UR5_CUBE[:3], "--cube-size-mm",
                  UR5_CUBE[3], "--cycles", "10", "--conditions", "100/100", "--out", str(plan), "--quiet"])
    assert code == 0
    robot = tcr.load_robot("ur5")
    rng = np.random.default_rng(12)
    model = _perturbed(robot, rng)
    head, cells = _plan_rows(plan)
    q = np.radians([[float(v) for v in c[:6]] for c in cells])
    base = _fk(robot, model, q) + rng.normal(0.0, 10e-6, (len(q), 3))
    rotation, translation = pin.exp3(np.array([0.3, -1.2, 2.0])), np.array([2.1, -0.7, 0.4])
    _write(folder / "base.csv", head, cells, base)
    _write(folder / "tracker.csv", head, cells, base @ rotation.T + translation)
    q_cal = rng.uniform(-np.pi, np.pi, (200, 6))
    cal = _fk(robot, model, q_cal) @ rotation.T + translation + rng.normal(0.0, 10e-6, (200, 3))
    _write(folder / "cal.csv", [f"{n}_deg" for n in robot.joint_names],
           [[repr(float(v)) for v in np.degrees(row)] for row in q_cal], cal)
    pose_of = [c[head.index("pose_id")] for c in cells]
    nominal = _fk(robot, robot.model, q)
    command = {p: nominal[pose_of.index(p)] for p in set(pose_of)}
    return folder, _ap_by_hand(pose_of, base, command)


def _main(argv):
    from tcr_accuracy.cli import main

    try:
        return main(argv)
    except SystemExit as exc:
        return exc.code


def _evaluate(capsys, folder, *argv):
    code, out, err = run(["iso9283", "evaluate", *argv, "--robot", "ur5", "--json", str(folder / "out.json")], capsys)
    assert code == 0, err
    return out, json.loads((folder / "out.json").read_text())


def test_default_ap_with_a_calibration_set_is_the_base_frames(ur5_test, capsys):
    """The standard's AP (base frame known) by hand; with a calibration set of the session the default
    gives it within 10 %; fitted on the five test poses it would take up most of it."""
    folder, truth = ur5_test
    out, base = _evaluate(capsys, folder, str(folder / "base.csv"), "--frame", "base")
    assert {p["pose_id"]: p["ap_mm"] for p in base["poses"]} == pytest.approx(truth, abs=1e-9)
    assert base["frame_source"] == "base" and base["ap_absolute"] is True and base["frame_n_points"] is None
    largest = max(truth.values())
    assert largest > 1.0  # a robot whose absolute error shows

    out, given = _evaluate(capsys, folder, str(folder / "tracker.csv"), "--frame-from", str(folder / "cal.csv"))
    assert given["frame_source"] == "calibration set (200 poses)" and given["ap_absolute"] is True
    assert given["frame_n_points"] == 200 and 0 < given["frame_residual_rms_mm"] < 2.0
    assert max(p["ap_mm"] for p in given["poses"]) == pytest.approx(largest, rel=0.10)
    assert "relative" not in out
    # each pose's distance from the instrument (the origin of the frame its readings are in), for its error
    head, cells = _plan_rows(folder / "tracker.csv")
    pose_of = [c[head.index("pose_id")] for c in cells]
    xyz = np.array([[float(c[head.index(f"{a}_mm")]) for a in "xyz"] for c in cells])
    for p in given["poses"]:
        bar = xyz[[i for i, name in enumerate(pose_of) if name == p["pose_id"]]].mean(axis=0)
        assert p["instrument_distance_mm"] == pytest.approx(np.sqrt(np.sum(bar ** 2)), rel=1e-12)
    assert all("instrument_distance_mm" not in p for p in base["poses"])

    out, fitted = _evaluate(capsys, folder, str(folder / "tracker.csv"))
    assert fitted["frame_source"] == "fitted on the test poses (relative)" and fitted["ap_absolute"] is False
    assert fitted["frame_n_points"] == 5 and fitted["frame_residual_rms_mm"] > 0
    assert max(p["ap_mm"] for p in fitted["poses"]) < 0.7 * largest  # what the issue saw: most of AP taken up


def test_without_a_frame_source_every_ap_line_says_relative(ur5_test, capsys):
    folder, truth = ur5_test
    out, fitted = _evaluate(capsys, folder, str(folder / "tracker.csv"))
    ap_lines = [line for line in out.splitlines() if re.match(r"\s+P\d\s", line) or "AP_P" in line]
    assert len(ap_lines) >= 7  # the head, five poses, the largest
    for line in ap_lines:
        assert "relative" in line.lower(), line
    assert "AP RELATIVE TO A FRAME FITTED ON THE TEST POSES" in out
    # readings in the base frame need no flag: found, and AP is the standard's
    out, found = _evaluate(capsys, folder, str(folder / "base.csv"))
    assert found["frame_source"] == "base" and found["ap_absolute"] is True and "relative" not in out
    assert "found: the readings lie in the robot's base frame" in found["frame_fit"]
    assert {p["pose_id"]: p["ap_mm"] for p in found["poses"]} == pytest.approx(truth, abs=1e-9)
    # an instrument's frame set up near the base (20 mm, 0.3 deg off, as simulate draws one) is not taken for it
    lines = (folder / "base.csv").read_text().splitlines()
    rotation, shift = pin.exp3(np.radians([0.2, -0.1, 0.2])), np.array([12.0, -9.0, 14.0])
    near = [lines[0]]
    for line in lines[1:]:
        cells = line.split(",")
        near.append(",".join(cells[:-3] + [repr(float(v)) for v in rotation @ np.array(cells[-3:], float) + shift]))
    (folder / "near.csv").write_text("\n".join(near) + "\n")
    out, fitted = _evaluate(capsys, folder, str(folder / "near.csv"))
    assert fitted["ap_absolute"] is False and "AP RELATIVE" in out


# ---------------------------------------------------------------------------------------
# A series of many cubes, most poses read once
# ---------------------------------------------------------------------------------------
#: How many poses are read how many times: the real UR10 series' shape (574 poses, 632 readings;
#: 543 read once, 31 read 2-5 times).
READ_COUNTS = {1: 543, 2: 13, 3: 11, 4: 5, 5: 2}


def _series(robot, rng):
    """(names, q (574, 6), count per pose, readings: list of (pose index, cycle, base-frame position)):
    70 cubes of 8-9 poses spread over the workspace, ids S01.E<cube>.<nnn>, each reading the perturbed
    arm's TCP with a per-visit scatter of 20 um and the instrument's 10 um."""
    model = _perturbed(robot, rng, zero_deg=0.05, link_mm=0.3)
    counts = np.concatenate([np.full(n, k) for k, n in READ_COUNTS.items()])
    rng.shuffle(counts)
    cube = np.sort(np.arange(len(counts)) % 70)
    ready = np.radians([0.0, -90.0, 0.0, -90.0, 0.0, 0.0])
    centres = ready + rng.uniform([-2.5, -0.8, -1.8, -1.0, -1.0, -1.0], [2.5, 0.8, 1.8, 1.0, 1.0, 1.0], (70, 6))
    q = centres[cube] + rng.uniform(-0.12, 0.12, (len(counts), 6))
    names = []
    for k in range(len(counts)):
        names.append(f"S01.E{100 + cube[k]}.{k % 1000:03d}")
    true = _fk(robot, model, q)
    readings = []
    for k, n in enumerate(counts):
        for c in range(n):
            readings.append((k, f"{c + 1}", true[k] + rng.normal(0.0, 20e-6, 3) + rng.normal(0.0, 10e-6, 3)))
    order = rng.permutation(len(readings))  # the file in the order measured, cubes interleaved as a campaign is
    return names, q, counts, [readings[i] for i in order]


def _write_series(path, robot, names, q, readings, positions):
    lines = [",".join(f"{n}_deg" for n in robot.joint_names) + ",pose_id,cycle,x_mm,y_mm,z_mm"]
    for (k, cycle, _), p in zip(readings, positions):
        lines.append(",".join([*(repr(float(v)) for v in np.degrees(q[k])), names[k], cycle,
                               *(repr(float(v)) for v in p * 1e3)]))
    path.write_text("\n".join(lines) + "\n")


def test_a_series_of_poses_read_once_and_several_times_is_evaluated(tmp_path, capsys):
    """AP for every pose with its n, RP where n >= 3, the standard's 30 cycles said against every line;
    for the poses read three times or more, RP within 0.005 mm and mean AP within 0.3 mm of the
    standard's formulas on raw numpy, in the base frame and through a calibration set's frame."""
    robot = tcr.load_robot("ur10")
    rng = np.random.default_rng(36)
    names, q, counts, readings = _series(robot, rng)
    assert len(readings) == 632 and len(names) == 574 and len(set(names)) == 574
    base = np.array([p for _, _, p in readings])
    rotation, translation = pin.exp3(np.array([-0.4, 0.9, 1.7])), np.array([-1.8, 2.6, 0.3])
    _write_series(tmp_path / "series_base.csv", robot, names, q, readings, base)
    _write_series(tmp_path / "series_tracker.csv", robot, names, q, readings, base @ rotation.T + translation)
    q_cal = rng.uniform(-np.pi, np.pi, (200, 6))
    model = _perturbed(robot, np.random.default_rng(36), zero_deg=0.05, link_mm=0.3)  # the same arm
    cal = _fk(robot, model, q_cal) @ rotation.T + translation + rng.normal(0.0, 10e-6, (200, 3))
    _write(tmp_path / "cal.csv", [f"{n}_deg" for n in robot.joint_names],
           [[repr(float(v)) for v in np.degrees(row)] for row in q_cal], cal)

    # the standard's formulas, written out, on the base-frame readings of the poses read 3 times or more
    nominal = _fk(robot, robot.model, q)
    expected = {}
    for k in np.flatnonzero(counts >= 3):
        p = base[[i for i, r in enumerate(readings) if r[0] == k]]
        bar = p.mean(axis=0)
        l = np.sqrt(np.sum((p - bar) ** 2, axis=1))
        rp = l.mean() + 3.0 * np.sqrt(np.sum((l - l.mean()) ** 2) / (len(l) - 1))
        expected[names[k]] = (len(p), float(np.sqrt(np.sum((bar - nominal[k]) ** 2))) * 1e3, rp * 1e3)
    assert len(expected) == 18

    for name, extra in (("series_base.csv", []), ("series_tracker.csv", ["--frame-from", str(tmp_path / "cal.csv")])):
        code, out, err = run(["iso9283", "evaluate", str(tmp_path / name), "--robot", "ur10", "--json",
                              str(tmp_path / "out.json"), *extra], capsys)
        assert code == 0, err
        got = json.loads((tmp_path / "out.json").read_text())
        assert got["ap_absolute"] is True and got["n_readings"] == 632 and got["standard_cycles"] == 30
        poses = {p["pose_id"]: p for p in got["poses"]}
        assert len(poses) == 574  # every pose, with its n
        assert {k: p["n"] for k, p in poses.items()} == {names[k]: int(n) for k, n in enumerate(counts)}
        assert all(p["rp_mm"] is None for p in poses.values() if p["n"] < 3)
        assert all(p["l_mean_mm"] is None for p in poses.values() if p["n"] == 1)
        for pose, (n, ap, rp) in expected.items():
            assert poses[pose]["rp_mm"] == pytest.approx(rp, abs=0.005)
        mean_ap = np.mean([v[1] for v in expected.values()])
        assert np.mean([poses[pose]["ap_mm"] for pose in expected]) == pytest.approx(mean_ap, abs=0.3)
        # every printed pose line with its n and, below 30, the standard's 30 cycles said against it
        rows = [line for line in out.splitlines() if re.match(r"\s+S01\.E\d+\.\d{3}\s+\d+\s", line)]
        assert len(rows) == 574
        for line in rows:
            n = int(line.split()[1])
            assert f"{n} of the standard's 30 cycles" in line, line
            assert ("AP only" in line) == (n == 1) and ("no RP" in line) == (n == 2)
        assert any("574 of 574 pose(s) read fewer times than the standard's 30 cycles" in n for n in got["notes"])
        assert any(n.startswith("543 pose(s) read once: AP only") for n in got["notes"])


# ---------------------------------------------------------------------------------------
# From a script
# ---------------------------------------------------------------------------------------
def test_plan_series_simulate_evaluate_with_public_names_only():
    """plan_iso_cube -> IsoPlan.series -> simulate_measurements -> evaluate_pose_test, names from
    ``tcr_accuracy`` only; the figures against the standard's formulas on the simulated readings."""
    robot = tcr.load_robot("ur5")
    plan = tcr.plan_iso_cube(robot, random_state=0, centre=[-0.13, -0.44, 0.32], size=0.3)
    assert plan.pose_ids == ["P1", "P2", "P3", "P4", "P5"]
    series = plan.series(cycles=6)
    labels = series.annotations
    assert len(series) == 30 and np.isnan(series.position).all()
    assert labels["pose_id"].tolist() == ["P5", "P4", "P3", "P2", "P1"] * 6  # the standard's order
    assert labels["cycle"].tolist() == [str(c) for c in range(1, 7) for _ in range(5)]
    assert set(labels["load_pct"]) == {100.0} and set(series.payload_kg) == {5.0}  # the UR5's rated load
    # the commanded joints reach the targets the series carries (Pinocchio, here)
    targets = np.stack([labels[f"target_{a}_mm"] for a in "xyz"], axis=1) * 1e-3
    np.testing.assert_allclose(_fk(robot, robot.model, series.q), targets, atol=1e-6)

    scenario = {"effects": {"joint_offsets": {"offsets_deg": {"shoulder_lift_joint": 0.05, "elbow_joint": -0.04}}},
                "noise_mm": 0.02}
    simulated, _ = tcr.simulate_measurements(robot, scenario, len(series), random_state=1, q=series.q,
                                             context=series.context)
    measured = dataclasses.replace(series, position=simulated.position)
    result = tcr.evaluate_pose_test(robot, measured)
    assert result.absolute and result.frame_source == "base"
    by_pose = {f.pose_id: f for f in result.figures.poses}
    assert sorted(by_pose) == plan.pose_ids and all(f.n == 6 for f in by_pose.values())
    for k, pose in enumerate(plan.pose_ids):
        rows = labels["pose_id"] == pose
        p = simulated.position[rows]
        bar = p.mean(axis=0)
        l = np.sqrt(np.sum((p - bar) ** 2, axis=1))
        assert by_pose[pose].ap == pytest.approx(np.sqrt(np.sum((bar - plan.positions[k]) ** 2)), abs=1e-7)
        assert by_pose[pose].rp == pytest.approx(l.mean() + 3 * l.std(ddof=1), abs=1e-12)

    # the standard's four conditions: one block each, evaluated per block
    four = plan.series(cycles=2, conditions=[(100, 100), (100, 50), (100, 10), (10, 100)])
    assert len(four) == 40 and four.payload_kg.tolist()[-1] == pytest.approx(0.5)
    with pytest.raises(InputError, match="4 test conditions"):
        tcr.evaluate_pose_test(robot, dataclasses.replace(four, position=_fk(robot, robot.model, four.q)))


def test_plan_iso_cube_takes_random_state_like_every_public_function():
    robot = tcr.load_robot("ur5")
    cube = dict(centre=[-0.13, -0.44, 0.32], size=0.2)
    a = tcr.plan_iso_cube(robot, 3, **cube)
    b = tcr.plan_iso_cube(robot, random_state=np.random.default_rng(3), **cube)
    np.testing.assert_array_equal(a.q, b.q)
    with pytest.warns(DeprecationWarning, match="rng=...\\) is deprecated"):
        c = tcr.plan_iso_cube(robot, rng=np.random.default_rng(3), **cube)
    np.testing.assert_array_equal(a.q, c.q)
