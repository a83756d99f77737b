"""A measured path test evaluated end to end, fast (``iso9283/path_evaluate.py:evaluate_path_test``):
its frame fitted to the commanded path, given by a registration on poses, or taken as the base; the
sentence saying how, with its residual RMS in mm; the planes' lower bound; and the figures after a
model's compensation. Until now only the slow command-line tests (a planned cube and paths, a
minute each) entered it, so a planted bug there ran out of the mutation run's time budget.

The robot is a UR5 moved along a straight line in joint space (41 samples, 2 s); the stream is read
at the commanded samples, two cycles, each reading put 0.1 mm off the path across both of its
neighbouring segments (so the nearest point of the polyline is the sample itself), the first cycle
to one side and the second to the other: the true frame leaves every reading exactly 0.1 mm from
the path, and no rigid motion does better by symmetry. Each test names a planted change it was seen
to catch.
"""

from types import SimpleNamespace

import numpy as np
import pinocchio as pin
import pytest
from scipy.spatial.transform import Rotation

from tcr_accuracy import load_robot
from tcr_accuracy.effects import make_effect
from tcr_accuracy.exceptions import InputError
from tcr_accuracy.frames.registration import register_tracker
from tcr_accuracy.io.measurements import MeasurementSet
from tcr_accuracy.io.tracker_stream import read_tracker_stream
from tcr_accuracy.iso9283.path_evaluate import evaluate_path_test, stream_cycles

from test_muti_iso_path_evaluate import _distance_to_polyline

#: Commanded line in joint space [rad], samples, seconds per run, the readings' offset across the path [m].
Q_START = np.array([0.3, -1.3, 1.4, -1.6, -1.57, 0.2])
Q_END = np.array([-0.5, -1.0, 1.1, -1.9, -1.3, 0.6])
N_SAMPLES, DURATION, OFF = 41, 2.0, 1e-4
#: The tracker's frame: p_tracker = trackerRbase @ p_base + trackerPbase
TRACKER_R = Rotation.from_rotvec([0.3, -0.2, 1.0]).as_matrix()
TRACKER_P = np.array([2.0, 0.5, -0.3])
#: Joint offsets the robot carries in the compensation test [rad]
OFFSETS = np.radians([0.02, -0.03, 0.025, 0.0, 0.01, 0.0])


def _tcp(robot, q):
    """The TCP positions (N, 3) [m] at joints q (N, 6), by Pinocchio directly."""
    data = robot.model.createData()
    out = []
    for row in np.atleast_2d(q):
        pin.framesForwardKinematics(robot.model, data, row)
        out.append(data.oMf[robot.tool_frame_id].translation.copy())
    return np.array(out)


@pytest.fixture(scope="module")
def line():
    robot = load_robot("ur5")
    q = Q_START + np.linspace(0.0, 1.0, N_SAMPLES)[:, None] * (Q_END - Q_START)
    times = np.linspace(0.0, DURATION, N_SAMPLES)
    commanded = MeasurementSet(joint_names=list(robot.joint_names), q=q, position=_tcp(robot, q), time_s=times,
                               annotations={"path": np.full(N_SAMPLES, "line", dtype=object)})
    return robot, commanded


def _across(points):
    """(N, 3) unit vectors each perpendicular to both segments at its sample (the end samples: to their one)."""
    steps = np.diff(points, axis=0)
    before = np.vstack([steps[:1], steps])
    after = np.vstack([steps, steps[-1:]])
    normal = np.cross(before, after)
    ends = np.cross(steps[[0, -1]], [0.0, 0.0, 1.0])
    normal[[0, -1]] = ends
    return normal / np.linalg.norm(normal, axis=1, keepdims=True)


def _write_stream(path, times, positions_by_cycle):
    rows = ["time_s,x_mm,y_mm,z_mm,path,cycle"]
    for c, positions in enumerate(positions_by_cycle, start=1):
        rows += [f"{10.0 * c + t:.6f},{x * 1e3:.7f},{y * 1e3:.7f},{z * 1e3:.7f},line,{c}"
                 for t, (x, y, z) in zip(times, positions)]
    path.write_text("\n".join(rows) + "\n")
    return read_tracker_stream(str(path))


def _labelled_stream(path, times):
    """A stream of one path read at ``times`` [s], cycle 1 before 5 s and cycle 2 after; file rows from 2."""
    lines = ["time_s,x_mm,y_mm,z_mm,path,cycle"] + [
        f"{t},{400 + 10 * k},{-100 + 3 * k},{300 + k},line,{1 if t < 5 else 2}" for k, t in enumerate(times)]
    path.write_text("\n".join(lines) + "\n")
    return read_tracker_stream(str(path))


#: The one run the labelled streams are matched to.
LINE_RUN = SimpleNamespace(path="line", speed_pct=None, words=lambda: "line")


def test_a_frame_fitted_to_the_path_says_its_readings_and_their_residual_rms_in_mm(line, tmp_path):
    """Two cycles 0.1 mm either side of the path, in a tracker frame turned 1.06 rad and 2 m away: the
    frame fitted to the path is the true one (each reading mapped back lies on the true path plus its
    offset, to 1 um), it is fitted on all 82 readings and the sentence says "82 readings, residual RMS
    0.1000 mm". Seen failing on ``fitted.residual_rms * 1e3`` as ``/ 1e3`` (it read 0.0000 mm)."""
    robot, commanded = line
    points = commanded.position
    across = _across(points)
    cycles = [(points + sign * OFF * across) @ TRACKER_R.T + TRACKER_P for sign in (1.0, -1.0)]
    stream = _write_stream(tmp_path / "stream.csv", commanded.time_s, cycles)
    measured, compensated = evaluate_path_test(robot, commanded, stream, frame="fit", planes=20)
    assert compensated is None and measured.frame == "fit"
    assert measured.how == ("fitted to the commanded paths (arc-length start, then closest points on the paths, "
                            "Kabsch) on 82 readings, residual RMS 0.1000 mm; a constant offset or rotation of the "
                            "attained paths is taken up and not seen in AT")


def test_a_registration_from_poses_is_said_with_its_poses_and_residual_in_mm(line, tmp_path):
    """The frame given by a registration on 12 poses measured in the same tracker frame with 20 um of
    noise: the sentence names the source, the 12 poses and the registration's residual RMS in mm to
    0.1 um (between 5 and 30 um here, by the noise drawn). Seen failing on
    ``registration.residual_rms * 1e3`` as ``/ 1e3`` or ``** 1e3``."""
    robot, commanded = line
    rng = np.random.default_rng(5)
    q_poses = Q_START + rng.uniform(-0.6, 0.6, (12, 6))
    measured_poses = _tcp(robot, q_poses) @ TRACKER_R.T + TRACKER_P + rng.normal(0.0, 20e-6, (12, 3))
    registration = register_tracker(robot, q_poses, measured_poses)
    assert 5e-6 < registration.residual_rms < 30e-6
    cycles = [_tcp(robot, commanded.q) @ TRACKER_R.T + TRACKER_P] * 2
    stream = _write_stream(tmp_path / "stream.csv", commanded.time_s, cycles)
    measured, _ = evaluate_path_test(robot, commanded, stream, registration=registration,
                                     registration_source="poses.csv", planes=20)
    assert measured.frame == "given"
    assert measured.how == (f"from poses.csv: fitted on its 12 poses (fit residual RMS "
                            f"{registration.residual_rms * 1000:.4f} mm)")


def test_three_planes_are_taken_and_two_refused(line, tmp_path):
    """At least 3 normal planes per path: 3 evaluates, 2 is refused in one line. Seen failing on the
    bound ``planes < 3`` turned to 4 (3 refused) or 2 (2 taken)."""
    robot, commanded = line
    stream = _write_stream(tmp_path / "stream.csv", commanded.time_s, [commanded.position] * 2)
    measured, _ = evaluate_path_test(robot, commanded, stream, frame="base", planes=3)
    assert measured.how == "not fitted: the readings are taken as base-frame positions"
    with pytest.raises(InputError, match=r"^planes 2: want at least 3 normal planes per path$"):
        evaluate_path_test(robot, commanded, stream, frame="base", planes=2)


def test_compensation_with_the_robots_own_offsets_leaves_a_fraction_of_the_deviation(line, tmp_path):
    """The robot carries joint offsets (0.02 ... deg); read in the base frame, the path deviates by
    their TCP displacement: the largest distance of a displaced sample (by Pinocchio, in the test) from
    the commanded polyline bounds AT_P, which reaches at least half of it; the figures after compensating with a joint_offsets model
    of those offsets fall below 2 % of it (what moving each reading by the displacement at its nearest
    commanded point leaves). Seen failing on ``base - _model_shift(...)`` as ``+`` (AT doubled) and on
    the displacement ``predict_positions(...) - tcp_poses(...)`` as ``+``."""
    robot, commanded = line
    displaced = _tcp(robot, commanded.q + OFFSETS)
    deviation = np.array([_distance_to_polyline(p, commanded.position) for p in displaced])
    stream = _write_stream(tmp_path / "stream.csv", commanded.time_s, [displaced] * 2)
    effect = make_effect("joint_offsets", robot)
    measured, compensated = evaluate_path_test(robot, commanded, stream, frame="base", planes=20,
                                               model=([effect], [OFFSETS]))
    before, after = measured.runs[0][1].at, compensated.runs[0][1].at
    assert 0.5 * deviation.max() < before <= deviation.max() * (1 + 1e-6)
    assert after < 0.02 * before


def test_of_two_repeated_times_in_a_cycle_the_first_is_named(tmp_path):
    """Cycle 2 of a stream repeats a time twice (its readings at 12, 12, 13, 13 s; the second 12 s on
    file row 9, the second 13 s on row 11): refused naming the first repeat, row 9 at 12 s. Seen failing
    on ``rows[same[0] + 1]`` as ``same[-1]`` (row 11 named)."""
    stream = _labelled_stream(tmp_path / "stream.csv", [0.0, 1.0, 2.0, 3.0, 10.0, 11.0, 12.0, 12.0, 13.0, 13.0])
    with pytest.raises(InputError) as refused:
        stream_cycles(stream, [LINE_RUN])
    assert str(refused.value) == (f"{tmp_path / 'stream.csv'}: row 9, column time_s: 12 s repeats a time of the same "
                                  "cycle (line, cycle 2)")


def test_a_cycle_of_three_readings_is_taken_and_one_of_two_refused(tmp_path):
    """A cycle is one run along the path, at least 3 readings: cycle 2 of three readings is taken,
    of two (file rows 5 and 6) refused naming its first row and the count. Seen failing on
    ``MIN_CYCLE_READINGS = 3`` turned to 4 (three refused) or 2 (two taken)."""
    three = _labelled_stream(tmp_path / "three.csv", [0.0, 1.0, 2.0, 10.0, 11.0, 12.0])
    cycles, _ = stream_cycles(three, [LINE_RUN])
    assert [list(rows) for rows in cycles[0]] == [[0, 1, 2], [3, 4, 5]]
    two = _labelled_stream(tmp_path / "stream.csv", [0.0, 1.0, 2.0, 10.0, 11.0])
    with pytest.raises(InputError) as refused:
        stream_cycles(two, [LINE_RUN])
    assert str(refused.value) == (f"{tmp_path / 'stream.csv'}: row 5, column cycle: cycle 2 of the line holds 2 "
                                  "reading(s); a cycle is one run along the path, its readings labelled alike (a "
                                  "label per run, not per reading)")
