"""3D scenes of ``predict`` and ``compensate`` (meshcat, through :class:`~tcr_accuracy.view.viewer.Scene`).

* :func:`prediction_scene` -- the query TCPs coloured by the predicted error, segments to the
  predicted real TCP.
* :func:`compensation_scene` -- the targets and the predicted real TCP before and after compensation.

Both draw in the robot's base frame, with the nominal (URDF) TCPs, the measured points where
there are some (the training data's tracker frame applied) and the tracker's frame; each returns
``(scene, caption)``.
"""

from __future__ import annotations

import numpy as np

from ..model.kinematics import tcp_poses
from .viewer import COLORS, Scene, data_extent, frame_axis_length, point_size, segment_magnification


def _median_index(values) -> int:
    """Index of the value nearest the median: the pose the scene shows the robot at."""
    return int(np.argmin(np.abs(values - np.median(values))))


def prediction_scene(robot, q, prediction, model, *, method: str, train: str, rows, measured=None):
    """The query TCPs of the model (nominal + fitted TCP offset) coloured by the predicted |e|,
    segments to the predicted real TCP; the robot at the query of median |e|, its point marked.

    Parameters
    ----------
    robot : RobotModel
    q : ndarray of shape (N, n_joints)
        Query joint values [rad, m].
    prediction : ErrorPrediction
        :func:`~tcr_accuracy.prediction.error_prediction.predict_errors` at q.
    model : MeasuredErrorModel
        The fitted model (its tracker frame and TCP offset).
    method, train : str
        The predictor's name and its training file, for the note.
    rows : array-like of shape (N,)
        Each query's line in its file, for the labels.
    measured : ndarray of shape (N, 3), optional
        Measured query positions in the tracker frame [m].
    """
    pred = prediction.predicted_error
    norm = np.linalg.norm(prediction.robot_error, axis=1)
    nominal = tcp_poses(robot, q).position
    model_tcp = model.registration_.tcp_positions(robot, q)  # the measured frame: nominal + TCP offset
    beyond = nominal + pred - model_tcp  # what the robot adds to the measured frame's offset
    extent = data_extent(nominal)
    magnify = segment_magnification(float(np.linalg.norm(beyond, axis=1).max()), extent)
    scene = Scene(f"{robot.name}: error predicted by {method}", frame="data")
    shown = _median_index(norm)
    row = int(rows[shown])
    scene.add_robot(robot, q[shown], name=f"nominal robot at query row {row} (median |e|)",
                    opacity=0.5)  # the TCP points sit in the tool
    scene.add_point_cloud(model_tcp, norm * 1e3, name="query TCP",
                          label="model TCP at the query joints (nominal + fitted TCP offset), coloured by the "
                                "predicted TCP error |e| [mm]", size_m=1.6 * point_size(extent))
    scene.add_marker(model_tcp[shown], "marked pose", f"the query point of row {row}, the pose the robot is "
                                                      "drawn at", radius_m=4.0 * point_size(extent))
    scene.add_error_segments(model_tcp, nominal + pred, magnify=magnify, name="predicted error", start_color=None,
                             start_label="model TCP at the query joints", end_label="predicted real TCP")
    _draw_measurement_frame(scene, robot, q, model, measured, extent)
    scene.add_note(f"{len(q)} query poses, {method} fitted to {train}; robot base frame; robot at query "
                   f"row {row} (median |e|); segments magnified x {magnify:g} (the TCP offset at true size)")
    return scene, (f"Query TCP points (base frame) coloured by the predicted |e|; segments to the predicted real "
                   f"TCP, magnified x {magnify:g}")


#: The colour of the targets in the compensation's view (RGB in 0..1): not the measured points' blue.
TARGET_COLOR = (0.45, 0.25, 0.70)


def compensation_scene(robot, done, model, *, method: str, targets: str, rows, measured=None):
    """The targets (the measured point of the model), the predicted real TCP before and after
    compensation.

    Parameters
    ----------
    robot : RobotModel
    done : TargetCompensation
        :func:`~tcr_accuracy.prediction.target_compensation.compensate_targets`' result.
    model : MeasuredErrorModel
    method, targets : str
        The predictor's name and the targets' file, for the note.
    rows : array-like of shape (S,)
        Each solved target's line in its file, for the labels.
    measured : ndarray of shape (S, 3), optional
        The solved targets' measured positions in the tracker frame [m].
    """
    before = done.error_before
    extent = data_extent(done.target)
    magnify = segment_magnification(float(before.max()), extent)
    scene = Scene(f"{robot.name}: compensation with {method}", frame="data")
    shown = _median_index(before)
    row = int(rows[shown])  # the target's line in its file
    scene.add_robot(robot, done.q_compensated[shown], name=f"robot at the compensated command of target row {row}",
                    opacity=0.5)
    drawn = scene.add_error_segments(done.target, done.predicted_before, magnify=magnify, name="before",
                                     start_color=TARGET_COLOR, start_label="target TCP",
                                     end_label="predicted real TCP, uncompensated command")
    scene.add_error_segments(done.target[drawn], done.predicted_after[drawn], magnify=magnify, name="after",
                             max_drawn=None, start_label="target TCP",
                             end_label="predicted real TCP, compensated command",
                             start_color=None, end_color=COLORS["trajectory"])  # the targets are drawn once
    scene.add_marker(done.target[shown], "marked pose", f"the target of row {row}, the pose the robot is drawn at",
                     radius_m=4.0 * point_size(extent))
    _draw_measurement_frame(scene, robot, done.q, model, measured, extent)
    scene.add_note(f"{len(done.q)} targets of {targets}; robot base frame; robot at target row {row} (median "
                   f"error before); segments magnified x {magnify:g}")
    return scene, f"Targets and the predicted real TCP before and after compensation, magnified x {magnify:g}"


def _draw_measurement_frame(scene, robot, q, model, measured, extent) -> None:
    """The nominal (URDF) TCPs at q, the measured points mapped into the base frame, the tracker triad."""
    nominal = tcp_poses(robot, q).position
    scene.add_points(nominal, "nominal TCP", COLORS["nominal_tcp"], size_m=0.7 * point_size(extent),
                     label="nominal TCP (URDF)")
    if measured is not None:
        scene.add_points(model.registration_.to_base(measured), "measured", COLORS["measured"],
                         size_m=point_size(extent), label="measured (tracker frame fitted, base frame)")
    scene.add_frame(np.linalg.inv(model.registration_.matrix), "tracker frame", length_m=frame_axis_length(nominal),
                    label="tracker frame (fitted)")
