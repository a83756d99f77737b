"""Every effect is made as the vocabulary documents it: the robot first (also by keyword), each option
by keyword only, and each option's default the documented one.

The defaults are written out here from the effects' documentation (a drift's warm-up constant is a
quarter of the campaign, a thermal model's reference 20 degC, 30 cyclic orders, 16 angle-table
intervals, transmission harmonics 1 and 2, ...). An effect built with those values given
explicitly reports no option (``Effect.options`` lists what differs from the default), so a default
moved by one (a planted ``time_constant: float = 0.25`` -> ``1.25``, ``max_order: int = 30`` ->
``31``, ``reference_temperature_c: float = 20.0`` -> ``21.0``) reports the documented value as an
option and fails; the keyword-only marker turned positional-only (``*`` -> ``/``: seen failing on
the clearance effect's) refuses the robot by keyword, and a marker removed takes an option by
position.
"""

import inspect

import pytest

from tcr_accuracy.effects.base import effect_classes

#: effect -> its options' documented defaults
DOCUMENTED = {
    "frames": {"tool_rotation": False, "sessions": None, "session_frames": True, "session_tools": False},
    "joint_offsets": {},
    "geometry": {"components": None},
    "compliance": {"link_mass_factors": None},
    "lateral_compliance": {"link_mass_factors": None},
    "backlash": {"link_mass_factors": None},
    "thermal": {"per_link": False, "reference_temperature_c": 20.0},
    "drift": {"time_axis": "order", "start": 0.0, "span": 1.0, "time_constant": 0.25},
    "encoder_scale": {},
    "transmission": {"harmonics": (1, 2)},
    "cyclic": {"max_order": 30},
    "angle_table": {"intervals": 16, "lower": None, "upper": None, "knots": None},
    "clearance": {"joints": None, "rng": None},
    "unmodelled": {},
    "link_bending": {},
}


def test_every_effect_of_the_registry_is_listed_here():
    assert set(effect_classes(vocabulary_only=False)) == set(DOCUMENTED)


@pytest.mark.parametrize("name", sorted(DOCUMENTED))
def test_the_documented_defaults_are_the_defaults(name, tool_changer):
    cls = effect_classes(vocabulary_only=False)[name]
    given = cls(robot=tool_changer, **DOCUMENTED[name])  # the robot by keyword too
    assert given.options == {}, given.options
    assert given.robot is tool_changer
    plain = cls(tool_changer)
    for option, value in DOCUMENTED[name].items():
        assert getattr(plain, option) == value or (value is not None and tuple(getattr(plain, option)) == value)
    assert plain.parameter_names() == given.parameter_names()


@pytest.mark.parametrize("name", sorted(n for n, options in DOCUMENTED.items() if options))
def test_options_are_taken_by_keyword_only(name, tool_changer):
    cls = effect_classes(vocabulary_only=False)[name]
    option, value = next(iter(DOCUMENTED[name].items()))
    with pytest.raises(TypeError):
        cls(tool_changer, value)
    keyword_only = [p.name for p in inspect.signature(cls.__init__).parameters.values()
                    if p.kind is inspect.Parameter.KEYWORD_ONLY]
    assert keyword_only == list(DOCUMENTED[name])


@pytest.mark.parametrize("name, option, other", [
    ("thermal", "reference_temperature_c", 25.0), ("drift", "time_constant", 0.5), ("drift", "span", 2.0),
    ("drift", "start", 1.0), ("cyclic", "max_order", 12), ("angle_table", "intervals", 8),
    ("transmission", "harmonics", (1, 2, 3)), ("frames", "session_frames", False),
])
def test_an_option_away_from_its_default_is_reported(name, option, other, tool_changer):
    effect = effect_classes(vocabulary_only=False)[name](tool_changer, **{option: other})
    assert list(effect.options) == [option]
