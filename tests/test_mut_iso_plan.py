"""The ISO 9283 test's geometry and timing (``iso9283/plan.py``, ``path_plan.py``, ``reach.py``)
against the standard's definitions written out here: the cube's five poses and corners, the cycle
order, the test conditions' payloads, the four test paths in the cube's plane, the trapezoidal
speed profile's kinematics, the joint-limited path speed and the workspace's room. Each test names
a planted change it was seen to catch.
"""

import math

import numpy as np
import pytest

from tcr_accuracy import load_robot
from tcr_accuracy.iso9283.path_plan import (CORNER_ANGLE, PLANE_NORMAL, RAMP_FRACTION, TestPath, _joint_limited_speed,
                                            arc_length, commanded_speed, corners_of, standard_paths,
                                            trapezoid_times)
from tcr_accuracy.iso9283.plan import (RATED_LOAD_KG, READY_POSE_DEG, cube_corners, cycle_order, iso_points,
                                       plan_conditions, ready_pose)
from tcr_accuracy.iso9283.reach import MAX_SWING, Reach, Workspace

CENTRE = np.array([0.3, -0.2, 0.5])
SIZE = 0.25


def _p():
    """P1..P5 written out from clause 6.8: P1 the centre, P2..P5 at 10 % of the plane's diagonal from
    its corners C1 (-,-,-), C2 (+,-,-), C3 (+,+,+), C4 (-,+,+): the corner is half a diagonal from
    the centre, so P = centre + 0.8 (C - centre)."""
    signs = np.array([[-1, -1, -1], [1, -1, -1], [1, 1, 1], [-1, 1, 1]])
    return np.vstack([CENTRE, CENTRE + 0.8 * (SIZE / 2) * signs])


def test_the_cubes_poses_corners_and_cycle_order_by_hand():
    """P1..P5 and the 8 corners of a 250 mm cube as written out; the cycle order P5, P4, P3, P2, P1
    per cycle. Catches ``CORNER_OFFSET`` 0.10 changed, ``0.5 * size`` as ``1.5 * size`` in the
    poses or the corners, ``2 * CORNER_OFFSET`` as ``3 *`` and ``np.arange(5, 0, -1)`` changed."""
    np.testing.assert_allclose(iso_points(CENTRE, SIZE), _p(), atol=1e-15)
    corners = cube_corners(CENTRE, SIZE)
    expected = {tuple(np.round(CENTRE + SIZE / 2 * np.array([x, y, z]), 12)) for x in (-1, 1) for y in (-1, 1)
                for z in (-1, 1)}
    assert {tuple(np.round(c, 12)) for c in corners} == expected
    pose, cycle = cycle_order(3)
    assert pose.tolist() == [5, 4, 3, 2, 1] * 3 and cycle.tolist() == [1] * 5 + [2] * 5 + [3] * 5


def test_test_conditions_payloads_and_the_makers_figures():
    """The standard's four conditions with the UR5's rated 5 kg (its data sheet): 5, 5, 5 and 0.5 kg; a
    given rated load of 8 kg at 50 % is 4 kg; the ready poses as the makers give them (UR: 0, -90, 0,
    -90, 0, 0 deg). Catches ``rated_load_kg * load / 100.0`` as ``/ 101.0`` and the tables'
    figures changed."""
    ur5 = load_robot("ur5")
    conditions, source = plan_conditions(ur5)
    assert [(c.load_pct, c.speed_pct, c.payload_kg) for c in conditions] == [
        (100.0, 100.0, 5.0), (100.0, 50.0, 5.0), (100.0, 10.0, 5.0), (10.0, 100.0, pytest.approx(0.5, rel=1e-12))]
    assert "5 kg" in source and RATED_LOAD_KG == {"ur3": 3.0, "ur5": 5.0, "ur10": 10.0, "panda": 3.0}
    (given,), _ = plan_conditions(ur5, [(50.0, 100.0)], rated_load_kg=8.0)
    assert given.payload_kg == pytest.approx(4.0, rel=1e-12)
    assert READY_POSE_DEG["ur5"] == (0.0, -90.0, 0.0, -90.0, 0.0, 0.0)
    assert READY_POSE_DEG["panda"] == (0.0, -45.0, 0.0, -135.0, 0.0, 90.0, 45.0)
    np.testing.assert_allclose(ready_pose(ur5), [0.0, -math.pi / 2, 0.0, -math.pi / 2, 0.0, 0.0], atol=1e-15)


def test_the_four_test_paths_in_the_cubes_plane_by_hand():
    """The line P2 -> P4 (0.8 of the cube's space diagonal, 0.8 sqrt 3 a), the large circle about P1
    of diameter 0.8 a and the small one of 0.08 a (n chords of a regular polygon, n = max(200,
    ceil(pi d / 1 mm))), starting along x and turning towards (0, 1, 1) / sqrt 2, and the rectangle
    P2 -> P3 -> P4 -> P5 -> P2 (perimeter 1.6 a (1 + sqrt 2)) with its corners at P3, P4, P5; every
    point in the plane through P1 normal to (0, -1, 1) / sqrt 2, samples at most 1 mm apart.
    Catches ``0.8 * size`` and ``0.08 * size`` changed, ``rectangle = 2 * (...)`` as ``3 *``, the
    radius ``diameter / 2`` as ``/ 3``, the circle's ``np.sin`` term's ``+`` as ``-`` and the
    sampling step ``total / MIN_SAMPLES`` mutated."""
    p = _p()
    paths = {path.name: path for path in standard_paths(CENTRE, SIZE)}
    assert list(paths) == ["line", "circle_large", "circle_small", "rectangle"]
    for path in paths.values():
        np.testing.assert_allclose((path.points - CENTRE) @ np.array([0.0, -1.0, 1.0]) / math.sqrt(2), 0.0,
                                   atol=1e-14)
        np.testing.assert_allclose(path.s, np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(path.points, axis=0),
                                                                                          axis=1))]), rtol=1e-12)
        assert np.diff(path.s).max() <= 1e-3 + 1e-12 and len(path.s) >= 200
    line = paths["line"]
    np.testing.assert_allclose(line.points[[0, -1]], p[[1, 3]], atol=1e-15)
    assert line.length == pytest.approx(0.8 * math.sqrt(3) * SIZE, rel=1e-12) and line.corners == ()
    for name, diameter in (("circle_large", 0.8 * SIZE), ("circle_small", 0.08 * SIZE)):
        circle = paths[name]
        n = max(200, math.ceil(math.pi * diameter / 1e-3))
        assert len(circle.points) == n + 1
        np.testing.assert_allclose(np.linalg.norm(circle.points - CENTRE, axis=1), diameter / 2, rtol=1e-12)
        np.testing.assert_allclose(circle.points[0], CENTRE + [diameter / 2, 0, 0], atol=1e-15)
        assert circle.length == pytest.approx(n * diameter * math.sin(math.pi / n), rel=1e-12)
        turn = np.cross(circle.points[0] - CENTRE, circle.points[1] - CENTRE)
        assert turn @ PLANE_NORMAL > 0  # counter-clockwise seen from the plane's normal
    rectangle = paths["rectangle"]
    assert rectangle.length == pytest.approx(1.6 * SIZE * (1 + math.sqrt(2)), rel=1e-12)
    np.testing.assert_allclose(rectangle.points[list(rectangle.corners)], p[[2, 3, 4]], atol=1e-15)
    np.testing.assert_allclose(rectangle.points[[0, -1]], p[[1, 1]], atol=1e-15)
    small = {path.name: path for path in standard_paths(CENTRE, 0.05)}  # a 50 mm cube: 200 samples or more
    assert len(small["line"].points) == 201
    assert np.diff(small["line"].s).max() == pytest.approx(0.8 * math.sqrt(3) * 0.05 / 200, rel=1e-12)
    perimeter = 1.6 * 0.05 * (1 + math.sqrt(2))  # 193 mm: sampled at most perimeter / 200 apart
    assert np.diff(small["rectangle"].s).max() <= perimeter / 200 * (1 + 1e-12)
    assert len(small["rectangle"].points) >= 201


def test_corners_are_turns_beyond_30_degrees():
    """A polyline turning by 45, 20 and 90 degrees: corners at the first and the third turn only."""
    turns = np.radians([45.0, 20.0, 90.0])
    heading, points = 0.0, [np.zeros(3)]
    for k in range(4):
        points.append(points[-1] + [math.cos(heading), math.sin(heading), 0.0])
        heading += turns[k] if k < 3 else 0.0
    assert CORNER_ANGLE == pytest.approx(math.radians(30.0))
    assert corners_of(np.array(points)) == (1, 3)
    np.testing.assert_allclose(arc_length(points), [0, 1, 2, 3, 4], rtol=1e-12)


def test_the_trapezoidal_profile_as_kinematics_gives_it():
    """A 0.6 m path at 0.25 m/s ramping over 10 % at each end (d = 60 mm): the constant acceleration
    a = v^2 / (2 d) reaches v at t = 2 d / v; in the ramp s = a t^2 / 2; the cruise at v; the whole
    run lasts (L + 2 d) / v and ends as it began, mirrored; the commanded speed is v on the cruise.
    Catches ``speed ** 2 / (2 * d)`` as ``/ (3 * d)``, ``np.sqrt(2 * s / accel)`` as ``3 * s``,
    ``t_ramp + t_cruise + t_ramp`` with a ``-`` and ``RAMP_FRACTION`` 0.10 changed."""
    s = np.linspace(0.0, 0.6, 601)
    v, d = 0.25, 0.06
    t = trapezoid_times(s, v)
    a = v ** 2 / (2 * d)
    assert RAMP_FRACTION == 0.10
    ramp = s <= d
    np.testing.assert_allclose(s[ramp], a * t[ramp] ** 2 / 2, atol=1e-15)
    cruise = (s > d) & (s < 0.6 - d)
    np.testing.assert_allclose(t[cruise], 2 * d / v + (s[cruise] - d) / v, rtol=1e-12)
    assert t[-1] == pytest.approx((0.6 + 2 * d) / v, rel=1e-12)
    np.testing.assert_allclose(t[-1] - t[::-1], t, atol=1e-12)  # the end mirrors the start
    speed = commanded_speed(s, t)
    np.testing.assert_allclose(speed[(s > d + 0.002) & (s < 0.6 - d - 0.002)], v, rtol=1e-9)
    assert speed.max() == pytest.approx(v, rel=1e-6)


def test_the_rated_path_speed_is_the_joints_velocity_limits_on_the_worst_sample():
    """Two paths with joint values written here on the UR5 (its URDF's velocity limits): the rated
    speed is the smallest over all samples and joints of v_max_j / |dq_j / ds|, and names the joint
    and path. Catches ``np.diff(path.q) / np.diff(path.s)`` as ``*``, and ``np.min`` over the joints
    as ``np.max``."""
    ur5 = load_robot("ur5")
    limits = np.asarray(ur5.model.velocityLimit, dtype=float)
    s = np.linspace(0.0, 0.3, 31)
    slow = np.outer(s, [0.5, 0.2, 1.0, 0.1, 0.3, 0.0])
    fast = np.outer(s, [0.1, 0.1, 0.1, 0.1, 0.1, 0.1])
    fast[12:, 4] += 0.05  # a 0.05 rad step of wrist_2 over 10 mm: 5 rad/m there
    paths = [TestPath("line", fast, s, fast), TestPath("circle_large", np.zeros((31, 3)), s, slow)]
    speed, where = _joint_limited_speed(ur5, paths)
    rates = [np.abs(np.diff(path.q, axis=0)) / np.diff(s)[:, None] for path in paths]
    expected = min(float(np.min(limits / np.maximum(r, 1e-12))) for r in rates)
    assert speed == pytest.approx(expected, rel=1e-12)
    assert speed == pytest.approx(limits[4] / (0.1 + 5.0), rel=1e-9)
    assert where.endswith(f"{ur5.joint_names[4]} on the line at its limit")


def test_the_workspace_room_and_half_a_turn_from_home():
    """A cube centred 0.4 m above a floor at 0.1 m in a box 0.2 m from the centre's nearest wall:
    room 2 x 0.2 m; without the box 2 x 0.3 m; the joint ranges drawn from are the limits cut to half
    a turn about home. Catches ``2.0 * max(half, 0.0)`` as ``3.0 *``, ``centre[2] - self.floor`` as
    ``+``, ``MAX_SWING`` changed and ``self.home - MAX_SWING`` as ``+``."""
    box = Workspace(floor=0.1, box=[[-1.0, -0.1, 0.0], [1.0, 0.6, 2.0]])
    assert box.room([0.0, 0.1, 0.4]) == pytest.approx(0.4, rel=1e-12)
    assert Workspace(floor=0.1).room([0.0, 0.1, 0.4]) == pytest.approx(0.6, rel=1e-12)
    assert Workspace(floor=0.5).room([0.0, 0.1, 0.4]) == 0.0
    assert box.words() == "above z = 100 mm, inside the cell box [-1000, 1000] x [-100, 600] x [0, 2000] mm"
    ur5 = load_robot("ur5")
    home = np.array([0.5, -1.0, 2.0, -3.0, 0.0, 1.0])
    reach = Reach(ur5, None, Workspace(), home, "exact")
    lo, hi = reach.bounds()
    limit_lo, limit_hi = ur5.joint_bounds(np.pi)
    assert MAX_SWING == pytest.approx(math.pi)
    np.testing.assert_allclose(lo, np.maximum(limit_lo, home - math.pi), rtol=1e-12)
    np.testing.assert_allclose(hi, np.minimum(limit_hi, home + math.pi), rtol=1e-12)
    q = home + np.array([[0.1, -0.2, 0.3, 0.0, 0.0, -0.4], [0.0, 0.0, 0.0, 0.0, 0.5, 0.0]])
    np.testing.assert_allclose(reach.swing(q), [0.4, 0.5], rtol=1e-12)


def test_whole_turns_move_a_revolute_joint_nearest_home_within_its_limits():
    """The UR5's joints (limits +-2 pi): a shoulder at 4.0 and 4.5 rad with home 0 is moved a turn
    down to 4.0 - 2 pi and 4.5 - 2 pi (both rows alike); a wrist at -5.5 rad with home 3.0 goes a
    turn up; a joint at 6.2 rad with home 6.0 stays (a turn up crosses its limit, a turn down is farther
    from home). Catches the limits' tolerance ``lo[j] - 1e-12`` as ``lo[j] % 1e-12`` (every
    negative value refused) and ``2 * np.pi * turns`` with its 2 changed."""
    ur5 = load_robot("ur5")
    home = np.array([0.0, 0.0, 0.0, 3.0, 0.0, 6.0])
    reach = Reach(ur5, None, Workspace(), home, "exact")
    q = np.array([[4.0, 0.1, 0.2, -5.5, 0.3, 6.2], [4.5, 0.1, 0.2, -5.4, 0.3, 6.1]])
    got = reach.nearest_home(q)
    expected = q.copy()
    expected[:, 0] -= 2 * math.pi
    expected[:, 3] += 2 * math.pi
    np.testing.assert_allclose(got, expected, rtol=1e-15, atol=1e-15)


def test_the_line_of_sight_words_give_the_tracker_in_mm():
    """The tracker at (2.5, -1.25, 0.4) m is quoted as (2500, -1250, 400) mm, whether or not the line
    of sight could be checked. Catches ``v * 1e3`` as ``v * 1e2`` or ``v ** 1e3``."""
    ur5 = load_robot("ur5")
    reach = Reach(ur5, None, Workspace(), np.zeros(6), "exact", tracker=np.array([2.5, -1.25, 0.4]))
    assert reach.sight_words() == ("not checked: the URDF of ur5 has no collision geometry (tracker at "
                                   "(2500, -1250, 400) mm)")
    assert Reach(ur5, None, Workspace(), np.zeros(6), "exact").sight_words() == \
        "not checked: no tracker position given"
