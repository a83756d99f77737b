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
