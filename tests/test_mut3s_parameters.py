"""``diagnosis/stages/parameters.py`` read whole (issue 36, third pass): a UR5 (its tool frame is ``tool0``, not
``tool``) measured at a point 5 cm from ``tool0`` by a tracker in a frame written out here, its joints 2-5
turned by hidden offsets (Pinocchio's forward kinematics; the effects the diagnosis fits are not used to make
the data). The fitted tracker frame, the as-built error vector and the TCP-offset check are compared with that
hidden truth and with the formulas written out. Each test names planted changes it was seen to catch."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest
from scipy.spatial.transform import Rotation

from tcr_accuracy.diagnosis.diagnose import GapDiagnosis
from tcr_accuracy.io.measurement_set import MeasurementSet
from tcr_accuracy.model.errors import ErrorModel
from tcr_accuracy.model.robot import load_robot

#: hidden joint offsets [rad] (joints 1 and 6 turn what the base and tool frames already hold: left at 0)
OFFSETS = np.array([0.0, 2e-3, -1.5e-3, 1e-3, 2.5e-3, 0.0])
#: the measured point in tool0's axes [m]
POINT = np.array([0.01, -0.02, 0.05])
#: the tool offset the user says [m] (1 mm off the hidden one along x)
GIVEN = np.array([0.011, -0.02, 0.05])
TRACKER = pin.SE3(Rotation.from_rotvec([0.05, -0.1, 0.8]).as_matrix(), np.array([2.0, -0.4, 0.3]))
NOISE_M = 5e-6


@pytest.fixture(scope="module")
def fitted():
    robot = load_robot("ur5")
    rng = np.random.default_rng(8)
    low, high = robot.joint_bounds()
    q = rng.uniform(np.maximum(low, -2.5), np.minimum(high, 2.5), (40, robot.n_joints))
    data = robot.model.createData()
    position = np.empty((40, 3))
    for i, row in enumerate(q + OFFSETS):
        pin.framesForwardKinematics(robot.model, data, robot.to_pinocchio_q(row))
        position[i] = TRACKER.act(data.oMf[robot.tool_frame_id].act(POINT))
    position += NOISE_M * rng.standard_normal(position.shape)
    measured = MeasurementSet(joint_names=robot.joint_names, q=q, position=position)
    estimator = GapDiagnosis(robot=robot, effects=["joint_offsets"], folds=5, stability_replays=2,
                             tcp_offset=GIVEN).fit(measured)
    return robot, estimator.result_


def test_the_tracker_frame_and_the_as_built_tool_offset_are_the_hidden_ones(fitted):
    """trackerMbase is the hidden tracker frame (to 30 um and 30 urad over a robot 1 m across, 5 um of
    noise); the as-built vector holds no base twist (exactly 0: it belongs to the tracker frame), its tool
    slice is the measured point's offset from tool0 (to 30 um) and its drive slice the hidden offsets of
    joints 2-5 (to 3e-5 rad). Seen failing on ``as_built[em.base_slice] = 0.0`` turned to ``1.0``, on
    ``homogeneous(*registered.stations[0]) @ pin.exp6(base_twist)`` losing the fitted twist (``base_twist *
    0``) and on ``theta = final["phi"] * final["scale"]`` turned to ``+`` (planted by hand)."""
    robot, d = fitted
    assert d.selected_effects == ["frames", "joint_offsets"] or list(d.selected_effects) == ["frames",
                                                                                              "joint_offsets"]
    np.testing.assert_allclose(d.trackerMbase[:3, :3], TRACKER.rotation, rtol=0, atol=3e-5)
    np.testing.assert_allclose(d.trackerMbase[:3, 3], TRACKER.translation, rtol=0, atol=3e-5)
    np.testing.assert_allclose(d.trackerMbase[3], [0.0, 0.0, 0.0, 1.0], rtol=0, atol=0)
    em = ErrorModel(robot)
    x = d.as_built_x
    assert np.all(x[em.base_slice] == 0.0)
    np.testing.assert_allclose(pin.exp6(x[em.tool_slice]).translation, POINT, rtol=0, atol=3e-5)
    np.testing.assert_allclose(x[em.drive_slice][1:5], OFFSETS[1:5], rtol=0, atol=3e-5)
    for name, value in d.parameters["joint_offsets"].items():
        j = robot.joint_names.index(name.split(".")[-1]) if name.split(".")[-1] in robot.joint_names else \
            int(name[-1]) - 1
        assert value == pytest.approx(OFFSETS[j], abs=3e-5), name


def test_the_tcp_offset_check_weighs_the_fitted_offsets_standard_errors_by_the_difference(fitted):
    """The given offset (1 mm off the hidden one along x) against the fitted one: their difference
    (fitted - given, mm in the detail) and its standard error, ``sqrt(sum((d_i / |d|)^2 s_i^2))`` with s_i the
    parameter table's standard errors of ``frames.tool.dx/dy/dz`` (written out): on a UR5, whose tool frame
    is ``tool0``, the TCP offset's parameters are still ``frames.tool.*`` (one measured frame). Seen failing
    on ``len(registered.parts) == 1`` turned to ``== 0`` and to ``== 2`` (planted by hand: the standard error
    is then 0, its names ``frames.tool0.*`` unknown)."""
    _, d = fitted
    check = next(c for c in d.stages.parameters.geometry_checks if c.what == "tcp_offset")
    fitted_mm = np.array(check.detail["fitted_mm"])
    np.testing.assert_allclose(fitted_mm, POINT * 1e3, rtol=0, atol=0.03)
    difference = fitted_mm * 1e-3 - GIVEN
    np.testing.assert_allclose(check.detail["difference_mm"], difference * 1e3, rtol=0, atol=1e-9)
    assert check.value == pytest.approx(np.linalg.norm(difference), rel=1e-9)
    std = d.parameter_table["frames"]["std"]
    sigma = np.array([std[f"frames.tool.{c}"] for c in ("dx", "dy", "dz")])
    assert np.all(sigma > 0) and np.all(np.isfinite(sigma))
    expected = math.sqrt(float(np.sum((difference / np.linalg.norm(difference)) ** 2 * sigma**2)))
    assert check.std == pytest.approx(expected, rel=1e-9)
