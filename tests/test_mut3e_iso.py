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
