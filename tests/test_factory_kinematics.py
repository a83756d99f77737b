"""The robot's own kinematics as the start (``--kinematics FILE``, issue 42 item 2).

Each file is read back against a forward kinematics written out here: the UR xacro's chain (each
joint ``origin * Rz(q)`` from ``base_link_inertia``, then the fixed ``flange`` and ``tool0``
rotations) for the ROS 2 driver's calibration YAML, and a product of DH/MDH rows
(tests/test_dh_tables.py) for the tables. The diagnosis test builds a UR5 on Pinocchio alone
(tests/hidden_robot.py: the URDF's tree with hidden joint placement errors and encoder offsets,
the factory's, and a joint compliance under gravity and a 5 kg payload, none of the package's
effect classes), writes its factory kinematics as the driver's YAML and its measurements as a
user's CSV, and asks the command line: with ``--kinematics`` the diagnosis names compliance only,
without it names geometry too. Bad files are decoys in tmp_path, refused in one line, exit 2.
"""

import csv
import io
import json
import math

import numpy as np
import pinocchio as pin
import pytest
import yaml

from tcr_accuracy.asbuilt.dh import dh_table, mdh_table
from tcr_accuracy.asbuilt.export import TableForm
from tcr_accuracy.asbuilt.factory_kinematics import with_factory_kinematics
from tcr_accuracy.asbuilt.ur_calibration import ur_kinematics
from tcr_accuracy.cli.export_tables import table_csv
from tcr_accuracy.model.robot import load_robot

from conftest import random_joint_values, run_command
from hidden_robot import DEG, MM, HiddenRobot, in_tracker, measurement_csv, noisy, random_poses, tracker_frame
from test_dh_tables import table_fk

LINKS = ("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3")


def _rpy(roll, pitch, yaw):
    """URDF's rpy written out: Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch), math.cos(yaw),
                              math.sin(yaw))
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return rz @ ry @ rx


def _h(rotation, translation=(0.0, 0.0, 0.0)):
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = rotation, translation
    return out


def xacro_tool0(document, q):
    """base_link_M_tool0 of ur_description's xacro for a kinematics document at joints q (6,) [rad]:
    base_link -> base_link_inertia (yaw pi), each joint's origin then Rz(q), wrist_3 -> flange
    (rpy 0, -90, -90 deg) -> tool0 (rpy 90, 0, 90 deg)."""
    out = _h(_rpy(0.0, 0.0, math.pi))
    for name, value in zip(LINKS, q):
        e = document["kinematics"][name]
        out = out @ _h(_rpy(e["roll"], e["pitch"], e["yaw"]), (e["x"], e["y"], e["z"])) @ _h(_rpy(0, 0, value))
    return out @ _h(_rpy(0.0, -math.pi / 2, -math.pi / 2)) @ _h(_rpy(math.pi / 2, 0.0, math.pi / 2))


def _factory(robot, seed, placement_mm=0.3, placement_deg=0.03, offset_deg=0.03):
    """(placement error screws {joint: (6,)}, encoder offsets (n,), the factory robot as a RobotModel): joint
    placements perturbed on Pinocchio, the offsets folded into them (joint(q + o) = M exp6(S o) exp6(S q))."""
    rng = np.random.default_rng(seed)
    placements = {n: np.concatenate([rng.normal(0, placement_mm * MM, 3), rng.normal(0, placement_deg * DEG, 3)])
                  for n in robot.joint_names}
    offsets = rng.normal(0, offset_deg * DEG, robot.n_joints)
    model = pin.Model(robot.model)
    for j, name in enumerate(robot.joint_names):
        axis = robot.motion_axes[j]
        model.jointPlacements[j + 1] = model.jointPlacements[j + 1] * pin.exp6(placements[name]) * \
            pin.exp6(axis * offsets[j])
    return placements, offsets, robot.with_model(model, name=robot.name)


def _fk(robot, q):
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, robot.to_pinocchio_q(q))
    return data.oMf[robot.tool_frame_id].homogeneous


def test_a_driver_calibration_file_is_read_back_as_the_xacro_chain(tmp_path, ur5):
    """The factory UR5's driver YAML (written by export's writer) read with --kinematics: the robot's TCP
    frame is the xacro's tool0 of that file, and the Pinocchio factory robot's, to 1e-9 m and rad."""
    _, _, factory = _factory(ur5, 1)
    document = ur_kinematics(factory, ur5, "ur5")
    path = tmp_path / "calibration.yaml"
    path.write_text("# written by ur_calibration\n" + yaml.safe_dump(document))
    robot = with_factory_kinematics(ur5, path)
    assert robot.name == "ur5" and robot.kinematics["format"] == "UR ROS 2 driver calibration"
    assert robot.kinematics["file"] == "calibration.yaml" and len(robot.kinematics["sha256"]) == 64
    for q in random_joint_values(ur5, 20, np.random.default_rng(2)):
        got, xacro, truth = _fk(robot, q), xacro_tool0(document, q), _fk(factory, q)
        assert np.abs(got[:3, 3] - xacro[:3, 3]).max() < 1e-9
        assert np.abs(got[:3, :3] - xacro[:3, :3]).max() < 1e-9
        assert np.abs(got[:3, 3] - truth[:3, 3]).max() < 1e-9
    # the catalogue's UR5 is 0.1 mm or more away: the file did change the robot
    q = random_joint_values(ur5, 20, np.random.default_rng(3))
    assert max(np.linalg.norm(_fk(robot, v)[:3, 3] - _fk(ur5, v)[:3, 3]) for v in q) > 1e-4


def _table_rows(text, suffix):
    rows = list(csv.DictReader(io.StringIO(text)))
    scale = {"a_mm": 1e-3, "alpha_deg": DEG, "d_mm": 1e-3, "theta_deg": DEG, "beta_deg": DEG}
    return [[float(r[f"{c}{suffix}"]) * s for c, s in scale.items()] for r in rows], [r["variable"] for r in rows]


def _base_tool(text, model):
    out = {}
    for r in csv.DictReader(io.StringIO(text)):
        if r["model"] == model:
            out[r["frame"]] = _h(_rpy(*(float(r[k]) * DEG for k in ("roll_deg", "pitch_deg", "yaw_deg"))),
                                 [float(r[k]) * 1e-3 for k in ("x_mm", "y_mm", "z_mm")])
    return out["base_to_frame0"], out["last_frame_to_tcp"]


@pytest.mark.parametrize("name, convention", [("ur5", "DH"), ("panda", "MDH"), ("kinova", "DH")])
def test_a_table_export_wrote_is_read_back_as_its_rows_product(name, convention, tmp_path):
    """A factory robot's table in export's form (dh.csv / mdh.csv and *_base_tool.csv): the robot read with
    it puts its TCP where the product of the file's as-built rows does (numbers read here with csv)."""
    robot = load_robot(name)
    _, _, factory = _factory(robot, 4)
    build = dh_table if convention == "DH" else mdh_table
    nominal = build(robot)
    rows_text, frames_text = table_csv(TableForm(convention, f"{convention.lower()}.csv", nominal,
                                                 build(factory, robot, reference=nominal)))
    path = tmp_path / f"{convention.lower()}.csv"
    path.write_text(rows_text)
    (tmp_path / f"{convention.lower()}_base_tool.csv").write_text(frames_text)
    read = with_factory_kinematics(robot, path)
    assert read.kinematics["format"] == f"{convention} table"
    rows, variable = _table_rows(rows_text, "_as_built")
    base, tool = _base_tool(frames_text, "as_built")
    for q in random_joint_values(robot, 15, np.random.default_rng(5)):
        expected = table_fk(convention, rows, variable, base, tool, q)
        got = _fk(read, q)
        assert np.abs(got[:3, 3] - expected[:3, 3]).max() < 1e-9
        assert np.abs(got[:3, :3] - expected[:3, :3]).max() < 1e-9


# ---------------------------------------------------------------------------------------
# Bad files: one line, exit 2
# ---------------------------------------------------------------------------------------
def _pose_csv(tmp_path, robot):
    joints = ",".join(f"{n}_deg" for n in robot.joint_names)
    path = tmp_path / "q.csv"
    path.write_text(joints + "\n" + ",".join("0" for _ in robot.joint_names) + "\n")
    return path


@pytest.mark.parametrize("case", ["another robot", "not yaml", "missing key", "text value", "extra key",
                                  "table rows", "table joint", "table of another robot", "a folder"])
def test_a_bad_kinematics_file_is_one_line_exit_2(case, tmp_path, capsys, ur5):
    ur10 = load_robot("ur10")
    good = ur_kinematics(ur5, ur5, "ur5")
    path = tmp_path / "decoy.yaml"
    expected = {"another robot": "the kinematics of another robot", "not yaml": "not valid YAML",
                "missing key": "kinematics.wrist_2: missing", "text value": "kinematics.forearm.x",
                "extra key": "not part of a UR calibration file", "table rows": "joint rows",
                "table joint": "row 4: joint", "table of another robot": "the kinematics of another robot",
                "a folder": "folder"}[case]
    if case == "another robot":
        path.write_text(yaml.safe_dump(ur_kinematics(ur10, ur10, "ur10")))
    elif case == "not yaml":
        path.write_text("kinematics: [unclosed\n")
    elif case == "missing key":
        del good["kinematics"]["wrist_2"]
        path.write_text(yaml.safe_dump(good))
    elif case == "text value":
        good["kinematics"]["forearm"]["x"] = "0.4 m"
        path.write_text(yaml.safe_dump(good))
    elif case == "extra key":
        path.write_text(yaml.safe_dump({**good, "calibration_checksum": "x"}))
    elif case.startswith("table"):
        form = TableForm("DH", "dh.csv", dh_table(ur10 if "another" in case else ur5),
                         dh_table(ur10 if "another" in case else ur5))
        rows_text, frames_text = table_csv(form)
        lines = rows_text.splitlines()
        if case == "table rows":
            lines = lines[:-1]
        elif case == "table joint":
            lines[3] = lines[3].replace("elbow_joint", "elbow")
        path = tmp_path / "dh.csv"
        path.write_text("\n".join(lines) + "\n")
    else:
        path = tmp_path / "folder.yaml"
        path.mkdir()
    code, out, err = run_command(["pose", "--robot", "ur5", "--kinematics", str(path), "--q", "0", "-90", "90",
                                  "0", "90", "0"], capsys)
    assert code == 2, (case, err)
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert expected in err and str(path.name) in err, err
    del out


# ---------------------------------------------------------------------------------------
# The diagnosis from the robot's own kinematics
# ---------------------------------------------------------------------------------------
NOISE_MM = 0.015


@pytest.fixture(scope="module")
def factory_campaign(tmp_path_factory, ur5):
    """A UR5 with factory deltas (placements 0.3 mm / 0.03 deg, encoder offsets 0.03 deg), a joint compliance
    (shoulder, elbow and wrist 1 giving way to gravity by 0.03 to 0.05 deg under their typical torque) and a
    5 kg payload in 60 % of 260 poses kept above the mounting plane, a reflector 40 mm out from tool0, a
    tracker 3 m away; its factory kinematics written as the driver's YAML by export's writer."""
    folder = tmp_path_factory.mktemp("factory")
    rng = np.random.default_rng(42)
    placements, offsets, factory = _factory(ur5, 42)
    (folder / "factory.yaml").write_text("# the factory calibration (ur_calibration)\n"
                                         + yaml.safe_dump(ur_kinematics(factory, ur5, "ur5")))
    hidden = HiddenRobot(ur5, placements, {"tool0": np.array([0.01, -0.02, 0.04])})
    q = random_poses(ur5, 2000, rng)
    links = ["shoulder_link", "upper_arm_link", "forearm_link", "wrist_1_link", "wrist_2_link", "wrist_3_link",
             "tool0"]
    heights = hidden.positions(q[:600] + offsets, links)
    above = np.min([heights[link][:, 2] for link in links], axis=0) > 0.05
    q = q[:600][above][:260]
    payload = np.where(rng.random(len(q)) < 0.6, 5.0, 0.0)
    compliance = np.array([0.0, 1.2e-5, 1.6e-5, 2.5e-5, 0.0, 0.0])  # [rad/Nm]
    q_set = q + offsets
    q_real = q_set - compliance * hidden.holding_torque(q_set, payload)
    tracker = tracker_frame(rng)
    measured = noisy(rng, in_tracker(tracker, hidden.positions(q_real, ["tool0"])["tool0"]), NOISE_MM * MM)
    (folder / "ur5.csv").write_text(measurement_csv(ur5, q, {"tool0": measured}, {"payload_kg": payload},
                                                    per_frame=False))
    sag = hidden.positions(q_real, ["tool0"])["tool0"] - hidden.positions(q_set, ["tool0"])["tool0"]
    return {"folder": folder, "sag_rms_mm": float(np.sqrt(np.mean(np.sum(sag**2, axis=1)))) / MM}


def _diagnose(folder, capsys, *extra):
    name = "with" if extra else "without"
    code, out, err = run_command(["diagnose", str(folder / "ur5.csv"), "--robot", "ur5", "--noise-mm", str(NOISE_MM),
                                  "--json", str(folder / f"{name}.json"), "--quiet", *extra], capsys)
    assert code == 0, err
    return json.loads((folder / f"{name}.json").read_text()), out


@pytest.mark.slow
def test_from_the_factory_kinematics_the_diagnosis_names_the_hidden_compliance_only(factory_campaign, capsys):
    folder = factory_campaign["folder"]
    print(f"gravity sag at the TCP: {factory_campaign['sag_rms_mm']:.3f} mm RMS")
    assert factory_campaign["sag_rms_mm"] > 0.15  # well above the noise: there is something to find
    with_start, printed = _diagnose(folder, capsys, "--kinematics", str(folder / "factory.yaml"))
    without, _ = _diagnose(folder, capsys)
    print("with --kinematics:", with_start["selected_effects"], "without:", without["selected_effects"])
    assert set(with_start["selected_effects"]) - {"frames"} == {"compliance"}
    assert {"geometry", "joint_offsets"} & set(without["selected_effects"])
    assert "compliance" in without["selected_effects"]
    assert with_start["kinematics"]["file"] == "factory.yaml" and "kinematics" not in without
    assert "Nominal robot: the factory kinematics of factory.yaml (UR ROS 2 driver calibration)" in printed


@pytest.mark.slow
def test_the_export_is_relative_to_the_start_and_says_so(factory_campaign, capsys):
    """export of the diagnosis from the factory kinematics: the model file carries the start and reloads onto
    it; the URDF and the UR file say it; the DH table's nominal columns are the factory robot's table."""
    import tcr_accuracy as tcr

    folder = factory_campaign["folder"]
    if not (folder / "with.json").exists():
        _diagnose(folder, capsys, "--kinematics", str(folder / "factory.yaml"))
    code, out, err = run_command(["export", str(folder / "with.json"), "--to", str(folder / "export"), "--quiet"],
                                 capsys)
    assert code == 0, err
    assert "start: the factory kinematics of factory.yaml (UR ROS 2 driver calibration)" in out
    model = tcr.load_as_built(folder / "export" / "as_built.yaml")
    assert model.robot.kinematics["file"] == "factory.yaml"
    factory = with_factory_kinematics(load_robot("ur5"), folder / "factory.yaml")
    for q in random_joint_values(factory, 5, np.random.default_rng(0)):
        assert np.abs(_fk(model.robot, q) - _fk(factory, q)).max() < 1e-9
    assert "factory kinematics of factory.yaml" in (folder / "export" / "as_built.urdf").read_text()
    assert "factory kinematics of factory.yaml" in (folder / "export" / "ur_calibration.yaml").read_text()
    rows, _ = _table_rows((folder / "export" / "dh.csv").read_text(), "")
    np.testing.assert_allclose(np.array(rows), dh_table(factory).params, atol=1e-9)
