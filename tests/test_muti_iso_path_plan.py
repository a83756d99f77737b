"""How a test path is solved (``iso9283/path_plan.py``), against what its definition asks of the
inverse kinematics, read off a stand-in reach that records every call: the samples in chunks of 20,
each chunk started from the last sample solved, a chunk that fails from there started from the
three anchors nearest its first sample (nearest first), and no orientation asked of a robot that
cannot hold one. Each test names a planted change it was seen to catch.
"""

from types import SimpleNamespace

import numpy as np
import pytest

from tcr_accuracy.exceptions import InputError
from tcr_accuracy.iso9283.path_plan import IK_TOL, TestPath, arc_length, solve_path


def _line(n=45, spacing=0.004):
    points = np.outer(np.arange(n) * spacing, [1.0, 0.0, 0.0]) + [0.5, -0.25, 0.125]
    return TestPath("line", points, arc_length(points))


def _joints(targets):
    """The stand-in's joints of each target: the sample's index and 0 (a smooth path)."""
    k = np.rint((targets[:, 0] - 0.5) / 0.004)
    return np.column_stack([0.001 * k, np.zeros(len(k))])


def _recording_reach(mode, works_from=None):
    """A stand-in reach recording (first sample, samples, start, rotation, tol) of each IK call; it
    solves from any start, or only from a start equal to ``works_from`` (then its joints)."""
    calls = []

    def solve_raw(targets, rotation, start, tol):
        targets = np.atleast_2d(targets)
        calls.append((int(np.rint((targets[0, 0] - 0.5) / 0.004)), len(targets), np.array(start, dtype=float),
                      rotation, tol))
        if works_from is not None and not np.array_equal(start, works_from):
            return None
        return _joints(targets)

    reach = SimpleNamespace(robot=SimpleNamespace(name="toy", n_joints=2), mode=mode, solve_raw=solve_raw,
                            nearest_home=lambda q: q, checker=None, swing=lambda q: np.zeros(len(q)),
                            below=lambda row: False, workspace=SimpleNamespace(inside=lambda p: np.ones(len(p), bool)))
    return reach, calls


def test_the_samples_are_solved_in_chunks_of_20_each_from_the_last_solved():
    """45 samples: IK on samples 0-19 from the start given, 20-39 from sample 19's joints, 40-44 from
    sample 39's, each at the test's orientation and a tolerance of 1 um; a robot that cannot hold an
    orientation is asked positions only. Catches the default ``chunk=20`` changed and ``IK_TOL``
    changed."""
    path = _line()
    rotation = np.eye(3)
    reach, calls = _recording_reach("exact")
    solved = solve_path(reach, path, rotation, np.array([7.0, 7.0]))
    np.testing.assert_allclose(solved.q, _joints(path.points), atol=1e-15)
    assert [(first, count) for first, count, *_ in calls] == [(0, 20), (20, 20), (40, 5)]
    np.testing.assert_array_equal(calls[0][2], [7.0, 7.0])
    np.testing.assert_allclose(calls[1][2], [0.019, 0.0], atol=1e-15)
    np.testing.assert_allclose(calls[2][2], [0.039, 0.0], atol=1e-15)
    assert all(call[3] is rotation for call in calls) and all(call[4] == 1e-6 for call in calls) and IK_TOL == 1e-6
    reach, calls = _recording_reach("best_effort")
    solve_path(reach, path, rotation, np.zeros(2))
    assert all(call[3] is None for call in calls)


@pytest.mark.parametrize("rank, solved", [(2, True), (3, True), (4, False)])
def test_a_chunk_that_fails_from_the_last_sample_starts_from_the_three_nearest_anchors(rank, solved):
    """Five anchors at growing distances from sample 0; the IK works only from the anchor that is
    ``rank``-th nearest: the path is solved from the 2nd or 3rd nearest (tried nearest first, each
    recorded), and refused at its start from the 4th (only three are tried). Catches ``near[:3]``
    changed to 2 or 4."""
    path = _line()
    distance = np.array([0.3, 0.05, 0.2, 0.01, 0.1])  # nearest first: anchors 3, 1, 4, 2, 0
    order = np.argsort(distance)
    positions = path.points[0] + np.outer(distance, [0.0, 0.0, 1.0])
    joints = np.column_stack([np.arange(5) + 10.0, np.zeros(5)])
    works_from = joints[order[rank - 1]]
    reach, calls = _recording_reach("exact", works_from=works_from)
    if solved:
        got = solve_path(reach, path, np.eye(3), np.array([-1.0, -1.0]), anchors=(positions, joints))
        np.testing.assert_allclose(got.q, _joints(path.points), atol=1e-15)
        first_chunk = [call[2] for call in calls if call[0] == 0]
        np.testing.assert_array_equal(np.array(first_chunk[1:]), joints[order[:rank]])
    else:
        with pytest.raises(InputError, match=r"^toy: the line test path at 0\.0 mm from its start \(500\.0, -250\.0, "
                                             r"125\.0 mm\): not reachable at the test's orientation; plan a smaller"):
            solve_path(reach, path, np.eye(3), np.array([-1.0, -1.0]), anchors=(positions, joints))
        np.testing.assert_array_equal(np.array([call[2] for call in calls[1:]]), joints[order[:3]])


def test_every_path_starts_from_the_cubes_p1_joints_at_its_p1_orientation():
    """A cube (stand-in) whose five poses hold different orientations and joints: each of the four
    paths' first sample is solved alone from P1's joints at P1's orientation, then the path from that
    solution, with the cube's poses and corners as anchors; a rated speed given is said in mm/s.
    Catches ``cube.rotation[0]`` and ``cube.q[0]`` changed to ``[1]`` and the speed's ``* 1e3``
    changed."""
    from tcr_accuracy.iso9283.path_plan import plan_test_paths, standard_paths
    from tcr_accuracy.iso9283.plan import iso_points

    centre, size = np.array([0.4, 0.1, 0.5]), 0.1
    rotations = np.array([np.eye(3) * (k + 1) for k in range(5)])
    cube = SimpleNamespace(centre=centre, size=size, positions=iso_points(centre, size), rotation=rotations,
                           q=np.arange(10.0).reshape(5, 2), corner_q=np.zeros((8, 2)))
    calls = []

    def solve_raw(targets, rotation, start, tol):
        targets = np.atleast_2d(targets)
        calls.append((len(targets), targets[0].copy(), np.array(start, dtype=float), rotation))
        return targets[:, :2] + 0.0

    reach = SimpleNamespace(robot=SimpleNamespace(name="toy", n_joints=2), mode="exact", solve_raw=solve_raw,
                            nearest_home=lambda q: q, checker=None, swing=lambda q: np.zeros(len(q)),
                            below=lambda row: False, workspace=SimpleNamespace(inside=lambda p: np.ones(len(p), bool)))
    plan = plan_test_paths(reach, cube, rated_speed=0.25)
    assert plan.speed_source == "given: 250 mm/s" and plan.rated_speed == 0.25
    assert all(np.array_equal(call[3], rotations[0]) for call in calls)
    paths = standard_paths(centre, size)
    singles = [call for call, after in zip(calls, calls[1:])  # a path's start, then its first chunk from there
               if call[0] == 1 and after[0] > 1 and np.array_equal(after[1], call[1])]
    assert len(singles) == 4
    for call, path in zip(singles, paths):
        np.testing.assert_array_equal(call[1], path.points[0])
        np.testing.assert_array_equal(call[2], [0.0, 1.0])  # P1's joints


def test_the_circles_turn_about_the_test_planes_unit_normal():
    """The circles' plane: its x direction U, its in-plane diagonal W = (0, 1, 1) / sqrt 2 and its
    normal N = (0, -1, 1) / sqrt 2 are unit vectors, orthogonal, with U x W = N; the large circle of a
    cube lies in the plane through P1 normal to N and turns counter-clockwise about it, each step's
    turn (r_k x r_k+1) a multiple of N as long as the chord's. Catches ``/ np.sqrt(2.0)`` as
    ``* np.sqrt(2.0)`` in N or W, and any of N's numbers changed."""
    from tcr_accuracy.iso9283.path_plan import PLANE_NORMAL, PLANE_U, PLANE_W, standard_paths

    for axis in (PLANE_U, PLANE_W, PLANE_NORMAL):
        assert np.linalg.norm(axis) == pytest.approx(1.0, rel=1e-15)
    np.testing.assert_allclose(np.cross(PLANE_U, PLANE_W), PLANE_NORMAL, atol=1e-15)
    np.testing.assert_allclose(PLANE_NORMAL, [0.0, -1.0 / np.sqrt(2), 1.0 / np.sqrt(2)], atol=1e-15)
    centre = np.array([0.4, 0.1, 0.5])
    circle = {path.name: path for path in standard_paths(centre, 0.2)}["circle_large"]
    r = circle.points - centre
    np.testing.assert_allclose(r @ PLANE_NORMAL, 0.0, atol=1e-15)
    turn = np.cross(r[:-1], r[1:])
    np.testing.assert_allclose(turn, np.outer(np.linalg.norm(turn, axis=1), PLANE_NORMAL), atol=1e-15)
