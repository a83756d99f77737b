"""Independent checks of the kinematics, as the seed checked its model against ADAMS.

The reference here is a product of exponentials written from the seed's equations with
scipy's matrix exponential of 4x4 twist matrices: it shares no code with Pinocchio or
with tcr_accuracy's batched engine.
"""

import numpy as np
import pinocchio as pin
import pytest
from scipy.linalg import expm

from tcr_accuracy.model.errors import ErrorModel
from tcr_accuracy.model.kinematics import pose_error, tcp_poses, tcp_poses_pinocchio

from conftest import random_joint_values

L = dict(l1=0.315, l2=0.210, l3=0.796, l4=0.560, l5=0.240, l6=0.165)


def twist_matrix(w, v):
    """se(3) matrix of the screw (w, v) as in the seed's Eq. (5)."""
    wx, wy, wz = w
    out = np.zeros((4, 4))
    out[:3, :3] = [[0, -wz, wy], [wz, 0, -wx], [-wy, wx, 0]]
    out[:3, 3] = v
    return out


def seed_screws(dl=np.zeros(6)):
    """Joint screws (w, v) and T(0) of the tool-changer, seed Eq. (3), (4), (23), (24)."""
    l1, l2, l3, l4, l5, l6 = np.array(list(L.values())) + dl
    points = [
        (0, 0, l1), (0, 0, l1 + l2), (0, l3, l1 + l2), None,
        (0, l3 + l4 + l5, l1 + l2), (0, l3 + l4 + l5 + l6, l1 + l2),
    ]
    axes = [(0, 0, 1), (1, 0, 0), (1, 0, 0), (0, 1, 0), (1, 0, 0), (0, 0, 1)]
    screws = []
    for point, axis in zip(points, axes):
        axis = np.array(axis, float)
        if point is None:  # prismatic: xi = (0, v)
            screws.append((np.zeros(3), axis))
        else:  # revolute: xi = (w, -w x q)
            screws.append((axis, -np.cross(axis, np.array(point, float))))
    t0 = np.eye(4)
    t0[:3, 3] = (0, l3 + l4 + l5 + l6, l1 + l2)
    return screws, t0


def seed_poe(theta, screws, t0, error_screws=None):
    """Seed Eq. (13) / (22): prod_i exp(xi_e,i) exp(theta_i xi_i) T(0)."""
    out = np.eye(4)
    for i, (w, v) in enumerate(screws):
        if error_screws is not None:
            out = out @ expm(twist_matrix(*error_screws[i]))
        out = out @ expm(twist_matrix(w, v) * theta[i])
    return out @ t0


def test_pinocchio_fk_equals_the_seed_poe(tool_changer):
    rng = np.random.default_rng(11)
    q = random_joint_values(tool_changer, 40, rng)
    screws, t0 = seed_screws()
    expected = np.array([seed_poe(qi, screws, t0) for qi in q])
    loop = tcp_poses_pinocchio(tool_changer, q)
    engine = tcp_poses(tool_changer, q)
    np.testing.assert_allclose(loop.position, expected[:, :3, 3], atol=1e-12)
    np.testing.assert_allclose(loop.rotation, expected[:, :3, :3], atol=1e-12)
    np.testing.assert_allclose(engine.position, expected[:, :3, 3], atol=1e-12)
    np.testing.assert_allclose(engine.rotation, expected[:, :3, :3], atol=1e-12)


def test_link_length_and_drive_errors_equal_the_seed_eq24_model(tool_changer):
    """Seed Eq. (24): link length errors move the axis points; drive errors add to theta."""
    rng = np.random.default_rng(5)
    em = ErrorModel(tool_changer)
    q = random_joint_values(tool_changer, 20, rng)
    for qi in q:
        dl = rng.normal(0, 0.2e-3, 6)
        dtheta = rng.normal(0, 0.0087, 6)
        x = em.zeros()
        for name, comp, value in zip(["j1", "j2", "j3", "j4", "j5", "j6"], ["dz", "dz", "dy", "dy", "dy", "dy"], dl):
            x[em.index(f"{name}.{comp}")] = value
        x[em.drive_slice] = dtheta
        screws, t0 = seed_screws(dl)
        expected = seed_poe(qi + dtheta, screws, t0)
        got = tcp_poses(tool_changer, qi, x, em)
        np.testing.assert_allclose(got.position[0], expected[:3, 3], atol=1e-12)
        np.testing.assert_allclose(got.rotation[0], expected[:3, :3], atol=1e-12)


def adjoint(transform):
    r, p = transform[:3, :3], transform[:3, 3]
    px = np.array([[0, -p[2], p[1]], [p[2], 0, -p[0]], [-p[1], p[0], 0]])
    out = np.zeros((6, 6))
    out[:3, :3] = r
    out[3:, 3:] = r
    out[:3, 3:] = px @ r
    return out


def test_placement_twists_equal_the_seed_error_screw_poe(tool_changer):
    """Seed Eq. (20)-(22): one error screw per joint, spatial, at the zero configuration.

    The error screw of joint i is the placement twist seen from the base at q = 0,
    Ad(T_i(0)) xi_i, written (w_e, v_e) with v_e = r' x w_e for a pure tilt.
    """
    rng = np.random.default_rng(8)
    em = ErrorModel(tool_changer)
    screws, t0 = seed_screws()
    model, data = tool_changer.model, tool_changer.model.createData()
    pin.forwardKinematics(model, data, pin.neutral(model))
    zero_frames = [data.oMi[j].homogeneous for j in range(1, model.njoints)]
    for scale in (1e-6, 1e-4, 1e-2):
        x = em.zeros()
        x[em.placement_slice] = rng.normal(0, scale, 36)
        x[em.drive_slice] = rng.normal(0, scale, 6)
        local = em.split(x).placement
        spatial = [adjoint(zero_frames[i]) @ local[i] for i in range(6)]  # (v, w)
        error_screws = [(s[3:], s[:3]) for s in spatial]
        qi = random_joint_values(tool_changer, 1, rng)[0]
        expected = seed_poe(qi + x[em.drive_slice], screws, t0, error_screws)
        got = tcp_poses(tool_changer, qi, x, em)
        np.testing.assert_allclose(got.position[0], expected[:3, 3], atol=1e-12)
        np.testing.assert_allclose(got.rotation[0], expected[:3, :3], atol=1e-12)


def test_tilt_screw_written_as_r_cross_w_is_the_placement_rotation(tool_changer):
    """A tilt of joint 3's axis about z through its centre r3: seed's xi_e = (w_e, r' x w_e)."""
    em = ErrorModel(tool_changer)
    angle = 1e-3
    x = em.zeros()
    x[em.index("j3.rz")] = angle
    r3 = np.array([0, L["l3"], L["l1"] + L["l2"]])
    w_e = np.array([0.0, 0.0, 1.0])
    error_screws = [(np.zeros(3), np.zeros(3))] * 6
    error_screws[2] = (w_e * angle, np.cross(r3, w_e) * angle)
    screws, t0 = seed_screws()
    q = np.radians([15, 30, -10, 0, -20, 0])
    expected = seed_poe(q, screws, t0, error_screws)
    got = tcp_poses(tool_changer, q, x, em)
    np.testing.assert_allclose(got.position[0], expected[:3, 3], atol=1e-12)


@pytest.mark.parametrize("scale", [1e-5, 1e-4, 1e-3])
def test_small_errors_follow_the_first_order_jacobian(tool_changer, scale):
    """Error screws are first order: the residual to the linear prediction shrinks as scale^2."""
    from tcr_accuracy.model.jacobians import error_jacobian

    rng = np.random.default_rng(2)
    em = ErrorModel(tool_changer)
    q = tool_changer.working_pose
    x = rng.normal(0, scale, em.size)
    err = pose_error(tcp_poses(tool_changer, q), tcp_poses(tool_changer, q, x, em))
    predicted = error_jacobian(tool_changer, q, em) @ x
    residual = np.abs(err.position[0] - predicted[:3]).max()
    assert residual < 20 * scale**2  # metres; reach ~2 m, second-order terms ~ |x|^2 * reach
    assert np.abs(err.position[0]).max() > 0.5 * scale  # and the error itself is first order
