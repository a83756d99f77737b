"""``diagnosis/stages/register.py`` read whole (issue 36, third pass): one session named by a single label,
base references seeing a linear tracker drift, and measured orientation, against a registration written
out here on numpy (the drift's least-squares slope, Kabsch on numpy's SVD, the rotation products) and
Pinocchio's forward kinematics. Each test names planted changes it was seen to catch."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from scipy.spatial.transform import Rotation

from tcr_accuracy.diagnosis.stages.register import MeasuredFrame, register_measurements
from tcr_accuracy.io.measurement_set import MeasurementSet
from tcr_accuracy.model.robot import load_robot

from test_mutp_register import _kabsch  # (R, t) with tracker ~ R base + t: Kabsch on numpy's SVD, written out

N = 24
#: the tracker frame: p_tracker = R p_base + t
TRACKER_R = Rotation.from_rotvec([0.1, -0.2, 0.3]).as_matrix()
TRACKER_T = np.array([1.0, -0.5, 0.2])
#: the tracker's drift per row [m]
VELOCITY = np.array([2e-6, -1e-6, 3e-6])
#: base references' places in the base frame [m]
PLACES = np.array([[0.8, 0.1, 0.0], [-0.3, 0.9, 0.05], [0.1, -0.7, 0.4]])


@pytest.fixture(scope="module")
def campaign():
    """24 poses of the tool changer (Pinocchio), measured in a turned and shifted tracker frame drifting by
    VELOCITY per row, with their orientation (w, x, y, z) and one session label on every row; three base
    references read on the same rows with 2 um of noise."""
    robot = load_robot()
    rng = np.random.default_rng(41)
    q = rng.uniform(*robot.joint_bounds(), size=(N, robot.n_joints))
    data = robot.model.createData()
    base = np.empty((N, 3))
    base_rotation = np.empty((N, 3, 3))
    for i, row in enumerate(q):
        pin.framesForwardKinematics(robot.model, data, robot.to_pinocchio_q(row))
        base[i] = data.oMf[robot.tool_frame_id].translation
        base_rotation[i] = data.oMf[robot.tool_frame_id].rotation
    drift = np.outer(np.arange(N), VELOCITY)
    tracker = base @ TRACKER_R.T + TRACKER_T + drift
    tracker_rotation = TRACKER_R @ base_rotation
    x, y, z, w = Rotation.from_matrix(tracker_rotation).as_quat().T
    measured = MeasurementSet(joint_names=robot.joint_names, q=q, position=tracker,
                              quaternion=np.stack([w, x, y, z], axis=1), session=np.array(["A"] * N))
    references = [(f"ref{k}", place, place @ TRACKER_R.T + TRACKER_T + drift + 2e-6 * rng.standard_normal((N, 3)),
                   None) for k, place in enumerate(PLACES)]
    registered = register_measurements([MeasuredFrame(robot, measured, robot.tool_frame)], references)
    return robot, base, tracker, tracker_rotation, references, registered


def test_one_session_label_is_one_session_and_its_drift_is_taken_out_of_every_point(campaign):
    """A single session label is one session (no labels, every row session 0) with one drift report
    ("all"); the references' drift is the pooled least-squares slope of their readings against the row
    (each its own offset, written out), taken out of every measured position and reference reading about
    the middle row; the tracker frame is Kabsch on the nominal points and the references' places against
    the corrected points and the references' mean readings. Seen failing on ``len(first.session_labels) >
    1`` turned to ``> 0``, on ``max(len(sessions), 1)`` turned to ``0`` and to ``2``, on
    ``f.measurements.position - drift`` and on ``measured - drift`` turned to ``+`` (planted by hand)."""
    _, base, tracker, _, references, registered = campaign
    assert registered.session_labels == () and registered.own_frames == ""
    assert registered.session_of.tolist() == [0] * N
    assert [d["session"] for d in registered.drift] == ["all"]
    assert registered.drift[0]["corrected"] is True
    rows = np.arange(N, dtype=float)
    t = rows - rows.mean()
    slope = sum(t @ (m - m.mean(axis=0)) for _, _, m, _ in references) / (len(references) * (t @ t))
    np.testing.assert_allclose(slope, VELOCITY, rtol=0, atol=2e-7)
    correction = np.outer(t, slope)
    np.testing.assert_allclose(registered.measurements.position, tracker - correction, rtol=0, atol=1e-12)
    for (_, _, before, _), (_, _, after, _) in zip(references, registered.references):
        np.testing.assert_allclose(after, before - correction, rtol=0, atol=1e-12)
    station = _kabsch(np.concatenate([base, PLACES]),
                      np.concatenate([tracker - correction] + [m.mean(axis=0)[None] - correction.mean(axis=0)
                                                              for _, _, m, _ in references]))
    assert len(registered.stations) == 1
    np.testing.assert_allclose(registered.stations[0][0], station[0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(registered.stations[0][1], station[1], rtol=0, atol=1e-9)
    np.testing.assert_allclose(registered.parts[0].target, (tracker - correction - station[1]) @ station[0],
                               rtol=0, atol=1e-12)


def test_measured_orientation_becomes_the_tool_rotation_in_the_base_frame_and_is_said_with_its_weight(campaign):
    """Each row's measured rotation (the quaternion read as w, x, y, z) taken into the base frame by the
    session's tracker rotation, ``R_station^T R_tracker`` (written out as a matrix product), which is
    Pinocchio's tool rotation to within the registration's error; the note gives the orientation weight, the
    corrected points' RMS spread about their centre, to four digits. Seen failing on
    ``np.stack([x, y, z, w], axis=1)`` turned to ``axis=2``, on the spread's ``** 2`` turned to ``** 3`` and on
    the einsum ``"nji,njk->nik"`` (R^T R_tracker) turned to ``"nij,njk->nik"`` (planted by hand)."""
    _, _, tracker, tracker_rotation, _, registered = campaign
    station = registered.stations[0][0]
    expected = np.array([station.T @ r for r in tracker_rotation])
    np.testing.assert_allclose(registered.parts[0].target_rotation, expected, rtol=0, atol=1e-12)
    points = registered.measurements.position
    weight = float(np.sqrt(np.mean(np.sum((points - points.mean(axis=0)) ** 2, axis=1))))
    assert registered.orientation_weight == pytest.approx(weight, rel=1e-12)
    assert registered.parts[0].orientation_weight == pytest.approx(weight, rel=1e-12)
    assert registered.notes == (
        f"measured orientation enters the fit: rotation errors [rad] weighted by {weight:.4g} m/rad (an angle counts "
        "as the position error it makes at the measured points' RMS spread about their centre)",)


def test_the_gravity_torque_is_the_first_measured_frames_at_its_own_payload(campaign):
    """Two measured frames on the same rows, the first carrying 5 kg, the second's file saying none: the gravity
    torque on each joint is the first frame's chain at 5 kg, which differs from the arm's own by the point
    mass' ``J^T (0, 0, m g)`` at the tool frame (Pinocchio's frame Jacobian, world-aligned, written out; up to
    the sign convention) and not at the second frame's 0 kg. Seen failing on ``context = parts[0].context``
    turned to ``parts[-1]`` (a measuring sample's survivor, seed 4200: one measured frame makes them the same)
    and on ``payload_kg`` read from ``main``'s context replaced by 0 (planted by hand)."""
    robot, _, tracker, _, _, _ = campaign
    q = campaign[5].measurements.q
    loaded = MeasurementSet(joint_names=robot.joint_names, q=q, position=tracker, payload_kg=np.full(N, 5.0))
    bare = MeasurementSet(joint_names=robot.joint_names, q=q, position=tracker + 0.05)
    registered = register_measurements([MeasuredFrame(robot, loaded, robot.tool_frame),
                                        MeasuredFrame(robot, bare, "second")])
    alone = register_measurements([MeasuredFrame(robot, bare, robot.tool_frame)]).gravity_torque
    model, data = robot.model, robot.model.createData()
    g = np.linalg.norm(model.gravity.linear)
    for i, row in enumerate(q):
        configuration = robot.to_pinocchio_q(row)
        pin.computeJointJacobians(model, data, configuration)
        pin.updateFramePlacements(model, data)
        jacobian = pin.getFrameJacobian(model, data, robot.tool_frame_id, pin.LOCAL_WORLD_ALIGNED)[:3]
        columns = [model.joints[model.getJointId(name)].idx_v for name in robot.joint_names]
        payload = jacobian[:, columns].T @ np.array([0.0, 0.0, 5.0 * g])
        np.testing.assert_allclose(np.abs(registered.gravity_torque[i] - alone[i]), np.abs(payload), rtol=1e-9,
                                   atol=1e-9)
    assert np.max(np.abs(registered.gravity_torque - alone)) > 1.0
    assert registered.measured_context == frozenset({"payload_kg"})
