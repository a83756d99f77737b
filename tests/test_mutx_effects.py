"""Effects' corners no other test enters (issue 36: mutation kill rate), each against a computation
written out here: the backlash's side is the sign of Pinocchio's gravity torque whatever the arm's
masses (a light arm's torques under 1 N m too); the compact Jacobian held whole up to 64 MB and made
row by row beyond; a prismatic joint's empty table; the parameter split by the effects' sizes; the
words of the refusals of a parameter vector and of link mass factors; an effect's repr with its
options; a table's knots held to +-1000 rad in a file. Each test names a planted change it was seen
to catch."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from tcr_accuracy.effects import make_effect
from tcr_accuracy.effects.compose import split_parameters
from tcr_accuracy.effects.joint_columns import RowsWhenRead
from tcr_accuracy.effects.option_schema import check_options
from tcr_accuracy.exceptions import InputError

from conftest import random_joint_values


def _gravity_side(robot, q):
    """sign of the torque gravity exerts on each joint (minus Pinocchio's generalized gravity, the torque that
    holds the arm), 0 where it is below 1e-6 of the row set's largest."""
    data = robot.model.createData()
    tau = -np.array([pin.computeGeneralizedGravity(robot.model, data, row) for row in q])
    return np.where(np.abs(tau) > 1e-6 * np.abs(tau).max(), np.sign(tau), 0.0)


@pytest.mark.parametrize("factor", [1.0, 1e-6])
def test_backlash_rests_on_the_side_gravity_loads_whatever_the_arm_weighs(ur5, factor):
    """The UR5 at random poses, no payload and no approach direction: each joint's side of the band is the sign
    of the torque gravity exerts (minus Pinocchio's computeGeneralizedGravity here), the base joint (a vertical axis, no
    torque) in the middle; an arm a million times lighter (link masses x 1e-6: torques under 1e-4 N m) rests
    on the same sides; dq = b / 2 x side; an approach direction overrides gravity, the joint lagging behind
    it. Seen failing on ``max(float(np.abs(tau).max()), 1e-300)`` turned to ``max(..., 1.0)`` (the light
    arm's joints all put in the middle), ``np.sign(tau), 0.0`` to ``1.0``, ``-direction`` to ``direction``
    and ``0.5 * self.side`` to ``1.5``."""
    from tcr_accuracy.model.context import MeasurementContext

    rng = np.random.default_rng(17)
    q = random_joint_values(ur5, 8, rng)
    expected = _gravity_side(ur5, q)
    assert np.all(expected[:, 0] == 0.0) and np.all(expected[:, 1] != 0.0)
    effect = make_effect("backlash", ur5, link_mass_factors=[factor] * 6)
    np.testing.assert_array_equal(effect.side(q, None), expected)
    width = np.array([1e-3, 2e-3, 3e-3, 4e-3, 5e-3, 6e-3])
    np.testing.assert_allclose(effect.perturb(width, q, None).dq, width / 2 * expected, rtol=1e-15)
    defaults = MeasurementContext.defaults(8, 6)
    direction = np.zeros((8, 6))
    direction[:, 2] = np.where(np.arange(8) % 2, 1.0, -1.0)
    context = MeasurementContext(defaults.payload_kg, defaults.temperature_c, direction)
    moved = expected.copy()
    moved[:, 2] = -direction[:, 2]
    np.testing.assert_array_equal(effect.side(q, context), moved)


def test_the_compact_jacobian_is_held_whole_up_to_64_mb_and_made_row_by_row_beyond(tool_changer):
    """A cyclic series to order 12 on the tool changer's five revolute joints: 100 parameters. At 80 000 poses
    its values are exactly 64e6 bytes, held as the array; at 80 001, made when read: a row by its index
    equals that pose's own columns (the series written out here), a row and a column range, a slice of
    rows, and the whole array; the joints each column moves, the same either way. Seen failing on
    ``HELD_BYTES = 64e6`` turned to ``63999999.0``, ``[0][0, columns]`` turned to ``[0][1, columns]``
    and to ``[-1][0, columns]``, and the joints' ``[1]`` turned to ``[0]``."""
    effect = make_effect("cyclic", tool_changer, max_order=12)
    assert effect.n_params == 100
    rng = np.random.default_rng(3)
    q = rng.uniform(-3.0, 3.0, (80_001, 6))
    values, joint = effect.joint_column_values(q[:80_000])
    assert isinstance(values, np.ndarray) and values.shape == (80_000, 100)
    revolute = [j for j, k in enumerate(tool_changer.joint_kinds) if k == "revolute"]
    expected_joint = np.repeat(revolute, 20)
    np.testing.assert_array_equal(joint, expected_joint)
    lazy, joint = effect.joint_column_values(q)
    assert isinstance(lazy, RowsWhenRead) and lazy.shape == (80_001, 100)
    np.testing.assert_array_equal(joint, expected_joint)

    def by_hand(row):
        return np.concatenate([[f(n * row[j]) for n in range(3, 13) for f in (np.sin, np.cos)] for j in revolute])

    for index in (0, 7, 80_000):
        np.testing.assert_allclose(lazy[index], by_hand(q[index]), atol=1e-13)
    np.testing.assert_allclose(lazy[5, 20:40], by_hand(q[5])[20:40], atol=1e-13)
    np.testing.assert_allclose(lazy[10:13], np.array([by_hand(row) for row in q[10:13]]), atol=1e-13)
    np.testing.assert_allclose(np.asarray(lazy)[79_999], by_hand(q[79_999]), atol=1e-13)


def test_a_prismatic_joint_has_no_table_and_its_basis_no_column(tool_changer):
    """The tool changer's j4 slides: an angle table gives it no parameter, and its basis at any positions is
    no name and an (M, 0) array. Seen failing on ``np.zeros((len(angles), 0))`` turned to
    ``np.zeros((len(angles), 1))``."""
    effect = make_effect("angle_table", tool_changer, intervals=8)
    prismatic = tool_changer.joint_names[3]
    assert tool_changer.joint_kinds[3] == "prismatic"
    assert not [n for n in effect.parameter_names() if f".{prismatic}." in n]
    names, basis = effect.joint_basis(prismatic, np.linspace(0.0, 0.5, 7))
    assert names == [] and basis.shape == (7, 0)
    np.testing.assert_array_equal(effect.joint_function(np.zeros(effect.n_params), prismatic, np.zeros(4)),
                                  np.zeros(4))


def test_parameters_split_by_each_effects_size_and_a_wrong_count_is_refused(ur5):
    """One flat vector over joint_offsets (6), geometry and drift (18): split
    at the running sums of the sizes written out here; a vector one value short refused naming both counts;
    no effects, no parts. Seen failing on ``np.cumsum(sizes)[:-1]`` turned to ``[:-2]`` and ``[:1]``."""
    effects = [make_effect(name, ur5) for name in ("joint_offsets", "geometry", "drift")]
    sizes = [e.n_params for e in effects]
    flat = np.arange(float(sum(sizes)))
    parts = split_parameters(effects, flat)
    assert [p.size for p in parts] == sizes
    start = 0
    for part, size in zip(parts, sizes):
        np.testing.assert_array_equal(part, flat[start:start + size])
        start += size
    with pytest.raises(InputError, match=f"^{sum(sizes) - 1} parameter values for effects with {sum(sizes)} "
                                         "parameters$"):
        split_parameters(effects, flat[:-1])
    assert split_parameters([], []) == []


def test_a_wrong_parameter_vector_and_bad_link_mass_factors_are_named_in_their_words(ur5):
    """check_params: a vector of the wrong length names the count given, the count the effect has and its
    first four names; a NaN is refused. link_mass_factors: the first factor below 0 (or not finite) named by
    its index and value, whichever others are bad after it. Seen failing on ``parameter_names()[:4]`` turned
    to ``[:5]``, and on ``bad[0]`` turned to ``bad[-1]`` and ``bad[1]`` in the message."""
    effect = make_effect("joint_offsets", ur5)
    names = effect.parameter_names()
    with pytest.raises(InputError) as refused:
        effect.check_params(np.zeros(5))
    assert str(refused.value) == (f"effect joint_offsets: 5 parameter values given, it has 6 ({', '.join(names[:4])}, "
                                  "...)")
    with pytest.raises(InputError, match="^effect joint_offsets: non-finite parameter value$"):
        effect.check_params([0.0, 0.0, np.nan, 0.0, 0.0, 0.0])
    with pytest.raises(ValueError) as refused:
        make_effect("compliance", ur5, link_mass_factors=[1.0, 1.0, -0.5, 1.0, -2.0, np.inf])
    assert str(refused.value) == "link_mass_factors[2]: -0.5 is not a factor >= 0"
    with pytest.raises(ValueError) as refused:
        make_effect("compliance", ur5, link_mass_factors=[1.0, np.nan, 1.0, 1.0, 1.0, 1.0])
    assert str(refused.value) == "link_mass_factors[1]: nan is not a factor >= 0"


def test_an_effects_repr_names_its_robot_and_the_options_it_was_given(ur5):
    """repr: the class, the robot's name and the options that differ from the defaults, comma-separated.
    Seen failing on the options' ``', ' + opts`` joined otherwise."""
    assert repr(make_effect("joint_offsets", ur5)) == "JointOffsets(ur5)"
    assert repr(make_effect("drift", ur5, span=30.0, time_axis="time_s")) == \
        "Drift(ur5, time_axis='time_s', span=30.0)"


def test_a_files_table_knots_are_held_to_a_thousand_radians_either_way():
    """An angle table's inner knots read from a file: -1000 and 1000 rad taken, -1000.001 refused naming the
    option. Seen failing on the knots' ``"minimum": -1e3`` turned to ``-1001.0``."""
    where = "d.json: effect_options.angle_table"
    assert check_options("angle_table", {"knots": [[-1e3, 0.0, 1e3]]}, where) == {"knots": [[-1e3, 0.0, 1e3]]}
    with pytest.raises(InputError, match=r"^d\.json: effect_options\.angle_table\.knots\[0\]\[0\]: "):
        check_options("angle_table", {"knots": [[-1000.001]]}, where)


def test_clearance_without_a_draw_is_the_mean_robot_and_cyclic_terms_are_radians(ur5):
    """Clearance is scatter: with no random generator (its own or the context's) it gives the mean robot, an
    (N, error-vector) array of zeros, one row per pose, and still refuses a wrong parameter count; each
    cyclic term is in rad, one unit per parameter. Seen failing on the zeros' ``q.shape[0]`` turned to
    ``q.shape[1]`` and ``["rad"] * self.n_params`` turned to ``["rad"] * (self.n_params + 1)``."""
    effect = make_effect("clearance", ur5)
    q = np.zeros((4, 6))
    out = effect.perturb([1e-5, 1e-5, 1e-5], q, None)
    assert out.dq is None
    np.testing.assert_array_equal(out.x, np.zeros((4, effect.error_model.size)))
    with pytest.raises(InputError, match="^effect clearance: 4 parameter values given, it has 3 "):
        effect.perturb(np.zeros(4), q, None)
    cyclic = make_effect("cyclic", ur5, max_order=5)
    assert cyclic.parameter_units() == ["rad"] * 36 and cyclic.n_params == 36


def test_a_noise_estimate_is_written_in_mm():
    """NoiseEstimate.to_dict: the per-axis figure in mm (x 1e3 of its m), its source, independence and detail
    as they are. Seen failing on ``self.per_axis * 1e3`` turned to ``* 1001.0``."""
    from tcr_accuracy.frames.noise import NoiseEstimate

    doc = NoiseEstimate(2.5e-5, "rigid frames", True, "two reflectors").to_dict()
    assert doc == {"per_axis_mm": pytest.approx(0.025, rel=1e-12), "source": "rigid frames", "independent": True,
                   "detail": "two reflectors"}
