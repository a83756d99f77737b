"""``diagnosis/compare.py`` on two fits that kept different members of an effect (issue 36): the common
parameters compared once what each fit's own members do to the TCP is carried into them (the common basis,
itself tested against scipy's least_squares in test_mutfit_compare), each change with the values as fitted
beside it, the one-sided members listed, the note naming the effect; the JSON form read back. Each test names
a planted change it was seen to catch."""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_mutfit_compare import _fit

from tcr_accuracy.diagnosis.compare import Comparison, compare_models, on_common_basis
from tcr_accuracy.model.robot import load_robot

COMMON = ["joint_offsets.j2", "joint_offsets.j3", "joint_offsets.j5"]


def _keep(fit, names):
    """The fit with only these joint offsets kept (identifiability dropped the others)."""
    from dataclasses import replace

    def only(table):
        return {**table, "joint_offsets": {n: v for n, v in table["joint_offsets"].items() if n in names}}

    return replace(fit, parameters=only(fit.parameters), std=only(fit.std), units=only(fit.units))


@pytest.fixture(scope="module")
def partial():
    robot = load_robot()
    values = np.array([4e-4, -3e-4, 2e-4, 1e-4, 5e-4, -2e-4])
    old = _fit(robot, values, np.full(6, 1e-5), "old")
    new = _keep(_fit(robot, values + np.array([0.0, 2e-4, 0.0, 0.0, -1e-5, 0.0]), np.full(6, 2e-5), "new"), COMMON)
    q = np.random.default_rng(5).uniform(*robot.joint_bounds(), size=(30, robot.n_joints))
    return robot, old, new, q, compare_models(robot, old, new, q)


def test_fits_keeping_different_members_are_compared_on_the_common_ones(partial):
    """Each common parameter's change is the difference of both fits' values on the common basis (the
    old fit's j1, j4 and j6 carried into j2, j3, j5 and a rigid motion), its z that change over the
    standard errors in quadrature; ``as_fitted`` keeps the values as fitted; j1, j4, j6 are listed as
    the old fit's alone; one note names joint_offsets. Seen failing on ``shared = {c.name for c in changes +
    setup}`` turned to ``changes * setup`` (planted by hand: the branch ran in no test of the map) and on
    ``raw = {c.name: (c.old, c.new) ...}`` reading ``(c.new, c.old)``, and on the common comparison's
    ``parameter_changes(*common, z)`` turned to ``z + 1`` (planted by hand)."""
    robot, old, new, q, result = partial
    names = set(COMMON) | {f"frames.tool.d{a}" for a in "xyz"}
    old_common, new_common = on_common_basis(robot, old, names, q), on_common_basis(robot, new, names, q)
    assert abs(old_common["joint_offsets.j2"] - old.parameters["joint_offsets"]["joint_offsets.j2"]) > 1e-6
    assert [c.name for c in result.changes] == COMMON
    for c in result.changes:
        assert (c.old, c.new) == pytest.approx((old_common[c.name], new_common[c.name]), rel=1e-9, abs=1e-15)
        assert c.as_fitted == (old.parameters["joint_offsets"][c.name], new.parameters["joint_offsets"][c.name])
        assert c.std_error == pytest.approx(math.hypot(1e-5, 2e-5), rel=1e-12)
        assert c.z == pytest.approx(abs(new_common[c.name] - old_common[c.name]) / math.hypot(1e-5, 2e-5), rel=1e-9)
        assert c.significant == (c.z > 3.0)
    z_j2 = result.changes[0].z
    assert z_j2 > 3.5
    flags = [c.significant for c in compare_models(robot, old, new, q, z=z_j2 - 0.5).changes]
    assert flags == [True] + [c.z > z_j2 - 0.5 for c in result.changes[1:]]
    one_sided, = result.one_sided
    assert (one_sided.effect, one_sided.present_in, one_sided.whole_effect) == ("joint_offsets", "old", False)
    assert sorted(one_sided.parameters) == ["joint_offsets.j1", "joint_offsets.j4", "joint_offsets.j6"]
    assert result.notes[0].startswith("the fits kept different parameters of joint_offsets (identifiability")
    again = Comparison.from_json(result.to_json())
    assert [c.as_fitted for c in again.changes] == [c.as_fitted for c in result.changes]
