"""What real robots bring to the model: names shared by a link and a joint, joints outside the
TCP chain whose masses load it, <mimic> joints, and joints that tilt across their axis.

Every expected value is computed here by hand (potential energy, moments of point masses)
or by Pinocchio on a URDF rewritten with the deflection built in, never by the code under test.
"""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tcr_accuracy.model.context import MeasurementContext
from tcr_accuracy.effects import make_effect, predict_positions
from tcr_accuracy.exceptions import InputError
from tcr_accuracy.model.gravity import gravity_torque, gravity_wrench
from tcr_accuracy.model.kinematics import tcp_poses
from tcr_accuracy.io.measurements import parse_measurements
from tcr_accuracy.model.robot import robot_from_urdf_text

G = 9.81
L1, L2, A1, A2, B, M1, M2, M3 = 0.8, 0.6, 0.35, 0.25, 0.3, 12.0, 7.0, 5.0
OX, OZ = 0.2, 0.1  # where the side branch sits on link j1


def urdf(j1_rpy=(0, 0, 0), j2_rpy=(0, 0, 0), mimic="", side_fixed_angle=None, j2_mimic=""):
    """Two joints about y carry the tool; a third (``side``, about z) hangs a mass off link j1.

    Link and joint names coincide (``j1`` is both), as URDF allows.
    """
    side = (f'<joint name="side" type="fixed"><parent link="j1"/><child link="side"/>'
            f'<origin xyz="{OX} 0 {OZ}" rpy="0 0 {side_fixed_angle}"/></joint>' if side_fixed_angle is not None else
            f'<joint name="side" type="revolute"><parent link="j1"/><child link="side"/>'
            f'<origin xyz="{OX} 0 {OZ}"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/>'
            f'{mimic}</joint>')
    return f"""<?xml version="1.0"?>
<robot name="branched">
  <link name="base"/>
  <link name="j1"><inertial><origin xyz="{A1} 0 0"/><mass value="{M1}"/>
    <inertia ixx="1e-9" iyy="1e-9" izz="1e-9" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="j2"><inertial><origin xyz="{A2} 0 0"/><mass value="{M2}"/>
    <inertia ixx="1e-9" iyy="1e-9" izz="1e-9" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="side"><inertial><origin xyz="{B} 0 0"/><mass value="{M3}"/>
    <inertia ixx="1e-9" iyy="1e-9" izz="1e-9" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="tool"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="j1"/>
    <origin xyz="0 0 0.5" rpy="{' '.join(repr(float(v)) for v in j1_rpy)}"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="j1"/><child link="j2"/>
    <origin xyz="{L1} 0 0" rpy="{' '.join(repr(float(v)) for v in j2_rpy)}"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/>{j2_mimic}</joint>
  <joint name="tool_joint" type="fixed"><parent link="j2"/><child link="tool"/><origin xyz="{L2} 0 0"/></joint>
  {side}
</robot>
"""


@pytest.fixture(scope="module")
def branched():
    return robot_from_urdf_text(urdf(), "tool", name="branched")


def _world_points(q, side_angle):
    """World positions of the three point masses and the tool (hand-written kinematics).

    A turn by a about +y maps (x, z) to (x cos a + z sin a, -x sin a + z cos a).
    """
    q1, q2 = q

    def ry(a, v):
        x, y, z = v
        return np.array([x * math.cos(a) + z * math.sin(a), y, -x * math.sin(a) + z * math.cos(a)])

    base = np.array([0.0, 0.0, 0.5])
    m1 = base + ry(q1, [A1, 0, 0])
    j2 = base + ry(q1, [L1, 0, 0])
    m2 = j2 + ry(q1 + q2, [A2, 0, 0])
    tool = j2 + ry(q1 + q2, [L2, 0, 0])
    side_local = np.array([OX + B * math.cos(side_angle), B * math.sin(side_angle), OZ])
    m3 = base + ry(q1, side_local)
    return base, j2, m1, m2, m3, tool


def test_a_link_and_a_joint_may_share_a_name(branched):
    assert branched.joint_names == ["j1", "j2"]
    assert branched.outside_joint_names == ["side"]
    frame = branched.model.frames[branched.tool_frame_id]
    assert frame.name == "tool"
    # the TCP frame may itself be named like a joint: the link is meant
    on_link = robot_from_urdf_text(urdf(), "j2", name="branched")
    q = np.array([0.3, -0.7])
    base, j2, *_ = _world_points(q, 0.0)
    np.testing.assert_allclose(tcp_poses(on_link, q).position[0], j2, atol=1e-12)
    with pytest.raises(InputError, match="no such frame.*frames: .*j1"):
        robot_from_urdf_text(urdf(), "hand", name="branched")


def test_joints_outside_the_chain_load_it(branched):
    rng = np.random.default_rng(2)
    q = rng.uniform(-1.5, 1.5, (6, 2))
    side = rng.uniform(-2.5, 2.5, (6, 1))
    tau = gravity_torque(branched, q, 0.0, outside_q=side)
    for i in range(6):
        base, j2, m1, m2, m3, _ = _world_points(q[i], side[i, 0])
        # torque gravity exerts about +y at a joint: g * sum(m * x-offset from the axis)
        expected_1 = G * (M1 * (m1 - base)[0] + M2 * (m2 - base)[0] + M3 * (m3 - base)[0])
        expected_2 = G * M2 * (m2 - j2)[0]
        np.testing.assert_allclose(tau[i], [expected_1, expected_2], rtol=1e-10, atol=1e-9)
    # independent path: the side joint frozen into a fixed joint at the same angle, Pinocchio on that URDF
    frozen = robot_from_urdf_text(urdf(side_fixed_angle=float(side[0, 0])), "tool", name="frozen")
    np.testing.assert_allclose(gravity_torque(branched, q[:1], 0.0, outside_q=side[:1]),
                               gravity_torque(frozen, q[:1], 0.0), rtol=1e-10)
    # without values the side joint sits at neutral (0)
    np.testing.assert_allclose(gravity_torque(branched, q[:1], 0.0),
                               gravity_torque(branched, q[:1], 0.0, outside_q=np.zeros((1, 1))), rtol=1e-12)


def test_the_csv_may_carry_every_joint_and_compliance_uses_them(branched):
    text = ("j1_deg,j2_deg,side_deg,x_mm,y_mm,z_mm\n"
            "10,20,0,1,2,3\n10,20,90,4,5,6\n-30,40,45,7,8,9\n")
    mset = parse_measurements(text, branched, check_units=False)
    np.testing.assert_allclose(mset.outside_q[:, 0], np.radians([0, 90, 45]))
    effect = make_effect("compliance", branched)
    dq = effect.perturb([1e-4, 2e-4], mset.q, mset.context).dq
    # rows 1 and 2 differ only in the side joint: the side mass moves, so j1 sags differently
    assert abs(dq[0, 0] - dq[1, 0]) > 1e-5 and dq[0, 1] == pytest.approx(dq[1, 1])
    _, _, _, _, m3_a, _ = _world_points(mset.q[0], 0.0)
    _, _, _, _, m3_b, _ = _world_points(mset.q[1], math.pi / 2)
    assert dq[0, 0] - dq[1, 0] == pytest.approx(1e-4 * G * M3 * (m3_a[0] - m3_b[0]), rel=1e-9)


def test_mimic_joints_follow_their_rule_when_their_column_is_missing():
    outside = robot_from_urdf_text(urdf(mimic='<mimic joint="j2" multiplier="-2" offset="0.1"/>'), "tool",
                                   name="mimic")
    mset = parse_measurements("j1_deg,j2_deg,x_mm,y_mm,z_mm\n10,20,1,2,3\n-5,30,4,5,6\n", outside,
                              check_units=False)
    np.testing.assert_allclose(mset.outside_q[:, 0], -2 * np.radians([20, 30]) + 0.1)
    given = parse_measurements("j1_deg,j2_deg,side_deg,x_mm,y_mm,z_mm\n10,20,7,1,2,3\n-5,30,8,4,5,6\n", outside,
                               check_units=False)
    np.testing.assert_allclose(given.outside_q[:, 0], np.radians([7, 8]))  # the log wins over the rule
    chain = robot_from_urdf_text(urdf(j2_mimic='<mimic joint="j1" multiplier="0.5"/>'), "tool", name="mimic")
    mset = parse_measurements("j1_deg,x_mm,y_mm,z_mm\n10,1,2,3\n-30,4,5,6\n", chain, check_units=False)
    np.testing.assert_allclose(mset.q[:, 1], 0.5 * np.radians([10, -30]))
    with pytest.raises(InputError, match="missing joint column j1_deg or j1_rad"):
        parse_measurements("j2_deg,x_mm,y_mm,z_mm\n10,1,2,3\n", chain, check_units=False)


def test_lateral_compliance_tilts_joints_as_a_rebuilt_urdf_does(branched):
    """Hand-derived gravity moments across each joint, the tilt built into the URDF's origins."""
    effect = make_effect("lateral_compliance", branched)
    # j1, j2 turn about y: the axes across them are z and x (names after the placement frame)
    assert effect.parameter_names() == ["lateral_compliance.j1.z", "lateral_compliance.j1.x",
                                        "lateral_compliance.j2.z", "lateral_compliance.j2.x"]
    c = np.array([3e-4, 5e-4, 7e-4, 2e-4])  # rad/Nm, large so the check is not lost in rounding
    rng = np.random.default_rng(5)
    for q, side in zip(rng.uniform(-1.2, 1.2, (4, 2)), rng.uniform(-2.0, 2.0, 4)):
        base, j2, m1, m2, m3, _ = _world_points(q, side)
        weight = np.array([0.0, 0.0, -G])
        moment_1 = np.cross(m1 - base, M1 * weight) + np.cross(m2 - base, M2 * weight) \
            + np.cross(m3 - base, M3 * weight)
        moment_2 = np.cross(m2 - j2, M2 * weight)
        # placement frames: j1's is the world's; j2's is link j1's, turned by q1 about y
        to_j1_link = Rotation.from_rotvec([0.0, q[0], 0.0]).as_matrix()
        m_place_2 = to_j1_link.T @ moment_2
        tilt_1 = np.array([c[1] * moment_1[0], 0.0, c[0] * moment_1[2]])
        tilt_2 = np.array([c[3] * m_place_2[0], 0.0, c[2] * m_place_2[2]])
        rebuilt = robot_from_urdf_text(urdf(j1_rpy=Rotation.from_rotvec(tilt_1).as_euler("xyz"),
                                            j2_rpy=Rotation.from_rotvec(tilt_2).as_euler("xyz")),
                                       "tool", name="rebuilt")
        ctx = MeasurementContext(np.zeros(1), np.full(1, 20.0), np.zeros((1, 2)), outside_q=np.array([[side]]))
        predicted = predict_positions(branched, [effect], [c], q[None], ctx)[0]
        expected = tcp_poses(rebuilt, q).position[0]
        np.testing.assert_allclose(predicted, expected, atol=1e-12)
        assert np.linalg.norm(expected - tcp_poses(branched, q).position[0]) > 1e-3  # the tilt is visible
    # the wrench's axial part is the gravity torque: one physics for both compliances
    qs = rng.uniform(-1, 1, (3, 2))
    wrench = gravity_wrench(branched, qs, 20.0, outside_q=np.ones((3, 1)))
    axial = np.einsum("njk,jk->nj", wrench, branched.motion_axes)
    np.testing.assert_allclose(axial, gravity_torque(branched, qs, 20.0, outside_q=np.ones((3, 1))), rtol=1e-10)


def test_prediction_feeds_the_other_joints_to_the_gravity_effects(branched):
    """The side joint swings a 5 kg mass on link j1: the j1 sag follows it. A predictor that is
    given every row's context sees that; one that freezes the side joint cannot."""
    from tcr_accuracy.prediction.calibration import DiagnosisCalibration
    from tcr_accuracy.prediction.composed import MeasuredErrorModel

    rng = np.random.default_rng(21)
    n = 160
    q = rng.uniform(-1.2, 1.2, (n, 2))
    side = rng.uniform(-2.5, 2.5, (n, 1))
    ctx = MeasurementContext(np.zeros(n), np.full(n, 20.0), np.zeros((n, 2)), outside_q=side)
    effect = make_effect("compliance", branched)
    tracker = np.array([0.3, -0.2, 0.1])  # the measurements sit in a tracker frame
    measured = predict_positions(branched, [effect], [[4e-5, 2e-5]], q, ctx) + tracker  # sags of ~0.3 deg
    measured += 1e-5 * rng.standard_normal(measured.shape)
    train, test = np.arange(120), np.arange(120, n)
    scores = {}
    for label, context in (("with", ctx), ("without", None)):
        model = MeasuredErrorModel(robot=branched, estimator=DiagnosisCalibration(robot=branched, folds=3,
                                                                                  effects=["compliance"]))
        model.fit(q[train], measured[train], context=None if context is None else context.subset(train))
        miss = model.heldout_residual(q[test], measured[test],
                                      context=None if context is None else context.subset(test))
        scores[label] = float(np.sqrt(np.mean(np.sum(miss**2, axis=1))))
    assert scores["with"] < 3 * np.sqrt(3) * 1e-5  # at the noise
    assert scores["without"] > 20 * scores["with"]  # the side mass's share of the sag is lost
