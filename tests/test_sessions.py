"""Measurement campaigns of several sessions: each its own tracker station, the robot shared.

Two sessions of the tool-changer measured from two tracker stations on a cold morning (9
degC) and at working temperature (21 degC); its links grow with the temperature (thermal
expansion of steel). The measured positions are made here with Pinocchio directly: every
joint placement's translation scaled by 1 + alpha (T - 20 degC), the reflector's offset too,
the session's tracker frame applied, 0.02 mm of noise. The diagnosis sees only the CSVs.
"""

import json

import numpy as np
import pinocchio as pin
import pytest

from tcr_accuracy.cli import main
from tcr_accuracy.io.measurements import join_sessions, read_measurements
from tcr_accuracy.diagnosis.diagnose import GapDiagnosis
from tcr_accuracy.model.robot import load_robot

from conftest import random_joint_values

ALPHA = 1.2e-5  # [1/K] steel
NOISE = 2e-5
STATIONS = {"cold": (9.0, [2.1, -0.8, -0.4], [0.0, 0.0, 0.6]), "warm": (21.0, [-1.5, 1.9, -0.3], [0.02, -0.01, 2.4])}
TOOL = np.array([0.0012, -0.0008, 0.0015])


def _session(robot, label: str, n: int, seed: int) -> str:
    temperature, translation, rpy = STATIONS[label]
    rng = np.random.default_rng(seed)
    q = random_joint_values(robot, n, rng)
    t = temperature + 0.5 * rng.standard_normal(n)  # a degree of spread inside a session
    station = pin.SE3(pin.rpy.rpyToMatrix(*rpy), np.array(translation))
    data = robot.model.createData()
    fid = robot.model.getFrameId(robot.tool_frame)
    position = np.empty((n, 3))
    for i in range(n):
        model = robot.model.copy()
        growth = 1.0 + ALPHA * (t[i] - 20.0)
        for j in range(1, model.njoints):
            placement = model.jointPlacements[j]
            model.jointPlacements[j] = pin.SE3(placement.rotation, placement.translation * growth)
        frame = model.frames[fid]
        frame.placement = pin.SE3(frame.placement.rotation, frame.placement.translation * growth)
        model.frames[fid] = frame
        data = model.createData()
        pin.framesForwardKinematics(model, data, robot.to_pinocchio_q(q[i]))
        position[i] = station.act(data.oMf[fid].act(TOOL * growth))
    position += NOISE * rng.standard_normal((n, 3))
    cols = [f"{j}_{'mm' if k == 'prismatic' else 'deg'}" for j, k in zip(robot.joint_names, robot.joint_kinds)]
    joints = np.where(np.array(robot.joint_kinds) == "prismatic", q * 1e3, np.degrees(q))
    rows = np.column_stack([joints, position * 1e3, t])
    header = ",".join(cols + ["x_mm", "y_mm", "z_mm", "temperature_c"])
    return header + "\n" + "\n".join(",".join(f"{v:.10g}" for v in r) for r in rows) + "\n"


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    robot = load_robot()
    folder = tmp_path_factory.mktemp("campaign")
    files = {}
    for seed, label in enumerate(STATIONS):
        files[label] = folder / f"{label}.csv"
        files[label].write_text(_session(robot, label, 150, seed))
    return robot, files


def _thermal(d) -> float | None:
    return d.parameters.get("thermal", {}).get("thermal.alpha")


@pytest.mark.slow
def test_two_sessions_at_two_temperatures_find_thermal(campaign):
    robot, files = campaign
    sets = [read_measurements(files[label], robot) for label in STATIONS]
    together = GapDiagnosis(robot=robot, tracker_noise=NOISE, stability_replays=5).fit(
        join_sessions(sets, list(STATIONS))).result_
    assert "thermal" in together.selected_effects
    assert _thermal(together) == pytest.approx(ALPHA, rel=0.1)
    assert [s["session"] for s in together.sessions] == list(STATIONS)
    assert all(s["heldout"]["rms_mm"] < 1.3 * together.noise_floor * 1e3 for s in together.sessions)
    for mset in sets:  # a degree of spread inside one session does not show the expansion
        alone = GapDiagnosis(robot=robot, tracker_noise=NOISE, stability_replays=5).fit(mset).result_
        assert "thermal" not in alone.selected_effects


@pytest.mark.slow
def test_a_session_column_is_the_same_as_two_files(campaign, tmp_path, capsys):
    robot, files = campaign
    lines = []
    for label in STATIONS:
        text = files[label].read_text().splitlines()
        if not lines:
            lines.append(text[0] + ",session")
        lines += [row + f",{label}" for row in text[1:]]
    joined = tmp_path / "joined.csv"
    joined.write_text("\n".join(lines) + "\n")
    assert main(["diagnose", str(joined), "--noise-mm", "0.02", "--quiet", "--json", str(tmp_path / "a.json")]) == 0
    assert main(["diagnose", *map(str, files.values()), "--noise-mm", "0.02", "--quiet",
                 "--json", str(tmp_path / "b.json")]) == 0
    import json

    a, b = (json.loads((tmp_path / f"{k}.json").read_text()) for k in "ab")
    assert a["selected_effects"] == b["selected_effects"]
    assert a["parameters"]["thermal"]["thermal.alpha"] == pytest.approx(ALPHA, rel=0.1)
    assert b["parameters"]["thermal"]["thermal.alpha"] == pytest.approx(a["parameters"]["thermal"]["thermal.alpha"],
                                                                        rel=1e-6)
    assert [s["session"] for s in a["sessions"]] == ["cold", "warm"]


def test_bad_session_input_is_one_line(tmp_path, capsys):
    robot = load_robot()
    path = tmp_path / "s.csv"
    path.write_text(_session(robot, "cold", 30, 1).replace("temperature_c", "session", 1))
    # the temperature cells are now session labels: numbers are labels too, so the file reads;
    # a session of fewer than 3 rows is refused
    text = path.read_text().splitlines()
    text[1] = ",".join(text[1].split(",")[:-1] + ["lonely"])
    path.write_text("\n".join(text) + "\n")
    assert main(["diagnose", str(path), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "session lonely" in err[0]
    assert main(["diagnose", str(path), str(path), "--quiet"]) == 2
    assert "given twice" in capsys.readouterr().err


@pytest.mark.slow
def test_a_length_scale_beyond_any_material_is_a_session_difference(tmp_path):
    """Two sessions 2 K apart whose lengths differ by 1.2e-4 (another floor, the tracker's
    scale): the length scale is kept (6e-5 per K, within 15 %), and read as the instrument's
    scale or a difference between sessions, not as the links' expansion (beyond aluminium)."""
    robot = load_robot()
    global STATIONS, ALPHA
    saved = STATIONS, ALPHA
    try:
        STATIONS = {"monday": (20.0, [2.1, -0.8, -0.4], [0.0, 0.0, 0.6]),
                    "friday": (22.0, [-1.5, 1.9, -0.3], [0.02, -0.01, 2.4])}
        ALPHA = 6e-5
        sets = []
        for seed, label in enumerate(STATIONS):
            path = tmp_path / f"{label}.csv"
            path.write_text(_session(robot, label, 150, seed + 10))
            sets.append(read_measurements(path, robot))
    finally:
        STATIONS, ALPHA = saved
    d = GapDiagnosis(robot=robot, tracker_noise=NOISE, stability_replays=5).fit(
        join_sessions(sets, ["monday", "friday"])).result_
    assert d.parameters["thermal"]["thermal.alpha"] == pytest.approx(6e-5, rel=0.15)
    reading = next(m for m in d.mechanisms if m["effect"] == "thermal")
    assert reading["mechanism_keys"] == ["instrument_scale"] and not reading["textbook"]
    assert "difference between sessions" in reading["mechanism"]
    said = [f for f in d.outside_physics if f["effect"] == "thermal"]
    assert said and said[0]["physical"]


def test_tool_names_the_measured_frame_everywhere(tmp_path, capsys):
    """A file with three reflectors on one tool: predict and compensate read the one --tool names
    and answer as on a file holding only that reflector's columns."""
    from test_fit_physics import THREE_REFLECTORS, _positions

    urdf = tmp_path / "arm.urdf"
    urdf.write_text(THREE_REFLECTORS)
    robots = {f: load_robot(str(urdf), f) for f in ("smr_1", "smr_2", "smr_3")}
    rng = np.random.default_rng(7)
    q = random_joint_values(robots["smr_1"], 80, rng)
    real = q + np.radians([0.05, -0.03, 0.04])
    joints = ",".join(f"{j}_deg" for j in robots["smr_1"].joint_names)
    blocks = {f: _positions(r, real, f) * 1e3 + 0.005 * rng.standard_normal((80, 3)) for f, r in robots.items()}
    multi = [joints + "," + ",".join(f"{f}.{a}_mm" for f in blocks for a in "xyz")]
    single = [joints + ",x_mm,y_mm,z_mm"]
    for i in range(80):
        angles = ",".join(f"{v:.10g}" for v in np.degrees(q[i]))
        multi.append(angles + "," + ",".join(f"{v:.10g}" for f in blocks for v in blocks[f][i]))
        single.append(angles + "," + ",".join(f"{v:.10g}" for v in blocks["smr_1"][i]))
    for name, lines in (("multi", multi), ("single", single)):
        (tmp_path / f"{name}_train.csv").write_text("\n".join(lines[:61]) + "\n")
        (tmp_path / f"{name}_query.csv").write_text("\n".join([lines[0]] + lines[61:]) + "\n")
    scores = {}
    for name in ("multi", "single"):
        out = tmp_path / f"{name}.json"
        assert main(["predict", "--train", str(tmp_path / f"{name}_train.csv"), "--query",
                     str(tmp_path / f"{name}_query.csv"), "--robot", str(urdf), "--tool", "smr_1",
                     "--method", "calibration", "--quiet", "--json", str(out)]) == 0
        scores[name] = json.loads(out.read_text())
        assert main(["compensate", "--train", str(tmp_path / f"{name}_train.csv"), "--targets",
                     str(tmp_path / f"{name}_query.csv"), "--robot", str(urdf), "--tool", "smr_1",
                     "--method", "calibration", "--quiet", "--json", str(tmp_path / f"{name}_c.json")]) == 0
    assert scores["multi"]["predicted_errors_mm"] == scores["single"]["predicted_errors_mm"]
    assert scores["multi"]["heldout"] == scores["single"]["heldout"]
    # without --tool the three reflectors are one too many
    assert main(["predict", "--train", str(tmp_path / "multi_train.csv"), "--query",
                 str(tmp_path / "multi_query.csv"), "--robot", str(urdf), "--quiet"]) == 2
    assert "--tool" in capsys.readouterr().err


DRIFT_ARM = """<?xml version="1.0"?>
<robot name="drift_arm">
  <link name="base"/>
  <link name="l1"><inertial><origin xyz="0 0 0.1"/><mass value="8"/>
    <inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="l2"><inertial><origin xyz="0.3 0 0"/><mass value="6"/>
    <inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="l3"/><link name="tool"/><link name="base_ref"/>
  <joint name="a" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0 0.3"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="b" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0 0 0.2"/>
    <axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="c" type="revolute"><parent link="l2"/><child link="l3"/><origin xyz="0.6 0 0"/>
    <axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="t" type="fixed"><parent link="l3"/><child link="tool"/><origin xyz="0.45 0.03 0.02"/></joint>
  <joint name="r" type="fixed"><parent link="base"/><child link="base_ref"/><origin xyz="0.4 -0.3 0.02"/></joint>
</robot>
"""


def _drift_files(tmp_path):
    """A session of 300 poses over 4 hours whose tracker drifts 0.05 mm/h, the tool and a base
    reference measured on every row; the same file without the reference."""
    urdf = tmp_path / "drift_arm.urdf"
    urdf.write_text(DRIFT_ARM)
    robot = load_robot(str(urdf), "tool")
    rng = np.random.default_rng(3)
    n = 300
    q = random_joint_values(robot, n, rng)
    time_s = np.sort(rng.uniform(0.0, 4 * 3600.0, n))
    drift = np.outer(time_s / 3600.0, np.array([0.6, -0.64, 0.48]) * 0.05e-3 / 0.989)  # 0.05 mm/h
    real = q + np.radians([0.04, -0.03, 0.05])
    station = pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, 0.8), np.array([1.5, -0.7, 0.2]))
    model = robot.full_model
    data = model.createData()
    tool, ref = model.getFrameId("tool"), model.getFrameId("base_ref")
    tool_pos, ref_pos = np.empty((n, 3)), np.empty((n, 3))
    for i in range(n):
        pin.framesForwardKinematics(model, data, robot.full_configurations(real[i][None])[0])
        tool_pos[i] = station.act(data.oMf[tool].translation) + drift[i]
        ref_pos[i] = station.act(data.oMf[ref].translation) + drift[i]
    tool_pos += NOISE * rng.standard_normal((n, 3))
    ref_pos += NOISE * rng.standard_normal((n, 3))
    joints = ",".join(f"{j}_deg" for j in robot.joint_names)
    with_ref = [joints + ",tool.x_mm,tool.y_mm,tool.z_mm,base_ref.x_mm,base_ref.y_mm,base_ref.z_mm,time_s"]
    without = [joints + ",x_mm,y_mm,z_mm,time_s"]
    for i in range(n):
        angles = ",".join(f"{v:.10g}" for v in np.degrees(q[i]))
        a, b = (",".join(f"{v:.10g}" for v in p[i] * 1e3) for p in (tool_pos, ref_pos))
        with_ref.append(f"{angles},{a},{b},{time_s[i]:.3f}")
        without.append(f"{angles},{a},{time_s[i]:.3f}")
    (tmp_path / "with_ref.csv").write_text("\n".join(with_ref) + "\n")
    (tmp_path / "without.csv").write_text("\n".join(without) + "\n")
    return urdf


@pytest.mark.slow
def test_a_base_reference_shows_the_tracker_drift(tmp_path):
    urdf = _drift_files(tmp_path)
    results = {}
    for name in ("with_ref", "without"):
        out = tmp_path / f"{name}.json"
        assert main(["diagnose", str(tmp_path / f"{name}.csv"), "--robot", str(urdf), "--tool", "tool",
                     "--noise-mm", "0.02", "--quiet", "--json", str(out)]) == 0
        results[name] = json.loads(out.read_text())
    drift = results["with_ref"]["drift"][0]
    assert drift["corrected"] and drift["time_axis"] == "time_s"
    assert float(np.linalg.norm(drift["drift_mm_per_h"])) == pytest.approx(0.05, rel=0.2)
    assert results["with_ref"]["final_over_noise"] < 1.15
    assert not results["without"]["drift"]
    # without the reference, the drift effect takes it: the base moving in time, 0.2 mm by the end
    assert "drift" in results["without"]["selected_effects"]
    fitted = results["without"]["parameters"]["drift"]
    moved = np.linalg.norm([sum(fitted.get(f"drift.base.{a}.{shape}", 0.0) for shape in ("linear", "warmup"))
                            for a in ("dx", "dy", "dz")])
    assert moved == pytest.approx(0.2e-3, rel=0.25)
    assert results["without"]["final_over_noise"] < 1.15


def _references(rng, n=200, sigma=0.02e-3, velocity=(0.03e-3, -0.04e-3, 0.0), hours=4.0):
    """One base reference read n times over ``hours``, drifting at ``velocity`` [m/h], noise sigma [m] per axis."""
    time_s = np.sort(rng.uniform(0.0, hours * 3600.0, n))
    measured = np.array([1.2, -0.4, 0.3]) + np.outer(time_s / 3600.0, velocity) + sigma * rng.standard_normal((n, 3))
    return time_s, measured


def test_29_09_one_base_reference_reading_off_does_not_make_the_instrument_noisy():
    """A reading 5 mm off among 200 of 0.02 mm noise: plain least squares would say 0.2 mm per axis
    (sqrt(25 mm^2 / 600 dof)); it is left out, listed, and the noise stays the simulated one."""
    from tcr_accuracy.frames.drift import tracker_drift

    rng = np.random.default_rng(11)
    time_s, measured = _references(rng)
    measured[57] += np.array([5e-3, 0.0, 0.0])
    plain = np.sqrt((np.sum((measured - measured.mean(axis=0)) ** 2)) / (3 * 199))  # what the outlier alone does
    assert plain > 0.1e-3
    _, report, noise = tracker_drift([("base_ref", np.zeros(3), measured, time_s)], np.zeros(200, dtype=int), 1, [])
    assert noise.per_axis == pytest.approx(0.02e-3, rel=0.15)
    assert [(o["row"], round(o["off_mm"])) for o in report[0]["outliers"]] == [(57, 5)]
    assert "1 reading(s) more than 6 robust standard deviations off left out" in noise.detail
    assert np.linalg.norm(report[0]["drift_mm_per_h"]) == pytest.approx(0.05, rel=0.2)


def test_29_09_a_constant_time_column_falls_back_to_the_measurement_order_and_says_so():
    from tcr_accuracy.frames.drift import tracker_drift

    rng = np.random.default_rng(12)
    _, measured = _references(rng, velocity=(0.0, 0.0, 0.0))
    same = np.full(200, 1700000000.0)
    _, report, noise = tracker_drift([("base_ref", np.zeros(3), measured, same)], np.zeros(200, dtype=int), 1, [])
    assert report[0]["time_axis"] == "measurement order (time_s is the same on every row)"
    assert "drift_mm_per_100_rows" in report[0] and noise.per_axis == pytest.approx(0.02e-3, rel=0.15)
    _, report, _ = tracker_drift([("base_ref", np.zeros(3), measured[:2], same[:2])], np.zeros(2, dtype=int), 1, [])
    assert report == [{"session": "all", "references": ["base_ref"], "time_axis":
                       "measurement order (time_s is the same on every row)", "fitted": False,
                       "why": "2 rows: a drift needs at least 3"}]
