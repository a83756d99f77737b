"""ISO 9283 reach and plan figures (``iso9283/reach.py``) at their boundaries, written out here: whole
turns of a revolute joint taken only where the joint's limits (as the UR5's model states them) allow,
to within their 1e-12 rad tolerance. Each test
names a planted change it was seen to catch.
"""

import math

import numpy as np
import pytest

from tcr_accuracy import load_robot
from tcr_accuracy.iso9283.reach import Reach, Workspace


@pytest.fixture(scope="module")
def ur5():
    return load_robot("ur5")


def test_a_whole_turn_is_taken_up_to_the_limit_within_its_tolerance_and_never_past_it(ur5):
    """UR5 limits +-6.28318530718 rad (read from the model here). Home -6 rad for the shoulder pan read
    where a turn down lands 5e-13 rad past its limit, inside the 1e-12 tolerance: taken. Home -6 for
    the shoulder lift read at -1 and -0.5: a turn down would be nearer home but 1 rad past the limit:
    left. The same upwards for wrist 1 (5e-13 past, home 6) and wrist 2 (at 1 and 0.5, home 6). Seen failing on ``lo[j] - 1e-12`` as ``lo[j] // 1e-12`` (the lower limit no longer
    held), as ``lo[j] + 1e-12`` (the turn to -2 pi refused), and on ``hi[j] + 1e-12`` as ``hi[j] -
    1e-12``."""
    lo, hi = ur5.joint_bounds(np.inf)
    near_lo = lo[0] + 2 * math.pi - 5e-13  # a turn down lands 5e-13 below the lower limit
    near_hi = hi[3] - 2 * math.pi + 5e-13
    assert -6e-13 < (near_lo - 2 * math.pi) - lo[0] < -4e-13 and 4e-13 < (near_hi + 2 * math.pi) - hi[3] < 6e-13
    home = np.array([-6.0, -6.0, 0.0, 6.0, 6.0, 0.0])
    reach = Reach(ur5, None, Workspace(), home, "exact")
    q = np.array([[near_lo, -1.0, 0.2, near_hi, 1.0, 0.3], [near_lo, -0.5, -0.2, near_hi, 0.5, -0.3]])
    expected = q.copy()
    expected[:, 0] -= 2 * math.pi  # within the tolerance of its limit
    expected[:, 3] += 2 * math.pi
    for j in (1, 4):  # a turn would cross the limit by about 1 rad
        assert np.any(q[:, j] + 2 * math.pi * np.sign(home[j]) < lo[j] - 1e-12) or \
            np.any(q[:, j] + 2 * math.pi * np.sign(home[j]) > hi[j] + 1e-12)
    np.testing.assert_allclose(reach.nearest_home(q), expected, rtol=0, atol=1e-15)


@pytest.mark.parametrize("name, payload, rated, source", [
    ("ur3", None, 3.0, "rated load 3 kg (ur3's data sheet)"),
    ("ur5", None, 5.0, "rated load 5 kg (ur5's data sheet)"),
    ("ur10", None, 10.0, "rated load 10 kg (ur10's data sheet)"),
    ("panda", None, 3.0, "rated load 3 kg (panda's data sheet)"),
    ("tool_changer", 150.0, 150.0, "rated load 150 kg (the robot's design payload)"),
])
def test_the_standards_four_conditions_carry_the_rated_load_of_the_makers_data_sheet(name, payload, rated, source):
    """ISO 9283's four test conditions by default (100 % load at 100, 50 and 10 % speed, then 10 % load
    at 100 % speed), each payload that share of the rated load: the maker's data sheet for the robots
    known by name (UR3 3 kg, UR5 5 kg, UR10 10 kg, Panda 3 kg), else the robot's design payload.
    Seen failing on ``STANDARD_CONDITIONS`` or ``RATED_LOAD_KG`` with a number changed and on
    ``rated_load_kg * load / 100.0`` as ``/ 101.0``."""
    from types import SimpleNamespace

    from tcr_accuracy.iso9283.plan import plan_conditions

    conditions, said = plan_conditions(SimpleNamespace(name=name, payload_kg=payload))
    assert said == source
    assert [(c.load_pct, c.speed_pct) for c in conditions] == [(100.0, 100.0), (100.0, 50.0), (100.0, 10.0),
                                                              (10.0, 100.0)]
    assert [c.payload_kg for c in conditions] == pytest.approx([rated, rated, rated, rated / 10], rel=1e-12)


def test_a_robot_of_unknown_rated_load_gives_its_conditions_without_payloads():
    """A robot neither known by name nor with a design payload: the conditions without payloads, said."""
    from types import SimpleNamespace

    from tcr_accuracy.iso9283.plan import plan_conditions

    conditions, said = plan_conditions(SimpleNamespace(name="arm", payload_kg=None), [(10.0, 100.0)])
    assert said == "rated load unknown (give it): the loads are percentages only, no payload_kg column"
    assert [(c.load_pct, c.speed_pct, c.payload_kg) for c in conditions] == [(10.0, 100.0, None)]


@pytest.mark.parametrize("skew, taken", [(0.45e-6, True), (0.55e-6, False)])
def test_a_tool_orientation_off_orthonormal_by_a_millionth_is_taken_and_past_it_refused(skew, taken):
    """R = I + e (E_xy + E_yx): R R^T differs from I by 2e off the diagonal (and e^2 on it): 0.9e-6 is
    within the 1e-6 the plan allows, 1.1e-6 is not. Seen failing on ``atol=1e-6`` as ``1.000001``."""
    from tcr_accuracy.exceptions import InputError
    from tcr_accuracy.iso9283.plan import _tool_rotation

    rotation = np.eye(3)
    rotation[0, 1] = rotation[1, 0] = skew
    assert np.max(np.abs(rotation @ rotation.T - np.eye(3))) == pytest.approx(2 * skew, rel=1e-6)
    if taken:
        assert np.array_equal(_tool_rotation(rotation), rotation)
    else:
        with pytest.raises(InputError, match=r"^tool_rotation: want a \(3, 3\) rotation matrix"):
            _tool_rotation(rotation)


def test_the_five_poses_lie_on_the_cubes_diagonal_plane_a_tenth_of_its_diagonal_from_the_corners():
    """ISO 9283 clause 6.8: P1 at the cube's centre, P2..P5 on the plane through the corners C1 (-,-,-),
    C2 (+,-,-), C3 (+,+,+), C4 (-,+,+), each 10 % of the plane's diagonal (C1 to C3) from its corner
    towards the centre; the cube's eight corners at centre +- size / 2; a test of 30 cycles by default
    (150 visits, P5 first). Written out here for a 0.3 m cube centred at (0.4, -0.2, 0.5). Seen failing
    on ``CORNER_OFFSET = 0.10`` and ``DEFAULT_CYCLES = 30`` with their numbers changed, ``0.5 * size``
    as ``1.5 * size`` and a corner of ``PLANE_CORNERS`` or ``CUBE_CORNERS`` changed."""
    from itertools import product

    from tcr_accuracy.iso9283.plan import cube_corners, cycle_order, iso_points

    centre, size = np.array([0.4, -0.2, 0.5]), 0.3
    corners = [centre + size / 2 * np.array(s) for s in ([-1, -1, -1], [1, -1, -1], [1, 1, 1], [-1, 1, 1])]
    diagonal = np.linalg.norm(corners[2] - corners[0])
    expected = [centre] + [c + 0.1 * diagonal * (centre - c) / np.linalg.norm(centre - c) for c in corners]
    np.testing.assert_allclose(iso_points(centre, size), expected, rtol=0, atol=1e-15)
    every = {tuple(np.round(centre + size / 2 * np.array(s), 12)) for s in product((-1, 1), repeat=3)}
    assert {tuple(np.round(c, 12)) for c in cube_corners(centre, size)} == every
    assert len(cube_corners(centre, size)) == 8
    pose, cycle = cycle_order()
    assert len(pose) == 150 and pose[:5].tolist() == [5, 4, 3, 2, 1] and cycle[-1] == 30


def _bent_path(first, second, speed=None, start=0.0, dt=0.002):
    """An L of edges ``first`` along x then ``second`` along y [m]: sampled every mm (points, s), or with
    a speed [m/s] one cycle's readings (times, positions) from 10 mm before its start to 10 mm past its end."""
    if speed is None:
        u = np.linspace(0.0, first + second, int(round((first + second) * 1000)) + 1)
    else:
        t = np.arange(0.0, (first + second + 0.02) / speed, dt)
        u = -0.01 + speed * t
    points = np.column_stack([np.minimum(u, first), np.maximum(u - first, 0.0), np.zeros_like(u)])
    return (points, u) if speed is None else (start + t, points)


def test_two_planes_either_side_of_one_left_out_at_a_corner_are_no_pair():
    """An L of 180 mm then 220 mm, 10 normal planes (every 40 mm, at 20 .. 380 mm): the plane at the corner
    (180 mm) is left out, so 140 and 220 mm are 80 mm apart (twice the spacing, the chord between them
    across the corner 57 mm): no neighbours. Two cycles at 0.10 and 0.11 m/s, 0.1 m/s commanded: every
    counted speed is its cycle's, v̄ = 0.105 m/s, AV = 5 %, RV = 3 S(0.10, 0.11) / 0.1, FV = 0, written
    out. Seen failing on the neighbours' ``1.5 * np.min(np.diff(s_i))`` as ``2.5 *`` (the pair across
    the corner read at 0.71 of the speed)."""
    from tcr_accuracy.iso9283.path import path_figures

    points, s = _bent_path(0.18, 0.22)
    cycles = [_bent_path(0.18, 0.22, 0.10), _bent_path(0.18, 0.22, 0.11, start=10.0)]
    got = path_figures(points, s, cycles, planes=10, corners=(180,), speed=0.1)
    np.testing.assert_allclose(got.s, [0.02, 0.06, 0.10, 0.14, 0.22, 0.26, 0.30, 0.34, 0.38], rtol=1e-12)
    assert got.v_mean == pytest.approx(0.105, rel=1e-9)
    assert got.av == pytest.approx(0.05, rel=1e-7)
    assert got.rv == pytest.approx(3 * np.std([0.10, 0.11], ddof=1) / 0.1, rel=1e-7)
    assert got.fv == pytest.approx(0.0, abs=1e-9)


def test_one_cycle_gives_accuracy_but_no_repeatability():
    """One cycle along the L 1 mm off in z at 0.1 m/s: AT is the 1 mm at every plane, v̄ and AV its
    speed's, but neither RT nor RV (a repeatability needs two cycles): None, not NaN. Seen failing on
    ``MIN_CYCLES = 2`` as 1 (RV NaN)."""
    import warnings

    from tcr_accuracy.iso9283.path import path_figures

    points, s = _bent_path(0.2, 0.2)
    t, x = _bent_path(0.2, 0.2, 0.1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        got = path_figures(points, s, [(t, x + [0.0, 0.0, 1e-3])], planes=20, corners=(200,), speed=0.1)
    assert got.n_cycles == 1 and got.at == pytest.approx(1e-3, rel=1e-9)
    assert got.v_mean == pytest.approx(0.1, rel=1e-9) and got.av == pytest.approx(0.0, abs=1e-7)
    assert got.rt is None and got.rv is None
    assert np.isnan(got.rt_planes).all()


def test_the_rated_path_speed_names_the_joint_whose_limit_over_its_rate_is_least():
    """A UR5 path along which the shoulder pan turns 0.50 rad/m and wrist 1 0.52 rad/m (the URDF's limits
    3.15 and 3.2 rad/s, read here): wrist 1 limits the speed (3.2 / 0.52 < 3.15 / 0.50 m/s) though the
    pan has less margin in rad/s (3.15 - 0.50 < 3.2 - 0.52): the speed is 3.2 / 0.52 m/s and wrist 1 is
    named. Seen failing on the named joint's ``limits / np.maximum(rate[k], 1e-12)`` as ``limits - ...``
    and on its ``1e-12`` as ``1.000000000001``."""
    from tcr_accuracy.iso9283.path_plan import TestPath, _joint_limited_speed

    ur5 = load_robot("ur5")
    limits = np.asarray(ur5.model.velocityLimit, dtype=float)
    assert limits[3] / 0.52 < limits[0] / 0.50 and limits[0] - 0.50 < limits[3] - 0.52
    s = np.linspace(0.0, 0.2, 21)
    q = np.outer(s, [0.50, 0.0, 0.0, 0.52, 0.0, 0.0])
    speed, where = _joint_limited_speed(ur5, [TestPath("line", np.zeros((21, 3)), s, q)])
    assert speed == pytest.approx(limits[3] / 0.52, rel=1e-9)
    assert where == f"the largest the joints' velocity limits allow: {ur5.joint_names[3]} on the line at its limit"


def test_of_two_repeated_times_in_a_streamed_visit_the_first_is_named():
    """Pose 1, cycle 1 streamed at 0.0, 0.5, 0.5, 0.9, 0.9 s (rows 2 .. 6): refused at row 4, the first
    reading that repeats a time, not row 6. Seen failing on ``rows[same[0] + 1]`` as ``rows[same[-1] + 1]``."""
    from tcr_accuracy.exceptions import InputError
    from tcr_accuracy.iso9283.evaluate import PoseLabels, visits_of

    from test_mute_iso_formulas import _Readings

    ones = np.array(["1"] * 5, dtype=object)
    mset = _Readings(time_s=np.array([0.0, 0.5, 0.5, 0.9, 0.9]), rows=np.arange(2, 7), source="stream.csv")
    with pytest.raises(InputError) as refused:
        visits_of(mset, PoseLabels(ones, ones, None))
    assert str(refused.value) == ("stream.csv: row 4, column time_s: 0.5 s repeats a time of the same visit (pose 1, "
                                  "cycle 1); the readings of one visit are a stream in time")
