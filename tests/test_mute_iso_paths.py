"""The ISO 9283 test paths' refusals and the cube search's rank (``iso9283/path_plan.py``,
``plan.py``) against what is written out here: the first sample of a hand-made path outside a cell
box, named by its arc length and position in mm; the generic rank of Jacobian spectra written by
hand. Each test names a planted change it was seen to catch (issue 36)."""

import numpy as np
import pytest

from tcr_accuracy import load_robot
from tcr_accuracy.exceptions import InputError
from tcr_accuracy.iso9283.path_plan import TestPath, arc_length, solve_path
from tcr_accuracy.iso9283.plan import _generic_rank
from tcr_accuracy.iso9283.reach import Reach, Workspace
from tcr_accuracy.model.kinematics import tcp_poses

Q_START = np.array([0.0, -1.2, 1.5, -1.9, -1.57, 0.0])


def test_a_path_leaving_the_box_is_refused_at_its_first_sample_outside_in_mm():
    """Eleven samples 4 mm apart along +x from the TCP of a UR5 start pose (rounded to the mm), the box's +x
    wall 21.5 mm out: samples 0..5 inside, sample 6 (24 mm along the path) the first outside, named by its
    arc length and its position in mm. Seen failing on ``path.s[k] * 1e3`` turned to ``- 1e3`` and the
    position's ``v * 1e3`` changed."""
    ur5 = load_robot("ur5")
    pose = tcp_poses(ur5, Q_START[None])
    start = np.round(pose.position[0], 3)
    points = start + np.outer(np.arange(11) * 0.004, [1.0, 0.0, 0.0])
    path = TestPath("line", points, arc_length(points))
    box = Workspace(box=[start - 1.0, start + [0.0215, 1.0, 1.0]])
    reach = Reach(ur5, None, box, Q_START, "exact")
    with pytest.raises(InputError) as refused:
        solve_path(reach, path, pose.rotation[0], Q_START)
    at = ", ".join(f"{v:.1f}" for v in (points[6] * 1000.0))
    assert str(refused.value) == (f"ur5: the line test path at 24.0 mm from its start ({at} mm): outside the "
                                  "workspace; plan a smaller cube")


def test_the_generic_rank_counts_singular_values_above_a_millionth_of_the_largest():
    """Spectra (rows, largest first) written out: [1000, 10, 2e-3] has two above 1e-6 x 1000 = 1e-3, [1, 0.5,
    2e-6] three (2e-6 > 1e-6), [1, 0.5, 5e-7] two; the rank is the largest count over the rows. Seen failing
    on ``1e-6 * spectra[:, :1]`` turned to ``1e-6 / spectra[:, :1]``, the 1e-6 turned to 1.000001 and
    ``spectra[:, :1]`` to ``spectra[:, :2]``."""
    assert _generic_rank(np.array([[1000.0, 10.0, 2e-3], [1.0, 0.5, 5e-7]])) == 3
    assert _generic_rank(np.array([[1000.0, 10.0, 5e-4], [1.0, 0.5, 5e-7]])) == 2
    assert _generic_rank(np.array([[1000.0, 10.0, 5e-4], [1.0, 0.5, 2e-6]])) == 3
    assert _generic_rank(np.array([[1.0, 0.5, 5e-7]])) == 2
    assert _generic_rank(np.array([[4.0, 2e-6, 1e-9]])) == 1


def test_the_floor_holds_the_joint_origins_below_the_mounting_plane_or_a_lower_floor():
    """A UR5 without collision geometry, its forearm folded down (q = 0, -0.3, 2.4, 0, 0, 0): Pinocchio puts
    the wrist_1 and wrist_2 origins at z = -124 mm and wrist_3's at -76 mm. A floor 100 mm above the
    mounting plane holds the arm to the mounting plane (z = 0: all three below); a floor at -100 mm (a
    pedestal) to itself (wrist_1 and wrist_2 below); at -300 mm none; the words give the plane in mm.
    Seen failing on ``min(self.floor, 0.0)`` turned to ``min(self.floor, 1.0)`` or ``-1.0`` and the
    words' ``lowest * 1e3`` changed."""
    import pinocchio as pin

    ur5 = load_robot("ur5")
    q = np.array([0.0, -0.3, 2.4, 0.0, 0.0, 0.0])
    data = ur5.model.createData()
    pin.forwardKinematics(ur5.model, data, q)
    z = {ur5.model.names[j]: data.oMi[j].translation[2] for j in range(1, ur5.model.njoints)}
    for floor, plane in ((0.1, 0.0), (-0.1, -0.1), (-0.3, -0.3)):
        workspace = Workspace(floor=floor)
        assert workspace.lowest == plane
        reach = Reach(ur5, None, workspace, np.zeros(6), "exact")
        assert reach.below(q) == [name for name in ur5.joint_names if z[name] < plane]
        assert reach.floor_words() == f"the robot's joint origins above z = {plane * 1e3:g} mm (not held: none)"
    assert len(Reach(ur5, None, Workspace(floor=-0.1), np.zeros(6), "exact").below(q)) == 2


def test_a_path_whose_first_sample_is_out_of_reach_is_refused_at_its_start():
    """A planned UR5 cube moved to a centre 2 m out (beyond its 0.85 m reach): the line's first sample, P2 of
    that cube, is refused at 0.0 mm from its start with its position in mm. Seen failing on the refusal's
    sample ``0`` turned to ``1``."""
    import dataclasses

    from tcr_accuracy.iso9283.path_plan import plan_test_paths
    from tcr_accuracy.iso9283.plan import iso_points, plan_iso_cube

    ur5 = load_robot("ur5")
    rotation = tcp_poses(ur5, Q_START[None]).rotation[0]
    cube = plan_iso_cube(ur5, 0, centre=[0.6, 0.1, 0.3], size=0.1, home=Q_START, tool_rotation=rotation)
    far = dataclasses.replace(cube, centre=np.array([2.0, 0.0, 0.5]))
    reach = Reach(ur5, None, Workspace(), Q_START, "exact")
    with pytest.raises(InputError) as refused:
        plan_test_paths(reach, far)
    p2 = iso_points(far.centre, far.size)[1] * 1000.0
    assert str(refused.value) == (f"ur5: the line test path at 0.0 mm from its start ({p2[0]:.1f}, {p2[1]:.1f}, "
                                  f"{p2[2]:.1f} mm): not reachable at the test's orientation; plan a smaller cube")


def test_a_path_test_runs_on_100_normal_planes_unless_told_in_the_api_as_in_the_command():
    """The API's default number of normal planes, in the figures and the evaluation, is the command's: 100.
    Seen failing on ``planes: int = 100`` turned to 101 in ``evaluate_path_test``."""
    import inspect

    from tcr_accuracy.cli.iso9283_path import PATH_PLANES
    from tcr_accuracy.iso9283.path import path_figures
    from tcr_accuracy.iso9283.path_evaluate import evaluate_path_test

    assert PATH_PLANES == 100
    for function in (evaluate_path_test, path_figures):
        assert inspect.signature(function).parameters["planes"].default == PATH_PLANES


@pytest.mark.parametrize("ratio, words", [(300.0, "the times look like s where the commanded file's are ms"),
                                          (299.5, "check the unit of time_s here and in the commanded file"),
                                          (3000.0, "the times look like s where the commanded file's are ms"),
                                          (3000.5, "check the unit of time_s here and in the commanded file"),
                                          (0.3e-3, "the times look like ms: give time_s in seconds"),
                                          (0.2995e-3, "check the unit of time_s here and in the commanded file")])
def test_the_time_unit_hint_at_the_ends_of_its_ranges(ratio, words):
    """A stream measured moving ``ratio`` times the commanded speed: s against ms from 300 to 3000 times (both
    ends in), ms from 0.3e-3; just outside, no unit named. Seen failing on the hint's ``0.3e3 <= ratio``
    turned to ``301`` or ``299`` and ``ratio <= 3e3`` to ``3001``."""
    from types import SimpleNamespace

    from tcr_accuracy.iso9283.path_evaluate import CommandedRun, _check_speed

    run = CommandedRun("line", 50.0, np.zeros((2, 3)), np.zeros(2), np.zeros((2, 6)), None, 0.1, ())
    with pytest.raises(InputError) as refused:
        _check_speed(SimpleNamespace(source="stream.csv"), run, SimpleNamespace(v_mean=0.1 * ratio, speed=0.1))
    assert str(refused.value).endswith(f"({ratio:.3g} times); {words}" + ("" if "look like" in words else
                                                                          " (seconds)"))


def test_corner_deviations_of_a_cycle_that_cuts_the_corner_and_one_that_overshoots():
    """An L path, 0.2 m along x then 0.2 m along y, its corner at (0.2, 0, 0). A cycle that cuts the corner
    on the chord from (0.15, 0, 0) to (0.2, 0.05, 0): CR the corner's distance to that chord, 0.05 / sqrt 2,
    and CO 0 (nothing beyond x = 0.2); one that runs 0.4 mm past the corner along x, then turns: CR 0, CO
    0.4 mm; one that stops at the corner (no reading past it along the second edge): CR 0 and CO 0. Seen
    failing on CO's ``else 0.0`` (no reading past the corner) turned to ``else -1.0``."""
    from tcr_accuracy.iso9283.path import corner_deviations

    n = 201
    first = np.column_stack([np.linspace(0.0, 0.2, n), np.zeros(n), np.zeros(n)])
    second = np.column_stack([np.full(n - 1, 0.2), np.linspace(0.0, 0.2, n)[1:], np.zeros(n - 1)])
    points = np.vstack([first, second])
    t = np.linspace(0.0, 1.0, 101)[:, None]
    cut = np.vstack([first[:150], (1 - t) * [0.15, 0.0, 0.0] + t * [0.2, 0.05, 0.0], second[50:]])
    over = np.vstack([first, [[0.2002, 0.0, 0.0], [0.2004, 0.0, 0.0], [0.2004, 0.001, 0.0]], second[5:]])
    (corner,) = corner_deviations(points, [n - 1], [cut, over, first])
    np.testing.assert_allclose(corner.point, [0.2, 0.0, 0.0])
    np.testing.assert_allclose(corner.cr, [0.05 / np.sqrt(2.0), 0.0, 0.0], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(corner.co, [0.0, 0.4e-3, 0.0], rtol=1e-9, atol=0)
