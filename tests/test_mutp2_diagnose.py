"""The diagnosis estimator's repr once fitted and its refusal of measurements with the wrong number of joint
columns (``diagnosis/diagnose.py``; two lines no test ran). Each test names planted changes it was seen to catch
(issue 36)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from tcr_accuracy.diagnosis.diagnose import GapDiagnosis
from tcr_accuracy.diagnosis.records import ErrorStats
from tcr_accuracy.exceptions import InputError
from tcr_accuracy.io.measurement_set import MeasurementSet
from tcr_accuracy.model.robot import load_robot


def test_a_fitted_diagnosis_repr_ends_on_what_was_found_in_mm():
    """The last step's held-out RMS 0.0123456 m said as 12.35 mm (4 significant figures) after the selected effects.
    Seen failing on the 1e3 of mm turned to 1e4 and the last step's index -1 turned to 0 (the first step's
    0.1 m)."""
    diagnosis = GapDiagnosis(robot=load_robot("ur5"))
    unfitted = repr(diagnosis)
    assert "fitted" not in unfitted
    steps = [SimpleNamespace(heldout=ErrorStats(0.0, 0.1, 0.0, 10)),
             SimpleNamespace(heldout=ErrorStats(0.0, 0.0123456, 0.0, 10))]
    diagnosis.result_ = SimpleNamespace(selected_effects=("frames", "joint_offsets"), steps=steps)
    assert repr(diagnosis) == unfitted + " fitted: selected [frames, joint_offsets], held-out RMS 12.35 mm"


def test_measurements_with_the_wrong_number_of_joints_are_refused_naming_both_counts():
    """Five joint columns for the six-joint UR5: one line naming 5 and 6."""
    robot = load_robot("ur5")
    rng = np.random.default_rng(0)
    measured = MeasurementSet(joint_names=[f"j{i}" for i in range(5)], q=rng.uniform(-1, 1, (30, 5)), position=rng.uniform(-1, 1, (30, 3)), source="five.csv")
    with pytest.raises(InputError) as err:
        GapDiagnosis(robot=robot).fit(measured)
    assert str(err.value) == "measurements have 5 joint columns, ur5 has 6"
