"""The ISO 9283 plan's refusals (``iso9283/plan.py``) read word for word against what the cube's
geometry says, written out here: which of P1..P5 and the eight corners (signs x, y, z, x slowest)
lie outside a cell box, the first four named and the rest counted, and the centre and edge in
millimetres. Each test names a planted change it was seen to catch.
"""

import itertools

import numpy as np
import pytest

from tcr_accuracy import load_robot
from tcr_accuracy.exceptions import InputError
from tcr_accuracy.iso9283.plan import _failing_points, plan_iso_cube
from tcr_accuracy.iso9283.reach import Reach, Workspace
from tcr_accuracy.model.kinematics import tcp_poses

#: A UR5 configuration away from its singularities, and a cube about its TCP.
Q_START = np.array([0.0, -1.2, 1.5, -1.9, -1.57, 0.0])
CENTRE = np.array([0.6, 0.1, 0.3])
SIZE = 0.1


def _corner_words(upper):
    """The corners (x, y, z signs, x slowest) beyond the box's upper corner ``upper``, each named as the
    refusal names it."""
    out = []
    for signs in itertools.product((-1, 1), repeat=3):
        corner = CENTRE + SIZE / 2 * np.array(signs)
        if np.any(corner > upper):
            out.append(f"corner ({', '.join('+' if s > 0 else '-' for s in signs)}) outside the workspace")
    return out


@pytest.fixture(scope="module")
def ur5_and_rotation():
    ur5 = load_robot("ur5")
    return ur5, tcp_poses(ur5, Q_START[None]).rotation[0]


def test_the_failing_targets_are_named_corner_by_corner_and_the_rest_counted(ur5_and_rotation):
    """A box whose +x wall is 45 mm from the centre of a 100 mm cube: the four +x corners (50 mm out) fail,
    P2..P5 (40 mm out) do not, so the words name exactly those four corners; with the +y wall 45 mm away
    too, six corners fail: the first four named, "(and 2 more)". Seen failing on the target names'
    ``range(1, 6)`` as ``range(1, 7)`` (every corner named as its predecessor), ``failing[:4]`` as
    ``[:5]`` and ``len(failing) - 4`` as ``- 5``."""
    ur5, rotation = ur5_and_rotation
    for upper, named, more in ((CENTRE + [0.045, 1.0, 1.0], 4, 0), (CENTRE + [0.045, 0.045, 1.0], 4, 2)):
        reach = Reach(ur5, None, Workspace(box=[CENTRE - 1.0, upper]), Q_START, "exact")
        words = _corner_words(upper)
        assert len(words) == named + more
        expected = "; ".join(words[:4]) + (f" (and {more} more)" if more else "")
        assert _failing_points(reach, CENTRE, SIZE, rotation, Q_START) == expected


def test_a_given_cube_outside_the_box_is_refused_with_its_centre_edge_and_corners_in_mm(ur5_and_rotation):
    """The cube centred at (600, 100, 300) mm, 100 mm edge, the tool held as at the start pose, in a box
    ending 45 mm from the centre in +x: refused with the centre and edge in mm, the four +x corners and
    the box in mm. Seen failing on the centre's ``v * 1e3`` and the edge's ``size * 1e3`` changed."""
    ur5, rotation = ur5_and_rotation
    upper = CENTRE + [0.045, 1.0, 1.0]
    with pytest.raises(InputError) as refused:
        plan_iso_cube(ur5, 0, centre=CENTRE, size=SIZE, home=Q_START, tool_rotation=rotation,
                      workspace=Workspace(box=[CENTRE - 1.0, upper]))
    assert str(refused.value) == (
        "cube centre (600.0, 100.0, 300.0) mm, edge 100.0 mm: " + "; ".join(_corner_words(upper))
        + "; the test must be reachable collision-free within the joint limits at one orientation, above z = 0 mm "
        "(the mounting plane), inside the cell box [-400, 645] x [-900, 1100] x [-700, 1300] mm: give a smaller "
        "cube or omit the centre and size to search the largest")


def test_a_given_cube_that_fits_is_planned_as_given_with_its_joints_reaching_the_points(ur5_and_rotation):
    """The same 100 mm cube with no box: planned as given (not searched, one centre tried), its five poses
    P1..P5 and eight corners reached by the joints written (Pinocchio's forward kinematics at them, to
    1e-6 m), the tool held as given, the largest swing from home the largest |q - home| of a revolute
    joint over all 13, the tracker's distances None (no tracker). Seen failing on the given cube's
    ``n_centres=1`` turned to 2."""
    import pinocchio as pin

    ur5, rotation = ur5_and_rotation
    plan = plan_iso_cube(ur5, 0, centre=CENTRE, size=SIZE, home=Q_START, tool_rotation=rotation)
    assert plan.searched is False and plan.n_centres == 1 and plan.size == SIZE
    np.testing.assert_allclose(plan.centre, CENTRE, rtol=0, atol=0)
    corners = np.array([CENTRE + SIZE / 2 * np.array(s) for s in itertools.product((-1, 1), repeat=3)])
    points = np.vstack([CENTRE, CENTRE + 0.8 * SIZE / 2 * np.array([[-1, -1, -1], [1, -1, -1], [1, 1, 1],
                                                                      [-1, 1, 1]]), corners])
    data = ur5.model.createData()
    frame = ur5.model.getFrameId(ur5.tool_frame)
    for q, target in zip(np.vstack([plan.q, plan.corner_q]), points):
        pin.framesForwardKinematics(ur5.model, data, ur5.to_pinocchio_q(q))
        np.testing.assert_allclose(data.oMf[frame].translation, target, rtol=0, atol=1e-6)
        np.testing.assert_allclose(data.oMf[frame].rotation, rotation, rtol=0, atol=1e-6)
    swing = np.abs(np.vstack([plan.q, plan.corner_q]) - Q_START).max()
    assert plan.max_swing == pytest.approx(swing, rel=1e-12)
    assert plan.tracker is None and plan.tracker_distance is None


def test_the_ready_poses_are_the_makers_home_poses():
    """Every UR arm's home on its teach pendant: 0, -90, 0, -90, 0, 0 deg; Franka's ready pose 0, -45, 0, -135,
    0, 90, 45 deg. Seen failing on the UR10's ``-90.0`` at wrist 1 turned to ``90.0``."""
    from tcr_accuracy.iso9283.plan import READY_POSE_DEG, ready_pose

    # (each robot's ready pose run through ready_pose, so that a mutation run counts this test as covering
    # the module: its table is read at import, in no test's context)
    for name in ("ur5", "ur10"):
        np.testing.assert_allclose(ready_pose(load_robot(name)), np.radians([0.0, -90.0, 0.0, -90.0, 0.0, 0.0]),
                                   rtol=0, atol=1e-15)
    assert READY_POSE_DEG == {"ur3": (0.0, -90.0, 0.0, -90.0, 0.0, 0.0), "ur5": (0.0, -90.0, 0.0, -90.0, 0.0, 0.0),
                              "ur10": (0.0, -90.0, 0.0, -90.0, 0.0, 0.0),
                              "panda": (0.0, -45.0, 0.0, -135.0, 0.0, 90.0, 45.0)}


def test_the_search_keeps_the_largest_cube_its_candidate_centres_allow(ur5_and_rotation, monkeypatch):
    """Two candidate configurations put in place of the random ones (the tool pointing down, TCP at z = 120
    mm, then at z = 170 mm): above the mounting plane a cube about a centre at height z has an edge of at
    most 2 z (240 and 340 mm; a little less where the tool's collision body meets the floor). The search
    keeps the second, centred on its TCP, with an edge above 300 mm (more than the first centre allows) and
    at most 340 mm: a later centre that allows a cube 1.4 times the best so far is tried, not skipped.
    Seen failing on the skip test's ``low * 1.01`` turned to ``low * 2.01``."""
    import tcr_accuracy.iso9283.plan as plan_module
    from tcr_accuracy.analysis.sampling import inverse_kinematics

    ur5, rotation = ur5_and_rotation
    centres = np.array([[0.45, 0.1, 0.12], [0.45, -0.1, 0.17]])
    ik = inverse_kinematics(ur5, centres, np.broadcast_to(rotation, (2, 3, 3)), Q_START, orientation="exact")
    assert ik.success.all()
    monkeypatch.setattr(plan_module, "_candidate_configurations",
                        lambda reach, rng, n_samples, n_centres: ik.q)
    plan = plan_iso_cube(ur5, 0, home=Q_START, bisections=8)
    assert plan.searched and plan.n_centres == 2
    np.testing.assert_allclose(plan.centre, centres[1], rtol=0, atol=1e-6)
    assert 0.3 < plan.size <= 2 * 0.17


def test_test_conditions_cycles_and_rated_load_at_their_bounds(ur5_and_rotation):
    """A condition's load is 0-100 % (both ends taken, -0.5 and 100.5 refused), its speed in (0, 100] % (0 and
    100.5 refused, 0.5 and 100 taken); a rated load must be positive (0 refused, 0.5 kg taken: 50 % of it is
    0.25 kg); cycles a whole number from 1 (0 refused, 1 taken); each refusal word for word. Seen failing on
    the bounds' ``0 <= load``, ``load <= 100``, ``0 < speed``, ``speed <= 100``, ``rated_load_kg > 0`` and
    ``cycles < 1`` with their numbers moved by one."""
    from tcr_accuracy.iso9283.plan import cycle_order, plan_conditions

    ur5, _ = ur5_and_rotation
    for load, speed in ((0.0, 100.0), (100.0, 0.5), (50.0, 100.0)):
        (condition,), _ = plan_conditions(ur5, [(load, speed)])
        assert (condition.load_pct, condition.speed_pct) == (load, speed)
    for load, speed in ((-0.5, 50.0), (100.5, 50.0), (50.0, 0.0), (50.0, 100.5)):
        with pytest.raises(InputError) as refused:
            plan_conditions(ur5, [(load, speed)])
        assert str(refused.value) == (f"test condition {load:g} % load, {speed:g} % speed: want a load of 0-100 % "
                                      "and a speed of (0, 100] % of the rated ones")
    (half,), source = plan_conditions(ur5, [(50.0, 100.0)], rated_load_kg=0.5)
    assert half.payload_kg == pytest.approx(0.25, rel=1e-12) and source == "rated load 0.5 kg (given)"
    with pytest.raises(InputError, match=r"^rated load 0\.0 kg: want a positive load$"):
        plan_conditions(ur5, [(50.0, 100.0)], rated_load_kg=0.0)
    pose, cycle = cycle_order(1)
    assert pose.tolist() == [5, 4, 3, 2, 1] and cycle.tolist() == [1] * 5
    with pytest.raises(InputError, match=r"^cycles=0: need a whole number of at least 1 \(the standard uses 30\)$"):
        cycle_order(0)


def test_a_given_cube_needs_an_edge_of_at_least_10_mm(ur5_and_rotation):
    """A 10 mm cube is planned; 9.9 mm is refused before any search, naming the 10 mm and the size given.
    Seen failing on ``MIN_CUBE_SIZE = 0.01`` turned to 1.01 or -0.99 and its ``* 1e3`` in the words."""
    ur5, rotation = ur5_and_rotation
    assert plan_iso_cube(ur5, 0, centre=CENTRE, size=0.01, home=Q_START, tool_rotation=rotation).size == 0.01
    with pytest.raises(InputError) as refused:
        plan_iso_cube(ur5, 0, centre=CENTRE, size=0.0099, home=Q_START, tool_rotation=rotation)
    assert str(refused.value) == "a given cube needs its centre and an edge of at least 10 mm (got size=0.0099 m)"


def test_a_search_that_finds_no_cube_of_10_mm_says_so(ur5_and_rotation, monkeypatch):
    """One candidate configuration, its TCP 4 mm above the mounting plane: no cube of 10 mm or more fits there
    (a cube about a centre at height z has an edge of at most 2 z = 8 mm), so the search is refused naming
    the 10 mm, the one centre tried and the room. Seen failing on the words' ``MIN_CUBE_SIZE * 1e3`` turned
    to ``** 1e3``."""
    import tcr_accuracy.iso9283.plan as plan_module
    from tcr_accuracy.analysis.sampling import inverse_kinematics

    ur5, rotation = ur5_and_rotation
    ik = inverse_kinematics(ur5, np.array([[0.45, 0.1, 0.004]]), rotation[None], Q_START, orientation="exact")
    assert ik.success.all()
    monkeypatch.setattr(plan_module, "_candidate_configurations", lambda reach, rng, n_samples, n_centres: ik.q)
    with pytest.raises(InputError) as refused:
        plan_iso_cube(ur5, 0, home=Q_START, bisections=4)
    assert str(refused.value) == (
        "ur5: no ISO test cube of 10 mm or more found among 1 candidate centres above z = 0 mm (the mounting plane); "
        "give one with the cube's centre and size, or another floor, box, home, orientation or tracker position")
