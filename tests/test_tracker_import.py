"""`tcr-accuracy import`: a semicolon/decimal-comma tracker export plus a timestamped joint log
become a measurement CSV that diagnose accepts, with every point that could not be joined named."""

import csv

import numpy as np
import pytest

from tcr_accuracy.cli import main
from tcr_accuracy.io.measurements import read_measurements
from tcr_accuracy.io.tracker_import import import_tracker
from tcr_accuracy.model.robot import load_robot

from conftest import REPO, pinocchio_kinematics

START = 10 * 3600 + 15 * 60  # 10:15:00 [s of the day]


def clock(seconds: float, decimal: str = ".") -> str:
    h, rest = divmod(seconds, 3600)
    m, s = divmod(rest, 60)
    return f"{int(h):02d}:{int(m):02d}:{s:06.3f}".replace(".", decimal)


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    """60 simulated measurements (the truth the import must reproduce), as plain CSV rows."""
    folder = tmp_path_factory.mktemp("import")
    path = folder / "truth.csv"
    assert main(["simulate", "--scenario", str(REPO / "examples" / "scenario_compliance.yaml"), "--n", "60",
                 "--seed", "3", "--out", str(path), "--quiet"]) == 0
    with path.open() as f:
        rows = list(csv.DictReader(f))
    return folder, path, rows


def write_exports(folder, rows, missing_log=(7, 31)):
    """A Leica-style export (metadata lines, semicolons, decimal commas, units in the header,
    times of day) and a controller's joint log (commas, samples between the points while the
    arm moves, clock times with a few ms of offset); the log has no sample near points 7, 31."""
    joints = [k for k in rows[0] if k.split("_")[-1] in ("deg", "mm") and k[0] == "j"]
    context = ["payload_kg", "temperature_c"] + [k for k in rows[0] if k.endswith("_dir")]
    tracker = ["Leica Absolute Tracker AT960 - measurement export", "Job: cutterhead survey; Units: mm",
               "", "Point ID;Time;X [mm];Y [mm];Z [mm];Quality"]
    log = [",".join(["timestamp", *joints, *context])]
    rng = np.random.default_rng(0)
    for i, row in enumerate(rows):
        t = START + 4.0 * i
        tracker.append(";".join([f"P{i + 1}", clock(t, ","), *(row[f"{a}_mm"].replace(".", ",") for a in "xyz"),
                                 "0,98"]))
        for dt in (-1.5, 1.5):  # the arm on its way to and from the pose: other joint values
            moving = [f"{float(row[j]) + 7.0 * dt:.6f}" for j in joints]
            log.append(",".join([clock(t + dt), *moving, *(row[c] for c in context)]))
        if i not in missing_log:
            log.append(",".join([clock(t + rng.uniform(-0.02, 0.02)), *(row[j] for j in joints),
                                 *(row[c] for c in context)]))
    (folder / "tracker.txt").write_text("\n".join(tracker) + "\n", encoding="utf-8")
    (folder / "joints.csv").write_text("\n".join(log) + "\n")
    return folder / "tracker.txt", folder / "joints.csv"


def test_import_joins_on_time_and_diagnose_accepts_the_result(simulated, capsys):
    folder, truth_path, rows = simulated
    tracker, log = write_exports(folder, rows)
    out = folder / "imported.csv"
    code = main(["import", str(tracker), "--joints", str(log), "--tolerance-ms", "50", "--out", str(out)])
    printed = capsys.readouterr().out
    assert code == 0
    # the two points without a log sample nearby are named, by their line in the export
    # (4 lines above the data: metadata, a blank line, the header)
    assert "58 of 60 tracker points" in printed and "2 not joined" in printed
    assert f"{tracker} row {4 + 7 + 1}: time {clock(START + 28.0, ',')}" in printed
    assert f"{tracker} row {4 + 31 + 1}: time {clock(START + 124.0, ',')}" in printed
    robot = load_robot()
    imported = read_measurements(out, robot)
    truth = read_measurements(truth_path, robot)
    keep = [i for i in range(60) if i not in (7, 31)]
    assert np.allclose(imported.q, truth.q[keep], rtol=0, atol=1e-9)            # the joints of the right sample
    assert np.allclose(imported.position, truth.position[keep], rtol=0, atol=1e-9)
    assert np.array_equal(imported.payload_kg, truth.payload_kg[keep])
    assert main(["diagnose", str(out), "--effects", "frames,joint_offsets", "--folds", "2", "--quiet"]) == 0


def test_units_decimal_commas_and_a_column_map(tmp_path):
    path = tmp_path / "faro.txt"
    path.write_text("FARO CAM2 export\nName\tMeas X\tMeas Y\tMeas Z\n"
                    "p1\t10,5 in\t1,0 in\t-2,25 in\n")
    result = import_tracker(path, {"x_mm": "Meas X", "y_mm": "Meas Y", "z_m": "Meas Z"})
    assert result.columns == ["x_mm", "y_mm", "z_m"]
    assert [float(v) for v in result.rows[0]] == pytest.approx([266.7, 25.4, -0.05715])  # inch = 25.4 mm


def test_positions_found_by_name_and_converted_from_the_header_unit(tmp_path):
    path = tmp_path / "points.csv"
    path.write_text("# exported\nid,X (m),Y (m),Z (m)\na,1.25,-0.5,2\n")
    result = import_tracker(path)
    assert result.columns == ["x_m", "y_m", "z_m"] and result.rows == [["1.25", "-0.5", "2"]]


def test_the_trackers_time_and_sessions_travel_into_the_measurements(tmp_path):
    # two stations, read across midnight: the times in seconds from the clock (written out here),
    # carried on past 24 h, and each row's session label as the export has it
    robot = load_robot("ur5")
    joints = ",".join(f"{n}_deg" for n in robot.joint_names)
    path = tmp_path / "stations.csv"
    lines = [f"Session,Time,X [mm],Y [mm],Z [mm],{joints}"]
    for session, clock_time, j1 in (("east", "23:59:58.500", 10), ("east", "23:59:59.750", 30),
                                    ("west", "00:00:01.250", 50)):
        q = np.radians([j1, -60, 80, -90, -90, 0])
        tcp = pinocchio_kinematics(robot, q)[1].translation * 1e3  # where the robot is: Pinocchio's own kinematics
        lines.append(",".join([session, clock_time, *(f"{v:.4f}" for v in tcp), *(f"{v:g}" for v in np.degrees(q))]))
    path.write_text("\n".join(lines) + "\n")
    result = import_tracker(path)
    assert result.columns[-2:] == ["time_s", "session"]
    times = [float(row[-2]) for row in result.rows]
    assert times == pytest.approx([86398.5, 86399.75, 86401.25], abs=1e-9)
    assert [row[-1] for row in result.rows] == ["east", "east", "west"]
    out = tmp_path / "m.csv"
    out.write_text(result.csv_text())
    measured = read_measurements(out, robot)
    assert list(measured.session) == ["east", "east", "west"]
    assert np.diff(measured.time_s) == pytest.approx([1.25, 1.5])


def test_a_session_label_with_a_comma_is_refused_naming_its_row(tmp_path):
    path = tmp_path / "stations.csv"
    path.write_text('session;X [mm];Y [mm];Z [mm]\neast;1;2;3\n"we,st";1;2;3\n')
    with pytest.raises(Exception, match=r"row 3, column 'session': a session label"):
        import_tracker(path)


@pytest.mark.parametrize("argv, message", [
    (["--map", "x_mm=Point X"], "no header line names the columns 'Point X'"),
    (["--map", "x_mm"], "--map 'x_mm': expected TARGET=SOURCE"),
])
def test_bad_maps_are_one_line_and_exit_2(tmp_path, capsys, argv, message):
    path = tmp_path / "t.csv"
    path.write_text("X;Y;Z\n1,0;2,0;3,0\n")
    code = main(["import", str(path), *argv, "--out", str(tmp_path / "o.csv")])
    err = capsys.readouterr().err
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o.csv").exists()


def test_a_bad_cell_names_file_row_and_column(tmp_path, capsys):
    path = tmp_path / "t.csv"
    path.write_text("meta line\nX;Y;Z\n1,0;2,0;3,0\n1,0;two;3,0\n")
    code = main(["import", str(path), "--out", str(tmp_path / "o.csv")])
    err = capsys.readouterr().err
    assert code == 2 and f"{path}: row 4, column 'Y': 'two' is not a number" in err
