"""A comparison of two diagnoses (``diagnosis/compare.py``): a change's z read back from its JSON where the fits
gave none (null), and the refusals of two fits whose common parameter belongs to two effects, or of a parameter
the robot's effect does not have, word for word (three branches no test entered). Each test names planted
changes it was seen to catch (issue 36)."""

from __future__ import annotations

import math

import pytest

from tcr_accuracy.diagnosis import compare
from tcr_accuracy.diagnosis.compare import FittedModel, check_same_robot
from tcr_accuracy.exceptions import InputError
from tcr_accuracy.model.robot import load_robot


@pytest.mark.parametrize("change, z", [({"z": 2.5, "std_error": 0.1, "change": 0.25}, 2.5),
                                       ({"z": None, "std_error": 0, "change": 1e-6}, math.inf),
                                       ({"z": None, "std_error": 0.0, "change": -1e-6}, math.inf),
                                       ({"z": None, "std_error": 0, "change": 0.0}, 0.0),
                                       ({"z": None, "std_error": 1.0, "change": 1e-6}, 0.0),
                                       ({"z": None, "std_error": None, "change": 1e-6}, 0.0)])
def test_a_null_z_is_infinite_only_where_the_value_moved_without_a_standard_error(change, z):
    """null z: inf where the standard error is exactly 0 and the value moved (either way), 0 otherwise (no
    standard error, or nothing moved); a z given is read as it is. Seen failing on ``== 0`` -> ``== 1`` and the
    0.0 returned -> 1.0 (that line ran in no test)."""
    assert compare._z(change) == z


def _fit(effect, name, value, source):
    return FittedModel("ur5", {effect: {name: value}}, {effect: {name: 1e-5}}, {effect: {name: "rad"}},
                       {effect: {}}, source)


def test_a_parameter_of_two_effects_is_refused_naming_both():
    """The same parameter name fitted under joint_offsets in one diagnosis and geometry in the other: refused,
    naming the parameter, each effect and each file (that line ran in no test)."""
    robot = load_robot("ur5")
    old, new = _fit("joint_offsets", "x.j2", 1e-3, "a.json"), _fit("geometry", "x.j2", 2e-3, "b.json")
    with pytest.raises(InputError) as err:
        check_same_robot(robot, old, new)
    assert str(err.value) == "parameter x.j2 belongs to joint_offsets in a.json but to geometry in b.json"


def test_a_parameter_the_robots_effect_does_not_have_is_refused_naming_the_robot_and_tool():
    """A joint offset of a seventh joint on the six-joint UR5: refused naming the parameter, the robot, the
    effect and the tool frame (that line ran in no test); the offsets it has give positions."""
    robot = load_robot("ur5")
    with pytest.raises(InputError) as err:
        compare._effects(robot, {"joint_offsets": {"joint_offsets.j7": 1e-3}}, {})
    assert str(err.value) == (f"parameter joint_offsets.j7 is not one of ur5's joint_offsets parameters (tool frame "
                              f"{robot.tool_frame!r}): give the robot= and tool= the diagnosis used")
