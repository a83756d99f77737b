"""Tracker-frame registration against transforms built by hand and hidden simulated frames."""

import numpy as np
import pinocchio as pin
import pytest

from tcr_accuracy.exceptions import InputError
from tcr_accuracy.model.kinematics import tcp_poses
from tcr_accuracy.frames.registration import register_tracker, rigid_fit
from tcr_accuracy.analysis.simulate import simulate_measurements

#: a tracker 1.2 m away, turned 40 deg about z and tilted a few degrees, with a 30 mm
#: TCP offset (a reflector on a tool): the situation of every laser tracker
TRACKER = {"base_mm": {"dx": 1200.0, "dy": -300.0, "dz": 450.0},
           "base_deg": {"rx": 3.0, "ry": -2.0, "rz": 40.0},
           "tool_mm": {"dx": 0.5, "dy": -1.0, "dz": 30.0}}
NOISE_M = 2e-5


def _hidden_frame(truth):
    """tracker_M_base of the simulated scenario, by Pinocchio's exp6 of the hidden base twist."""
    p = truth["effects"]["frames"]["parameters"]
    twist = np.array([p[f"frames.base.{c}"] for c in ("dx", "dy", "dz", "rx", "ry", "rz")])
    tool = np.array([p[f"frames.tool.{c}"] for c in ("dx", "dy", "dz")])
    return pin.exp6(pin.Motion(twist[:3], twist[3:])), tool


@pytest.fixture(scope="module")
def tracked(ur5):
    rng = np.random.default_rng(21)
    mset, truth = simulate_measurements(ur5, {"effects": {"frames": TRACKER}}, 200, rng, noise_m=NOISE_M)
    return mset, truth


def test_rigid_fit_recovers_a_transform_built_by_hand():
    rng = np.random.default_rng(0)
    points = rng.uniform(-0.8, 0.8, (25, 3))
    rotation = pin.exp3(np.array([0.4, -1.1, 2.0]))  # 133 deg about a skew axis
    translation = np.array([1.5, -0.2, 0.7])
    r, t = rigid_fit(points, points @ rotation.T + translation)
    np.testing.assert_allclose(r, rotation, atol=1e-12)
    np.testing.assert_allclose(t, translation, atol=1e-12)


def test_rigid_fit_refuses_points_on_a_line():
    line = np.outer(np.linspace(0, 1, 10), [1.0, 2.0, -0.5])
    with pytest.raises(InputError, match="lie on one line"):
        rigid_fit(line, line + 1.0)
    with pytest.raises(InputError, match="at least 3 poses"):
        rigid_fit(line[:2], line[:2])


def test_registration_recovers_the_hidden_tracker_frame_and_tcp_offset(ur5, tracked):
    mset, truth = tracked
    hidden, tool = _hidden_frame(truth)
    reg = register_tracker(ur5, mset.q, mset.position)
    # rotation to a few microradians, translation to a few micrometres (200 points, 20 um noise)
    angle = np.linalg.norm(pin.log3(hidden.rotation.T @ reg.rotation))
    assert angle < 2e-5
    np.testing.assert_allclose(reg.translation, hidden.translation, atol=2e-5)
    np.testing.assert_allclose(reg.tool_offset, tool, atol=2e-5)
    np.testing.assert_allclose(reg.matrix, hidden.homogeneous, atol=2e-5)
    # what is left is the tracker noise: RMS norm sqrt(3) x 20 um, within 15 %
    assert reg.residual_rms == pytest.approx(np.sqrt(3) * NOISE_M, rel=0.15)
    assert len(reg.fitted) == 9 and reg.n_points == 200


def test_the_closed_form_alone_misses_by_the_tcp_offset_the_refinement_finds(ur5, tracked):
    mset, _ = tracked
    reg = register_tracker(ur5, mset.q, mset.position)
    nominal = tcp_poses(ur5, mset.q).position
    closed = nominal @ reg.closed_form_rotation.T + reg.closed_form_translation - mset.position
    closed_rms = np.sqrt(np.mean(np.sum(closed**2, axis=1)))
    assert closed_rms > 1e-2  # a 30 mm offset turning with the tool: centimetres
    assert reg.residual_rms < 2.5 * NOISE_M < 2e-3 * closed_rms


def test_points_map_both_ways_and_base_mode_fits_only_the_tcp_offset(ur5, tracked):
    mset, truth = tracked
    hidden, tool = _hidden_frame(truth)
    reg = register_tracker(ur5, mset.q, mset.position)
    points = np.random.default_rng(1).normal(size=(7, 3))
    np.testing.assert_allclose(reg.to_base(reg.to_tracker(points)), points, atol=1e-12)
    np.testing.assert_allclose(reg.to_tracker(points), points @ hidden.rotation.T + hidden.translation, atol=1e-4)
    # the same robot measured in its base frame: no frame to fit, the TCP offset is still found
    in_base = (mset.position - hidden.translation) @ hidden.rotation
    base = register_tracker(ur5, mset.q, in_base, fit_base=False)
    np.testing.assert_array_equal(base.rotation, np.eye(3))
    np.testing.assert_array_equal(base.translation, np.zeros(3))
    assert base.fitted == ("frames.tool.dx", "frames.tool.dy", "frames.tool.dz")
    np.testing.assert_allclose(base.tool_offset, tool, atol=2e-5)
    # the model with the fitted offset is the nominal TCP moved by R(q) d
    rotation = tcp_poses(ur5, mset.q).rotation
    np.testing.assert_allclose(base.tcp_positions(ur5, mset.q),
                               tcp_poses(ur5, mset.q).position + rotation @ base.tool_offset, atol=1e-12)


def test_a_tcp_offset_the_poses_cannot_separate_from_the_frame_is_held_at_zero(ur5):
    """Constant TCP orientation (UR5: q1, q5, q6 fixed and q2 + q3 + q4 constant): a TCP offset
    is then a base translation, so it is not fitted."""
    rng = np.random.default_rng(2)
    q = np.zeros((40, 6))
    q[:, 0], q[:, 4], q[:, 5] = 0.3, 1.2, -0.4
    q[:, 1] = rng.uniform(-1.8, -0.8, 40)
    q[:, 2] = rng.uniform(0.5, 1.8, 40)
    q[:, 3] = -1.2 - q[:, 1] - q[:, 2]
    assert np.ptp(tcp_poses(ur5, q).rotation, axis=0).max() < 1e-12
    measured = tcp_poses(ur5, q).position + np.array([0.3, 0.1, -0.2])
    reg = register_tracker(ur5, q, measured)
    assert not any(n.startswith("frames.tool.") for n in reg.fitted)
    np.testing.assert_array_equal(reg.tool_offset, np.zeros(3))
    assert reg.residual_rms < 1e-9


def test_registration_input_errors_name_the_problem(ur5):
    q = np.zeros((5, 6))
    with pytest.raises(InputError, match=r"needs joint values \(N, 6\) and positions \(N, 3\)"):
        register_tracker(ur5, q, np.zeros((4, 3)))
    bad = np.ones((5, 3))
    bad[2, 1] = np.nan
    with pytest.raises(InputError, match="must be finite"):
        register_tracker(ur5, q + np.arange(5)[:, None] * 0.1, bad)


def test_the_residual_rms_is_the_root_mean_square_of_the_point_distances(ur5, tracked):
    """The residual figure against the distances recomputed here with Pinocchio's own forward
    kinematics: the root of the mean squared distance, not the mean distance (for 3D Gaussian
    noise the mean is sqrt(8 / (3 pi)) = 0.92 of the RMS, which a tolerance on the noise alone
    would not tell apart)."""
    mset, _ = tracked
    reg = register_tracker(ur5, mset.q, mset.position)
    model, data = ur5.model, ur5.model.createData()
    points = []
    for q in mset.q:
        pin.framesForwardKinematics(model, data, q)
        tool = data.oMf[ur5.tool_frame_id]
        points.append(tool.translation + tool.rotation @ reg.tool_offset)
    distances = np.linalg.norm(np.asarray(points) @ reg.rotation.T + reg.translation - mset.position, axis=1)
    assert reg.residual_rms == pytest.approx(np.sqrt(np.mean(distances**2)), rel=1e-9)
    assert abs(reg.residual_rms - distances.mean()) > 0.02 * reg.residual_rms  # the two figures differ here
