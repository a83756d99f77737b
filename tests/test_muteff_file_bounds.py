"""The bounds a file's effect options and setup parameters are held to (``effects/option_schema.py``,
``effects/file_values.py``), each tried at the bound (accepted) and just beyond it (refused with one line
naming the file, the key and the option) (issue 36). Each bound is the one the module's comments state;
a bound moved by one (a planted change) accepts the value beyond or refuses the one on it."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from tcr_accuracy.effects import make_effect
from tcr_accuracy.effects.file_values import effect_options, parameter_vector
from tcr_accuracy.effects.option_schema import check_options
from tcr_accuracy.exceptions import InputError

WHERE = "d.json: effect_options"


@pytest.mark.parametrize("effect, option, on_the_bound, beyond", [
    ("angle_table", "intervals", 4, 3), ("angle_table", "intervals", 1000, 1001),
    ("angle_table", "lower", [-1e3], [-1000.001]), ("angle_table", "upper", [1e3], [1000.001]),
    ("angle_table", "lower", [0.0] * 10_000, [0.0] * 10_001),
    ("angle_table", "knots", [[0.0] * 999], [[0.0] * 1000]), ("angle_table", "knots", [[1e3, -1e3]], [[1000.001]]),
    ("angle_table", "knots", [None] * 10_000, [None] * 10_001),
    ("compliance", "link_mass_factors", [0.0, 1e3], [-1e-9]), ("backlash", "link_mass_factors", [1e3], [1000.001]),
    ("lateral_compliance", "link_mass_factors", [1.0] * 10_000, [1.0] * 10_001),
    ("clearance", "joints", ["j" * 1000], ["j" * 1001]), ("clearance", "joints", ["j"], [""]),
    ("geometry", "components", ["j1.dx"] * 100_000, ["j1.dx"] * 100_001),
    ("cyclic", "max_order", 3, 2), ("cyclic", "max_order", 200, 201),
    ("drift", "start", -1e12, -1e12 - 1), ("drift", "start", 1e12, 1e12 + 1),
    ("drift", "span", 1e-300, 0.0), ("drift", "span", 1e12, 1e12 + 1),
    ("drift", "time_constant", 1e-300, 0.0), ("drift", "time_constant", 100.0, 100.001),
    ("frames", "sessions", ["a"] * 10_000, ["a"] * 10_001),
    ("thermal", "reference_temperature_c", -273.15, -273.16), ("thermal", "reference_temperature_c", 1000, 1000.01),
    ("transmission", "harmonics", [1], []), ("transmission", "harmonics", list(range(1, 101)), [0]),
    ("transmission", "harmonics", [100], [101]), ("transmission", "harmonics", [1, 2], [2, 2]),
])
def test_an_option_on_its_bound_is_taken_and_one_beyond_it_refused_naming_it(effect, option, on_the_bound, beyond):
    """The schema's bounds as its comments give them: at most 1000 knot intervals and 1000 rad of travel, 999
    inner knots a joint, link masses 0 to 1000 times the URDF's, names of 1 to 1000 characters, 3 to 200
    Fourier orders, a campaign's start and span within 1e12 (the span and the warm-up's time constant
    above 0, the latter at most 100 spans), -273.15 to 1000 degC, harmonics 1 to 100 (1 to 100 of them,
    each once), lists up to 10 000 (100 000 names). Seen failing on ``"maximum": 200`` turned to ``201``,
    ``"minimum": -273.15`` to ``-274.15``, ``"exclusiveMinimum": 0`` to ``-1`` and ``"maxItems": 999`` to
    ``1000``."""
    assert check_options(effect, {option: on_the_bound}, f"{WHERE}.{effect}") == {option: on_the_bound}
    with pytest.raises(InputError, match=rf"^{WHERE}\.{effect}\.{option}"):
        check_options(effect, {option: beyond}, f"{WHERE}.{effect}")


def test_a_files_whole_numbers_reals_and_texts_are_held_to_their_sizes_before_the_schema():
    """An integer option from 0 to 1000 (1001 refused as not such a whole number, before the schema's own
    bound), a real one within 1e9 in size, a text of at most 200 characters, a list of at most 1000
    items (each item a number, a short text or a list of numbers). Seen failing on
    ``MAX_INTEGER_OPTION = 1000`` turned to ``1001``, ``MAX_REAL_OPTION = 1e9`` to ``1e9 + 1`` and
    ``len(value) > 200`` to ``> 201``."""
    where = f"{WHERE}.angle_table"
    assert effect_options("angle_table", {"intervals": 1000}, where) == {"intervals": 1000}
    with pytest.raises(InputError, match=r"intervals: 1001 is not a whole number from 0 to 1000$"):
        effect_options("angle_table", {"intervals": 1001}, where)
    assert effect_options("drift", {"start": -1e9, "span": 1e9}, f"{WHERE}.drift") == {"start": -1e9, "span": 1e9}
    with pytest.raises(InputError, match=r"drift\.span: 1e\+09 is beyond 1e\+09$"):
        effect_options("drift", {"span": 1e9 + 1}, f"{WHERE}.drift")
    with pytest.raises(InputError, match=r"time_axis: 'x{201}' is not a short text$"):
        effect_options("drift", {"time_axis": "x" * 201}, f"{WHERE}.drift")
    with pytest.raises(InputError, match=r"time_axis: 'x{200}' is not one of"):  # short enough: the schema's turn
        effect_options("drift", {"time_axis": "x" * 200}, f"{WHERE}.drift")
    assert effect_options("angle_table", {"lower": [-1000] + [0.5] * 999}, where) == {"lower": [-1000] + [0.5] * 999}
    with pytest.raises(InputError, match=r"lower: 1001 items; at most 1000$"):
        effect_options("angle_table", {"lower": [0.5] * 1001}, where)
    with pytest.raises(InputError, match=r"^d.json: effect_options.clearance.joints\[0\]: 'j{201}' is not a number$"):
        effect_options("clearance", {"joints": ["j" * 201]}, f"{WHERE}.clearance")
    with pytest.raises(InputError, match=r"^d.json: effect_options.angle_table.lower\[0\]: 1001 is greater than the "
                                         r"maximum of 1000"):  # a whole number beyond 1000: a real, then bounded
        effect_options("angle_table", {"lower": [1001]}, where)


@pytest.mark.parametrize("name, bound", [("frames.tool.dz", 10.0), ("frames.base.dx", 1000.0),
                                         ("frames.base.rz", 2 * math.pi), ("frames.tool.rx", 2 * math.pi)])
def test_a_setup_parameter_from_a_file_is_held_within_its_stated_bound(tool_changer, name, bound):
    """The measured point within 10 m of the TCP frame, the tracker within 1000 m of the base, any rotation
    within one turn: on the bound taken, 0.1 % beyond refused naming the key, its value, unit and both
    ranges. Seen failing on ``"tool_m": 10.0`` turned to ``11.0``, ``"base_m": 1000.0`` to ``1001.0`` and
    ``2.0 * math.pi`` to ``3.0 * math.pi``."""
    effect = make_effect("frames", tool_changer, tool_rotation=True)
    where = "m.yaml: parameters.frames"
    vector = parameter_vector(effect, {name: -bound}, where)
    assert vector[effect.parameter_names().index(name)] == -bound and np.count_nonzero(vector) == 1
    unit = "rad" if name.rsplit(".", 1)[-1].startswith("r") else "m"
    said = (f"{where}.{name}: {bound * 1.001:.6g} {unit} is beyond what a diagnosis can fit (-{bound:.3g} to "
            f"{bound:.3g} {unit}; physical range -inf to inf {unit})")
    with pytest.raises(InputError, match=f"^{re.escape(said)}$"):
        parameter_vector(effect, {name: bound * 1.001}, where)
