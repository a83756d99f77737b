"""Measurement CSV files under attack (issues 12 and 22): cells that are no plain number,
values out of range, position columns in the wrong unit or of a frame the robot lacks,
repeated or impossible poses, and data too thin for the fit asked of it. Each refusal names
the file, row and column.

The rules every test here holds the command to, and the helpers, are in ``hostile.py``.
"""

import json

import pytest
from hypothesis import given, settings, strategies as st

from hostile import assert_one_line, mimic_urdf, run
from tcr_accuracy.cli import main


# ---------------------------------------------------------------------------------------
# Cells and row numbers (12: 18, 19)
# ---------------------------------------------------------------------------------------
def _with_comments(measurements, tmp_path, edit):
    """The fixture's CSV behind three comment lines, its data rows changed by ``edit(rows)``;
    returns (path, line of data row k = k + 4)."""
    header, *rows = measurements.read_text().splitlines()
    rows = [r.split(",") for r in rows]
    edit(header.split(","), rows)
    path = tmp_path / "c.csv"
    path.write_text("# tracker: a comment\n#\n# another one\n" + header + "\n"
                    + "\n".join(",".join(r) for r in rows) + "\n")
    return path


@pytest.mark.parametrize("cell", ["1_5", "\uff11\uff15", "0x1f", "1e999"])
def test_12_19_strict_numbers_in_a_measurement_csv(cell, measurements, tmp_path, capsys):
    def edit(header, rows):
        rows[2][header.index("x_mm")] = cell

    path = _with_comments(measurements, tmp_path, edit)
    code, out, err = run(["diagnose", path, "--effects", "joint_offsets"], capsys)
    assert code == 2
    assert_one_line(err, f"{path}: row 7, column x_mm")


def test_12_19_strict_numbers_in_a_trajectory_csv(tmp_path, capsys):
    path = tmp_path / "t.csv"
    path.write_text("t_s,j1_deg,j2_deg,j3_deg,j4_mm,j5_deg,j6_deg\n0,0,0,0,0,0,0\n1,1_5,0,0,0,0,0\n")
    code, out, err = run(["trajectory", "--file", path, "--samples", "10"], capsys)
    assert code == 2
    assert_one_line(err, f"{path}: row 3, column 'j1_deg'")


def test_12_18_duplicate_training_poses_are_named_by_file_line(measurements, tmp_path, capsys):
    def edit(header, rows):  # data row 12 takes data row 5's joint values, with another position
        joints = [i for i, h in enumerate(header) if h.startswith("j") and h.endswith(("_deg", "_mm"))]
        for i in joints:
            rows[11][i] = rows[4][i]
        rows[11][header.index("x_mm")] = str(float(rows[4][header.index("x_mm")]) + 0.5)

    path = _with_comments(measurements, tmp_path, edit)
    code, out, err = run(["predict", "--train", path, "--query", path, "--method", "kriging"], capsys)
    assert code == 2
    last = err.splitlines()[-1]
    assert "rows 9 and 16 have the same joint values" in last, err


# ---------------------------------------------------------------------------------------
# Values held to ranges, as settings files' are (22: 12)
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("column, value, fragment", [
    ("payload_kg", "1e300", "1e+300 kg is beyond the 1e+06 kg"),
    ("temperature_c", "1e300", "1e+300 degC is beyond the 1000 degC"),
    ("j1_deg", "1e300", "1e+300 deg is beyond"),
    ("j4_mm", "1e12", "1e+12 mm is beyond the 1e+07 mm"),
    ("x_mm", "-1e300", "-1e+300 mm is beyond the 1e+06 mm"),
])
def test_22_12_a_huge_csv_value_is_refused_with_its_row_and_column(column, value, fragment, m60, tmp_path, capsys):
    lines = m60.read_text().splitlines()
    header = lines[0].split(",")
    cells = lines[5].split(",")
    cells[header.index(column)] = value
    lines[5] = ",".join(cells)
    path = tmp_path / "huge.csv"
    path.write_text("\n".join(lines) + "\n")
    code, out, err = run(["diagnose", path, "--json", tmp_path / "d.json"], capsys)
    assert code == 2 and out == ""
    assert_one_line(err, f"{path}: row 6, column {column}: {fragment}")
    assert [p.name for p in tmp_path.iterdir()] == ["huge.csv"]


@settings(max_examples=60, deadline=None, derandomize=True)
@given(st.sampled_from(["payload_kg", "temperature_c", "j2_deg", "j4_mm", "y_mm"]),
       st.floats(allow_nan=False, allow_infinity=False, width=64))
def test_fuzz_22_12_a_csv_value_is_in_range_or_one_refusal(column, value):
    import math
    import warnings

    from tcr_accuracy.exceptions import InputError
    from tcr_accuracy.io.measurements import parse_measurements
    from tcr_accuracy.model.robot import load_robot

    header = ["j1_deg", "j2_deg", "j3_deg", "j4_mm", "j5_deg", "j6_deg", "x_mm", "y_mm", "z_mm", "payload_kg",
              "temperature_c"]
    rows = [[10, 20, -10, 100, 5, 0, 100, 1500, 1200, 10, 20], [12, 22, -8, 120, 7, 2, 110, 1510, 1190, 10, 20]]
    rows[1][header.index(column)] = repr(value)
    text = ",".join(header) + "\n" + "\n".join(",".join(map(str, r)) for r in rows) + "\n"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # joint limits: warned, not at issue here
        try:
            mset = parse_measurements(text, load_robot(), source="f.csv")
        except InputError as exc:
            assert str(exc).startswith("f.csv: row 3") and "\n" not in str(exc), exc
            return
    assert all(math.isfinite(v) for v in [*mset.q.ravel(), *mset.position.ravel(), *mset.payload_kg,
                                          *mset.temperature_c])
    assert abs(value) <= 1e6


# ---------------------------------------------------------------------------------------
# Position columns: units and measured frames (22: 8, 22, 23)
# ---------------------------------------------------------------------------------------
def test_22_08_positions_x10_without_the_mimic_joints_column_is_the_unit_message(tmp_path, capsys):
    import csv

    urdf = tmp_path / "mim2.urdf"
    urdf.write_text(mimic_urdf())
    full = tmp_path / "mm.csv"
    assert main(["simulate", "--robot", str(urdf), "--tool", "tool", "--random", "--n", "60", "--seed", "3",
                 "--out", str(full), "--quiet"]) == 0
    rows = list(csv.DictReader(full.read_text().splitlines()))
    path = tmp_path / "no_j3_x10.csv"
    with path.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["j1_deg", "j2_deg", "x_mm", "y_mm", "z_mm"])
        # j3 follows its rule, so that no joint leaves its limits
        writer.writerows([r["j1_deg"], r["j2_deg"], *(float(r[a]) * 10 for a in ("x_mm", "y_mm", "z_mm"))]
                         for r in rows)
    code, out, err = run(["diagnose", path, "--robot", urdf, "--tool", "tool"], capsys)
    assert code == 2
    assert_one_line(err, f"{path}: columns x_mm, y_mm, z_mm", "times); check the position units",
                    "j3 (its <mimic> rule)")


def _renamed_positions(m60, tmp_path, frame):
    lines = m60.read_text().splitlines()
    lines[0] = lines[0].replace("x_mm,y_mm,z_mm", f"{frame}.x_mm,{frame}.y_mm,{frame}.z_mm")
    path = tmp_path / f"{frame}.csv"
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.parametrize("command", [
    ["predict", "--train", "F", "--query", "Q", "--method", "kriging"],
    ["plan-poses", "F", "-k", "3", "--effects", "joint_offsets", "--out", "T/p.csv"],
])
def test_22_22_one_measured_frame_that_is_the_tcp_is_read(command, m60, tmp_path, capsys):
    path = _renamed_positions(m60, tmp_path, "tool")
    # the query: the training poses' joints without what was measured there (a measured training pose
    # is refused as a query: its error would be in-sample)
    header, *rows = [line.split(",") for line in m60.read_text().splitlines() if not line.startswith("#")]
    joints = [i for i, name in enumerate(header) if name not in ("x_mm", "y_mm", "z_mm")]
    query = tmp_path / "query.csv"
    query.write_text("\n".join(",".join(cells[i] for i in joints) for cells in [header, *rows]) + "\n")
    argv = [str(path) if a == "F" else str(query) if a == "Q" else a.replace("T/", f"{tmp_path}/") for a in command]
    code, out, err = run(argv, capsys)
    assert code == 0, err
    code, out, err = run(argv + ["--tool", "j5"], capsys)  # another TCP: the file's frame is named
    assert code == 2
    assert_one_line(err, f"{path}: columns tool.x_mm ...: measures frame tool, not the robot's TCP frame j5; "
                         "give --tool tool")


def test_22_23_a_frame_the_robot_lacks_is_named_by_its_column(m60, tmp_path, capsys):
    path = _renamed_positions(m60, tmp_path, "nosuch")
    code, out, err = run(["diagnose", path], capsys)
    assert code == 2
    assert_one_line(err, f"{path}: column nosuch.x_mm: no such frame in built-in tool_changer")
    assert "--tool" not in err


# ---------------------------------------------------------------------------------------
# Repeated poses, candidate poses (22: 5, 29)
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("command", [["predict", "--train", "M", "--query", "Q", "--method", "kriging"],
                                     ["compensate", "--train", "M", "--targets", "Q", "--method", "kriging"]])
def test_22_29_repeated_query_or_target_poses_are_answered(command, m60, tmp_path, capsys):
    from conftest import REPO

    poses = (REPO / "examples" / "poses.csv").read_text().splitlines()
    query = tmp_path / "q.csv"
    query.write_text("\n".join([*poses, poses[-1], poses[-1]]) + "\n")  # the last pose asked three times
    argv = [str(m60) if a == "M" else str(query) if a == "Q" else a for a in command]
    code, out, err = run([*argv, "--csv", tmp_path / "out.csv"], capsys)
    assert code == 0, err
    lines = (tmp_path / "out.csv").read_text().splitlines()
    header = lines[0].split(",")
    # the same answer each time (compensate's CSV also names each target's row in the file)
    keep = [i for i, name in enumerate(header) if name != "target_row"]
    rows = [[line.split(",")[i] for i in keep] for line in lines]
    assert rows[-1] == rows[-2] == rows[-3]
    # a training file keeps refusing a copied row
    train = tmp_path / "t.csv"
    lines = m60.read_text().splitlines()
    train.write_text("\n".join([*lines, lines[-1]]) + "\n")
    argv = [str(train) if a == "M" else str(query) if a == "Q" else a for a in command]
    code, out, err = run(argv, capsys)
    assert code == 2
    assert_one_line(err, f"{train}: row 62 repeats row 61 exactly")


def test_22_05_a_candidate_outside_the_joint_limits_is_refused_with_its_row(m60, tmp_path, capsys):
    header = "j1_deg,j2_deg,j3_deg,j4_mm,j5_deg,j6_deg\n"
    bad = tmp_path / "cand.csv"
    bad.write_text("# candidates\n" + header + "10,20,30,100,10,0\n10,20,-40,5000,10,0\n0,0,0,0,0,0\n")
    code, out, err = run(["plan-poses", m60, "-k", "3", "--candidates", bad, "--out", tmp_path / "p.csv",
                          "--effects", "joint_offsets"], capsys)
    assert code == 2 and out == ""
    assert_one_line(err, f"{bad}: row 4: joint j4 = 5000 mm is outside its limits [0, 600] mm")
    assert not (tmp_path / "p.csv").exists()
    good = tmp_path / "good.csv"
    good.write_text(header + "10,20,30,100,10,0\n11,21,31,100,10,0\n0,0,0,0,0,0\n5,5,5,5,5,5\n")
    code, out, err = run(["plan-poses", m60, "-k", "3", "--candidates", good, "--out", tmp_path / "p.csv",
                          "--effects", "joint_offsets"], capsys)
    assert code == 0, err
    assert len((tmp_path / "p.csv").read_text().splitlines()) >= 4


# ---------------------------------------------------------------------------------------
# Data that cannot carry the fit (12: 10; 22: 4)
# ---------------------------------------------------------------------------------------
def test_12_10_diagnose_with_every_parameter_unidentifiable(measurements, tmp_path, capsys):
    # at 1 m tracker noise nothing is identifiable: the diagnosis must say so, not crash
    target = tmp_path / "d.json"
    code, out, err = run(["diagnose", measurements, "--noise-mm", "1000", "--effects", "joint_offsets",
                          "--quiet", "--json", target], capsys)
    assert code == 0, err
    steps = json.loads(target.read_text())["steps"]
    assert steps[0]["n_parameters"] == 0
    # no parameter fitted: the held-out residual is the training residual
    assert steps[0]["heldout_rms_mm"] == pytest.approx(steps[0]["train_rms_mm"])


@pytest.mark.parametrize("command", [
    ["predict", "--method", "calibration+local-gp", "--train", "T7", "--query", "POSES"],
    ["compensate", "--method", "calibration", "--train", "T7", "--targets", "POSES"],
])
def test_22_04_a_calibration_on_as_many_equations_as_parameters_is_refused(command, tmp_path, capsys):
    from conftest import REPO

    t7 = tmp_path / "t7.csv"  # 3 comment lines, the header and 7 rows
    t7.write_text("".join((REPO / "examples" / "measured.csv").read_text().splitlines(keepends=True)[:11]))
    argv = [str(t7) if a == "T7" else str(REPO / "examples" / "poses.csv") if a == "POSES" else a for a in command]
    code, out, err = run(argv, capsys)
    assert code == 2 and out == ""
    assert_one_line(err, f"{t7}: GeometricCalibration: 7 poses give 21 equations for 21 identifiable parameters",
                    "too few to check the fit")


def test_22_04_with_enough_poses_the_calibration_still_fits():
    import numpy as np

    from tcr_accuracy.model.robot import load_robot
    from tcr_accuracy.prediction.calibration import GeometricCalibration

    robot = load_robot()
    rng = np.random.default_rng(0)
    X = robot.working_pose + rng.uniform(-0.5, 0.5, size=(16, robot.n_joints))
    model = GeometricCalibration(robot=robot).fit(X, rng.normal(0.0, 1e-3, size=(16, 3)))
    assert 3 * 16 >= 2 * model.identifiable_.size > 0
