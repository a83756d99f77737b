"""``diagnosis/diagnose.py``: what a diagnosis of several measured frames reads of the first (issue 36, third
pass). Each test names planted changes it was seen to catch."""

from __future__ import annotations

import numpy as np
import pytest

from tcr_accuracy.diagnosis import diagnose
from tcr_accuracy.diagnosis.diagnose import GapDiagnosis
from tcr_accuracy.exceptions import InputError
from tcr_accuracy.io.measurement_set import MeasurementSet
from tcr_accuracy.model.robot import load_robot


def _measured(robot, n: int, source: str) -> MeasurementSet:
    q = np.random.default_rng(n).uniform(-1.0, 1.0, (n, robot.n_joints))
    return MeasurementSet(joint_names=robot.joint_names, q=q, position=np.zeros((n, 3)), source=source)


def test_measured_frames_are_held_to_the_first_ones_rows_and_named_by_its_source():
    """Two measured frames of 20 and 19 rows: refused naming the second's 19 rows against the first's 20 (not
    the other way round); the source of a list of frames is the first frame's measurements'. Seen failing on
    ``n = len(frames[0].measurements)`` turned to ``frames[-1]`` and on ``measurements = measurements[0][1]``
    turned to ``[0][0]`` (measuring sample survivors, seed 4202: budget spent)."""
    robot = load_robot()
    first, second = _measured(robot, 20, "first.csv"), _measured(robot, 19, "second.csv")
    with pytest.raises(InputError, match=r"^measured frame tool: 19 rows, the first frame has 20$"):
        GapDiagnosis(robot=robot, effects=["joint_offsets"]).fit([(robot, first), (robot, second)])
    assert diagnose._source_of([(robot, first), (robot, second)]) == "first.csv"
    assert diagnose._source_of(second) == "second.csv"
