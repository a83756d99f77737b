"""The effects' figures against calculations written out here (issue 36): what an effect does to the TCP
on a Pinocchio model perturbed in the test, its typical sizes and ranges as its physics states them, the
draws ``simulate`` makes of it against the ranges its rules state, and the shared helpers of
``effects/base.py`` by hand. Each test names a planted change it was seen to catch."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest

from tcr_accuracy.effects import make_effect, predict_positions
from tcr_accuracy.model.context import MeasurementContext

from conftest import random_joint_values

DEG = math.pi / 180.0


def _tcp_with_placements(robot, q, moved):
    """(N, 3) TCP positions by Pinocchio on a copy of the robot's model whose joint placements are
    changed row by row: ``moved(i, j)`` gives the SE3 that row i puts on the right of joint j's
    placement (None: unchanged)."""
    model = robot.model
    ids = [model.getJointId(name) for name in robot.joint_names]
    out = []
    for i, row in enumerate(q):
        changed = model.copy()
        for j, jid in enumerate(ids):
            right = moved(i, j)
            if right is not None:
                changed.jointPlacements[jid] = model.jointPlacements[jid] * right
        data = changed.createData()
        qp = pin.neutral(changed)
        for jid, value in zip(ids, row):
            qp[changed.joints[jid].idx_q] = value
        pin.framesForwardKinematics(changed, data, qp)
        out.append(data.oMf[changed.getFrameId(robot.tool_frame)].translation.copy())
    return np.array(out)


def test_unmodelled_shifts_the_longest_link_by_its_three_joint_formula_on_pinocchio(ur5, tool_changer):
    """The UR5's longest arm link is the upper arm (the elbow's placement, 0.425 m): its placement moved in
    its own frame by A (sin(2 q1 + q2), sin(q2 - 2 q3 + 0.5), cos(3 q1 - q3)); on the tool changer
    the 0.796 m link (j3). The TCP by Pinocchio on a model so moved; the one parameter [m] and its
    typical size 0.3 mm; its (finite-difference) Jacobian is the shift per metre of amplitude.
    Seen failing on ``cos(3 * q[:, a] - q[:, c])`` turned to ``cos(4 * ...)``, ``+ 0.5`` to ``+ 1.5``
    and ``np.array([3e-4])`` to ``[1.0003]``."""
    for robot, longest in ((ur5, "elbow_joint"), (tool_changer, "j3")):
        rng = np.random.default_rng(11)
        q = random_joint_values(robot, 5, rng)
        effect = make_effect("unmodelled", robot)
        assert effect.parameter_names() == ["unmodelled.amplitude"] and effect.parameter_units() == ["m"]
        np.testing.assert_allclose(effect.parameter_scales(), [3e-4], rtol=1e-12)
        amplitude = 4e-3
        shift = amplitude * np.stack([np.sin(2 * q[:, 0] + q[:, 1]), np.sin(q[:, 1] - 2 * q[:, 2] + 0.5),
                                      np.cos(3 * q[:, 0] - q[:, 2])], axis=1)
        j_long = robot.joint_names.index(longest)
        expected = _tcp_with_placements(robot, q, lambda i, j: pin.SE3(np.eye(3), shift[i]) if j == j_long else None)
        got = predict_positions(robot, [effect], [[amplitude]], q, MeasurementContext.defaults(5, robot.n_joints))
        np.testing.assert_allclose(got, expected, atol=1e-12)
        jac = effect.parameter_jacobian([amplitude], q, None).x[:, :, 0]
        em = effect.error_model
        start = em.index(f"{longest}.dx")
        np.testing.assert_allclose(jac[:, start:start + 3], shift / amplitude, atol=1e-9)
        assert np.count_nonzero(np.abs(jac) > 1e-12) == np.count_nonzero(np.abs(shift) > 1e-12)


def test_link_bending_drops_the_longest_links_end_across_it_by_gravity_on_pinocchio(ur5):
    """The upper arm's far end moves, without turning, by tip x (gravity's unit direction less its part along
    the link), the link read from Pinocchio's placement of its parent joint; the TCP by Pinocchio on
    the model so moved. Typical size 0.5 mm. Seen failing on ``g - (g @ u) * u`` turned to ``g + ...``
    and ``np.array([5e-4])`` to ``[1.0005]``."""
    rng = np.random.default_rng(12)
    q = random_joint_values(ur5, 4, rng)
    effect = make_effect("link_bending", ur5)
    np.testing.assert_allclose(effect.parameter_scales(), [5e-4], rtol=1e-12)
    assert effect.parameter_units() == ["m"]
    tip = 2e-3
    model = ur5.model
    k = ur5.joint_names.index("elbow_joint")
    parent = model.parents[model.getJointId("elbow_joint")]
    drops = []
    for row in q:
        data = model.createData()
        pin.forwardKinematics(model, data, ur5.to_pinocchio_q(row))
        world = data.oMi[parent] * model.jointPlacements[model.getJointId("elbow_joint")]
        link = data.oMi[parent].rotation @ model.jointPlacements[model.getJointId("elbow_joint")].translation
        u = link / np.linalg.norm(link)
        down = np.array([0.0, 0.0, -1.0])
        drops.append(world.rotation.T @ (tip * (down - (down @ u) * u)))  # in the placement's own frame
    expected = _tcp_with_placements(ur5, q, lambda i, j: pin.SE3(np.eye(3), drops[i]) if j == k else None)
    got = predict_positions(ur5, [effect], [[tip]], q, MeasurementContext.defaults(4, 6))
    np.testing.assert_allclose(got, expected, atol=1e-12)


def test_thermal_per_link_grows_each_placement_and_the_tool_by_its_own_alpha_on_pinocchio(ur5):
    """Per link, each placement with a length (and the tool's offset) scaled by 1 + alpha_k (T - T_ref) with its
    own alpha, about a reference of 25 degC: a Pinocchio model with those translations scaled, row by row
    at 5 .. 45 degC; the base moved by (T - T_ref) x its rate. Names and units (1/K per link, m/K for the
    base), typical sizes (steel 1.2e-5/K; 1e-5 m/K), the physics' range (0 to 2.5e-5/K; +-3e-5 m/K) and
    the fit's (+-1e-3/K; +-2e-3 m/K). The fit's reference is the rows' mean temperature, to 6 decimals.
    Seen failing on ``d_t = temperature - t_ref`` turned to ``+``, ``directions[em.base_slice.start + a, ...]``
    turned to ``start - a``, ``[1e-5] * 3`` to ``[1.00001] * 3`` and the fit range's ``-2e-3`` to ``-1.002``."""
    rng = np.random.default_rng(13)
    n = 6
    q = random_joint_values(ur5, n, rng)
    temperature = np.linspace(5.0, 45.0, n)
    effect = make_effect("thermal", ur5, per_link=True, reference_temperature_c=25.0)
    links = [name for name, placement in zip(ur5.joint_names, ur5.joint_placements)
             if np.linalg.norm(placement.translation) > 1e-9]
    assert links == list(ur5.joint_names)  # every UR5 placement has a length
    names = effect.parameter_names()
    assert names == [f"thermal.alpha.{name}" for name in links] + ["thermal.alpha.tool", "thermal.base.dx",
                                                                   "thermal.base.dy", "thermal.base.dz"]
    assert effect.parameter_units() == ["1/K"] * 7 + ["m/K"] * 3
    np.testing.assert_allclose(effect.parameter_scales(), [1.2e-5] * 7 + [1e-5] * 3, rtol=1e-12)
    lower, upper = effect.physical_range()
    np.testing.assert_allclose(lower, [0.0] * 7 + [-3e-5] * 3, rtol=1e-12)
    np.testing.assert_allclose(upper, [2.5e-5] * 7 + [3e-5] * 3, rtol=1e-12)
    wide_lower, wide_upper = effect.fit_range()
    np.testing.assert_allclose(wide_lower, [-1e-3] * 7 + [-2e-3] * 3, rtol=1e-12)
    np.testing.assert_allclose(wide_upper, [1e-3] * 7 + [2e-3] * 3, rtol=1e-12)
    own, instrument = effect.mechanisms()
    np.testing.assert_allclose(own.lower, lower) and np.testing.assert_allclose(instrument.upper, wide_upper)

    alphas = np.array([1e-5, 2e-5, -1e-5, 3e-5, 1.5e-5, -2e-5, 4e-5])
    rate = np.array([2e-5, -3e-5, 1e-5])
    params = np.r_[alphas, rate]
    d_t = temperature - 25.0
    model = ur5.model
    expected = []
    for i, row in enumerate(q):
        hot = model.copy()
        for j, name in enumerate(ur5.joint_names):
            jid = model.getJointId(name)
            placement = model.jointPlacements[jid]
            hot.jointPlacements[jid] = pin.SE3(placement.rotation, placement.translation * (1 + alphas[j] * d_t[i]))
        tool_id = model.getFrameId(ur5.tool_frame)
        frame = hot.frames[tool_id]
        frame.placement = pin.SE3(frame.placement.rotation, frame.placement.translation * (1 + alphas[6] * d_t[i]))
        hot.frames[tool_id] = frame
        data = hot.createData()
        pin.framesForwardKinematics(hot, data, ur5.to_pinocchio_q(row))
        expected.append(data.oMf[tool_id].translation + d_t[i] * rate)
    context = MeasurementContext.defaults(n, 6)
    context = MeasurementContext(context.payload_kg, temperature, context.direction)
    got = predict_positions(ur5, [effect], [params], q, context)
    np.testing.assert_allclose(got, np.array(expected), atol=1e-12)
    assert effect.fit_policy.options_for_data(ur5, q, MeasurementContext(
        context.payload_kg, np.array([20.0, 21.0, 22.1234567, 20.0, 20.0, 20.0]), context.direction)) == {
        "reference_temperature_c": round((103.1234567 + 20.0) / 6, 6)}


@pytest.mark.parametrize("name, key, low, high, draws, end", [
    ("thermal", "alpha_per_k", 1.0e-5, 2.4e-5, 5000, 0.002),
    ("backlash", "backlash_deg", 0.01, 0.05, 5000, 0.002),
    ("backlash", "backlash_mm", 0.01, 0.05, 5000, 0.002),
    ("encoder_scale", "spread_ppm", 100.0, 500.0, 5000, 0.002),
    ("transmission", "spread_deg", 0.005, 0.02, 5000, 0.002),
    ("compliance", "tcp_rms_mm", 0.5, 3.0, 400, 0.02),  # each draw sizes the compliances: fewer
])
def test_a_dominant_draw_spans_the_range_its_rules_state(tool_changer, name, key, low, high, draws, end):
    """Seeded draws of a dominant truth's setting lie inside the range the rules' docstring states and reach
    within ``end`` (a share of the range) of both ends: uniform draws all miss a 0.2 % end in 5000 draws
    with a chance of 5e-5 (2 % in 400: 3e-4). Seen failing on ``rng.uniform(1.0e-5, 2.4e-5)`` turned to
    ``(1.0e-5, 3.4e-5)``, ``uniform(0.01, 0.05)`` to ``(1.01, 0.05)`` and ``uniform(100.0, 500.0)`` to
    ``(101.0, ...)``."""
    effect = make_effect(name, tool_changer)
    rng = np.random.default_rng(17)
    values = np.array([effect.simulation.dominant_spec(effect, rng)[key] for _ in range(draws)])
    span = high - low
    assert low <= values.min() <= low + end * span and high - end * span <= values.max() <= high


@pytest.mark.parametrize("name, low, high, times", [
    ("thermal", 5.0, 10.0, 1), ("encoder_scale", 30.0, 60.0, 1), ("transmission", 30.0, 80.0, 1),
    ("backlash", 1.0, 1.5, -1), ("compliance", 1.0, 1.0, -1),
])
def test_a_draw_beyond_physics_scales_the_dominant_one_as_its_rules_state(tool_changer, name, low, high, times):
    """Beyond physics, a dominant draw is multiplied by one factor drawn in the stated range (the instrument's
    scale 5-10 x, a wrong gear ratio 30-60 x, an eccentric encoder 30-80 x), or turned against its own
    physics (backlash ahead by 1-1.5 x, compliance against gravity): 400 draws of the ratio span the range
    to 2 %. Seen failing on ``rng.uniform(5.0, 10.0)`` turned to ``(6.0, 10.0)``, ``uniform(30.0, 80.0)``
    to ``(30.0, 81.0)`` and ``-np.asarray(params)`` turned to ``np.asarray(params)``."""
    effect = make_effect(name, tool_changer)
    params = effect.parameter_scales()
    rng = np.random.default_rng(19)
    ratios = np.array([effect.simulation.beyond_physics(effect, params, rng) / params for _ in range(400)])
    assert np.allclose(ratios, ratios[:, :1], rtol=1e-12)  # one factor for every parameter
    factor = times * ratios[:, 0]
    span = high - low
    assert low <= factor.min() <= low + 0.02 * span and high - 0.02 * span <= factor.max() <= high


def test_encoder_scale_dominant_parameters_are_100_to_500_ppm_of_either_sign(tool_changer):
    """A dominant encoder-scale draw's last touch: each joint's scale of either sign, 1e-4 to 5e-4 in size
    (200 draws reach both ends to 2 % and both signs). Seen failing on ``uniform(1e-4, 5e-4)`` turned
    to ``(1.0001, 5e-4)`` and ``choice([-1.0, 1.0])`` to ``([-1.0, 2.0])``."""
    effect = make_effect("encoder_scale", tool_changer)
    rng = np.random.default_rng(23)
    drawn = np.array([effect.simulation.finish_dominant(effect, effect.zeros(), rng) for _ in range(200)]).ravel()
    size = np.abs(drawn)
    assert 1e-4 <= size.min() <= 1.08e-4 and 4.92e-4 <= size.max() <= 5e-4
    assert set(np.sign(drawn)) == {-1.0, 1.0}


def test_typical_sizes_physical_and_fit_ranges_as_each_effects_physics_states(tool_changer):
    """On the tool changer (j4 prismatic): encoder zeros 0.03 deg / 0.05 mm, within 10 deg / 20 mm, fitted to
    45 deg / 100 mm; link screws 0.2 mm and 0.2 mrad, within 20 mm / 3 deg, fitted to 100 mm / 15 deg;
    backlash 0.03 deg / 0.05 mm wide, 0 to 0.5 deg / 0.5 mm, fitted from -2 x that (a compensation
    set too high); gear ratios 300 ppm within 1 % (fitted to 10 %); gear harmonics 0.01 deg within
    0.25 deg (fitted to 5 deg); angle tables 50 / sqrt 2 urad per mode within 1 mrad (fitted to 10 mrad);
    the tracker frame 10 mm / 10 mrad and the TCP offset 1 mm; clearance 0.01 mm and 0.01 mrad, at least 0.
    Each parameter's unit by its name's kind. Seen failing on ``math.radians(10.0)`` turned to
    ``radians(11.0)``, ``np.radians(15.0)`` to ``16.0``, ``-2.0 * upper`` to ``-3.0 * upper``,
    ``np.full(self.n_params, 3e-4)`` to ``1.0003``, ``PHYSICAL_LIMIT = 1e-3`` to ``1.001`` and
    ``5e-5 / math.sqrt(2.0)`` to ``sqrt(3.0)``."""
    robot = tool_changer
    prismatic = np.array([k == "prismatic" for k in robot.joint_kinds])
    per_kind = lambda revolute, slide: np.where(prismatic, slide, revolute)  # noqa: E731

    def ranges(name, **options):
        effect = make_effect(name, robot, **options)
        return effect, effect.parameter_scales(), effect.physical_range(), effect.fit_range()

    effect, scales, (lo, hi), (flo, fhi) = ranges("joint_offsets")
    assert effect.parameter_units() == ["m" if p else "rad" for p in prismatic]
    np.testing.assert_allclose(scales, per_kind(0.03 * DEG, 5e-5), rtol=1e-12)
    np.testing.assert_allclose(hi, per_kind(10 * DEG, 0.02), rtol=1e-12)
    np.testing.assert_allclose(fhi, per_kind(45 * DEG, 0.1), rtol=1e-12)
    np.testing.assert_allclose([lo, flo], [-hi, -fhi])

    effect, scales, (lo, hi), (flo, fhi) = ranges("geometry")
    rotation = np.tile([False] * 3 + [True] * 3, robot.n_joints)
    assert effect.parameter_units() == ["rad" if r else "m" for r in rotation]
    np.testing.assert_allclose(scales, 2e-4, rtol=1e-12)
    np.testing.assert_allclose(hi, np.where(rotation, 3 * DEG, 0.02), rtol=1e-12)
    np.testing.assert_allclose(fhi, np.where(rotation, 15 * DEG, 0.1), rtol=1e-12)
    np.testing.assert_allclose([lo, flo], [-hi, -fhi])

    effect, scales, (lo, hi), (flo, fhi) = ranges("backlash")
    np.testing.assert_allclose(scales, per_kind(0.03 * DEG, 5e-5), rtol=1e-12)
    np.testing.assert_allclose(lo, 0.0) and np.testing.assert_allclose(hi, per_kind(0.5 * DEG, 5e-4), rtol=1e-12)
    np.testing.assert_allclose(flo, -2 * hi, rtol=1e-12) and np.testing.assert_allclose(fhi, hi, rtol=1e-12)
    band, compensation = effect.mechanisms()
    np.testing.assert_allclose(compensation.lower, -2 * hi, rtol=1e-12)
    np.testing.assert_allclose(band.upper, hi, rtol=1e-12)

    effect, scales, (lo, hi), (flo, fhi) = ranges("encoder_scale")
    assert effect.parameter_units() == ["1"] * 6
    np.testing.assert_allclose(scales, 3e-4, rtol=1e-12)
    np.testing.assert_allclose([lo, hi, flo, fhi], [[-0.01] * 6, [0.01] * 6, [-0.1] * 6, [0.1] * 6], rtol=1e-12)

    effect, scales, (lo, hi), (flo, fhi) = ranges("transmission")
    assert effect.n_params == 4 * 5 and effect.parameter_units() == ["rad"] * 20  # revolute joints only
    np.testing.assert_allclose(scales, 0.01 * DEG, rtol=1e-12)
    np.testing.assert_allclose([lo, hi, flo, fhi], np.outer([-0.25, 0.25, -5.0, 5.0], np.full(20, DEG)), rtol=1e-12)

    effect, scales, (lo, hi), (flo, fhi) = ranges("angle_table", intervals=10)
    assert effect.n_params == 5 * (10 + 3 - 6)  # revolute joints, intervals + degree - constrained modes each
    np.testing.assert_allclose(scales, 5e-5 / math.sqrt(2.0), rtol=1e-12)
    np.testing.assert_allclose([lo, hi, flo, fhi], np.outer([-1e-3, 1e-3, -1e-2, 1e-2], np.ones(35)), rtol=1e-12)

    effect = make_effect("frames", robot, tool_rotation=True)
    assert effect.parameter_units() == ["m"] * 3 + ["rad"] * 3 + ["m"] * 3 + ["rad"] * 3
    np.testing.assert_allclose(effect.parameter_scales(), [1e-2] * 6 + [1e-3] * 6, rtol=1e-12)
    lo, hi = effect.physical_range()
    assert np.all(np.isneginf(lo)) and np.all(np.isposinf(hi))

    effect = make_effect("clearance", robot)
    assert effect.parameter_units() == ["m", "m", "rad"]
    np.testing.assert_allclose(effect.parameter_scales(), [1e-5] * 3, rtol=1e-12)
    lo, hi = effect.physical_range()
    assert np.all(lo == 0.0) and np.all(np.isposinf(hi))  # a magnitude: at least zero, the default


def _gravity_rms(robot, q, payload):
    """(n_joints,) RMS over the rows of the torque gravity exerts on each joint, by Pinocchio: the links'
    generalized gravity plus the payload as a point mass at the TCP (J_v^T m g), signs aside."""
    model = robot.model
    data = model.createData()
    fid = model.getFrameId(robot.tool_frame)
    tau = []
    for row in q:
        qp = robot.to_pinocchio_q(row)
        links = pin.computeGeneralizedGravity(model, data, qp)
        pin.computeJointJacobians(model, data, qp)
        pin.framesForwardKinematics(model, data, qp)
        jv = pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)[:3]
        tau.append(links - jv.T @ (payload * model.gravity.linear))
    return np.sqrt(np.mean(np.array(tau) ** 2, axis=0))


def test_compliance_turns_each_joint_by_a_hundredth_of_a_degree_under_its_rms_gravity_torque(ur5, tool_changer):
    """The typical compliance of each loaded joint turns it by 0.01 deg (slides it 0.05 mm) under its RMS
    gravity torque over 64 reference poses drawn uniformly inside the limits (seed 20240501) with the
    robot's typical payload: the torque by Pinocchio here; a joint gravity never loads (the first,
    vertical axis) gets the median of the others'. The physics' range: 0 to 200 typical; the
    fit's +-200 typical. Seen failing on ``math.radians(0.01), 5e-5`` turned to ``5e-5 + 1``,
    ``np.nanmedian`` standing in for the unloaded joint turned to another value, ``200.0 *`` to
    ``201.0 *`` and the reference poses' ``lo + (hi - lo) * u`` turned to ``lo - ...``."""
    for robot in (ur5, tool_changer):
        lo, hi = robot.joint_bounds()
        q_ref = lo + (hi - lo) * np.random.default_rng(20240501).uniform(size=(64, robot.n_joints))
        rms = _gravity_rms(robot, q_ref, robot.typical_payload_kg)
        target = np.array([0.01 * DEG if k == "revolute" else 5e-5 for k in robot.joint_kinds])
        loaded = rms > 1e-6 * rms.max()
        expected = np.where(loaded, target / np.where(loaded, rms, 1.0), np.nan)
        expected[~loaded] = np.median(expected[loaded])
        effect = make_effect("compliance", robot)
        np.testing.assert_allclose(effect.parameter_scales(), expected, rtol=1e-9)
        low, high = effect.physical_range()
        np.testing.assert_allclose(high, 200 * expected, rtol=1e-9) and np.testing.assert_allclose(low, 0.0)
        np.testing.assert_allclose(effect.fit_range()[0], -200 * expected, rtol=1e-9)
        assert effect.parameter_units() == ["rad/Nm" if k == "revolute" else "m/N" for k in robot.joint_kinds]
        assert not loaded[0] and loaded[1:3].all()  # both first axes are vertical: gravity never loads them


def _pedestal_urdf(lengths):
    """A chain of revolute joints (axes alternating y and x) whose placements rise by ``lengths`` [m]."""
    links = "".join(f'<link name="l{k}"/>' for k in range(len(lengths) + 1))
    joints = "".join(f'<joint name="q{k}" type="revolute"><parent link="l{k}"/><child link="l{k + 1}"/>'
                     f'<origin xyz="0 0 {length}"/><axis xyz="{k % 2} {(k + 1) % 2} 0"/>'
                     f'<limit lower="-3" upper="3" effort="1" velocity="1"/></joint>'
                     for k, length in enumerate(lengths))
    return f'<?xml version="1.0"?><robot name="pedestal">{links}{joints}</robot>'


def test_the_longest_link_is_an_arm_link_even_below_a_taller_pedestal():
    """On a chain whose first placement (a 1.2 m pedestal, which trades with the base frame) is the longest,
    0.5, 0.7 and 0.3 m after it: the distorted link is the 0.7 m one (the third placement), as unmodelled
    and link_bending move it; a single joint's pedestal is its only link. Seen failing on
    ``lengths[0] = -1.0`` turned to ``lengths[-1] = -1.0`` and ``len(lengths) > 1`` to ``> 2`` (on a
    two-joint chain)."""
    from tcr_accuracy.effects.unmodelled import longest_link
    from tcr_accuracy.model.robot import robot_from_urdf_text

    robot = robot_from_urdf_text(_pedestal_urdf([1.2, 0.5, 0.7, 0.3]), "l4", name="pedestal")
    assert longest_link(robot) == 2
    x = make_effect("unmodelled", robot).perturb([1e-3], np.full((1, 4), 0.3), None).x
    em = make_effect("unmodelled", robot).error_model
    assert np.flatnonzero(x[0]).tolist() == [em.index("q2.dx"), em.index("q2.dy"), em.index("q2.dz")]
    two = robot_from_urdf_text(_pedestal_urdf([1.2, 0.5]), "l2", name="two")
    assert longest_link(two) == 1
    one = robot_from_urdf_text(_pedestal_urdf([1.2]), "l1", name="one")
    assert longest_link(one) == 0


def test_a_dominant_compliance_and_backlash_are_drawn_about_their_typical_sizes(tool_changer):
    """A dominant compliance: each joint's typical compliance times a log-normal factor of log-spread 0.5
    (400 draws x 6 joints: the logs' spread 0.5 within 0.03, their mean 0 within 0.05), the links' masses
    spread by 5 %; a dominant backlash's band per joint 0.01 to 0.05 deg (mm on the prismatic j4), 2000
    draws reaching both ends within 1 %. Seen failing on ``np.exp(0.5 * rng.standard_normal(...))`` turned
    to ``np.exp(1.5 * ...)``, ``"link_mass_spread": 0.05`` to ``1.05``, ``math.pi / 180.0`` to ``/ 181.0``
    and ``1e-3)`` (per mm) to ``1.001)``."""
    compliance = make_effect("compliance", tool_changer)
    scales = compliance.parameter_scales()
    rng = np.random.default_rng(47)
    logs, spreads = [], set()
    for _ in range(400):
        spec = compliance.simulation.dominant_spec(compliance, rng)
        drawn = np.array([spec["parameters"][f"compliance.{j}"] for j in tool_changer.joint_names])
        logs.append(np.log(drawn / scales))
        spreads.add(spec["options"]["link_mass_spread"])
    logs = np.array(logs).ravel()
    assert abs(logs.std() - 0.5) < 0.03 and abs(logs.mean()) < 0.05 and spreads == {0.05}
    backlash = make_effect("backlash", tool_changer)
    per_unit = np.array([1e-3 if k == "prismatic" else math.pi / 180.0 for k in tool_changer.joint_kinds])
    bands = np.array([backlash.simulation.finish_dominant(backlash, backlash.zeros(), rng) / per_unit
                      for _ in range(2000)])
    assert np.all((0.01 <= bands.min(axis=0)) & (bands.min(axis=0) <= 0.0104))
    assert np.all((0.0496 <= bands.max(axis=0)) & (bands.max(axis=0) <= 0.05))


def test_an_effect_without_its_own_jacobian_ranges_or_mechanisms_gets_the_base_classes(tool_changer):
    """A toy effect (each joint turned by p_j^3, one parameter per joint of typical size 0.2) written here with
    none of the hooks: its Jacobian is the central difference at a step of 1e-3 of the typical size, so
    3 p^2 + h^2 exactly for a cube (h = 2e-4); its fit range ten times the largest bound of its physics' range
    (-0.1 .. 0.3: +-3), its one mechanism that range; a magnitude's default range 0 .. inf. Seen failing on
    ``steps = 1e-3 * self.parameter_scales()`` turned to ``1.001 *``, ``/ (2 * h)`` to ``/ (3 * h)`` and
    ``bound = 10.0 * ...`` to ``11.0 *``."""
    from tcr_accuracy.effects.base import Effect, EffectOutput, plugged_in

    class Cube(Effect):
        name = "toy_cube"

        def parameter_names(self):
            return [f"toy_cube.{j}" for j in self.robot.joint_names]

        def parameter_units(self):
            return ["1"] * self.robot.n_joints

        def parameter_scales(self):
            return np.full(self.robot.n_joints, 0.2)

        def physical_range(self):
            return np.full(self.n_params, -0.1), np.full(self.n_params, 0.3)

        def perturb(self, params, q, context):
            params = self.check_params(params)
            return EffectOutput(dq=np.broadcast_to(params**3, np.atleast_2d(q).shape).copy())

    class Magnitude(Cube):
        name = "toy_magnitude"
        non_negative = True
        physical_range = Effect.physical_range

    with plugged_in(Cube), plugged_in(Magnitude):
        effect = make_effect("toy_cube", tool_changer)
        assert not effect.analytic_jacobian
        params = np.array([0.1, -0.2, 0.3, 0.05, -0.15, 0.25])
        jac = effect.parameter_jacobian(params, np.zeros((2, 6)), None)
        h = 1e-3 * 0.2
        np.testing.assert_allclose(jac.dq[0], np.diag(3 * params**2 + h**2), rtol=1e-9, atol=1e-15)
        assert not jac.x.any()
        low, high = effect.fit_range()
        np.testing.assert_allclose([low, high], [np.full(6, -3.0), np.full(6, 3.0)], rtol=1e-12)
        (own,) = effect.mechanisms()
        assert own.key == "toy_cube" and own.textbook
        np.testing.assert_allclose([own.lower, own.upper], [np.full(6, -0.1), np.full(6, 0.3)])
        low, high = make_effect("toy_magnitude", tool_changer).physical_range()
        assert np.all(low == 0.0) and np.all(np.isposinf(high))


def test_lateral_compliance_tilts_each_axis_by_a_hundredth_of_a_degree_under_its_rms_moment(ur5):
    """Each joint's two tilt compliances turn it by 0.01 deg under the RMS, over the 64 reference poses (seed
    20240501, uniform inside the limits), of the gravity moment it carries across that axis with the
    typical payload: the moments from Pinocchio's RNEA at rest on a model whose tool body carries the
    payload as a point mass at tool0 (the joint's force ``data.f``, turned into its placement frame by
    exp3(a q)); an axis gravity never loads across gets the median of the others'. Physics 0 .. 200 x.
    Seen failing on the revolute target ``math.radians(0.01)`` turned to ``radians(1.01)``,
    ``np.sqrt(np.mean((moment[:, j] @ e) ** 2))`` turned to ``** 3`` and ``200.0 *`` to ``201.0 *``."""
    robot = ur5
    lo, hi = robot.joint_bounds()
    q_ref = lo + (hi - lo) * np.random.default_rng(20240501).uniform(size=(64, robot.n_joints))
    model = robot.model.copy()
    tool = model.frames[model.getFrameId(robot.tool_frame)]
    model.inertias[tool.parentJoint] = model.inertias[tool.parentJoint] + pin.Inertia(
        robot.typical_payload_kg, tool.placement.translation, np.zeros((3, 3)))
    data = model.createData()
    ids = [model.getJointId(name) for name in robot.joint_names]
    across = np.zeros((64, robot.n_joints, 2))
    for i, row in enumerate(q_ref):
        pin.rnea(model, data, robot.to_pinocchio_q(row), np.zeros(model.nv), np.zeros(model.nv))
        for j, jid in enumerate(ids):
            placed = pin.exp3(robot.joint_axis(j) * row[j]) @ data.f[jid].angular
            across[i, j] = [placed @ e for e in robot.axis_perpendiculars(j)]
    rms = np.sqrt(np.mean(across**2, axis=0))  # (n_joints, 2)
    loaded = rms > 1e-6 * rms.max()
    expected = np.where(loaded, math.radians(0.01) / np.where(loaded, rms, 1.0), np.nan)
    expected[~loaded] = np.median(expected[loaded])
    effect = make_effect("lateral_compliance", robot)
    np.testing.assert_allclose(effect.parameter_scales(), expected.ravel(), rtol=1e-9)
    np.testing.assert_allclose(effect.physical_range()[1], 200 * expected.ravel(), rtol=1e-9)
    assert effect.parameter_units() == ["rad/Nm"] * 12


def _tcp_by_pinocchio(robot, q):
    data = robot.model.createData()
    fid = robot.model.getFrameId(robot.tool_frame)
    out = []
    for row in q:
        pin.framesForwardKinematics(robot.model, data, robot.to_pinocchio_q(row))
        out.append(data.oMf[fid].copy())
    return out


def test_one_fixed_point_step_of_the_compliances_moves_the_tcp_as_pinocchio_says(ur5):
    """The UR5 with compliances 20 x typical: dq1 = c x (the torque gravity exerts, minus Pinocchio's
    generalized gravity) at the commanded q, dq2 = the same at q + dq1; the TCP moves between q + dq1 and
    q + dq2 by Pinocchio. Seen failing on the deflected joints' ``q + dq`` turned to ``q - dq`` and
    ``second - first`` to ``second + first``."""
    from tcr_accuracy.effects.compose import fixed_point_motion

    rng = np.random.default_rng(53)
    q = random_joint_values(ur5, 4, rng)
    effect = make_effect("compliance", ur5)
    c = 20 * effect.parameter_scales()

    def sag(joints):
        return np.array([-c * pin.computeGeneralizedGravity(ur5.model, ur5.model.createData(), ur5.to_pinocchio_q(row))
                         for row in joints])

    first = q + sag(q)
    second = q + sag(first)
    expected = np.array([b.translation - a.translation
                         for a, b in zip(_tcp_by_pinocchio(ur5, first), _tcp_by_pinocchio(ur5, second))])
    got = fixed_point_motion(ur5, [effect], [c], q, MeasurementContext.defaults(4, 6))
    np.testing.assert_allclose(got, expected, atol=1e-13)
    assert np.abs(expected).max() > 1e-7  # the step is there to be seen


def test_each_session_adds_its_own_tracker_frame_and_tcp_offset_to_its_rows(ur5):
    """Three sessions (labels a, b.2, c): the rows of the first seen through the base twist xi and the TCP
    offset t, those of a later session s through exp6(xi + xi_s) and t + t_s, the tool frame's pose by
    Pinocchio; the parameters named per session (a dot in a label replaced). Typical sizes 10 mm /
    10 mrad for every tracker frame, 1 mm for every offset. Seen failing on ``1.0 if only is None else
    session == only`` turned to ``2.0 if ...`` and the later sessions' ``[1:]`` to ``[2:]``."""
    rng = np.random.default_rng(59)
    n = 6
    q = random_joint_values(ur5, n, rng)
    session = np.array([0, 1, 2, 0, 2, 1])
    effect = make_effect("frames", ur5, sessions=["a", "b.2", "c"], session_tools=True)
    names = effect.parameter_names()
    assert names[:6] == [f"frames.base.{c}" for c in ("dx", "dy", "dz", "rx", "ry", "rz")]
    assert names[6:8] == ["frames.base.b_2.dx", "frames.base.b_2.dy"] and names[12] == "frames.base.c.dx"
    assert names[18:21] == ["frames.tool.dx", "frames.tool.dy", "frames.tool.dz"]
    assert names[21:] == [f"frames.tool.{s}.{c}" for s in ("b_2", "c") for c in ("dx", "dy", "dz")]
    np.testing.assert_allclose(effect.parameter_scales(), [1e-2] * 18 + [1e-3] * 9, rtol=1e-12)
    base = rng.normal(0.0, [0.5, 0.5, 0.5, 0.1, 0.1, 0.1], (3, 6))
    tool = rng.normal(0.0, 0.01, (3, 3))
    params = np.r_[base.ravel(), tool.ravel()]
    context = MeasurementContext.defaults(n, 6)
    context = MeasurementContext(context.payload_kg, context.temperature_c, context.direction, session=session)
    expected = []
    for row, pose in zip(session, _tcp_by_pinocchio(ur5, q)):
        twist = base[0] + (base[row] if row else 0.0)
        offset = tool[0] + (tool[row] if row else 0.0)
        expected.append(pin.exp6(pin.Motion(twist[:3], twist[3:])).act(pose.act(offset)))
    got = predict_positions(ur5, [effect], [params], q, context)
    np.testing.assert_allclose(got, np.array(expected), atol=1e-12)


def test_joint_scales_fill_only_the_joints_below_a_millionth_of_the_largest_load(tool_changer):
    """loaded_joint_scales on loads chosen here (a light arm: 0.02 Nm at most): a joint turned by the target under
    its load, 0.01 deg (0.05 mm on the prismatic j4); a load of 5e-8 Nm (above a millionth of the largest)
    still loaded, an exact 0 (and 1e-8 Nm, below it) given the median of the loaded joints' scales. Seen
    failing on ``rms_load > 1e-6 * max(...)`` turned to ``1e-6 % max(...)`` (an absolute 1e-6 Nm)."""
    from tcr_accuracy.effects.base import loaded_joint_scales

    load = np.array([0.0, 5e-8, 0.02, 0.01, 1e-8, 0.004])
    target = np.array([0.01 * DEG] * 3 + [5e-5] + [0.01 * DEG] * 2)
    loaded = np.array([False, True, True, True, False, True])
    scales = target[loaded] / load[loaded]
    expected = np.full(6, np.median(scales))
    expected[loaded] = scales
    np.testing.assert_allclose(loaded_joint_scales(tool_changer, load, 0.01 * DEG, 5e-5), expected, rtol=1e-12)


def test_a_prismatic_joint_has_no_cyclic_terms(tool_changer):
    """The tool changer's sliding j4 has no Fourier series of its angle: no parameters, a basis of no columns
    at every position asked, and no error. Seen failing on ``np.zeros((len(angles), 0))`` turned to
    ``(len(angles), 1)``."""
    effect = make_effect("cyclic", tool_changer, max_order=5)
    positions = np.linspace(-0.1, 0.3, 7)
    names, basis = effect.joint_basis("j4", positions)
    assert names == [] and basis.shape == (7, 0)
    assert not any(".j4." in n for n in effect.parameter_names())
    values = effect.joint_function(np.ones(effect.n_params) * 1e-4, "j4", positions)
    assert values.shape == (7,) and not values.any()
