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


def test_a_data_view_frames_the_data_not_the_robot(tool_changer):
    points = np.array([[1.0, 1.0, 0.5], [1.2, 1.1, 0.6], [1.1, 0.9, 0.7]])
    for frame in ("all", "data"):
        scene = Scene("t", frame=frame)
        scene.add_robot(tool_changer, tool_changer.working_pose)
        scene.add_points(points, "data")
        target, camera = scene._view_target()
        centre = 0.5 * (points.min(axis=0) + points.max(axis=0))
        if frame == "data":
            assert target == pytest.approx(centre)
            # the camera stands off by about the data's size, not the robot's
            assert np.linalg.norm(camera - target) < 1.0
        else:
            assert np.linalg.norm(target - centre) > 0.2
            assert np.linalg.norm(camera - target) > 2.0
