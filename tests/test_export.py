"""``tcr-accuracy export``: the calibrated robot of a diagnosis written for controllers and tools,
and read back. Round trips against the fitted model the diagnosis itself predicts (mapped into the
base frame by its own tracker transform), and the exported URDF re-parsed from its text."""

import json

import numpy as np
import pytest

import tcr_accuracy as tcr
from tcr_accuracy.cli import main
from tcr_accuracy.diagnosis.diagnose import diagnose
from tcr_accuracy.io.measurements import read_measurements
from tcr_accuracy.model.kinematics import tcp_poses
from tcr_accuracy.model.robot import load_robot

DEMO = "src/tcr_accuracy/data/tool_changer_cutter.csv"


def _export(tmp_path, csv, robot_args, capsys, extra=()):
    """diagnose --json, then export: (JSON dict, export folder)."""
    out_json, folder = tmp_path / "d.json", tmp_path / "export"
    assert main(["diagnose", str(csv), *robot_args, "--quiet", "--json", str(out_json)]) == 0
    assert main(["export", str(out_json), "--to", str(folder), "--quiet", *extra]) == 0
    capsys.readouterr()
    return json.loads(out_json.read_text()), folder


def _fitted_in_base(robot, csv, data, frame=None):
    """The fitted model's TCP at the measured joints, base frame: the diagnosis' own prediction
    (tracker frame) mapped back with the tracker transform the JSON gives."""
    parts = read_measurements(csv, robot, frame=frame) if frame else read_measurements(csv, robot)
    d = diagnose(robot, parts if frame is None else _all_frames(csv, robot, frame),
                 effects=data["selected_effects"])
    base = np.linalg.inv(np.array(data["tracker_transform"]))
    tracker = d.predict(robot, parts.q, parts.context)
    return parts, tracker @ base[:3, :3].T + base[:3, 3]


def _all_frames(csv, robot, first):
    from tcr_accuracy.io.measurements import measured_frames

    frames = [first] + [f for f in measured_frames(csv) if f != first]
    robots = [robot] + [load_robot(str(robot.urdf_path), f) for f in frames[1:]]
    return [(r, read_measurements(csv, r, frame=f)) for r, f in zip(robots, frames)]


def _check_round_trip(folder, robot, parts, fitted):
    """The loaded model's TCP is the fitted one to 1e-9 m; the URDF's is its geometric part."""
    model = tcr.load_as_built(folder / "as_built.yaml")
    loaded = model.tcp_poses(parts.q, parts.context).position
    print(f"loaded vs fitted: {np.abs(loaded - fitted).max():.3g} m")
    np.testing.assert_allclose(loaded, fitted, atol=1e-9, rtol=0)
    # the URDF carries the geometry: re-parsed from its text, its TCP is the geometric part
    import yaml

    doc = yaml.safe_load((folder / "as_built.yaml").read_text())
    urdf_robot = load_robot(str(folder / doc["urdf"]), doc["urdf_tool_frame"])
    geometric = tcp_poses(model.geometric_robot(), parts.q).position
    np.testing.assert_allclose(tcp_poses(urdf_robot, parts.q).position, geometric, atol=1e-9, rtol=0)
    return model


def test_export_round_trips_the_demo_tool_changer_with_its_compliance(tmp_path, capsys):
    robot = load_robot()
    data, folder = _export(tmp_path, DEMO, [], capsys, ["--targets", "examples/poses.csv"])
    parts, fitted = _fitted_in_base(robot, DEMO, data)
    model = _check_round_trip(folder, robot, parts, fitted)
    assert "compliance" in model.parameters  # a non-geometric effect, applied at each row's payload
    no_payload = parts.context
    no_payload.payload_kg[:] = 0.0
    sag = np.linalg.norm(model.tcp_poses(parts.q, parts.context).position
                         - model.tcp_poses(parts.q, no_payload).position, axis=1)
    assert sag.max() > 2e-4  # the cutter's weight moves the TCP by tenths of a mm
    # joint offsets and TCP in deg and mm, as fitted
    rows = dict(line.split(",")[:2] for line in (folder / "joint_offsets_tcp.csv").read_text().splitlines()[1:])
    assert float(rows["joint_offset.j2"]) == pytest.approx(np.degrees(data["effect_parameters"]["joint_offsets"]
                                                                      ["joint_offsets.j2"]), rel=1e-6)
    assert float(rows["tcp_offset_in_tcp_frame.z"]) == pytest.approx(
        data["effect_parameters"]["frames"]["frames.tool.dz"] * 1e3, rel=1e-6)
    # the compensation table: the loaded model's TCP at the command is where the nominal robot with
    # the fitted TCP offset puts it at the target joints
    table = np.genfromtxt(folder / "compensation.csv", delimiter=",", names=True, dtype=None, encoding="utf-8")
    ok = table["status"] == "ok"
    assert ok.sum() >= 0.9 * len(table)
    names = table.dtype.names
    q_target = np.stack([table[n] for n in names[:6]], axis=1)[ok] / robot.display_scale
    q_command = np.stack([table[n] for n in names[6:12]], axis=1)[ok] / robot.display_scale
    pose = tcp_poses(robot, q_target)
    target = pose.position + pose.rotation @ model.tcp_offset()
    targets = read_measurements("examples/poses.csv", robot, require_position=False)
    context = targets.context.subset(np.flatnonzero(ok))
    reached = model.tcp_poses(q_command, context).position
    assert np.linalg.norm(reached - target, axis=1).max() < 2e-7
    assert np.linalg.norm(model.tcp_poses(q_target, context).position - target, axis=1).mean() > 1e-4


def test_export_round_trips_a_ur5_with_a_reflector_in_a_tracker_frame(tmp_path, capsys):
    scenario = tmp_path / "ur5.yaml"
    scenario.write_text("robot: ur5\neffects:\n  frames:\n    base_mm: {dx: 900.0, dy: -1400.0, dz: 300.0}\n"
                        "    base_deg: {rz: 179.9}\n    tool_mm: {dx: 0.07, dz: 28.0}\n"
                        "  geometry: {spread_mm: 0.3, spread_mrad: 0.5}\n"
                        "  joint_offsets:\n    offsets_deg: {shoulder_lift_joint: 0.05, elbow_joint: -0.04}\n"
                        "noise_mm: 0.015\n")
    csv = tmp_path / "ur5.csv"
    assert main(["simulate", "--robot", "ur5", "--scenario", str(scenario), "--n", "150", "--seed", "4",
                 "--out", str(csv), "--quiet"]) == 0
    robot = load_robot("ur5")
    data, folder = _export(tmp_path, csv, ["--robot", "ur5", "--effects", "geometry,joint_offsets"], capsys)
    parts, fitted = _fitted_in_base(robot, csv, data)
    model = _check_round_trip(folder, robot, parts, fitted)
    assert model.tcp_offset()[2] == pytest.approx(0.028, abs=2e-4)


def test_export_round_trips_a_multi_joint_robot_measured_at_two_hands(tmp_path, capsys):
    """A torso joint that loads both arms, compliance under the arms' weight: the chain of the first
    measured frame, its gravity from the whole tree (the other arm's joints from the CSV)."""
    from test_measured_frames import TWO_ARMS, _simulate

    urdf = tmp_path / "two_arms.urdf"
    urdf.write_text(TWO_ARMS)
    csv = tmp_path / "hands.csv"
    csv.write_text(_simulate(150, 1e-5, 5))
    robot = load_robot(str(urdf), "right_marker")
    data, folder = _export(tmp_path, csv, ["--robot", str(urdf), "--effects", "joint_offsets,compliance",
                                           "--noise-mm", "0.01"], capsys)
    assert "compliance" in data["effect_parameters"]
    parts, fitted = _fitted_in_base(robot, csv, data, frame="right_marker")
    _check_round_trip(folder, robot, parts, fitted)


def test_export_refuses_a_json_without_the_model_in_one_line(tmp_path, capsys):
    bad = tmp_path / "old.json"
    bad.write_text(json.dumps({"robot": "tool_changer", "parameters": {}}))
    assert main(["export", str(bad), "--to", str(tmp_path / "never")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "'effect_parameters'" in err[0] and "are missing" in err[0]
    assert not (tmp_path / "never").exists()


def _mdh_product(folder, q):
    """base_M_tcp (4, 4) from the exported mdh.csv (as-built columns, mm and deg), written out here:
    Rx(alpha) Tx(a) Ry(beta) Rz(theta + q) Tz(d) per row, between the base and tool frames."""
    from scipy.spatial.transform import Rotation

    def homogeneous(rotation=None, translation=(0.0, 0.0, 0.0)):
        out = np.eye(4)
        if rotation is not None:
            out[:3, :3] = rotation.as_matrix()
        out[:3, 3] = translation
        return out

    rows = np.genfromtxt(folder / "mdh.csv", delimiter=",", names=True, dtype=None, encoding="utf-8")
    frames = np.genfromtxt(folder / "mdh_base_tool.csv", delimiter=",", names=True, dtype=None, encoding="utf-8")

    def fixed(name):
        f = frames[(frames["frame"] == name) & (frames["model"] == "as_built")][0]
        rotation = Rotation.from_euler("ZYX", [f["yaw_deg"], f["pitch_deg"], f["roll_deg"]], degrees=True)
        return homogeneous(rotation, np.array([f["x_mm"], f["y_mm"], f["z_mm"]]) * 1e-3)

    out = fixed("base_to_frame0")
    for row, value in zip(rows, q):
        theta = np.radians(row["theta_deg_as_built"]) + (value if row["variable"] == "theta" else 0.0)
        d = row["d_mm_as_built"] * 1e-3 + (value if row["variable"] == "d" else 0.0)
        out = (out @ homogeneous(Rotation.from_euler("x", row["alpha_deg_as_built"], degrees=True))
               @ homogeneous(translation=(row["a_mm_as_built"] * 1e-3, 0, 0))
               @ homogeneous(Rotation.from_euler("y", row["beta_deg_as_built"], degrees=True))
               @ homogeneous(Rotation.from_euler("z", theta)) @ homogeneous(translation=(0, 0, d)))
    return out @ fixed("last_frame_to_tcp")


@pytest.mark.parametrize("case", ["tool_changer", "two_arms"])
def test_exported_mdh_table_is_the_calibrated_geometry_and_dh_is_refused_in_one_line(case, tmp_path, capsys):
    if case == "tool_changer":
        robot, csv, args = load_robot(), DEMO, []
    else:
        from test_measured_frames import TWO_ARMS, _simulate

        urdf = tmp_path / "two_arms.urdf"
        urdf.write_text(TWO_ARMS)
        csv = tmp_path / "hands.csv"
        csv.write_text(_simulate(150, 1e-5, 5))
        robot, args = load_robot(str(urdf), "right_marker"), ["--robot", str(urdf), "--noise-mm", "0.01"]
    out_json, folder = tmp_path / "d.json", tmp_path / "export"
    assert main(["diagnose", str(csv), *args, "--quiet", "--json", str(out_json)]) == 0
    capsys.readouterr()
    assert main(["export", str(out_json), "--to", str(folder)]) == 0
    out, err = capsys.readouterr()
    model = tcr.load_as_built(folder / "as_built.yaml")
    rng = np.random.default_rng(2)
    for q in rng.uniform(*robot.joint_bounds(np.pi), (5, robot.n_joints)):
        expected = tcp_poses(model.geometric_robot(), q)
        product = _mdh_product(folder, q)
        np.testing.assert_allclose(product[:3, 3], expected.position[0], atol=1e-8)
        np.testing.assert_allclose(product[:3, :3], expected.rotation[0], atol=1e-8)
    if case == "tool_changer":  # j2, j3, j5 parallel by design, tilted as built: no DH table, said once
        warning = [line for line in err.splitlines() if "no DH table" in line]
        assert len(warning) == 1 and "j2 and j3 are parallel by design" in warning[0]
        assert not (folder / "dh.csv").exists() and "DH: not written" in out


def test_dh_table_of_the_nominal_ur5_is_the_published_one():
    """Universal Robots' published UR5 DH parameters (d1 89.159, a2 -425, a3 -392.25, d4 109.15,
    d5 94.65, d6 82.3 mm; alpha 90, 0, 0, 90, -90, 0 deg): the same lengths up to the sign
    conventions, d6 in the tool transform."""
    from tcr_accuracy.model.dh import dh_table

    table = dh_table(load_robot("ur5"))
    a, alpha, d = table.params[:, 0], table.params[:, 1], table.params[:, 2]
    np.testing.assert_allclose(np.abs(a) * 1e3, [0, 425, 392.25, 0, 0, 0], atol=1e-6)
    np.testing.assert_allclose(np.abs(d[:5]) * 1e3, [89.159, 0, 0, 109.15, 94.65], atol=1e-6)
    np.testing.assert_allclose(np.abs(np.degrees(alpha)), [90, 0, 0, 90, 90, 0], atol=1e-6)
    assert np.linalg.norm(table.tool[:3, 3]) * 1e3 == pytest.approx(82.3, abs=1e-6)
