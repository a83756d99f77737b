"""Reports readable at a glance: the printed summary as printed, no panels of pure noise,
3D views framed on their data with point sizes and magnifications that fit it."""

import numpy as np
import pytest

from tcr_accuracy.model.gravity import gravity_torque
from tcr_accuracy.view.plots_diagnose import joints_with_gravity_torque
from tcr_accuracy.view.report import Report
from tcr_accuracy.view.viewer import Scene, data_extent, point_size, segment_magnification

from conftest import random_joint_values

SUMMARY = ("4. How far it shrinks (k-fold held-out) [mm]\n"
           "   step               params  train RMS      mean\n"
           "   frames                  9     1.4700    1.3286\n"
           "   +compliance            13     0.3195    0.2969")


def test_printed_text_keeps_its_lines_and_alignment_in_html_and_markdown(tmp_path):
    report = Report("r", command="tcr-accuracy diagnose m.csv")
    report.add_preformatted(SUMMARY, heading="Full printed summary")
    report.add_text("a paragraph")
    page = report.html()
    # the aligned lines inside one <pre>, every space kept (a <p> would collapse them)
    assert f'<h2>Full printed summary</h2>\n<pre class="printed">{SUMMARY}</pre>' in page
    assert "<p>a paragraph</p>" in page
    assert f"## Full printed summary\n\n```\n{SUMMARY}\n```" in report.markdown()


def test_joints_without_gravity_torque_get_no_panel(tool_changer):
    # the tool-changer's j1 turns about the vertical: gravity puts no torque on it, whatever
    # the pose; Pinocchio returns rounding noise there (~1e-11 Nm) next to kNm on j2, j3
    q = random_joint_values(tool_changer, 50, np.random.default_rng(3))
    tau = gravity_torque(tool_changer, q, payload_kg=150.0)
    assert np.max(np.abs(tau[:, 0])) < 1e-6 < np.max(np.abs(tau[:, 1]))  # the premise
    kept = joints_with_gravity_torque(tau)
    assert 0 not in kept and {1, 2} <= set(kept.tolist())


def test_gravity_filter_is_relative_to_the_largest_joint():
    tau = np.array([[1e-9, 2.0, -0.5], [-1e-9, -3.0, 0.01]])
    assert joints_with_gravity_torque(tau).tolist() == [1, 2]
    assert joints_with_gravity_torque(tau * 1e-6).tolist() == [1, 2]  # units do not matter
    assert joints_with_gravity_torque(np.zeros((4, 3))).tolist() == []


def test_point_size_and_magnification_follow_the_data_extent():
    cube = np.array([[0, 0, 0], [2.1, 0.5, 1.0], [1.0, 1.4, 0.2]])
    assert data_extent(cube) == pytest.approx(2.1)
    assert point_size(2.1) == pytest.approx(0.03)           # 1/70 of 2.1 m
    assert point_size(0.01) == 0.003 and point_size(100.0) == 0.08
    # a 4.3 mm largest gap over 5 m of data: drawn at most 15 % of 5 m = 0.75 m -> x 100 (a round factor)
    assert segment_magnification(4.3e-3, 5.0) == 100.0
    assert segment_magnification(4.3e-3, 5.0) * 4.3e-3 <= 0.75


def test_a_data_view_frames_the_data_and_the_robot_not_far_frames_or_outliers(tool_changer):
    """frame="data": the data (a grid's outer layer whole) and the robot drawn among it, without a
    tracker triad 10 m away or one point 50 m out; frame="all": everything."""
    from conftest import pinocchio_kinematics

    axis = np.linspace(0.6, 1.4, 6)
    grid = np.array([[x, y, z] for x in axis for y in axis for z in np.linspace(0.2, 1.0, 6)])
    data = np.vstack([grid, [[50.0, 0.0, 0.0]]])
    data_, tcp = pinocchio_kinematics(tool_changer, tool_changer.working_pose)
    robot_points = np.array([data_.oMi[j].translation for j in range(tool_changer.model.njoints)] + [tcp.translation])
    far = np.eye(4)
    far[:3, 3] = [10.0, 10.0, 0.0]
    for frame in ("all", "data"):
        scene = Scene("t", frame=frame)
        scene.add_robot(tool_changer, tool_changer.working_pose)
        scene.add_points(data, "data")
        scene.add_frame(far, "tracker")
        lo, hi = scene.framed_bounds()
        inside = lambda p: np.all((p >= lo - 1e-9) & (p <= hi + 1e-9), axis=-1)  # noqa: E731
        assert inside(grid).all() and inside(robot_points).all()
        assert inside(far[:3, 3]) == (frame == "all") and inside(data[-1]) == (frame == "all")


def test_an_even_spread_of_points_keeps_the_one_asked_for_and_leaves_no_region_empty():
    from tcr_accuracy.view.view_scales import spread_subset

    axis = np.arange(10) * 0.05  # a 10 x 10 x 10 grid, 5 cm apart
    grid = np.array([[x, y, z] for x in axis for y in axis for z in axis])
    chosen = spread_subset(grid, 125, keep=[0, 999])
    assert len(chosen) <= 125 and {0, 999} <= set(chosen.tolist())
    assert len(np.unique(chosen)) == len(chosen)
    nearest = np.linalg.norm(grid[:, None] - grid[chosen][None], axis=2).min(axis=1)
    assert nearest.max() <= 2 * 0.05 * np.sqrt(3) + 1e-9  # every point within two grid diagonals of one drawn
    assert spread_subset(grid[:50], 125).tolist() == list(range(50))  # fewer than k: all of them


def test_the_view_redraws_the_monte_carlo_run_s_own_samples(tool_changer):
    """The error vectors drawn again for the view give the TCP errors the run recorded for its first
    samples (through the run's chunks and seeds), across chunk boundaries."""
    from tcr_accuracy.analysis.montecarlo import drawn_error_vectors, run_monte_carlo
    from tcr_accuracy.model.errors import seed_budget
    from conftest import pinocchio_kinematics

    budget = seed_budget(tool_changer, "table2")
    q = tool_changer.working_pose
    run = run_monte_carlo(budget, q, 900, 7, chunk=400)
    x = drawn_error_vectors(budget, 900, 7, chunk=400, count=850)
    assert x.shape == (850, budget.error_model.size)
    _, nominal = pinocchio_kinematics(tool_changer, q)
    for i in (0, 399, 400, 849):  # each sample's as-built robot through Pinocchio
        _, tcp = pinocchio_kinematics(budget.error_model.perturbed_robot(x[i]), q)
        np.testing.assert_allclose(tcp.translation - nominal.translation, run.cloud[i], atol=1e-9)
