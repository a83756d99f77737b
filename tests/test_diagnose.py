"""diagnose against hidden simulated truths it never sees.

The hidden robots are written on Pinocchio alone (tests/hidden_robot.py: joint placement errors,
encoder offsets, compliance as -C g(q), joint play drawn anew at each pose, a TCP offset, the
tracker's frame), never through the effect classes the diagnosis fits. The diagnosis gets the
measurement set only (or the CSV file for the CLI) and is
judged on what the hidden robot holds.
"""

import json
import subprocess
import sys

import numpy as np
import pytest

from tcr_accuracy.diagnosis.diagnose import diagnose
from tcr_accuracy.effects import predict_positions
from tcr_accuracy.exceptions import InputError
from tcr_accuracy.model.kinematics import tcp_poses
from tcr_accuracy.model.robot import load_robot
from tcr_accuracy.io.measurements import parse_measurements

from conftest import REPO
from hidden_robot import DEG, MM, HiddenRobot, fixed_tracker, geometric_errors, in_tracker, measurement_csv, \
    noisy, random_poses

NOISE = 2e-5


def _geometry_measurements(robot, q, rng, *, placement_mm, placement_deg, offset_deg=0.0, tcp_mm=(0.8, -0.5, 1.2),
                           displacement=None, context=None):
    """CSV text of ``robot`` at commanded q with hidden geometry, on Pinocchio alone
    (tests/hidden_robot.py): joint placement errors, encoder offsets (prismatic: 0.2 x in mm), the TCP
    ``tcp_mm`` off, the tracker 1.6 m away turned 35 deg, 0.02 mm noise per axis; ``displacement``
    (N, 3) [m] added to the TCP in the base frame."""
    offsets, placements = geometric_errors(robot, rng, offset_deg=offset_deg, offset_mm=0.2 * offset_deg,
                                           placement_mm=placement_mm, placement_deg=placement_deg)
    tcp = robot.tool_frame
    hidden = HiddenRobot(robot, placements, {tcp: np.asarray(tcp_mm) * MM})
    positions = hidden.positions(q + offsets, [tcp])[tcp] + (0.0 if displacement is None else displacement)
    tracker = fixed_tracker()
    measured = noisy(rng, in_tracker(tracker, positions), NOISE)
    return measurement_csv(robot, q, {tcp: measured}, context or {}, per_frame=False)


COMPLIANCE_SI = {"j2": 0.012 * DEG / 1e3, "j3": 0.02 * DEG / 1e3, "j5": 0.03 * DEG / 1e3,  # rad/Nm
                 "j4": 0.05 * MM / 1e3}  # m/N


def _compliance_measurements(robot, n, seed):
    """The hidden truth of the compliance case on Pinocchio alone (tests/hidden_robot.py, no
    effect class): joints j2-j5 give way to gravity, ``dq = -C g(q + dq)`` (g from
    pin.computeGeneralizedGravity, solved by fixed-point steps) with the 150 kg cutter at the TCP
    in about half the poses; joint placement errors of 0.05 mm / 0.05 mrad, the TCP 0.8 / -0.5 /
    1.2 mm off, the tracker 1.6 m away turned 35 deg, 0.02 mm noise per axis."""
    rng = np.random.default_rng(seed)
    q = random_poses(robot, n, rng)
    payload = np.where(rng.random(n) < 0.5, 150.0, 0.0)
    _, placements = geometric_errors(robot, rng, offset_deg=0.0, offset_mm=0.0, placement_mm=0.05,
                                     placement_deg=0.05e-3 / DEG)
    tcp = robot.tool_frame
    hidden = HiddenRobot(robot, placements, {tcp: np.array([0.8, -0.5, 1.2]) * MM})
    compliance = np.array([COMPLIANCE_SI.get(j, 0.0) for j in robot.joint_names])
    dq = np.zeros_like(q)
    for _ in range(4):  # the sag changes the torque by a thousandth: a few steps converge
        dq = -compliance * hidden.holding_torque(q + dq, payload)
    tracker = fixed_tracker()
    measured = noisy(rng, in_tracker(tracker, hidden.positions(q + dq, [tcp])[tcp]), NOISE)
    text = measurement_csv(robot, q, {tcp: measured}, {"payload_kg": payload}, per_frame=False)
    return parse_measurements(text, robot)


@pytest.fixture(scope="module")
def compliance_case(tool_changer):
    mset = _compliance_measurements(tool_changer, 260, seed=11)
    train = mset.subset(np.arange(200))
    test = mset.subset(np.arange(200, 260))
    result = diagnose(tool_changer, train, folds=3, random_state=1, tracker_noise=NOISE)
    return result, COMPLIANCE_SI, test


def test_compliance_dominant_is_named_and_the_gap_shrinks_to_the_noise(compliance_case, tool_changer):
    result, truth, test = compliance_case
    assert result.primary_effect == "compliance"
    assert "compliance" in result.selected_effects
    assert result.gap.rms > 10 * result.noise_floor  # there was a gap to explain
    final = result.steps[-1].heldout.rms
    assert final < 1.5 * result.noise_floor
    # the fitted model predicts measurements it never saw to the noise floor
    predicted = result.tracker_positions(tool_changer, test.q, test.context)
    rms = np.sqrt(np.mean(np.sum((predicted - test.position) ** 2, axis=1)))
    assert rms < 1.5 * result.noise_floor
    # and recovers the hidden compliances of the two heavily loaded joints within 10 %
    fitted = result.parameters["compliance"]
    for joint in ("j2", "j3"):
        assert fitted[f"compliance.{joint}"] == pytest.approx(truth[joint], rel=0.1)
    assert not result.structure_remains


def test_identifiability_names_duplicated_parameters(compliance_case, tool_changer):
    result, _, _ = compliance_case
    # the whole vocabulary, in its order
    everything = result.identifiability["all_effects"]
    removed = {r["parameter"]: r for info in everything["effects"].values() for r in info["removed"]}
    # j1 turns about the base z axis: its offset is a rotation of the tracker frame
    assert "joint_offsets.j1" in removed
    assert "frames.base.rz" in removed["joint_offsets.j1"]["duplicates"]
    # a placement twist about a revolute joint's own axis is that joint's offset
    # (parentMjoint exp(r axis) R(q) = parentMjoint R(q + r)); the axes are read off the model
    for j, (name, kind) in enumerate(zip(tool_changer.joint_names, tool_changer.joint_kinds)):
        if kind != "revolute" or f"joint_offsets.{name}" in removed:
            continue
        axis = "xyz"[int(np.argmax(np.abs(tool_changer.motion_axes[j][3:])))]
        entry = removed[f"geometry.{name}.r{axis}"]
        assert f"joint_offsets.{name}" in entry["duplicates"]
    assert everything["condition_number"] < 1e4
    # the final model: nothing it fitted was named unidentifiable in it, and what it kept
    # is well conditioned
    final_removed = {r["parameter"] for info in result.identifiability["effects"].values() for r in info["removed"]}
    kept = {n for p in result.parameters.values() for n in p}
    assert kept and not kept & final_removed
    assert result.identifiability["condition_number"] < 1e4


def test_out_of_vocabulary_effect_leaves_structure(tool_changer):
    """A smooth TCP displacement of about 0.6 mm that mixes several joints in the base frame: no
    effect of the vocabulary given expresses it."""
    rng = np.random.default_rng(5)
    q = random_poses(tool_changer, 200, rng)
    field = 0.6 * MM * np.column_stack([np.sin(q[:, 0] + 2 * q[:, 1]), np.cos(q[:, 2] - q[:, 4]),
                                        np.sin(2 * q[:, 4] + q[:, 1])])
    text = _geometry_measurements(tool_changer, q, rng, placement_mm=0.1, placement_deg=0.1e-3 / DEG,
                                  displacement=field)
    result = diagnose(tool_changer, parse_measurements(text, tool_changer), folds=3, random_state=2,
                      tracker_noise=NOISE, effects=["joint_offsets", "geometry", "compliance", "transmission"])
    assert result.steps[-1].heldout.rms > 2 * result.noise_floor
    assert result.structure_remains


def test_clearance_shows_as_scatter_without_structure(tool_changer):
    """Joint play on Pinocchio alone (tests/hidden_robot.py, no effect class): at every pose each
    joint's placement sits off by its own random screw (0.03 mm along and across the axis,
    0.03 mrad tilt) on top of fixed placement errors of 0.1 mm / 0.1 mrad: a scatter beyond the
    tracker's 0.02 mm that follows no joint, read as clearance, not as structure."""
    rng = np.random.default_rng(6)
    q = random_poses(tool_changer, 200, rng)
    _, placements = geometric_errors(tool_changer, rng, offset_deg=0.0, offset_mm=0.0, placement_mm=0.1,
                                     placement_deg=0.1e-3 / DEG)
    tcp = tool_changer.tool_frame
    positions = np.empty((len(q), 3))
    for i in range(len(q)):  # the play drawn anew at each pose
        played = {name: xi + np.concatenate([rng.normal(0.0, 0.03 * MM, 3), rng.normal(0.0, 0.03e-3, 3)])
                  for name, xi in placements.items()}
        positions[i] = HiddenRobot(tool_changer, played, {tcp: np.array([0.8, -0.5, 1.2]) * MM}).positions(
            q[i:i + 1], [tcp])[tcp][0]
    measured = noisy(rng, in_tracker(fixed_tracker(), positions), NOISE)
    mset = parse_measurements(measurement_csv(tool_changer, q, {tcp: measured}, {}, per_frame=False), tool_changer)
    result = diagnose(tool_changer, mset, folds=3, random_state=3, tracker_noise=NOISE,
                      effects=["joint_offsets", "geometry", "clearance"])
    assert result.scatter["detected"]
    assert result.scatter["ratio"] > 1.5
    assert not result.structure_remains
    assert result.scatter.get("named") == "clearance"


def test_geometry_only_as_built_urdf_reproduces_the_robot(tmp_path, ur5):
    """Export and reload: the as-built URDF plus the tracker frame predict the measurements (hidden
    geometry, encoder offsets and TCP offset written on Pinocchio alone)."""
    rng = np.random.default_rng(8)
    q = random_poses(ur5, 150, rng)
    text = _geometry_measurements(ur5, q, rng, placement_mm=0.3, placement_deg=0.3e-3 / DEG, offset_deg=0.05,
                                  tcp_mm=(0.6, -0.9, 0.4))
    mset = parse_measurements(text, ur5)
    csv = tmp_path / "meas.csv"
    csv.write_text(text)
    urdf = tmp_path / "asbuilt.urdf"
    out = tmp_path / "out.json"
    proc = subprocess.run([sys.executable, "-m", "tcr_accuracy", "diagnose", str(csv), "--robot", "ur5",
                           "--effects", "joint_offsets,geometry,compliance", "--folds", "3", "--quiet",
                           "--json", str(out), "--as-built-urdf", str(urdf), "--out", str(tmp_path / "rep")],
                          capture_output=True, text=True, cwd=REPO, timeout=300,
                          env={"PYTHONPATH": str(REPO / "src"), "PATH": "/usr/bin:/bin", "MPLBACKEND": "Agg"})
    assert proc.returncode == 0, proc.stderr
    payload = json.loads(out.read_text())
    for key in ("gap", "steps", "selected_effects", "primary_effect", "leave_one_out", "where", "noise_floor_mm",
                "identifiability", "structure_remains"):
        assert key in payload
    assert {"effect", "train_rms_mm", "heldout_rms_mm", "heldout_mean_mm", "heldout_max_mm"} <= set(payload["steps"][0])
    assert "compliance" not in payload["selected_effects"]  # not hidden: not chosen
    for name in ("report.md", "index.html", "figure-1.png", "scene-1.html"):
        assert (tmp_path / "rep" / name).is_file()
    side = tmp_path / "asbuilt.effects.yaml"
    import yaml

    doc = yaml.safe_load(side.read_text())
    tracker = np.array(doc["trackerMbase"])
    asbuilt = load_robot(str(urdf), doc["urdf_measured_frame"])
    position = tcp_poses(asbuilt, mset.q).position @ tracker[:3, :3].T + tracker[:3, 3]
    rms = np.sqrt(np.mean(np.sum((position - mset.position) ** 2, axis=1)))
    assert rms < 1.5 * np.sqrt(3) * NOISE
    nominal = predict_positions(ur5, [], [], mset.q)
    assert np.sqrt(np.mean(np.sum((nominal @ tracker[:3, :3].T + tracker[:3, 3] - mset.position) ** 2,
                                  axis=1))) > 10 * rms


def test_cli_bad_csv_exits_2_with_one_line(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("j1_deg,j2_deg,j3_deg,j4_mm,j5_deg,j6_deg,x_mm,y_mm,z_mm\n"
                   "1,2,3,4,5,6,100,200,300\n1,2,abc,4,5,6,100,200,300\n")
    proc = subprocess.run([sys.executable, "-m", "tcr_accuracy", "diagnose", str(bad), "--quiet"],
                          capture_output=True, text=True, cwd=REPO, timeout=300,
                          env={"PYTHONPATH": str(REPO / "src"), "PATH": "/usr/bin:/bin"})
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1
    assert "bad.csv" in lines[0] and "row 3" in lines[0] and "j3_deg" in lines[0]


def test_too_few_measurements_is_an_input_error(tool_changer):
    q = random_poses(tool_changer, 8, np.random.default_rng(1))
    text = _geometry_measurements(tool_changer, q, np.random.default_rng(1), placement_mm=0.0, placement_deg=0.0)
    mset = parse_measurements(text, tool_changer)
    with pytest.raises(InputError, match="too few"):
        diagnose(tool_changer, mset, folds=5)


def test_an_effect_left_with_no_parameter_does_not_stop_the_diagnosis(tool_changer):
    """At one constant temperature off the reference, thermal growth is a fixed geometric
    error: once geometry is in the model it keeps no parameter of its own (the hidden robot:
    geometry only, on Pinocchio alone, measured at 31 degC)."""
    rng = np.random.default_rng(11)
    q = random_poses(tool_changer, 120, rng)
    text = _geometry_measurements(tool_changer, q, rng, placement_mm=0.3, placement_deg=0.3e-3 / DEG,
                                  context={"temperature_c": np.full(120, 31.0)})
    mset = parse_measurements(text, tool_changer)
    assert np.all(mset.temperature_c == 31.0)
    result = diagnose(tool_changer, mset, effects=["geometry", "thermal", "joint_offsets"], folds=3,
                      tracker_noise=2e-5)
    assert result.primary_effect == "geometry" and "thermal" not in result.selected_effects
    assert result.steps[-1].heldout.rms < 1.5 * result.noise_floor
