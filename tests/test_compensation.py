"""Cyclic joint compensation on a simulated real robot, and the predict/compensate commands."""

import json

import numpy as np
import pytest

from tcr_accuracy.cli import main
from tcr_accuracy.prediction.compensation import compensate_joints
from tcr_accuracy.model.kinematics import tcp_poses
from tcr_accuracy.prediction.kriging import JointKriging
from tcr_accuracy.analysis.sampling import TaskWorkspace, sample_task_workspace
from conftest import run_command as run
from conftest import write_measurement_csv as _write
from hidden_robot import draw_tracked_robot

UR5_REF = np.array([0.3, -1.2, 1.5, -1.9, -1.57, 0.4])
TC_REF = np.array([np.radians(15), np.radians(30), np.radians(-10), 0.2, np.radians(20), 0.0])


class Oracle:
    """Predicts the hidden truth exactly: isolates the cyclic search from prediction error."""

    def __init__(self, real):
        self.real = real

    def predict(self, q):
        return self.real.true_errors(q)


class Constant:
    def __init__(self, error):
        self.error = np.asarray(error, dtype=float)

    def predict(self, q):
        return np.tile(self.error, (len(q), 1))


def test_compliance_gives_way_to_the_payloads_weight_in_the_effects_and_the_hidden_robot(tool_changer):
    """A point mass at the TCP adds J^T (0, 0, -m g) to the torque gravity exerts on the joints
    (Pinocchio's frame Jacobian, not the gravity code). The effect library's compliance turns each
    joint by its compliance times that; the tests' hidden robot (tests/hidden_robot.py, Pinocchio's
    generalized gravity) does the same: one sign of the physics for the diagnosis and the tests."""
    import pinocchio as pin

    from tcr_accuracy.effects.compliance import Compliance
    from tcr_accuracy.model.context import MeasurementContext

    q = TC_REF + np.array([0.2, -0.1, 0.3, 0.1, -0.4, 0.5])
    model, data = tool_changer.model, tool_changer.model.createData()
    pin.computeJointJacobians(model, data, tool_changer.to_pinocchio_q(q))
    pin.updateFramePlacements(model, data)
    jac = pin.getFrameJacobian(model, data, tool_changer.tool_frame_id, pin.LOCAL_WORLD_ALIGNED)[:3]
    weight = jac.T @ np.array([0.0, 0.0, -150.0 * 9.81])
    assert np.abs(weight).max() > 1000.0  # N m: the cutter loads the shoulder
    effect = Compliance(tool_changer)
    context = {m: MeasurementContext.defaults(1, 6, payload_kg=m) for m in (0.0, 150.0)}
    extra = (effect.signal(q[None], context[150.0]) - effect.signal(q[None], context[0.0]))[0]
    np.testing.assert_allclose(extra, weight, rtol=1e-9, atol=1e-9)
    loaded = draw_tracked_robot(tool_changer, np.random.default_rng(11), payload_kg=150.0, noise_m=0.0)
    moved = (loaded.joint_deflection(q) - loaded.with_payload(0.0).joint_deflection(q))[0]
    # the hidden robot's placement errors move the Jacobian by a fraction of a thousandth; they
    # also tilt the first (vertical) axis, which the nominal weight does not turn
    assert weight[0] == pytest.approx(0.0, abs=1e-9)
    np.testing.assert_allclose(moved[1:], loaded.compliance[1:] * weight[1:], rtol=3e-3, atol=1e-12)
    assert np.abs(moved).max() > 1e-4  # rad: a deflection the tests see


@pytest.mark.parametrize("robot_name", ["ur5", "tool_changer"])
def test_compensation_with_the_true_error_lands_on_target(robot_name, ur5, tool_changer):
    robot, q_ref, payload = (ur5, UR5_REF, 5.0) if robot_name == "ur5" else (tool_changer, TC_REF, 150.0)
    real = draw_tracked_robot(robot, np.random.default_rng(11), payload_kg=payload, noise_m=0.0)
    q_target = q_ref + np.random.default_rng(12).uniform(-0.1, 0.1, (15, robot.n_joints))
    target = tcp_poses(robot, q_target).position
    before = np.linalg.norm(real.true_positions(q_target) - target, axis=1)
    result = compensate_joints(robot, Oracle(real), q_target, threshold=1e-8)
    after = np.linalg.norm(real.true_positions(result.q) - target, axis=1)
    assert before.mean() > 1e-3  # millimetres before
    assert result.converged.all()
    assert after.max() < 2e-8  # the threshold, checked on the hidden truth
    # the orientation is kept as the robot allows: only small joint corrections were needed
    assert np.abs(result.q - q_target).max() < 0.05


def test_compensation_with_kriging_cuts_the_measured_error_to_near_the_noise(ur5):
    rng = np.random.default_rng(13)
    real = draw_tracked_robot(ur5, rng, payload_kg=5.0, noise_m=2e-5)
    ws = TaskWorkspace.around(ur5, UR5_REF, [0.12, 0.12, 0.08], np.radians(12))
    train = sample_task_workspace(ur5, ws, 120, rng, n_dense=600, q_init=UR5_REF)
    e_train = real.measure(train.q) - tcp_poses(ur5, train.q).position
    model = JointKriging(weight_search="particle_filter", n_particles=16, max_iter=8, random_state=0)
    model.fit(train.q, e_train)
    q_test = train.dense_q[rng.choice(len(train.dense_q), 30, replace=False)]
    target = tcp_poses(ur5, q_test).position
    result = compensate_joints(ur5, model, q_test)
    before = np.linalg.norm(real.measure(q_test) - target, axis=1).mean()
    after = np.linalg.norm(real.measure(result.q) - target, axis=1).mean()
    assert result.converged.all()
    assert before > 1e-3
    # measurement noise alone gives a mean |noise| of 0.032 mm; the goal is < 2 x 0.02 mm per axis
    assert after < 6e-5
    # what is left is the noise: within 1.5 x its own mean length, sqrt(8 / pi) x 0.02 mm
    assert after < 1.5 * np.sqrt(8 / np.pi) * 2e-5


def test_targets_out_of_reach_are_flagged_not_hidden(ur5):
    q_target = UR5_REF + np.zeros((2, 6))
    result = compensate_joints(ur5, Constant([3.0, 0.0, 0.0]), q_target, max_iter=5)  # 3 m "error"
    assert not result.converged.any()
    assert np.all(np.isfinite(result.q)) and np.all(result.predicted_miss > 1.0)


# ---------------------------------------------------------------------------------------
# command line
# ---------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def measured(tool_changer, tmp_path_factory):
    d = tmp_path_factory.mktemp("measured")
    real = draw_tracked_robot(tool_changer, np.random.default_rng(14), noise_m=2e-5)
    rng = np.random.default_rng(15)
    q_train = TC_REF + rng.uniform(-0.08, 0.08, (60, 6))
    q_query = TC_REF + rng.uniform(-0.06, 0.06, (8, 6))
    return {
        "real": real, "q_query": q_query, "dir": d,
        "train": _write(d / "train.csv", tool_changer, q_train, real.measure(q_train)),
        "query": _write(d / "query.csv", tool_changer, q_query),
    }


def test_cli_predict_writes_predictions_close_to_the_hidden_error(measured, tool_changer, capsys):
    """The hidden robot is measured in its base frame (--frame base): its hidden error is the truth."""
    out_csv = measured["dir"] / "pred.csv"
    code, out, err = run(["predict", "--train", measured["train"], "--query", measured["query"], "--frame", "base",
                          "--method", "kriging", "--csv", str(out_csv), "--json", str(measured["dir"] / "p.json")],
                         capsys)
    assert code == 0, err
    rows = np.loadtxt(out_csv, delimiter=",", skiprows=1)
    header = out_csv.read_text().splitlines()[0].split(",")
    assert header[6:] == ["ex_mm", "ey_mm", "ez_mm", "e_norm_mm", "ex_std_mm", "ey_std_mm", "ez_std_mm"]
    np.testing.assert_allclose(rows[:, :6] / tool_changer.display_scale, measured["q_query"], atol=1e-8)
    truth = measured["real"].true_errors(measured["q_query"]) * 1e3
    assert np.abs(rows[:, 6:9] - truth).max() < 0.1 * np.abs(truth).max()
    payload = json.loads((measured["dir"] / "p.json").read_text())
    assert payload["n_train"] == 60 and payload["method"] == "kriging"


def test_cli_compensate_writes_joints_that_reach_the_targets(measured, tool_changer, capsys):
    """The measured point (nominal TCP + the fitted TCP offset, a reflector's place) goes to where
    the model puts it at the target joints: the robot's error is corrected, the offset is not."""
    out_csv, out_json = measured["dir"] / "comp.csv", measured["dir"] / "comp.json"
    code, out, err = run(["compensate", "--train", measured["train"], "--targets", measured["query"],
                          "--frame", "base", "--method", "kriging", "--csv", str(out_csv), "--json", str(out_json)],
                         capsys)
    assert code == 0, err
    offset = np.array(json.loads(out_json.read_text())["tracker_frame"]["tool_offset_mm"]) * 1e-3
    q_comp = np.loadtxt(out_csv, delimiter=",", skiprows=1)[:, :6] / tool_changer.display_scale
    # the target by hand: the TCP's rotation times the offset, added to the nominal TCP
    pose = tcp_poses(tool_changer, measured["q_query"])
    target = pose.position + pose.rotation @ offset
    before = np.linalg.norm(measured["real"].true_positions(measured["q_query"]) - target, axis=1)
    after = np.linalg.norm(measured["real"].true_positions(q_comp) - target, axis=1)
    assert before.mean() > 2e-4 and after.mean() < before.mean() / 5
    # kriging on 60 poses with 0.02 mm noise per axis: measured 0.039 mm on this draw (the noise's
    # own mean length is 0.032 mm)
    assert after.mean() < 2.5 * 2e-5
    # corrections of the size of the robot's errors, not of the offset (a few mm here)
    assert np.linalg.norm(offset) > 1e-3
    assert np.abs(q_comp - measured["q_query"]).max() < 5e-3


def test_cli_bad_inputs_are_one_line_exit_2_and_write_nothing(measured, tool_changer, capsys):
    d = measured["dir"]
    rng = np.random.default_rng(16)
    q = TC_REF + rng.uniform(-0.05, 0.05, (6, 6))
    few = _write(d / "few.csv", tool_changer, q, tcp_poses(tool_changer, q).position)
    q_dup = TC_REF + rng.uniform(-0.05, 0.05, (12, 6))
    q_dup[9] = q_dup[3]  # the same pose measured twice: two different tracker readings
    p_dup = tcp_poses(tool_changer, q_dup).position + rng.normal(0, 2e-5, (12, 3))
    dup = _write(d / "dup.csv", tool_changer, q_dup, p_dup)
    bad = d / "bad.csv"
    text = (d / "train.csv").read_text().splitlines()
    text[4] = text[4].replace(text[4].split(",")[2], "abc", 1)
    bad.write_text("\n".join(text) + "\n")
    cases = [
        (["predict", "--train", few, "--query", measured["query"]], "6 training poses for 6 joints"),
        (["predict", "--train", dup, "--query", measured["query"]], "rows 5 and 11 have the same joint values"),
        (["predict", "--train", str(bad), "--query", measured["query"]], "row 5, column j3_deg: 'abc' is not a number"),
        (["predict", "--train", measured["query"], "--query", measured["query"]], "missing position columns"),
    ]
    for argv, message in cases:
        out_csv, report = d / "never.csv", d / "never_report"
        code, out, err = run(argv + ["--csv", str(out_csv), "--out", str(report)], capsys)
        assert code == 2, (argv, err)
        last = err.splitlines()[-1]  # a repeated pose also warns first, on its own line
        assert message in last and last.startswith("tcr-accuracy predict: error:"), err
        assert not out_csv.exists() and not report.exists()
    # a target the compensation cannot reach: j4 at the end of its stroke and the arm stretched
    # straight, while the hidden error of this robot asks for a longer reach
    far = TC_REF.copy()
    far[1], far[2], far[3], far[4] = 0.0, 0.0, 0.6, 0.0
    targets = _write(d / "far.csv", tool_changer, np.vstack([TC_REF, far]))
    out_csv, out_json = d / "partial.csv", d / "partial.json"
    code, out, err = run(["compensate", "--train", measured["train"], "--targets", targets, "--method", "kriging",
                          "--csv", str(out_csv), "--json", str(out_json)], capsys)
    # the other target is still solved and written; the far one is listed with its reason
    assert code == 0, err
    warning = [line for line in err.splitlines() if "warning" in line]
    assert len(warning) == 1 and "1 of 2 targets not solved (rows 3;" in warning[0]
    unsolved = json.loads(out_json.read_text())["unsolved"]
    assert [u["row"] for u in unsolved] == [3] and unsolved[0]["reason"] in ("outside limits", "singular")
    written = np.loadtxt(out_csv, delimiter=",", skiprows=1, ndmin=2)
    assert written.shape[0] == 1 and written[0, -1] == 2  # target_row: the file's row 2
    # nothing solvable: one line, exit 2, nothing written
    targets = _write(d / "far_only.csv", tool_changer, far[None])
    code, out, err = run(["compensate", "--train", measured["train"], "--targets", targets, "--method", "kriging",
                          "--csv", str(d / "never.csv")], capsys)
    assert code == 2 and "none of the 1 targets can be compensated (row 2:" in err.splitlines()[-1]
    assert not (d / "never.csv").exists()


# ---------------------------------------------------------------------------------------
# report, view, plots (the shared output options of cli_output)
# ---------------------------------------------------------------------------------------
def _report_tables(index):
    from test_cli_outputs import _tables

    return _tables(index)


def test_cli_predict_report_view_and_csv_agree_with_the_json(measured, tool_changer, capsys):
    d = measured["dir"] / "predict_outputs"
    d.mkdir()
    code, out, err = run(["predict", "--train", measured["train"], "--query", measured["query"], "--method", "kriging",
                          "--frame", "base", "--csv", str(d / "p.csv"), "--json", str(d / "p.json"),
                          "--out", str(d / "report"), "--view", str(d / "view.html")], capsys)
    assert code == 0, err
    data = json.loads((d / "p.json").read_text())
    csv = np.loadtxt(d / "p.csv", delimiter=",", skiprows=1)
    np.testing.assert_allclose(csv[:, 6:9], data["predicted_errors_mm"], rtol=1e-8, atol=1e-12)
    pred = np.array(data["predicted_robot_errors_mm"])  # the report's error: beyond the fitted TCP offset
    tables = _report_tables(d / "report" / "index.html")
    stats = {r[0]: [float(v) for v in r[1:]] for r in tables["Predicted error at the query poses"][1:]}
    norm = np.linalg.norm(pred, axis=1)
    assert stats["mean"][0] == pytest.approx(data["predicted_error_mean_mm"], rel=1e-3)
    assert stats["max"][0] == pytest.approx(norm.max(), rel=1e-3)
    assert stats["max"][3] == pytest.approx(np.abs(pred[:, 2]).max(), rel=1e-3)
    per_pose = tables["Predicted error per query pose"]
    assert len(per_pose) == 1 + 8 and per_pose[0][-2:] == ["|e| [mm]", "std x / y / z [mm]"]
    std = np.array(data["predicted_std_mm"])
    np.testing.assert_allclose(csv[:, 10:13], std, rtol=1e-8, atol=1e-12)
    for row, p, s in zip(per_pose[1:], pred, std):
        assert [float(v) for v in row[7:10]] == pytest.approx(p, rel=1e-3, abs=1e-6)
        assert [float(v) for v in row[-1].split(" / ")] == pytest.approx(s, rel=1e-3, abs=1e-6)
    assert data["uncertainty"] == "kriging standard deviation" and data["heldout"] is None
    predictor = dict(tables["Predictor"][1:])
    assert predictor["method"] == "kriging" and predictor["training poses"] == "60"
    page = (d / "report" / "index.html").read_text(encoding="utf-8")
    assert page.count('<img src="figure-') == 1 and 'iframe src="scene-1.html"' in page
    view = (d / "view.html").read_text(encoding="utf-8")
    assert "predicted TCP error |e| [mm]" in view and "segments magnified x " in view
    assert "<script>" in view and "127.0.0.1" not in view  # self-contained, no server
    assert "report written to" in err and "predictions written to" in err


def test_cli_compensate_report_shows_before_and_after_of_the_json(measured, tool_changer, capsys):
    d = measured["dir"] / "compensate_outputs"
    code, out, err = run(["compensate", "--train", measured["train"], "--targets", measured["query"], "--frame", "base",
                          "--method", "kriging", "--json", str(d.with_suffix(".json")), "--out", str(d),
                          "--plots", str(d.with_name("comp_plots")), "--quiet"], capsys)
    assert code == 0 and err == ""
    data = json.loads(d.with_suffix(".json").read_text())
    tables = _report_tables(d / "index.html")
    rows = {r[0]: [float(v) for v in r[1:]]
            for r in tables["Predicted error at the targets, before and after compensation"][1:]}
    assert rows["uncompensated (target joints)"] == pytest.approx(
        [data["predicted_error_before_mean_mm"], data["predicted_error_before_max_mm"]], rel=1e-3)
    assert rows["compensated: the model's own miss"] == pytest.approx([data["predicted_miss_mean_mm"], data["predicted_miss_max_mm"]],
                                                rel=1e-3)
    # independent check of "before": the uncompensated command's predicted error is the hidden
    # error of the real robot beyond the measured point (nominal TCP + the fitted TCP offset), to
    # the accuracy of the kriging fit
    pose = tcp_poses(tool_changer, measured["q_query"])
    point = pose.position + pose.rotation @ (np.array(data["tracker_frame"]["tool_offset_mm"]) * 1e-3)
    truth = np.linalg.norm(measured["real"].true_positions(measured["q_query"]) - point, axis=1) * 1e3
    assert data["predicted_error_before_mean_mm"] == pytest.approx(truth.mean(), rel=0.1)
    assert data["predicted_miss_max_mm"] < 0.001 <= data["predicted_error_before_max_mm"]
    cycles = {int(r[0]): int(r[1]) for r in tables["Convergence"][1:]}
    assert cycles == {int(k): v for k, v in data["cycles_targets"].items()} and sum(cycles.values()) == 8
    assert data["n_converged"] == 8
    assert (d.with_name("comp_plots") / "compensation.png").read_bytes().startswith(b"\x89PNG")
    scene = (d / "scene-1.html").read_text(encoding="utf-8")
    assert "predicted real TCP, uncompensated command" in scene and "compensated command" in scene
    assert scene.count("target TCP") == 1


@pytest.mark.parametrize("command, function", [("predict", "plot_predicted_errors"),
                                               ("compensate", "plot_compensation")])
def test_cli_a_failure_mid_run_leaves_no_csv_report_json_or_view(command, function, measured, tmp_path,
                                                                  monkeypatch, capsys):
    from tcr_accuracy.view import plots_prediction

    def boom(*args, **kwargs):
        raise RuntimeError("plot failed")

    monkeypatch.setattr(plots_prediction, function, boom)
    source = "--query" if command == "predict" else "--targets"
    code = main([command, "--train", measured["train"], source, measured["query"], "--method", "idw-joint", "--quiet",
                 "--csv", str(tmp_path / "o.csv"), "--out", str(tmp_path / "report"), "--json", str(tmp_path / "o.json"),
                 "--view", str(tmp_path / "view.html")])
    assert code == 1 and "RuntimeError: plot failed" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.rglob("*")) == []


@pytest.mark.parametrize("extra, message", [
    (["--csv", "/nonexistent-folder/p.csv"], "--csv /nonexistent-folder/p.csv: the folder /nonexistent-folder"),
    (["--open"], "--open needs --serve"),
])
def test_cli_bad_output_options_are_one_line_exit_2(extra, message, measured, capsys):
    code, out, err = run(["predict", "--train", measured["train"], "--query", measured["query"], *extra], capsys)
    assert code == 2 and message in err and err.count("\n") == 1
