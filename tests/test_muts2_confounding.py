"""What follows the measurement order (``diagnosis/confounding.py``), second pass (issue 36): a variable that
does not vary follows no clock, and a clock that does not tick makes nothing follow it (their correlation read
as 0, not 0 / 0), against scipy's Pearson r for the rest. Each test names a planted change it was seen to
catch."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from tcr_accuracy.diagnosis.confounding import confounded_variables
from tcr_accuracy.model.context import MeasurementContext


def test_a_fixed_joint_follows_no_clock_and_a_still_clock_leads_nothing():
    """Joint a swept with the order (listed, r by scipy), joint b held at 0.25 rad (spread 0: correlation 0, not
    listed and no 0 / 0); then the same rows with a measurement order of one value (a clock that does not tick)
    and no time: nothing follows it. Seen failing on ``np.std(a) == 0`` turned to ``== -1`` (a NaN warning) and
    on its ``return 0.0`` turned to ``1.0`` (the fixed joint said to follow the order at r = 1)."""
    n = 20
    order = np.arange(n, dtype=float)
    q = np.column_stack([0.1 * order + 0.1 * np.sin(order), np.full(n, 0.25)])
    context = MeasurementContext(np.zeros(n), np.full(n, 20.0), np.zeros((n, 2)), time_s=None, order=order)
    got = confounded_variables(["a", "b"], q, context, set())
    assert [(c.variable, c.clock) for c in got] == [("joint a", "measurement order")]
    assert got[0].r == pytest.approx(stats.pearsonr(q[:, 0], order)[0], rel=1e-12)
    still = MeasurementContext(np.zeros(n), np.full(n, 20.0), np.zeros((n, 2)), time_s=None, order=np.full(n, 3.0))
    assert confounded_variables(["a", "b"], q, still, set()) == []
