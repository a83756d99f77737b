"""DH and modified DH tables (Hayati's beta where consecutive axes are parallel) and the makers'
published tables, each checked by a forward kinematics written out here (numpy matrices of the
conventions' elementary transforms, not the package's) against Pinocchio's."""

import math

import numpy as np
import pinocchio as pin
import pytest

from tcr_accuracy.asbuilt.dh import dh_table, mdh_table
from tcr_accuracy.asbuilt.maker_dh import PUBLISHED, maker_table, published_table
from tcr_accuracy.model.errors import ErrorModel
from tcr_accuracy.model.robot import load_robot

from conftest import random_joint_values


def _rx(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])


def _ry(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1.0]])


def _rz(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def _t(x=0.0, y=0.0, z=0.0):
    out = np.eye(4)
    out[:3, 3] = (x, y, z)
    return out


def table_fk(convention, rows, variable, base, tool, q):
    """base_M_tcp of a table: standard DH rows Rz(theta) Tz(d) Tx(a) Rx(alpha) Ry(beta), modified
    (Craig) rows Rx(alpha) Tx(a) Ry(beta) Rz(theta) Tz(d); rows (a, alpha, d, theta, beta)."""
    out = np.array(base, dtype=float)
    for (a, alpha, d, theta, beta), kind, value in zip(rows, variable, q):
        theta, d = (theta + value, d) if kind == "theta" else (theta, d + value)
        if convention == "DH":
            out = out @ _rz(theta) @ _t(z=d) @ _t(x=a) @ _rx(alpha) @ _ry(beta)
        else:
            out = out @ _rx(alpha) @ _t(x=a) @ _ry(beta) @ _rz(theta) @ _t(z=d)
    return out @ tool


def pinocchio_tcp(robot, q):
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, robot.to_pinocchio_q(q))
    return data.oMf[robot.tool_frame_id].homogeneous


def _as_built(robot, seed, size=2e-3):
    em = ErrorModel(robot)
    x = np.random.default_rng(seed).normal(0.0, size, em.size)
    return em.perturbed_robot(x)


@pytest.mark.parametrize("name", ["ur5", "ur10", "panda", None])
@pytest.mark.parametrize("build", [dh_table, mdh_table], ids=["DH", "MDH"])
def test_tables_of_the_nominal_and_the_as_built_robot_are_its_kinematics(name, build):
    """UR5/UR10 (shoulder, elbow and wrist 1 parallel), Panda and the tool-changer (j2, j3, j5
    parallel, j4 sliding): every table, nominal and as built with mm-sized errors that tilt the
    parallel axes, gives Pinocchio's TCP to 1e-9 m at random joints."""
    robot = load_robot(name)
    as_built = _as_built(robot, 3)
    nominal_table = build(robot)
    table = build(as_built, robot, reference=nominal_table)
    rng = np.random.default_rng(5)
    for q in random_joint_values(robot, 6, rng):
        for t, r in ((nominal_table, robot), (table, as_built)):
            product = table_fk(t.convention, t.params, t.variable, t.base, t.tool, q)
            expected = pinocchio_tcp(r, q)
            np.testing.assert_allclose(product[:3, 3], expected[:3, 3], atol=1e-9, rtol=0)
            np.testing.assert_allclose(product[:3, :3], expected[:3, :3], atol=1e-9, rtol=0)
    # the parallel pairs take Hayati's beta, the table keeps lengths of the robot's size
    assert np.abs(table.params[:, [0, 2]]).max() < 2.0
    if name in ("ur5", "ur10", None):
        assert np.count_nonzero(np.abs(table.params[:, 4]) > 1e-6) >= 1


def test_without_hayati_a_tilted_parallel_pair_puts_the_common_normal_far_away():
    """Plain DH of a UR5 whose parallel axes are tilted by a milliradian: still exact, but d runs to
    hundreds of metres (what the maker's own calibrations hold); Hayati's table stays at 0.5 m."""
    robot = load_robot("ur5")
    as_built = _as_built(robot, 4, 1e-3)
    plain = dh_table(as_built, robot, hayati=False)
    hayati = dh_table(as_built, robot)
    assert np.abs(plain.params[:, 2]).max() > 50.0
    assert np.abs(hayati.params[:, 2]).max() < 0.5
    q = random_joint_values(robot, 1, np.random.default_rng(1))[0]
    np.testing.assert_allclose(table_fk("DH", plain.params, plain.variable, plain.base, plain.tool, q)[:3, 3],
                               pinocchio_tcp(as_built, q)[:3, 3], atol=1e-9, rtol=0)


#: Universal Robots' published DH parameters (CB3): d1, a2, a3, d4, d5, d6 [m]; alpha (90, 0, 0, 90, -90, 0) deg.
UR_PUBLISHED = {"ur5": (0.089159, -0.425, -0.39225, 0.10915, 0.09465, 0.0823),
                "ur10": (0.1273, -0.612, -0.5723, 0.163941, 0.1157, 0.0922)}


@pytest.mark.parametrize("name", sorted(UR_PUBLISHED))
def test_universal_robots_published_dh_is_example_robot_datas_tcp(name):
    """The nominal UR5/UR10 DH as Universal Robots publishes it, multiplied out here from the controller's
    base (example-robot-data's base_link turned 180 deg about z) to the flange, is example-robot-data's
    tool0 within 1e-9 m; the package's maker table of the nominal robot is those numbers."""
    d1, a2, a3, d4, d5, d6 = UR_PUBLISHED[name]
    alpha = np.radians([90, 0, 0, 90, -90, 0])
    a, d = (0, a2, a3, 0, 0, 0), (d1, 0, 0, d4, d5, d6)
    robot = load_robot(name)
    for q in random_joint_values(robot, 8, np.random.default_rng(2)):
        product = _rz(math.pi)
        for i in range(6):
            product = product @ _rz(q[i]) @ _t(z=d[i]) @ _t(x=a[i]) @ _rx(alpha[i])
        expected = pinocchio_tcp(robot, q)
        np.testing.assert_allclose(product[:3, 3], expected[:3, 3], atol=1e-9, rtol=0)
    published, table = published_table(name, robot)
    nominal = maker_table(robot, robot, published)
    np.testing.assert_allclose(nominal.params[:, 0], a, atol=1e-9)
    np.testing.assert_allclose(nominal.params[:, 2], d, atol=1e-9)
    np.testing.assert_allclose(nominal.params[:, 1], alpha, atol=1e-9)
    np.testing.assert_allclose(nominal.params[:, 3], 0.0, atol=1e-9)


def test_franka_published_modified_dh_is_example_robot_datas_panda():
    """Franka's published Craig table (a, d, alpha per row, the flange at d = 0.107 m), multiplied out
    here, is example-robot-data's panda_link8; the maker table of the as-built Panda in Franka's
    convention gives its TCP to 1e-9 m and reads like the published one (corrections of millimetres,
    no sign flipped)."""
    a = (0, 0, 0, 0.0825, -0.0825, 0, 0.088)
    d = (0.333, 0, 0.316, 0, 0.384, 0, 0)
    alpha = np.radians([0, -90, 90, 90, -90, 90, 90])
    robot = load_robot("panda")
    model, data = robot.model, robot.model.createData()
    for q in random_joint_values(robot, 5, np.random.default_rng(3)):
        product = np.eye(4)
        for i in range(7):
            product = product @ _rx(alpha[i]) @ _t(x=a[i]) @ _rz(q[i]) @ _t(z=d[i])
        product = product @ _t(z=0.107)
        pin.framesForwardKinematics(model, data, robot.to_pinocchio_q(q))
        np.testing.assert_allclose(product, data.oMf[model.getFrameId("panda_link8")].homogeneous, atol=1e-9)
    published, _ = published_table("panda", robot)
    as_built = _as_built(robot, 6, 5e-4)
    table = maker_table(as_built, robot, published)
    q = random_joint_values(robot, 1, np.random.default_rng(4))[0]
    np.testing.assert_allclose(table_fk("MDH", table.params, table.variable, table.base, table.tool, q),
                               pinocchio_tcp(as_built, q), atol=1e-9)
    assert np.abs(table.params[:, 0] - a).max() < 3e-3 and np.abs(table.params[:, 2] - d).max() < 5e-3
    assert np.abs(np.degrees(table.params[:, 1] - alpha)).max() < 1.0


def test_as_built_ur_in_the_makers_convention_is_plain_dh_with_the_published_signs():
    robot = load_robot("ur5")
    as_built = _as_built(robot, 8, 3e-4)
    published, _ = published_table("ur5", robot)
    table = maker_table(as_built, robot, published)
    assert not table.params[:, 4].any()  # no beta: the controller's form
    assert np.sign(table.params[1, 0]) == -1 and np.sign(table.params[2, 0]) == -1  # a2, a3 < 0 as published
    q = random_joint_values(robot, 1, np.random.default_rng(9))[0]
    np.testing.assert_allclose(table_fk("DH", table.params, table.variable, table.base, table.tool, q)[:3, 3],
                               pinocchio_tcp(as_built, q)[:3, 3], atol=1e-9, rtol=0)
    assert set(PUBLISHED) >= {"ur3", "ur5", "ur10", "panda"}


def test_the_chain_of_a_two_armed_robot_to_one_hand_has_tables(tmp_path):
    """The torso and one arm of a tree (the other arm outside the chain): both tables exist and give
    the hand's TCP."""
    from test_measured_frames import TWO_ARMS

    urdf = tmp_path / "two_arms.urdf"
    urdf.write_text(TWO_ARMS)
    robot = load_robot(str(urdf), "right_marker")
    as_built = _as_built(robot, 2)
    for build in (dh_table, mdh_table):
        table = build(as_built, robot, reference=build(robot))
        for q in random_joint_values(robot, 3, np.random.default_rng(0)):
            np.testing.assert_allclose(table_fk(table.convention, table.params, table.variable, table.base,
                                                table.tool, q), pinocchio_tcp(as_built, q), atol=1e-9)
