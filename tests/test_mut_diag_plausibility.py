"""Plausibility of a fitted geometry (``diagnosis/plausibility.py``): an axis tilt's size and its standard
error written out by hand (issue 36)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tcr_accuracy.diagnosis.plausibility import TOLERANCES, geometry_checks
from tcr_accuracy.model.errors import ErrorModel


def test_axis_tilt_and_its_standard_error_by_hand(ur5):
    """The UR5's first joint (axis z) given a placement rotation w = (6, -8, 7) mrad: its tilt is the part
    across the axis, |(6, -8)| = 10 mrad, beyond the industrial arm's 0.3 deg; its standard error to first
    order sqrt(sum (t_c / |t|)^2 s_c^2) with the fitted rotations' errors (0.2, 0.1, 9) mrad:
    sqrt(0.36 x 0.04 + 0.64 x 0.01) mrad (the error along the axis not read). A second joint tilted by
    0.1 mrad (within) is not listed. Catches ``(t / size) ** 2 * s**2`` turned to ``s*2`` and ``tilt = w -
    (w @ axis) * axis`` turned to ``w + ...``."""
    em = ErrorModel(ur5)
    x = em.zeros()
    x[em.placement_slice.start + 3:em.placement_slice.start + 6] = [6e-3, -8e-3, 7e-3]
    x[em.placement_slice.start + 6 + 3] = 1e-4  # joint 2: 0.1 mrad about x (its axis is y)
    first = ur5.joint_names[0]
    table = {"geometry": {"std": {f"geometry.{first}.rx": 2e-4, f"geometry.{first}.ry": 1e-4,
                                  f"geometry.{first}.rz": 9e-3}}}
    checks = [c for c in geometry_checks(ur5, np.zeros((0, 6)), x, table) if c.what == "axis_tilt"]
    assert [c.subject for c in checks] == [first]
    tilt = checks[0]
    assert tilt.value == pytest.approx(1e-2, rel=1e-12)
    assert tilt.std == pytest.approx(math.sqrt(0.36 * 4e-8 + 0.64 * 1e-8), rel=1e-12)
    assert tilt.flagged and tilt.tolerance == TOLERANCES["industrial arm"].axis_tilt == pytest.approx(math.radians(0.3))
