"""An angle table's modes (``effects/angle_table.py``) against integrals taken here with scipy's adaptive
quadrature (issue 36): each mode of unit RMS over the travel, orthogonal to what the other joint-side
effects hold (1, q, the first two harmonics) and to the other modes, its roughness weight the mean
squared curvature over 81; the knots clamped where the options put them; the options the diagnosis
takes from the data; the cycles per turn by the modes' roots; the TCP by Pinocchio. Each test names a
planted change it was seen to catch."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.interpolate import BSpline, PPoly

from tcr_accuracy.effects import make_effect, predict_positions
from tcr_accuracy.effects.angle_table import density_knots, joint_table, travel
from tcr_accuracy.model.context import MeasurementContext

from conftest import pinocchio_kinematics


def _mean_over(f, knots):
    """(1 / travel) x the integral of f over the travel, interval by interval (scipy's quad)."""
    inner = np.unique(knots)
    total = sum(quad(f, a, b, epsabs=1e-13, epsrel=1e-11, limit=200)[0] for a, b in zip(inner[:-1], inner[1:]))
    return total / (inner[-1] - inner[0])


@pytest.mark.parametrize("lower, upper, intervals, inner", [
    (-2.0, 3.0, 9, None),
    (-1.0, 1.5, 8, [-0.8, -0.5, -0.45, -0.1, 0.3, 0.9, 1.2]),
])
def test_each_mode_has_unit_rms_holds_nothing_of_the_other_effects_and_its_weight_is_its_curvature(
        lower, upper, intervals, inner):
    """Over the travel (scipy's quad, interval by interval): each mode's mean square is 1, its mean product
    with 1, q, sin q, cos q, sin 2q, cos 2q is 0 (to 1e-9 of their RMS), with another mode 0; its weight
    is the mean of its squared second derivative over 81 (the spline's derivative, scipy's), the
    weights rising (smoothest first); the knots clamped, three repeats of each end around the equal
    (or given) inner ones; each mode's first coefficient of note positive. Seen failing on
    ``/ 81.0`` turned to ``/ 82.0``, ``CONSTRAINED = 6`` to ``5``, ``np.full(DEGREE, lower)`` to
    ``DEGREE + 1`` repeats, ``(half * weights).ravel() / (upper - lower)`` to ``* (upper - lower)``
    and ``np.sin(2 * grid)`` to ``np.sin(3 * grid)``."""
    table = joint_table(lower, upper, intervals, inner)
    place = np.linspace(lower, upper, intervals + 1) if inner is None else np.r_[lower, inner, upper]
    np.testing.assert_allclose(table.knots, np.r_[[lower] * 3, place, [upper] * 3], rtol=0, atol=1e-15)
    m = intervals + 3 - 6
    assert table.modes.shape == (intervals + 3, m) and table.weights.shape == (m,)
    splines = [BSpline(table.knots, table.modes[:, i], 3) for i in range(m)]
    curvature = [s.derivative(2) for s in splines]
    others = [np.ones_like, lambda x: x, np.sin, np.cos, lambda x: np.sin(2 * x), lambda x: np.cos(2 * x)]
    for i in range(m):
        assert _mean_over(lambda x: splines[i](x) ** 2, table.knots) == pytest.approx(1.0, abs=1e-9)
        for f in others:
            size = math.sqrt(_mean_over(lambda x: f(x) ** 2, table.knots))
            assert abs(_mean_over(lambda x: splines[i](x) * f(x), table.knots)) < 1e-9 * size
        for k in range(i):
            assert abs(_mean_over(lambda x: splines[i](x) * splines[k](x), table.knots)) < 1e-9
        roughness = _mean_over(lambda x: curvature[i](x) ** 2, table.knots)
        assert table.weights[i] == pytest.approx(roughness / 81.0, rel=1e-7, abs=1e-12)
        first = np.flatnonzero(np.abs(table.modes[:, i]) > 1e-3 * np.abs(table.modes[:, i]).max())[0]
        assert table.modes[first, i] > 0
    assert np.all(np.diff(table.weights) >= -1e-9 * table.weights.max())
    # the values: the splines' own, held at the nearer end outside the travel
    angles = np.array([lower - 1.0, lower, 0.5 * (lower + upper), upper, upper + 2.0])
    expected = np.array([[s(min(max(a, lower), upper)) for s in splines] for a in angles])
    np.testing.assert_allclose(table.values(angles), expected, rtol=1e-10, atol=1e-12)


def test_travel_widens_to_a_fifth_of_a_radian_and_inner_knots_follow_the_poses_four_fifths_of_the_way():
    """A travel narrower than 0.2 rad is widened about its middle to 0.2 rad; the inner knots are 0.8 x the
    angles' quantiles at 1/n .. (n-1)/n (numpy's, of the angles clipped to the travel) plus 0.2 x the equal
    intervals' knots. Seen failing on ``MIN_SPAN = 0.2`` turned to ``1.2``, ``0.5 * (lower + upper)`` to
    ``1.5 * ...`` and ``UNIFORM_SHARE = 0.2`` to ``1.2``."""
    assert travel(0.3, 0.35) == pytest.approx((0.225, 0.425), abs=1e-15)
    assert travel(-1.0, 2.0) == (-1.0, 2.0)
    rng = np.random.default_rng(29)
    angles = np.r_[rng.normal(0.5, 0.3, 200), [-9.0, 9.0]]  # two beyond the travel, clipped
    got = density_knots(angles, -1.0, 2.0, 6)
    share = np.arange(1, 6) / 6
    expected = 0.8 * np.quantile(np.clip(angles, -1.0, 2.0), share) + 0.2 * (-1.0 + 3.0 * share)
    np.testing.assert_allclose(got, expected, rtol=1e-12)
    np.testing.assert_allclose(density_knots(np.zeros(0), -1.0, 2.0, 6), -1.0 + 3.0 * share, rtol=1e-12)


def test_the_diagnosis_options_give_eight_poses_per_parameter_between_8_and_256_intervals(tool_changer):
    """The tool changer (five revolute joints, j4 prismatic): intervals = min(256, max(8, 3 + N // 40)) for
    N poses; the travel each joint's measured min and max; the knots density_knots of its angles, None for
    the prismatic joint. Seen failing on ``POSES_PER_PARAMETER = 8`` turned to ``9``, ``MAX_INTERVALS =
    256`` to ``257`` and ``max(8, ...)`` to ``max(9, ...)``."""
    effect = make_effect("angle_table", tool_changer)
    rng = np.random.default_rng(31)
    for n, intervals in ((200, 8), (240, 9), (1000, 28), (10119, 255), (10160, 256)):
        q = rng.uniform(-1.0, 1.0, (n, 6))
        options = effect.fit_policy.options_for_data(tool_changer, q, None)
        assert options["intervals"] == min(256, max(8, 3 + n // 40)) == intervals
    assert options["lower"] == pytest.approx(q.min(axis=0).tolist()) and options["upper"] == pytest.approx(
        q.max(axis=0).tolist())
    assert options["knots"][3] is None
    np.testing.assert_allclose(options["knots"][1], density_knots(q[:, 1], q[:, 1].min(), q[:, 1].max(), 256),
                               rtol=1e-12)


def test_cycles_per_turn_count_each_modes_roots_and_the_table_turns_the_joints_on_pinocchio(ur5):
    """A UR5 table over +-300 deg on every joint, 12 intervals: each mode's cycles per turn are half its
    sign changes (the spline's roots inside the travel, scipy's PPoly) over the travel in turns; a mode
    at 2.5 or more a turn is read as a gear or encoder error, a slower one as cable wind-up (each
    mechanism's range open for its own modes only). The TCP by Pinocchio at q + the table's dq (each
    joint's modes times its parameters); each joint's function the same sum. Seen failing on
    ``changes / 2.0`` turned to ``/ 3.0``, ``CYCLIC_PER_TURN = 2.5`` to ``3.5`` and the values' chunk
    ``dq[start:start + self.CHUNK, j]`` summing ``params[joint == j]`` turned to another joint's."""
    half = math.radians(300.0)
    effect = make_effect("angle_table", ur5, intervals=12, lower=[-half] * 6, upper=[half] * 6)
    table = effect.table(0)
    turns = 2 * half / (2 * math.pi)
    expected = []
    for i in range(effect.modes_per_joint):
        pp = PPoly.from_spline(BSpline(table.knots, table.modes[:, i], 3))
        roots = pp.roots(extrapolate=False)
        roots = np.unique(np.round(roots[(roots > -half + 1e-6) & (roots < half - 1e-6)], 9))
        expected.append(len(roots) / 2 / turns)
    cycles = effect.mode_cycles_per_turn()
    np.testing.assert_allclose(cycles, np.tile(expected, 6), rtol=1e-12)
    assert min(expected) < 2.5 <= max(expected)  # both readings occur
    fast = cycles >= 2.5
    gear, cable, slip = effect.mechanisms()
    np.testing.assert_allclose(gear.upper[fast], 1e-3) and np.testing.assert_allclose(cable.upper[~fast], 1e-3)
    assert np.all(gear.upper[~fast] < gear.lower[~fast]) and np.all(cable.upper[fast] < cable.lower[fast])
    np.testing.assert_allclose(slip.upper, 1e-2)

    rng = np.random.default_rng(37)
    q = rng.uniform(-half, half, (5, 6))
    params = rng.normal(0.0, 3e-4, effect.n_params)
    m = effect.modes_per_joint
    dq = np.stack([effect.table(j).values(q[:, j]) @ params[j * m:(j + 1) * m] for j in range(6)], axis=1)
    for j in range(6):
        spline = BSpline(effect.table(j).knots, effect.table(j).modes @ params[j * m:(j + 1) * m], 3)
        np.testing.assert_allclose(dq[:, j], spline(q[:, j]), rtol=1e-10, atol=1e-15)
        np.testing.assert_allclose(effect.joint_function(params, ur5.joint_names[j], q[:, j]), dq[:, j], rtol=1e-12)
    expected_tcp = np.array([pinocchio_kinematics(ur5, row)[1].translation for row in q + dq])
    got = predict_positions(ur5, [effect], [params], q, MeasurementContext.defaults(5, 6))
    np.testing.assert_allclose(got, expected_tcp, atol=1e-12)
    np.testing.assert_allclose(effect.fit_policy.penalty_weights(effect),
                               np.concatenate([effect.table(j).weights for j in range(6)]), rtol=1e-12)


def test_a_table_needs_four_intervals_and_inner_knots_strictly_inside_its_travel(ur5):
    """At least CONSTRAINED - DEGREE + 1 = 4 knot intervals (3 refused, naming 4); given knots, intervals - 1
    strictly increasing angles inside the travel (widened to 0.2 rad), else refused naming the joint, the
    count and the travel; a travel ending below its start refused; lists of the wrong length refused.
    Seen failing on ``intervals < CONSTRAINED - DEGREE + 1`` turned to ``+ 2`` and ``values.size !=
    self.intervals - 1`` to ``- 2``."""
    assert make_effect("angle_table", ur5, intervals=4).modes_per_joint == 1
    with pytest.raises(ValueError, match="at least 4 knot intervals, got 3"):
        make_effect("angle_table", ur5, intervals=3)
    low, high = [-1.0] * 6, [1.0] * 6
    good = [[-0.5, 0.0, 0.5]] + [None] * 5
    effect = make_effect("angle_table", ur5, intervals=4, lower=low, upper=high, knots=good)
    np.testing.assert_allclose(effect.table(0).knots, [-1, -1, -1, -1, -0.5, 0, 0.5, 1, 1, 1, 1])
    for bad in ([[-0.5, 0.5]] + [None] * 5, [[-0.5, 0.0, 0.0]] + [None] * 5, [[-1.0, 0.0, 0.5]] + [None] * 5,
                [[-0.5, 0.0, 0.5, 0.7]] + [None] * 5):
        with pytest.raises(ValueError, match=r"knots\[0\]: 3 increasing angles \[rad\] strictly inside the travel -1 "
                                             r"to 1 rad"):
            make_effect("angle_table", ur5, intervals=4, lower=low, upper=high, knots=bad)
    with pytest.raises(ValueError, match=r"knots\[2\]: .* inside the travel 0\.4 to 0\.6 rad"):  # widened to 0.2 rad
        make_effect("angle_table", ur5, intervals=4, lower=[0.5] * 6, upper=[0.5] * 6,
                    knots=[None, None, [0.45, 0.5, 0.65]] + [None] * 3)
    with pytest.raises(ValueError, match="travel of shoulder_lift_joint ends below where it starts"):
        make_effect("angle_table", ur5, lower=low, upper=[1.0, -2.0] + [1.0] * 4)
    with pytest.raises(ValueError, match="lower: 5 values for 6 joints"):
        make_effect("angle_table", ur5, lower=low[:5])
    with pytest.raises(ValueError, match="knots: 2 lists for 6 joints"):
        make_effect("angle_table", ur5, intervals=4, knots=good[:2])
