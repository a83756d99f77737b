"""Drift and the cyclic error (``effects/drift.py``, ``effects/cyclic.py``) on the tool changer, whose
fourth joint slides: the figures their physics states per joint kind (typical sizes, the physical
range and the fit's), a slide's drift put into Pinocchio's forward kinematics here, and the cyclic
series' orders counted over the revolute joints only. Each test names a planted change it was seen
to catch.
"""

import math

import numpy as np
import pytest

from tcr_accuracy.effects import make_effect, predict_positions
from tcr_accuracy.model.context import MeasurementContext

from conftest import pinocchio_kinematics, random_joint_values

DEG = math.pi / 180


def test_drift_sizes_per_joint_kind_on_a_robot_with_a_slide(tool_changer):
    """The drift's two shapes per joint: typical 0.01 deg per revolute joint, 0.02 mm per slide, 0.05 mm
    per base axis; physics 0.2 deg / 0.5 mm (joint) and 0.5 mm (base); the fit's range 5 deg / 10 mm
    and 10 mm; units rad or m by kind. Seen failing on the slide's ``2e-5`` as ``1.00002``, the
    physical range's ``5e-4`` of a slide as ``1.0005`` and the fit range's slide ``0.01`` as
    ``1.01``."""
    effect = make_effect("drift", tool_changer)
    slide = np.repeat([k == "prismatic" for k in tool_changer.joint_kinds], 2)
    assert slide.sum() == 2
    assert effect.parameter_units() == ["m" if s else "rad" for s in slide] + ["m"] * 6
    np.testing.assert_allclose(effect.parameter_scales(), np.r_[np.where(slide, 2e-5, 0.01 * DEG), np.full(6, 5e-5)],
                               rtol=1e-12)
    lower, upper = effect.physical_range()
    np.testing.assert_allclose(upper, np.r_[np.where(slide, 5e-4, 0.2 * DEG), np.full(6, 5e-4)], rtol=1e-12)
    np.testing.assert_allclose(lower, -upper, rtol=1e-12)
    wide_lower, wide_upper = effect.fit_range()
    np.testing.assert_allclose(wide_upper, np.r_[np.where(slide, 0.01, 5 * DEG), np.full(6, 0.01)], rtol=1e-12)
    np.testing.assert_allclose(wide_lower, -wide_upper, rtol=1e-12)
    warm_up, slip = effect.mechanisms()
    np.testing.assert_allclose([warm_up.lower, warm_up.upper, slip.lower, slip.upper],
                               [-upper, upper, -wide_upper, wide_upper], rtol=1e-12)


def test_a_slides_drift_moves_the_tcp_as_pinocchio_says(tool_changer):
    """The slide (j4) drifting 0.3 mm linearly and 0.1 mm in a warm-up over 7 rows in measurement order
    (start 0, span 6, tau 0.25): its joint value moved by a_lin (u - 1/2) + a_warm (w(u) - mean w), the
    TCP by Pinocchio at the moved joints. Seen failing on the shapes' ``u - 0.5`` as ``u - 1.5`` and
    on ``np.clip(..., 0.0, None)`` turned to ``1.0``."""
    rng = np.random.default_rng(17)
    n = 7
    q = random_joint_values(tool_changer, n, rng)
    base = MeasurementContext.defaults(n, 6)
    context = MeasurementContext(base.payload_kg, base.temperature_c, base.direction, order=np.arange(n, dtype=float))
    effect = make_effect("drift", tool_changer, time_axis="order", start=0.0, span=float(n - 1))
    params = np.zeros(effect.n_params)
    params[6:8] = [3e-4, 1e-4]  # j4's linear and warm-up
    u = np.arange(n) / (n - 1)
    settle = 1 - math.exp(-4.0)
    warm = (1 - np.exp(-u / 0.25)) / settle - (1 - 0.25 * settle) / settle
    moved = q.copy()
    moved[:, 3] += 3e-4 * (u - 0.5) + 1e-4 * warm
    expected = np.array([pinocchio_kinematics(tool_changer, row)[1].translation for row in moved])
    np.testing.assert_allclose(predict_positions(tool_changer, [effect], [params], q, context), expected, atol=1e-12)
    assert np.abs(moved - q).max() > 1e-4


@pytest.mark.parametrize("n_poses, order", [(10, 3), (61, 5), (200, 12), (579, 30), (100000, 30)])
def test_the_cyclic_orders_count_the_revolute_joints_only(tool_changer, n_poses, order):
    """Five revolute joints and a slide: the highest order 2 + N // (4 x 5), at least 3 and at most 30;
    the series has 2 (max_order - 2) terms per revolute joint and none for the slide, 50 urad each,
    in rad. Seen failing on the policy counting every joint (``4 * 6``: 61 poses give 4, 200 give 10)."""
    effect = make_effect("cyclic", tool_changer)
    assert effect.fit_policy.options_for_data(tool_changer, np.zeros((n_poses, 6)), None) == {"max_order": order}
    sized = make_effect("cyclic", tool_changer, max_order=order)
    names = sized.parameter_names()
    assert len(names) == 5 * 2 * (order - 2) == sized.n_params
    assert not any(".j4." in name for name in names)
    assert names[-1] == f"cyclic.j6.b{order}"
    np.testing.assert_allclose(sized.parameter_scales(), 5e-5)
    assert sized.parameter_units() == ["rad"] * sized.n_params


def test_a_mechanism_reads_only_the_values_beyond_two_standard_errors_and_their_intervals(ur5):
    """UR5 encoder zeros with standard errors of 0.01 rad: j1 at 2.1 sigma (resolved), j2 at 1.9 sigma (not),
    j3 at 10 deg + 1.5 sigma (resolved; its interval value +- 2 sigma reaches the 10 deg of an encoder zero),
    j4 at 10 deg + 2.5 sigma (resolved; its interval starts beyond 10 deg: a joint mastered on the wrong mark),
    the rest 0. The parameters read are j1, j3, j4 with those mechanisms, weighed by value over the 0.03 deg
    typical size; each joint named with its share. Seen failing on ``np.abs(values) > significance *
    finite_std`` as ``+`` (nothing resolved, so all read), on the default ``significance: float = 2.0``
    changed and on the interval's ``significance * finite_std`` as ``+``."""
    from tcr_accuracy.effects.mechanisms import read_mechanism

    effect = make_effect("joint_offsets", ur5)
    sigma, ten = 0.01, math.radians(10.0)
    values = np.array([2.1 * sigma, 1.9 * sigma, ten + 1.5 * sigma, ten + 2.5 * sigma, 0.0, 0.0])
    reading = read_mechanism(effect, values, np.full(6, sigma))
    names = effect.parameter_names()
    assert [(p["parameter"], p["mechanism"]) for p in reading.parameters] == [
        (names[0], "encoder_zero"), (names[2], "encoder_zero"), (names[3], "wrong_mark")]
    weight = np.abs(values[[0, 2, 3]]) / math.radians(0.03)
    own, wrong = (weight[0] + weight[1]) / weight.sum(), weight[2] / weight.sum()
    assert reading.keys == ("encoder_zero", "wrong_mark")
    assert f"shoulder_pan_joint, elbow_joint, {own:.0%} of its TCP motion" in reading.mechanism
    assert f"wrist_1_joint, {wrong:.0%} of its TCP motion" in reading.mechanism
    assert reading.physical and not reading.textbook


def test_an_angle_tables_knot_lists_hold_ten_thousand_joints_of_999_knots_at_most():
    """The schema's bounds on an angle table's ``knots`` option: at most 10 000 joints' lists (10 001
    refused), each of at most 999 inner knots (1000 refused), one line naming the option. A fast test of
    its own, so that a mutation run's budget reaches it. Seen failing on ``"maxItems": 10_000`` as 9999
    and ``"maxItems": 999`` as 998."""
    from tcr_accuracy.effects.option_schema import check_options
    from tcr_accuracy.exceptions import InputError

    for knots, taken in (([None] * 10_000, True), ([None] * 10_001, False), ([[0.0] * 999], True),
                         ([[0.0] * 1000], False)):
        if taken:
            assert check_options("angle_table", {"knots": knots}, "d.json") == {"knots": knots}
        else:
            with pytest.raises(InputError, match=r"^d\.json\.knots"):
                check_options("angle_table", {"knots": knots}, "d.json")


@pytest.mark.parametrize("name", ["cyclic", "angle_table"])
def test_values_made_when_read_are_a_two_dimensional_float_array_like(ur5, name):
    """The compact Jacobian values the diagnosis keeps as rows made when read (a cyclic series', an angle
    table's): to numpy an (N, k) float array like the one it stands for, np.ndim 2, its rows and
    columns those of the whole array. Seen failing on ``ndim = 2`` as ``ndim = 1``."""
    from tcr_accuracy.effects.angle_table import TableValues
    from tcr_accuracy.effects.joint_columns import RowsWhenRead

    effect = make_effect(name, ur5)
    q = random_joint_values(ur5, 7, np.random.default_rng(3))
    whole = effect.joint_columns(q)[0]
    lazy = RowsWhenRead(effect, q) if name == "cyclic" else TableValues(effect, q)
    assert np.ndim(lazy) == 2 and np.shape(lazy) == whole.shape and lazy.dtype == np.dtype(float)
    np.testing.assert_allclose(np.asarray(lazy), whole, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(lazy[[1, 4]], whole[[1, 4]], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(lazy[2, 3:6], whole[2, 3:6], rtol=1e-12, atol=1e-15)
