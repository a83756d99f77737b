"""An ISO 9283 pose test's account of itself (``iso9283/evaluate.py``): the target columns' warning,
how the frame was found or fitted in words with its figures in mm, and the readings a compensation
would leave, against a hidden truth built here (the UR5's nominal TCP, a base-frame error per pose,
a tracker frame the code never sees, encoder offsets put into Pinocchio's forward kinematics by
hand). Each test names a planted change it was seen to catch.
"""

import dataclasses
import warnings

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import tcr_accuracy as tcr
from tcr_accuracy.effects.joint_offsets import JointOffsets
from tcr_accuracy.iso9283.evaluate import (RELATIVE_WORDS, compensated_readings, evaluate_conditions,
                                           evaluate_pose_test, register_from)

MM = 1e-3


@pytest.fixture(scope="module")
def setup():
    robot = tcr.load_robot("ur5")
    plan = tcr.plan_iso_cube(robot, random_state=0, centre=[-0.13, -0.44, 0.32], size=0.2)
    series = plan.series(cycles=3)
    series = dataclasses.replace(series, rows=np.arange(len(series)) + 2, source="t.csv")
    rng = np.random.default_rng(3)
    error = {f"P{k}": rng.normal(0, 0.6 * MM, 3) for k in range(1, 6)}
    pose_id = series.annotations["pose_id"]
    nominal = tcr.tcp_poses(robot, series.q).position
    base = nominal + np.array([error[p] for p in pose_id]) + rng.normal(0, 0.02 * MM, (len(series), 3))
    rotation = Rotation.from_rotvec([0.1, 0.4, -0.9]).as_matrix()
    translation = np.array([1.7, 0.6, -0.3])
    q_cal = rng.uniform(-1.5, 1.5, (25, 6))
    calibration = tcr.MeasurementSet(joint_names=list(robot.joint_names), q=q_cal, source="cal.csv",
                                     position=tcr.tcp_poses(robot, q_cal).position @ rotation.T + translation
                                     + rng.normal(0, 0.03 * MM, (25, 3)))
    return robot, series, nominal, base, rotation, translation, calibration


def test_target_columns_past_ten_micrometres_warn_naming_the_row_and_the_gap_in_mm(setup):
    """The plan's target columns moved 9.9 um off the nominal TCP on every row: no warning; row 7 of the
    file moved 12 um: one warning naming row 7 and 0.012 mm. Catches the warning's ``gap[r] * 1e3``
    as ``/ 1e3`` and the targets' ``* 1e-3`` changed."""
    robot, series, nominal, base, *_ = setup
    direction = np.array([1.0, 2.0, -2.0]) / 3.0

    def with_targets(targets):
        labels = dict(series.annotations)
        labels.update({f"target_{a}_mm": targets[:, k] * 1e3 for k, a in enumerate("xyz")})
        return dataclasses.replace(series, position=base, annotations=labels)

    inside = nominal + 0.99e-5 * direction
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        evaluate_pose_test(robot, with_targets(inside), frame="base")
    past = inside.copy()
    past[5] = nominal[5] + 1.2e-5 * direction
    with pytest.warns(UserWarning) as caught:
        evaluate_pose_test(robot, with_targets(past), frame="base")
    assert len(caught) == 1
    assert str(caught[0].message) == ("t.csv: row 7, columns target_x_mm..target_z_mm: 0.012 mm from the robot's "
                                      "nominal TCP at the commanded joints (another robot or tool?); the figures "
                                      "use the nominal TCP")


def test_how_the_frame_came_gives_its_residual_and_what_it_moves_in_mm(setup):
    """The same readings three ways: in a tracker frame with the frame from a calibration set of 25
    poses (its residual RMS in mm, 4 decimals); fitted on the test's poses (the fit's residual RMS in
    mm); as base-frame readings, found so (what a frame fitted on them would move, in mm, 3 digits:
    the largest displacement of the nominal TCP by that fit, written out here). Catches each
    ``residual_rms * 1e3`` in the words as ``/ 1e3`` and ``moved * 1e3`` likewise."""
    robot, series, nominal, base, rotation, translation, calibration = setup
    registration = register_from(robot, calibration)
    readings = base @ rotation.T + translation
    given = evaluate_pose_test(robot, dataclasses.replace(series, position=readings), registration=registration,
                               registration_source="cal.csv")
    rms = registration.residual_rms * 1e3
    assert 0.02 < rms < 0.05
    assert given.how == (f"from cal.csv: fitted on its 25 poses (Kabsch, then least squares with the TCP offset; "
                         f"fit residual RMS {rms:.4f} mm)")
    fitted = evaluate_pose_test(robot, dataclasses.replace(series, position=readings), frame="fit")
    fit_rms = fitted.registration.residual_rms * 1e3
    assert 0.1 < fit_rms < 2.0
    assert fitted.how.startswith("fitted on the test poses: Kabsch on the barycentres of the 5 poses against the "
                                 "nominal TCP, refined by least squares; ")
    assert fitted.how.endswith(f"; fit residual RMS {fit_rms:.4f} mm; {RELATIVE_WORDS}")
    in_base = dataclasses.replace(series, position=base)
    frame = evaluate_pose_test(robot, in_base, frame="fit").registration
    poses = tcr.tcp_poses(robot, np.array([q for q in evaluate_pose_test(robot, in_base, frame="fit")
                                            .pose_q.values()])).position
    moved = np.max(np.linalg.norm(frame.to_tracker(poses) - poses, axis=1)) * 1e3
    assert 0.05 < moved < 5.0
    found = evaluate_pose_test(robot, in_base)
    assert found.frame == "base"
    assert f"would move them by {moved:.3g} mm at most" in found.how


def test_a_later_condition_in_the_reference_blocks_frame_says_its_residual_in_mm(setup):
    """Two conditions in a tracker frame, no calibration set: the reference block's frame is fitted on
    its poses and used for the 10 % load block, whose account names the block, its 5 poses and the
    fit's residual RMS in mm. Catches that ``residual_rms * 1e3`` as ``/ 1e3``."""
    robot, series, nominal, base, rotation, translation, _ = setup
    n = len(series)
    both = series.subset(np.concatenate([np.arange(n), np.arange(n)]))
    labels = dict(both.annotations)
    labels["load_pct"] = np.r_[np.full(n, 100.0), np.full(n, 10.0)]
    labels["speed_pct"] = np.full(2 * n, 100.0)
    readings = np.vstack([base, base + 0.1 * MM]) @ rotation.T + translation
    blocks = evaluate_conditions(robot, dataclasses.replace(both, position=readings, annotations=labels))
    (_, reference), (_, light) = blocks
    rms = reference.registration.residual_rms * 1e3
    assert 0.1 < rms < 2.0
    assert light.how == (f"fitted on the 100 % rated load, 100 % rated speed block: 5 poses of this test (fit "
                         f"residual RMS {rms:.4f} mm); {RELATIVE_WORDS}")


def test_compensated_readings_take_off_the_models_displacement_turned_into_the_tracker_frame(setup):
    """Encoder offsets (0.3, -0.2, 0.4, 0.1, -0.5, 0.2 mrad) as the model: the readings a compensation
    leaves are the readings less (FK(q + offset) - FK(q)) turned into the tracker frame by its
    rotation, FK on Pinocchio in the test; the orientations are dropped. Catches ``mset.position -
    shift`` as ``+`` and ``predict_positions(...) - tcp_poses(...)`` as ``+``."""
    import pinocchio as pin

    robot, series, nominal, base, rotation, translation, calibration = setup
    registration = register_from(robot, calibration)
    offsets = np.array([0.3, -0.2, 0.4, 0.1, -0.5, 0.2]) * 1e-3
    readings = base @ rotation.T + translation
    quaternion = np.tile([1.0, 0.0, 0.0, 0.0], (len(series), 1))
    mset = dataclasses.replace(series, position=readings, quaternion=quaternion)
    got = compensated_readings(robot, mset, registration, [JointOffsets(robot)], [offsets])

    def fk(q):
        data = robot.model.createData()
        out = []
        for row in q:
            pin.framesForwardKinematics(robot.model, data, robot.to_pinocchio_q(row))
            out.append(data.oMf[robot.tool_frame_id].translation.copy())
        return np.array(out)

    shift = fk(series.q + offsets) - fk(series.q)
    assert np.abs(shift).max() > 0.1 * MM
    np.testing.assert_allclose(got.position, readings - shift @ registration.rotation.T, atol=1e-12)
    assert got.quaternion is None
    unturned = compensated_readings(robot, dataclasses.replace(mset, position=base), None, [JointOffsets(robot)],
                                    [offsets])
    np.testing.assert_allclose(unturned.position, base - shift, atol=1e-12)


def test_the_column_unit_check_runs_from_four_points(setup):
    """The nominal TCP of four poses of the plan mapped into a tracker frame, its z column divided by
    1000 (metres under ``z_mm``): with four points refused naming ``z_mm``; with three not checked
    (the check runs from four points; the same three are refused when it runs). Catches ``len(measured) < 4`` with its 4 changed to 3 or 5."""
    from tcr_accuracy.exceptions import InputError
    from tcr_accuracy.iso9283.evaluate import check_column_units

    robot, series, nominal, base, rotation, translation, _ = setup
    points = np.unique(nominal.round(12), axis=0)[:4]
    wrong = points @ rotation.T + translation
    wrong[:, 2] *= 1e-3
    with pytest.raises(InputError, match=r"^m\.csv: column z_mm: its values look like m "):
        check_column_units(wrong, points, "m.csv")
    check_column_units(wrong[:3], points[:3], "m.csv")


def test_orientations_read_in_a_tracker_frame_give_their_deviations_about_the_base_axes(setup):
    """Readings and orientations in a tracker frame turned as the calibration set's, the reflector's
    frame turned 0.2 rad from the TCP frame, each visit's orientation off by its own small rotation
    about the base axes (0.5-2 mrad): brought into the base frame by the registration's rotation, the
    offset is the mean rotation of R_commanded^T R_measured over the readings and AP_a.. / RP_a.. the
    mean and three standard deviations (n - 1) of log(R_measured (R_commanded offset)^T), written out
    on scipy here; the deviations drawn come back to within 0.5 mrad and the offset to 1 mrad.
    Catches the transposes' axes ``(0, 2, 1)`` changed and the tracker frame not undone
    (``registration.rotation.T @ measured`` without the transpose)."""
    robot, series, nominal, base, rotation, translation, calibration = setup
    registration = register_from(robot, calibration)
    np.testing.assert_allclose(registration.rotation, rotation, atol=1e-4)
    rng = np.random.default_rng(8)
    commanded = tcr.tcp_poses(robot, series.q).rotation
    reflector = Rotation.from_rotvec([0.1, -0.15, 0.05])
    drawn = rng.uniform(0.5e-3, 2e-3, (len(series), 3)) * rng.choice([-1.0, 1.0], (len(series), 3))
    in_base = Rotation.from_rotvec(drawn) * Rotation.from_matrix(commanded) * reflector
    in_tracker = Rotation.from_matrix(rotation) * in_base
    quaternion = in_tracker.as_quat()[:, [3, 0, 1, 2]]
    mset = dataclasses.replace(series, position=base @ rotation.T + translation, quaternion=quaternion)
    result = evaluate_pose_test(robot, mset, registration=registration)
    measured = Rotation.from_matrix(registration.rotation.T @ in_tracker.as_matrix())
    offset = (Rotation.from_matrix(commanded).inv() * measured).mean()
    deviation = (measured * (Rotation.from_matrix(commanded) * offset).inv()).as_rotvec()
    np.testing.assert_allclose(result.orientation_offset, offset.as_matrix(), atol=1e-12)
    assert np.abs(offset.as_rotvec() - reflector.as_rotvec()).max() < 1e-3
    assert np.abs(deviation - drawn).max() < 5e-4  # the registration's own error: 0.1 mrad
    pose_id = series.annotations["pose_id"]
    for f in result.figures.poses:
        rows = pose_id == f.pose_id
        np.testing.assert_allclose(f.ap_abc, deviation[rows].mean(axis=0), atol=1e-12)
        np.testing.assert_allclose(f.rp_abc, 3 * deviation[rows].std(axis=0, ddof=1), rtol=1e-9)


def test_the_fit_says_whether_the_measured_points_offset_from_the_tcp_was_fitted(setup):
    """Six poses of six orientations, read three times each in the tracker frame, 30 mm off the TCP
    along its tool axes: the frame fitted on them fits the offset on all three axes and says so;
    the cube's five poses at one orientation cannot tell it from the frame: held at 0, said.
    Catches ``len(tool) == 3`` with its 3 changed (three axes said as a partial fit)."""
    robot, series, nominal, base, rotation, translation, _ = setup
    q = np.repeat(np.random.default_rng(4).uniform(-1.4, 1.4, (6, 6)), 3, axis=0)
    poses = tcr.tcp_poses(robot, q)
    reflector = poses.position + np.einsum("nij,j->ni", poses.rotation, [0.01, -0.02, 0.03])
    many = tcr.MeasurementSet(joint_names=list(robot.joint_names), q=q, position=reflector @ rotation.T + translation,
                              annotations={"pose_id": np.repeat(np.arange(1, 7), 3).astype(str).astype(object)})
    fitted = evaluate_pose_test(robot, many, frame="fit")
    assert sorted(n for n in fitted.registration.fitted if n.startswith("frames.tool.")) == [
        "frames.tool.dx", "frames.tool.dy", "frames.tool.dz"]
    assert "; with the measured point's offset from the TCP frame fitted; fit residual RMS" in fitted.how
    cube = evaluate_pose_test(robot, dataclasses.replace(series, position=base @ rotation.T + translation), frame="fit")
    assert ("; the measured point's offset from the TCP frame is not identifiable from these poses (one orientation: "
            "it moves the frame) and held at 0; fit residual RMS") in cube.how
