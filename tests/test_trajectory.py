"""Trajectory files, the built-in tool-change motion, and Monte Carlo error bands."""

import json
import math

import numpy as np
import pinocchio as pin
import pytest
from scipy.stats import norm

from tcr_accuracy.cli import main
from tcr_accuracy.model.errors import ErrorBudget, seed_budget
from tcr_accuracy.exceptions import InputError
from tcr_accuracy.model.kinematics import tcp_poses_pinocchio
from tcr_accuracy.model.robot import JointLimitWarning
from tcr_accuracy.analysis.trajectory import (STOWED_POSE, JointTrajectory, quintic_time_scaling, read_trajectory_csv,
                                     tool_change_motion, trajectory_error_bands)

HEADER = "t_s,j1_deg,j2_deg,j3_rad,j4_mm,j5_deg,j6_deg"


def _write(tmp_path, text, name="traj.csv"):
    path = tmp_path / name
    path.write_text(text)
    return path


# ---------------------------------------------------------------------------------------
# Reading trajectories
# ---------------------------------------------------------------------------------------
def test_read_csv_converts_units_and_reorders_columns(tool_changer, tmp_path):
    path = _write(tmp_path, "j6_deg,j5_deg,j4_m,j3_rad,j2_deg,j1_deg,t_s\n"
                            "0,-20,0.0,-0.1,30,15,0\n"
                            "10,-10,0.25,0.2,20,5,0.5\n")
    traj = read_trajectory_csv(path, tool_changer)
    np.testing.assert_allclose(traj.time, [0.0, 0.5])
    np.testing.assert_allclose(traj.q[0], [math.radians(15), math.radians(30), -0.1, 0.0, math.radians(-20), 0.0])
    np.testing.assert_allclose(traj.q[1], [math.radians(5), math.radians(20), 0.2, 0.25, math.radians(-10),
                                           math.radians(10)])


def test_read_csv_without_time_uses_row_numbers(tool_changer, tmp_path):
    path = _write(tmp_path, "j1_deg,j2_deg,j3_deg,j4_mm,j5_deg,j6_deg\n" + "1,2,3,4,5,6\n" * 3)
    traj = read_trajectory_csv(path, tool_changer)
    np.testing.assert_allclose(traj.time, [0.0, 1.0, 2.0])
    np.testing.assert_allclose(traj.q[:, 3], 4e-3)


@pytest.mark.parametrize("text, needles", [
    (HEADER + "\n0,1,2,0.1,4,5\n", ["row 2", "6 values", "7 columns"]),
    (HEADER + "\n0,1,2,0.1,4,5,6\n1,1,abc,0.1,4,5,6\n", ["row 3", "'j2_deg'", "'abc'"]),
    (HEADER + "\n0,1,2,nan,4,5,6\n", ["row 2", "'j3_rad'", "finite"]),
    ("t_s,j1_deg,j2_deg,j3_deg,j4_deg,j5_deg,j6_deg\n0,1,2,3,4,5,6\n", ["row 1", "j4", "j4_deg", "wrong unit"]),
    ("t_s,j1_deg,j2_deg,j3_deg,j5_deg,j6_deg\n0,1,2,3,5,6\n", ["row 1", "no column for joint j4"]),
    (HEADER + ",speed_mps\n0,1,2,0.1,4,5,6,1\n", ["row 1", "column 8", "'speed_mps'"]),
    (HEADER + "\n0,1,2,0.1,4,5,6\n0,1,2,0.1,4,5,6\n", ["row 3", "t_s", "increase"]),
    (HEADER + "\n", ["no data rows"]),
    ("", ["empty"]),
])
def test_read_csv_errors_name_file_row_and_column(tool_changer, tmp_path, text, needles):
    path = _write(tmp_path, text)
    with pytest.raises(InputError) as exc:
        read_trajectory_csv(path, tool_changer)
    message = str(exc.value)
    assert str(path) in message and "\n" not in message
    for needle in needles:
        assert needle in message


def test_read_csv_warns_once_outside_limits(tool_changer, tmp_path):
    path = _write(tmp_path, HEADER + "\n0,1,100,0.1,4,5,6\n1,1,100,0.1,4,5,6\n")
    with pytest.warns(JointLimitWarning, match="row 2: joint j2 = 100 deg .*2 rows outside") as record:
        read_trajectory_csv(path, tool_changer)
    assert sum(issubclass(w.category, JointLimitWarning) for w in record) == 1  # once, not per row


def test_cli_bad_trajectory_file_one_line_exit_2(tmp_path, capsys):
    path = _write(tmp_path, HEADER + "\n0,1,2,0.1,4,5\n")
    assert main(["trajectory", "--file", str(path), "--samples", "10", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "row 2" in err and str(path) in err and "Traceback" not in err


# ---------------------------------------------------------------------------------------
# The built-in motion
# ---------------------------------------------------------------------------------------
def test_tool_change_motion_phases(tool_changer):
    traj = tool_change_motion(tool_changer, n_steps=121, approach_s=8.0, extend_s=4.0, extension=0.2)
    assert len(traj) == 121 and traj.time[-1] == pytest.approx(12.0)
    np.testing.assert_allclose(traj.q[0], STOWED_POSE)
    at_goal = np.searchsorted(traj.time, 8.0)
    np.testing.assert_allclose(traj.q[at_goal], tool_changer.working_pose, atol=1e-12)
    expected_end = tool_changer.working_pose.copy()
    expected_end[3] = 0.2
    np.testing.assert_allclose(traj.q[-1], expected_end, atol=1e-12)
    # quintic: half way at mid-time, and no jump in speed where the phases meet
    mid = np.searchsorted(traj.time, 4.0)
    np.testing.assert_allclose(traj.q[mid], 0.5 * (STOWED_POSE + tool_changer.working_pose), atol=1e-12)
    speed = np.diff(traj.q, axis=0) / np.diff(traj.time)[:, None]
    assert np.abs(speed[[0, at_goal - 1, at_goal, -1]]).max() < 0.01
    tau = np.linspace(0, 1, 11)
    np.testing.assert_allclose(quintic_time_scaling(tau), 10 * tau**3 - 15 * tau**4 + 6 * tau**5)


def test_tool_change_motion_needs_the_tool_changer(ur5):
    with pytest.raises(InputError, match="robot ur5 has other joints: give its trajectory$") as caught:
        tool_change_motion(ur5)
    assert (caught.value.parameter, caught.value.value) == ("robot", "ur5")  # the command line adds: with --file


# ---------------------------------------------------------------------------------------
# Error bands
# ---------------------------------------------------------------------------------------
def test_bands_equal_a_per_sample_pinocchio_loop(tool_changer):
    """Same draws (the function draws x = budget.sample(n, rng) first), recomputed with
    the plain per-sample Pinocchio loop at three time steps: identical statistics."""
    budget = seed_budget(tool_changer, "table2")
    traj = tool_change_motion(tool_changer, n_steps=9)
    n = 40
    bands = trajectory_error_bands(budget, traj, n, np.random.default_rng(5), chunk=100)
    x = budget.sample(n, np.random.default_rng(5))
    for t in (0, 4, 8):
        nominal = tcp_poses_pinocchio(tool_changer, traj.q[t]).position[0]
        err = tcp_poses_pinocchio(tool_changer, traj.q[t], x, budget.error_model).position - nominal
        np.testing.assert_allclose(bands.mean[t], err.mean(axis=0), atol=1e-12)
        np.testing.assert_allclose(bands.std[t], err.std(axis=0, ddof=1), atol=1e-12)
        np.testing.assert_allclose(bands.lower[t], np.quantile(err, 0.025, axis=0), atol=1e-12)
        np.testing.assert_allclose(bands.upper[t], np.quantile(err, 0.975, axis=0), atol=1e-12)
        np.testing.assert_allclose(bands.norm_upper[t], np.quantile(np.linalg.norm(err, axis=1), 0.975), atol=1e-12)


def test_bands_match_first_order_normal_theory(tool_changer):
    """Small drive errors: dP = J_q dq to first order (J_q from Pinocchio's frame
    Jacobian), so dx, dy, dz are normal with std sqrt(diag(J S J^T)) at every step and the
    97.5 % quantile sits 1.96 std above the mean."""
    table2 = seed_budget(tool_changer, "table2")
    drives = [s for s in table2.sources if s.group == "drive"]
    budget = ErrorBudget(table2.error_model, drives, "drives").scaled(0.01)
    traj = tool_change_motion(tool_changer, n_steps=13)
    n = 4000
    bands = trajectory_error_bands(budget, traj, n, np.random.default_rng(2))
    sigma = np.diag([s.std for s in budget.sources]) ** 2
    model, data = tool_changer.model, tool_changer.model.createData()
    for t in range(len(traj)):
        jac = pin.computeFrameJacobian(model, data, tool_changer.to_pinocchio_q(traj.q[t]),
                                       tool_changer.tool_frame_id, pin.LOCAL_WORLD_ALIGNED)[:3]
        std = np.sqrt(np.diag(jac @ sigma @ jac.T))
        np.testing.assert_allclose(bands.first_order_std[t], std, rtol=1e-9, atol=1e-15)
        # sampling error of a std from 4000 normal draws: 1.1 %; allow 4 sigma
        np.testing.assert_allclose(bands.std[t], std, rtol=0.045, atol=1e-9)
        np.testing.assert_allclose(bands.upper[t] - bands.mean[t], norm.ppf(0.975) * std, rtol=0.08, atol=1e-9)
        assert np.all(np.abs(bands.mean[t]) < 4 * std / math.sqrt(n) + 1e-12)


def test_cli_trajectory_from_file_json_and_plot(tool_changer, tmp_path):
    rows = [HEADER] + [f"{t},{15 + t},{30 - t},{-0.17},{10 * t},{-20},{0}" for t in range(5)]
    path = _write(tmp_path, "\n".join(rows) + "\n")
    out, plots = tmp_path / "bands.json", tmp_path / "plots"
    assert main(["trajectory", "--file", str(path), "--samples", "300", "--seed", "4", "--quiet",
                 "--json", str(out), "--plots", str(plots)]) == 0
    data = json.loads(out.read_text())
    assert data["time_s"] == [0, 1, 2, 3, 4]
    assert np.array(data["std_m"]).shape == (5, 3)
    lower, upper, mean = (np.array(data[k]) for k in ("lower_m", "upper_m", "mean_m"))
    assert np.all(lower < mean) and np.all(mean < upper)
    png = plots / "trajectory_error_bands.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not list(plots.glob(".*"))  # no temporary files left behind
    # the same trajectory and seed through the Python API give the same numbers
    traj = read_trajectory_csv(path, tool_changer)
    api = trajectory_error_bands(seed_budget(tool_changer, "table2"), traj, 300, np.random.default_rng(4))
    np.testing.assert_allclose(np.array(data["std_m"]), api.std, rtol=1e-12)


def test_bands_reject_too_few_samples(tool_changer):
    traj = JointTrajectory(np.array([0.0]), tool_changer.working_pose[None], "one pose")
    with pytest.raises(InputError, match="at least 2 samples"):
        trajectory_error_bands(seed_budget(tool_changer, "table2"), traj, 1, np.random.default_rng(0))


def test_source_contributions_closed_form_and_sum(tool_changer):
    """Joint 1 turns about the vertical base axis, so its drive error moves the TCP by
    (-p_y, p_x, 0) per radian: its std contribution is (|p_y|, |p_x|, 0) sigma_1. The
    independent contributions add up in quadrature to the first-order std."""
    budget = seed_budget(tool_changer, "table2")
    traj = tool_change_motion(tool_changer, n_steps=7)
    bands = trajectory_error_bands(budget, traj, 50, np.random.default_rng(0))
    k = bands.source_names.index("j1 drive")
    sigma = math.radians(0.3)
    p = bands.nominal_position
    np.testing.assert_allclose(bands.contributions[:, k, :],
                               np.column_stack([np.abs(p[:, 1]), np.abs(p[:, 0]), np.zeros(len(p))]) * sigma,
                               atol=1e-12)
    np.testing.assert_allclose(np.sqrt((bands.contributions**2).sum(axis=1)), bands.first_order_std, rtol=1e-12)
