"""Each effect against an independent calculation; the composed Jacobian against finite differences."""

import math

import numpy as np
import pinocchio as pin
import pytest

from tcr_accuracy.model.context import MeasurementContext
from tcr_accuracy.effects import Effect, effect_classes, predict_poses, predict_positions, prediction_jacobian
from tcr_accuracy.effects.backlash import Backlash
from tcr_accuracy.effects.clearance import Clearance
from tcr_accuracy.effects.compliance import Compliance
from tcr_accuracy.effects.encoder_scale import EncoderScale
from tcr_accuracy.effects.frames import Frames
from tcr_accuracy.effects.geometry import Geometry
from tcr_accuracy.effects.joint_offsets import JointOffsets
from tcr_accuracy.effects.thermal import Thermal
from tcr_accuracy.effects.transmission import Transmission
from tcr_accuracy.model.errors import ErrorModel
from tcr_accuracy.model.gravity import gravity_torque
from tcr_accuracy.model.kinematics import pose_error, tcp_poses, tcp_poses_pinocchio
from tcr_accuracy.model.robot import robot_from_urdf_text
from tcr_accuracy.model.tool_changer import ToolChangerDimensions, tool_changer_urdf
from tcr_accuracy.units import display_value

from conftest import random_joint_values

EFFECTS = effect_classes()

# A planar two-link arm: both joints turn about y, links along x, point-like masses.
L1, L2, A1, A2, M1, M2 = 0.8, 0.6, 0.35, 0.25, 12.0, 7.0
TWO_LINK = f"""<?xml version="1.0"?>
<robot name="two_link">
  <link name="base"/>
  <link name="link1"><inertial><origin xyz="{A1} 0 0"/><mass value="{M1}"/>
    <inertia ixx="1e-9" iyy="1e-9" izz="1e-9" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="link2"><inertial><origin xyz="{A2} 0 0"/><mass value="{M2}"/>
    <inertia ixx="1e-9" iyy="1e-9" izz="1e-9" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="tip"/>
  <joint name="a" type="revolute"><parent link="base"/><child link="link1"/>
    <origin xyz="0 0 0.5"/><axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="b" type="revolute"><parent link="link1"/><child link="link2"/>
    <origin xyz="{L1} 0 0"/><axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="tip_joint" type="fixed"><parent link="link2"/><child link="tip"/><origin xyz="{L2} 0 0"/></joint>
</robot>
"""


@pytest.fixture(scope="module")
def two_link():
    return robot_from_urdf_text(TWO_LINK, "tip", name="two_link")


def _hand_gravity_torque(q, payload, m1=M1, m2=M2):
    """-dV/dq for V = g * sum(m z); a turn about +y takes x towards -z."""
    g = 9.81
    c1, c12 = np.cos(q[:, 0]), np.cos(q[:, 0] + q[:, 1])
    tau1 = g * (m1 * A1 * c1 + m2 * (L1 * c1 + A2 * c12) + payload * (L1 * c1 + L2 * c12))
    tau2 = g * (m2 * A2 * c12 + payload * L2 * c12)
    return np.stack([tau1, tau2], axis=1)


def _context(n, n_joints, payload=0.0, temperature=20.0, direction=None):
    return MeasurementContext(np.broadcast_to(np.asarray(payload, float), (n,)).copy(),
                              np.broadcast_to(np.asarray(temperature, float), (n,)).copy(),
                              np.zeros((n, n_joints)) if direction is None else direction)


def test_vocabulary_order_and_interface(tool_changer):
    assert list(EFFECTS) == ["frames", "joint_offsets", "geometry", "compliance", "lateral_compliance", "backlash",
                             "thermal", "drift", "encoder_scale", "transmission", "cyclic", "angle_table", "clearance"]
    for name, cls in EFFECTS.items():
        effect = cls(tool_changer)
        assert isinstance(effect, Effect) and effect.name == name
        names = effect.parameter_names()
        assert all(n.startswith(name + ".") for n in names) and len(set(names)) == len(names)
        assert len(effect.parameter_units()) == len(names) == effect.parameter_scales().shape[0]
        assert np.all(effect.parameter_scales() > 0)
        assert effect.stochastic == (name == "clearance")


def test_gravity_torque_matches_hand_derivation(two_link):
    rng = np.random.default_rng(0)
    q = rng.uniform(-2, 2, size=(10, 2))
    payload = rng.choice([0.0, 150.0, 3.5], 10)
    assert two_link.model.gravity.linear[2] == pytest.approx(-9.81)
    np.testing.assert_allclose(gravity_torque(two_link, q, payload), _hand_gravity_torque(q, payload),
                               rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(gravity_torque(two_link, q, payload, link_mass_factors=[1.1, 0.9]),
                               _hand_gravity_torque(q, payload, 1.1 * M1, 0.9 * M2), rtol=1e-10, atol=1e-9)


def test_compliance_turns_joints_by_c_times_gravity_torque_and_the_tip_sags(two_link):
    q = np.array([[0.0, 0.0], [0.3, -0.5], [-0.4, 0.2]])
    c = np.array([2e-5, 5e-5])
    ctx = _context(3, 2, payload=150.0)
    out = Compliance(two_link).perturb(c, q, ctx)
    np.testing.assert_allclose(out.dq, c * _hand_gravity_torque(q, 150.0), rtol=1e-10)
    nominal = tcp_poses(two_link, q).position
    sagged = predict_positions(two_link, [Compliance(two_link)], [c], q, ctx)
    assert np.all(sagged[:, 2] < nominal[:, 2])  # the tip goes down, never up
    # horizontal arm: the tip drops by about (c1 tau1 (L1 + L2) + c2 tau2 L2)
    tau = _hand_gravity_torque(q[:1], 150.0)[0]
    assert nominal[0, 2] - sagged[0, 2] == pytest.approx(c[0] * tau[0] * (L1 + L2) + c[1] * tau[1] * L2, rel=1e-3)


def test_tool_changer_cutter_sag_needs_payload_context(tool_changer):
    q = tool_changer.working_pose[None]
    effect = Compliance(tool_changer)
    c = effect.parameter_scales()
    light = predict_positions(tool_changer, [effect], [c], q, _context(1, 6, 0.0))
    heavy = predict_positions(tool_changer, [effect], [c], q, _context(1, 6, 150.0))
    nominal = tcp_poses(tool_changer, q).position
    assert heavy[0, 2] < light[0, 2] < nominal[0, 2]


def test_encoder_scale_and_transmission_closed_forms(tool_changer):
    rng = np.random.default_rng(1)
    q = random_joint_values(tool_changer, 7, rng)
    ctx = _context(7, 6)
    s = rng.normal(scale=3e-4, size=6)
    np.testing.assert_allclose(EncoderScale(tool_changer).perturb(s, q, ctx).dq, s * q, rtol=1e-14)
    trans = Transmission(tool_changer)
    names = trans.parameter_names()
    assert "transmission.j4.a1" not in names and len(names) == 5 * 4  # no prismatic harmonics
    params = rng.normal(scale=1e-4, size=len(names))
    dq = trans.perturb(params, q, ctx).dq
    p = dict(zip(names, params))
    j5 = 4
    expected = (p["transmission.j5.a1"] * np.sin(q[:, j5]) + p["transmission.j5.b1"] * np.cos(q[:, j5])
                + p["transmission.j5.a2"] * np.sin(2 * q[:, j5]) + p["transmission.j5.b2"] * np.cos(2 * q[:, j5]))
    np.testing.assert_allclose(dq[:, j5], expected, rtol=1e-12)
    np.testing.assert_array_equal(dq[:, 3], 0.0)


def test_backlash_side_follows_direction_else_gravity(two_link, tool_changer):
    b = np.array([2e-3, 4e-3])
    q = np.array([[0.2, 0.1], [0.2, 0.1], [2.0, 1.5]])
    tau = _hand_gravity_torque(q, 0.0)
    direction = np.array([[0.0, 0.0], [1.0, -1.0], [0.0, 1.0]])
    dq = Backlash(two_link).perturb(b, q, _context(3, 2, direction=direction)).dq
    np.testing.assert_allclose(dq[0], b / 2 * np.sign(tau[0]))  # gravity's side
    np.testing.assert_allclose(dq[1], -b / 2 * direction[1])  # lags behind the motion
    np.testing.assert_allclose(dq[2], [b[0] / 2 * np.sign(tau[2, 0]), -b[1] / 2])
    # the tool-changer's turret (vertical axis) feels no gravity: centred without a direction
    dq = Backlash(tool_changer).perturb(np.full(6, 1e-3), tool_changer.working_pose[None],
                                        _context(1, 6, 150.0)).dq
    assert dq[0, 0] == 0.0 and dq[0, 1] != 0.0


def test_thermal_matches_a_robot_built_with_scaled_links(tool_changer):
    alpha, temperature = 1.2e-5, 45.0
    growth = 1 + alpha * (temperature - 20.0)
    d = ToolChangerDimensions()
    scaled = ToolChangerDimensions(**{f"l{k}": getattr(d, f"l{k}") * growth for k in range(1, 7)})
    hot = robot_from_urdf_text(tool_changer_urdf(scaled), "tool", name="hot")
    q = random_joint_values(tool_changer, 9, np.random.default_rng(2))
    predicted = predict_positions(tool_changer, [Thermal(tool_changer)], [[alpha, 0.0, 0.0, 0.0]], q,
                                  _context(9, 6, temperature=temperature))
    np.testing.assert_allclose(predicted, tcp_poses(hot, q).position, atol=1e-12)
    # the base moving with temperature: every TCP translated by dT times the base's rate [m/K]
    rate = np.array([2e-5, -1e-5, 3e-5])
    moved = predict_positions(tool_changer, [Thermal(tool_changer)], [np.r_[0.0, rate]], q,
                              _context(9, 6, temperature=temperature))
    np.testing.assert_allclose(moved, tcp_poses(tool_changer, q).position + (temperature - 20.0) * rate,
                               atol=1e-12)
    per_link = Thermal(tool_changer, per_link=True)
    assert per_link.parameter_names() == [f"thermal.alpha.j{k}" for k in range(1, 7)] + list(Thermal.BASE)
    np.testing.assert_allclose(
        predict_positions(tool_changer, [per_link], [np.r_[np.full(6, alpha), 0.0, 0.0, 0.0]], q,
                          _context(9, 6, temperature=temperature)),
        predicted, atol=1e-12)


def test_joint_offsets_geometry_and_frames_against_pinocchio(tool_changer):
    rng = np.random.default_rng(4)
    q = random_joint_values(tool_changer, 5, rng)
    em = ErrorModel(tool_changer)
    offsets = rng.normal(scale=1e-3, size=6)
    geometry = rng.normal(scale=1e-3, size=36)
    frames = np.array([1.2, -0.7, 0.4, 0.1, -0.2, 0.9, 1e-3, -2e-3, 5e-4])
    effects = [Frames(tool_changer), JointOffsets(tool_changer), Geometry(tool_changer)]
    got = predict_poses(tool_changer, effects, [frames, offsets, geometry], q, _context(5, 6))
    x = em.zeros()
    x[em.placement_slice] = geometry
    x[em.base_slice] = frames[:6]
    x[em.tool_slice.start:em.tool_slice.start + 3] = frames[6:]
    reference = tcp_poses_pinocchio(tool_changer, q + offsets, x, em)  # one perturbed pin model per row
    np.testing.assert_allclose(got.position, reference.position, atol=1e-12)
    np.testing.assert_allclose(got.rotation, reference.rotation, atol=1e-12)
    # the base twist is the tracker frame, exactly
    base = pin.exp6(frames[:6])
    nominal = tcp_poses(tool_changer, q + offsets, np.where(np.arange(em.size) < em.base_slice.start, x, 0.0), em)
    tool_off = nominal.position + np.einsum("nij,j->ni", nominal.rotation, frames[6:])
    np.testing.assert_allclose(got.position, tool_off @ base.rotation.T + base.translation, atol=1e-12)


def test_clearance_draws_match_its_covariance(tool_changer):
    effect = Clearance(tool_changer, rng=np.random.default_rng(5))
    params = np.array([2e-5, 3e-5, 4e-5])
    q = np.zeros((20000, 6))
    x = effect.perturb(params, q, _context(20000, 6)).x
    cov = effect.twist_covariance(params)
    start = ErrorModel(tool_changer).index("j2.dx")
    block = slice(start, start + 6)
    np.testing.assert_allclose(np.cov(x[:, block].T), cov[block, block], atol=0.05 * 4e-5**2)
    assert not x[:, ErrorModel(tool_changer).index("j4.dx")].any()  # prismatic: no play by default
    # without a generator, the mean robot (an as-built model's): what the draws average to, no play
    assert not Clearance(tool_changer).perturb(params, q[:2], _context(2, 6)).x.any()
    np.testing.assert_allclose(x[:, block].mean(axis=0), 0.0, atol=5 * 4e-5 / np.sqrt(20000))


def _finite_difference_jacobian(robot, effects, params, q, ctx, scales):
    sizes = [e.n_params for e in effects]
    flat = np.concatenate(params)
    out = np.zeros((q.shape[0], 6, flat.size))
    for k in range(flat.size):
        h = 1e-4 * scales[k]
        plus, minus = flat.copy(), flat.copy()
        plus[k] += h
        minus[k] -= h
        pp = predict_poses(robot, effects, np.split(plus, np.cumsum(sizes)[:-1]), q, ctx)
        pm = predict_poses(robot, effects, np.split(minus, np.cumsum(sizes)[:-1]), q, ctx)
        out[:, :3, k] = (pp.position - pm.position) / (2 * h)
        out[:, 3:, k] = pose_error(pm, pp).rotation_vector / (2 * h)
    return out


@pytest.mark.parametrize("robot_name", ["tool_changer", "ur5"])
def test_prediction_jacobian_matches_finite_differences(robot_name, request):
    robot = request.getfixturevalue(robot_name)
    rng = np.random.default_rng(6)
    n = 6
    q = random_joint_values(robot, n, rng)
    ctx = MeasurementContext(rng.choice([0.0, 150.0], n), np.full(n, 20.0),
                             rng.choice([-1.0, 0.0, 1.0], size=(n, robot.n_joints)))
    effects = [Frames(robot, tool_rotation=True)] + [EFFECTS[k](robot) for k in list(EFFECTS)[1:-1]]
    params = [3 * e.parameter_scales() * rng.standard_normal(e.n_params) for e in effects]
    params[0][:6] = [0.8, -0.5, 0.3, 0.2, -0.4, 0.6]  # a tracker far from the base
    jac = prediction_jacobian(robot, effects, params, q, ctx, orientation=True)
    scales = np.concatenate([e.parameter_scales() for e in effects])
    fd = _finite_difference_jacobian(robot, effects, params, q, ctx, scales)
    assert jac.shape == fd.shape
    # columns are compared relative to their own size (compliance columns are ~1e4)
    size = np.abs(fd).max(axis=(0, 1))
    # (columns that barely move the TCP here, ~1e-8, are at the finite differences' round-off: 5e-8 absolute)
    assert np.all(np.abs(jac - fd).max(axis=(0, 1)) <= 1e-6 * size + 5e-8)
    assert np.count_nonzero(size > 1e-3) > 0.8 * size.size  # most columns really move the TCP
    pos_only = prediction_jacobian(robot, effects, params, q, ctx)
    np.testing.assert_allclose(pos_only, jac[:, :3])


def test_stochastic_effect_gets_zero_jacobian_columns(tool_changer):
    q = tool_changer.working_pose[None]
    effects = [JointOffsets(tool_changer), Clearance(tool_changer)]
    jac = prediction_jacobian(tool_changer, effects, [np.zeros(6), np.array([1e-5, 1e-5, 1e-5])], q)
    assert jac.shape == (1, 3, 9) and not jac[:, :, 6:].any() and jac[:, :, :6].any()


def test_effects_leave_the_nominal_model_untouched(tool_changer):
    before = [pin.SE3(p) for p in tool_changer.joint_placements]
    q = tool_changer.working_pose[None]
    effects = [EFFECTS[k](tool_changer) for k in list(EFFECTS)[:-1]]
    params = [e.parameter_scales() for e in effects]
    prediction_jacobian(tool_changer, effects, params, q, _context(1, 6, 150.0, 35.0))
    for a, b in zip(before, tool_changer.joint_placements):
        assert a.isApprox(b, 0.0)
    assert math.isclose(tool_changer.model.inertias[6].mass, 60.0)


def test_display_units():
    assert display_value(math.radians(0.05), "rad") == (pytest.approx(0.05), "deg")
    assert display_value(2.5e-4, "m") == (pytest.approx(0.25), "mm")
    assert display_value(math.radians(0.02) / 1e3, "rad/Nm") == (pytest.approx(0.02), "deg/kNm")
    assert display_value(1.2e-5, "1/K") == (pytest.approx(12.0), "ppm/K")


@pytest.mark.parametrize("time_constant", [0.05, 0.25, 1.0])
def test_drift_shapes_average_zero_over_the_campaign_and_rise_by_one(time_constant):
    """Both drift shapes integrate to zero over the campaign's progress u in [0, 1] (scipy's
    quadrature of the class's own shape, not its closed-form mean: the other effects describe the
    robot as it was on average) and rise by exactly 1 from the first row to the last."""
    from scipy.integrate import quad

    from tcr_accuracy.effects import make_effect
    from tcr_accuracy.model.robot import load_robot

    drift = make_effect("drift", load_robot("ur5"), time_constant=time_constant)
    for k in range(2):
        mean, _ = quad(lambda u: drift.shapes(np.array([u]), 1)[0, k], 0.0, 1.0, epsabs=1e-13)
        assert abs(mean) < 1e-10
        ends = drift.shapes(np.array([0.0, 1.0]), 2)[:, k]
        assert ends[1] - ends[0] == pytest.approx(1.0, abs=1e-12)
