"""Where an ISO 9283 test may go (``iso9283/reach.py``), against geometry written out here and
stand-ins for the collision geometry: the instrument's beam to a measured point stopped the
reflector's clearance short of it, the floor the bodies are held to and which bodies it does not
hold. Each test names a planted change it was seen to catch.
"""

from types import SimpleNamespace

import numpy as np
import pytest

from tcr_accuracy import load_robot
from tcr_accuracy.analysis.reachable import BEAM_RADIUS_M, REFLECTOR_CLEARANCE_M
from tcr_accuracy.iso9283.reach import Reach, Workspace


class _Beams:
    """A stand-in collision checker that records every beam asked about and says a body blocks the
    beams whose index is in ``blocked`` (nothing collides, nothing is below the floor)."""

    def __init__(self, blocked=()):
        self.beams, self.blocked = [], set(blocked)

    def blocking_bodies(self, q, start, end, radius):
        self.beams.append((np.array(q, dtype=float), np.array(start, dtype=float), np.array(end, dtype=float),
                           radius))
        return ["forearm"] if len(self.beams) - 1 in self.blocked else []


def _reach(checker, tracker):
    ur5 = load_robot("ur5")
    reach = Reach(ur5, None, Workspace(), np.zeros(6), "exact", tracker=tracker)
    reach.checker = checker  # after __post_init__: the floor's exemptions are those without geometry
    return reach


def test_the_beam_runs_from_the_tracker_to_the_reflectors_clearance_short_of_each_point():
    """The tracker at (2, -1, 0.5) m; three points 1.3 m, 0.6 m and 20 mm from it: the first two are
    asked about a beam of radius 1 mm from the tracker to the point moved 25 mm towards the tracker
    (``point + (tracker - point) * 0.025 / |tracker - point|``, written out here), at their own
    joints; the third, nearer than the clearance, is never hidden and not asked about. The checker's
    answer for the second beam (a body on it) is the second point's. Catches the clearance's ratio
    ``REFLECTOR_CLEARANCE_M / distance`` as ``* distance``, ``point + (...)`` as ``-``, ``self.tracker
    - point`` as ``+`` and the ``distance > REFLECTOR_CLEARANCE_M`` guard's sides swapped."""
    tracker = np.array([2.0, -1.0, 0.5])
    directions = np.array([[-1.0, 0.5, 0.2], [0.3, 1.0, -0.4], [0.0, 0.6, 0.8]])
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    points = tracker + directions * np.array([[1.3], [0.6], [0.02]])
    q = np.arange(18, dtype=float).reshape(3, 6) * 0.01
    beams = _Beams(blocked={1})
    hidden = _reach(beams, tracker).hidden(q, points)
    assert hidden.tolist() == [False, True, False]
    assert len(beams.beams) == 2
    assert REFLECTOR_CLEARANCE_M == 0.025 and BEAM_RADIUS_M == 1e-3
    for k, (row, start, end, radius) in enumerate(beams.beams):
        np.testing.assert_array_equal(row, q[k])
        np.testing.assert_array_equal(start, tracker)
        toward = (tracker - points[k]) / np.linalg.norm(tracker - points[k])
        np.testing.assert_allclose(end, points[k] + 0.025 * toward, atol=1e-15)
        assert np.linalg.norm(end - points[k]) == pytest.approx(0.025, rel=1e-12)
        assert radius == 1e-3


def test_without_a_tracker_or_geometry_nothing_is_hidden_and_nothing_asked():
    """No tracker: every point in sight and the checker never asked; a tracker without collision
    geometry likewise (a checker of None)."""
    beams = _Beams(blocked={0, 1})
    assert _reach(beams, None).hidden(np.zeros((2, 6)), np.ones((2, 3))).tolist() == [False, False]
    assert beams.beams == []
    assert _reach(None, np.array([2.0, 0.0, 0.0])).hidden(np.zeros((1, 6)), np.ones((1, 3))).tolist() == [False]


def test_the_floor_holds_the_joint_origins_and_says_so_in_mm():
    """A UR5 without geometry above a floor 50 mm below its mounting plane: the bodies are held above
    the lower of the two (-50 mm), said in mm; a floor 80 mm above it holds the points, not the arm
    (held above 0); the points' check is z >= floor exactly. Catches ``min(self.floor, 0.0)`` as
    ``max``, ``* 1e3`` changed in the words, and ``>=`` at the floor itself."""
    ur5 = load_robot("ur5")
    low = Reach(ur5, None, Workspace(floor=-0.05), np.zeros(6), "exact")
    assert low.workspace.lowest == -0.05
    assert "joint origins above z = -50 mm" in low.floor_words()
    high = Workspace(floor=0.08)
    assert high.lowest == 0.0
    assert high.inside([[0.0, 0.0, 0.08], [0.0, 0.0, 0.08 - 1e-12]]).tolist() == [True, False]
    assert high.words() == "above z = 80 mm"
    assert Workspace().words() == "above z = 0 mm (the mounting plane)"


def test_without_geometry_only_the_first_joints_origin_below_the_floor_at_home_is_not_held():
    """A UR5 without collision geometry whose joint origins below the floor at home (a stand-in for the
    skeleton's forward kinematics) are its first and its third joints': the first (a base flange
    turning on the floor) is not held to the floor, the third is, and the words say which. Catches
    ``self.robot.joint_names[0]`` as ``[1]``."""
    ur5 = load_robot("ur5")
    first, third = ur5.joint_names[0], ur5.joint_names[2]

    class AtHome(Reach):
        def below(self, q, exempt=True):
            names = [first, third]
            return [n for n in names if not (exempt and n in self.floor_exempt)]

    reach = AtHome(ur5, None, Workspace(), np.zeros(6), "exact")
    assert reach.floor_exempt == {first}
    assert reach.below(np.zeros(6)) == [third]
    assert reach.floor_words() == f"the robot's joint origins above z = 0 mm (not held: {first})"


def test_with_geometry_the_bases_bodies_and_the_first_joints_below_at_home_are_not_held():
    """A stand-in collision geometry on the UR5: a body fixed to the base (parent joint 0), two on the
    first joint (one below the floor at home, one not) and one on the second joint below at home: the
    base's body and the first joint's body below at home are not held to the floor; the others are.
    Catches ``body.parentJoint == 0`` changed to 1 and ``chain_joint_ids[0]`` changed to ``[1]``."""
    ur5 = load_robot("ur5")
    j1, j2 = ur5.chain_joint_ids[0], ur5.chain_joint_ids[1]
    bodies = [SimpleNamespace(name="base_0", parentJoint=0), SimpleNamespace(name="flange_0", parentJoint=j1),
              SimpleNamespace(name="shoulder_0", parentJoint=j1), SimpleNamespace(name="upper_arm_0", parentJoint=j2)]
    below_at_home = ["base_0", "flange_0", "upper_arm_0"]
    checker = SimpleNamespace(geometry=SimpleNamespace(geometryObjects=bodies),
                              bodies_below=lambda q, lowest: list(below_at_home))
    reach = Reach(ur5, checker, Workspace(), np.zeros(6), "exact")
    assert reach.floor_exempt == {"base_0", "flange_0"}
    assert reach.below(np.zeros(6)) == ["upper_arm_0"]
    assert reach.floor_words() == ("the robot's collision bodies (coal half-space) above z = 0 mm (not held: base_0, "
                                   "flange_0)")
