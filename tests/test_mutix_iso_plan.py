"""The ISO 9283 plan's refusals and figures that no other test entered (``iso9283/plan.py``), second
pass of issue 36's mutation line: a given cube whose centre no configuration within half a turn of
home reaches is refused in one line that names the centre and edge in mm and says the centre itself
failed (with or without the tool orientation given). Each test names a planted change it was seen
to catch.
"""

import numpy as np
import pytest

from tcr_accuracy import load_robot, plan_iso_cube
from tcr_accuracy.exceptions import InputError


@pytest.fixture(scope="module")
def ur5():
    return load_robot("ur5")


@pytest.mark.parametrize("rotation, said", [(None, ""), (np.eye(3), " at the tool orientation given")])
def test_a_cube_whose_centre_nothing_reaches_is_refused_naming_the_centre_itself(ur5, rotation, said):
    """A centre 2.5 m from a UR5 (reach 0.85 m): no start of the inverse kinematics reaches it, so no
    point list was gathered, and the refusal says the centre itself, in mm to 0.1 (the centre's
    metres times 1000), the edge likewise. Seen failing on the message's ``" at the tool orientation
    given"`` ``+`` turned to ``-`` (a TypeError, not the InputError) and on ``v * 1e3`` / ``size * 1e3``
    with the number changed."""
    expected = ("cube centre (2000.0, -1500.0, 400.0) mm, edge 100.0 mm: the centre itself (not reachable within "
                f"half a turn of home{said}); the test must be reachable collision-free within the joint limits "
                "at one orientation, above z = 0 mm (the mounting plane): give a smaller cube or omit the centre "
                "and size to search the largest")
    with pytest.raises(InputError) as refused:
        plan_iso_cube(ur5, random_state=0, centre=[2.0, -1.5, 0.4], size=0.1, tool_rotation=rotation)
    assert str(refused.value) == expected
