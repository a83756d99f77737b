"""The diagnosis' deprecation warnings point at the caller's line (``stacklevel``), so that a user's
``-W error`` or a log names their own file, not the library's (issue 36)."""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest

import tcr_accuracy as tcr
from tcr_accuracy.exceptions import InputError

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def test_the_old_fit_form_warns_at_the_callers_line():
    """``GapDiagnosis().fit(robot, measurements)``: the warning's file is this test's, its line the call's
    (the bad measurements then stop the fit with an InputError). Seen failing on ``stacklevel=2``
    turned to ``3`` and to ``1``."""
    robot = tcr.load_robot()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with pytest.raises(InputError, match="reads a MeasurementSet"):
            line = _line_after()
            tcr.GapDiagnosis().fit(robot, None)
    deprecations = [w for w in caught if issubclass(w.category, DeprecationWarning)]
    assert len(deprecations) == 1
    assert "fit(robot, measurements) is deprecated" in str(deprecations[0].message)
    assert (deprecations[0].filename, deprecations[0].lineno) == (__file__, line)


def test_the_old_tracker_transform_name_warns_at_the_callers_line():
    """``Diagnosis.tracker_transform``: the same matrix as ``trackerMbase``, its warning at the reading
    line. Seen failing on ``stacklevel=2`` turned to ``3``."""
    robot = tcr.load_robot()
    measured = tcr.read_measurements(str(EXAMPLES / "measured.csv"), robot)
    diagnosis = tcr.diagnose(robot, measured, effects=["joint_offsets"], folds=3)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        line = _line_after()
        old = diagnosis.tracker_transform
    assert (old == diagnosis.trackerMbase).all()
    warning, = [w for w in caught if issubclass(w.category, DeprecationWarning)]
    assert (warning.filename, warning.lineno) == (__file__, line)


def _line_after() -> int:
    """The line number after the caller's line."""
    import inspect

    return inspect.currentframe().f_back.f_lineno + 1
