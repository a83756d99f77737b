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
    tracker = d.predict(robot, parts.q, parts.context())
    return parts, tracker @ base[:3, :3].T + base[:3, 3]


def _all_frames(csv, robot, first):
    from tcr_accuracy.io.measurements import measured_frames

    frames = [first] + [f for f in measured_frames(csv) if f != first]
    robots = [robot] + [load_robot(str(robot.urdf_path), f) for f in frames[1:]]
    return [(r, read_measurements(csv, r, frame=f)) for r, f in zip(robots, frames)]


def _check_round_trip(folder, robot, parts, fitted):
    """The loaded model's TCP is the fitted one to 1e-9 m; the URDF's is its geometric part."""
    model = tcr.load_as_built(folder / "as_built.yaml")
    loaded = model.tcp_poses(parts.q, parts.context()).position
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
    no_payload = parts.context()
    no_payload.payload_kg[:] = 0.0
    sag = np.linalg.norm(model.tcp_poses(parts.q, parts.context()).position
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
    context = targets.context().subset(np.flatnonzero(ok))
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
    assert len(err) == 1 and "key 'effect_parameters' is missing" in err[0]
    assert not (tmp_path / "never").exists()
