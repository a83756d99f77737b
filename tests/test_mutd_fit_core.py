"""The fit core's thresholds and defaults (``diagnosis/least_squares.py``, ``diagnosis/fitting.py``) at their
boundaries, against figures written out here: numpy's pseudo-inverse at the documented cut-off, the engine's
identifiability report with its default thresholds. Each test names a planted change it was seen to catch
(issue 36)."""

from __future__ import annotations

import numpy as np
import pytest
from mutd_truth import offset_measurements

from tcr_accuracy.diagnosis.diagnose import GapDiagnosis
from tcr_accuracy.diagnosis.fitting import FitEngine
from tcr_accuracy.diagnosis.least_squares import DampedSolver

EPS = np.finfo(float).eps


def _near_twins(k: int, factor: float) -> np.ndarray:
    """A (k, k) Gram matrix with unit diagonal: the identity but for two columns whose correlation leaves
    the smallest eigenvalue 1 - c = ``factor`` times the cut-off k * eps * 10 * (largest eigenvalue, 1 + c)."""
    small = factor * 2.0 * k * EPS * 10  # 1 + c = 2 to 1e-12
    gram = np.eye(k)
    gram[0, 1] = gram[1, 0] = 1.0 - small
    return gram


@pytest.mark.parametrize("factor", [0.92, 1.08])
def test_the_smallest_eigenvalue_kept_is_ten_times_size_times_eps_of_the_largest(factor):
    """An eigenvalue of the scaled Gram matrix is information when it exceeds 10 k eps times the largest
    (k the parameters): numpy's ``pinv`` with ``rcond = 10 k eps`` cuts at the same place. At 0.92 of the
    cut-off the twin direction is dropped (both twins' standard errors infinite, the covariance the
    pseudo-inverse); at 1.08 it is kept (standard errors of the plain inverse). Seen failing on ``eps * 10``
    turned to ``eps // 10`` (every round-off eigenvalue kept) and to ``eps * 11`` and ``eps * 9``."""
    k = 100
    gram = _near_twins(k, factor)
    solver = DampedSolver(gram)
    pinv = np.linalg.pinv(gram, rcond=10 * k * EPS, hermitian=True)
    np.testing.assert_allclose(solver.covariance(2.0), 2.0 * pinv, rtol=1e-9, atol=1e-9)
    errors = solver.standard_errors(2.0)
    if factor < 1:
        assert solver.kept.sum() == k - 1
        assert np.isinf(errors[:2]).all()
        np.testing.assert_allclose(errors[2:], np.sqrt(2.0), rtol=1e-12)
    else:
        assert solver.kept.all()
        np.testing.assert_allclose(errors, np.sqrt(2.0 * np.diag(np.linalg.inv(gram))), rtol=1e-6)


N_POSES = 14


@pytest.fixture(scope="module")
def diagnosed():
    """A diagnosis of 14 poses of the tool-changer with joint offsets hidden through Pinocchio (30 um noise per
    axis)."""
    robot, measured = offset_measurements(N_POSES, 1036)
    return GapDiagnosis(robot=robot, effects=["joint_offsets"], folds=2, stability_replays=2).fit(measured)


@pytest.fixture(scope="module")
def fitted(diagnosed):
    """That diagnosis' fit engine."""
    return diagnosed.engine_


def test_an_engine_judges_identifiability_with_no_motion_threshold_by_default(fitted):
    """Built without thresholds, the engine keeps every column its rank test keeps and says so: the report's
    ``min_motion_mm`` is 0 and its ``rank_tol`` 1e-6. Seen failing on the default ``min_motion=0.0`` turned to
    ``-1.0`` (a report of -1000 mm) and ``rank_tol=1e-6`` turned to ``2e-06``."""
    engine = FitEngine(fitted.parts, fitted.bases, fitted.folds)
    _, report = engine.identify(["frames", "joint_offsets"])
    assert report["min_motion_mm"] == 0.0
    assert report["rank_tol"] == 1e-6


def test_column_views_read_the_rows_and_columns_numpy_indexing_reads():
    """A model's columns read without copying (``error_map.ColumnSubset``, ``ColumnBlocks``): their shapes and
    rows those of numpy's fancy indexing and concatenation of a (7, 5) array (rows and columns of different
    counts, so that no axis stands in for the other). Seen failing on ``ColumnSubset``'s ``(values.shape[0],
    ...)`` turned to ``values.shape[-1]`` and ``ColumnBlocks``' ``self.blocks[0].shape[0]`` turned to ``[1]``."""
    from tcr_accuracy.diagnosis.error_map import ColumnBlocks, ColumnSubset

    values = np.arange(35.0).reshape(7, 5)
    positions = np.array([4, 1])
    subset = ColumnSubset.of(values, positions)
    assert subset.shape == (7, 2)
    np.testing.assert_array_equal(subset[[0, 6]], values[[0, 6]][:, positions])
    np.testing.assert_array_equal(np.asarray(subset), values[:, positions])
    assert ColumnSubset.of(values, np.arange(5)) is values
    blocks = ColumnBlocks([values[:, :2], ColumnBlocks([values[:, 2:3], values[:, 3:]])])
    assert blocks.shape == (7, 5) and len(blocks.blocks) == 3
    np.testing.assert_array_equal(blocks[2:5], values[2:5])
    np.testing.assert_array_equal(np.asarray(blocks), values)


def test_joint_columns_sensitivity_is_its_dense_product_over_chunks():
    """A sensitivity held as its factors (``error_map.JointColumnsSensitivity``: g[n, :, c] = jac_q[n, :,
    joint[c]] values[n, c] on 6 of 9 columns, each joint's columns a run that does not start at 0) against the
    product written out with numpy: its rows, g^T residual and g @ theta, on 2100 poses (two chunks of 2048)
    and on some rows. Seen failing on ``_run``'s ``slice(int(index[0]), ...)`` turned to ``index[1]``, on the
    chunk's ``start + ErrorMap.CHUNK`` turned to ``- ErrorMap.CHUNK`` and on the shape's ``jac_q.shape[1]``
    turned to ``[2]``."""
    from tcr_accuracy.diagnosis.error_map import JointColumnsSensitivity

    rng = np.random.default_rng(1042)
    n, k = 2100, 9
    jac_q = rng.standard_normal((n, 3, 4))
    columns = np.array([1, 2, 4, 5, 6, 8])
    joint = np.array([0, 0, 2, 2, 2, 3])
    values = rng.standard_normal((n, columns.size))
    dense = np.zeros((n, 3, k))
    for i, (c, j) in enumerate(zip(columns, joint)):
        dense[:, :, c] = jac_q[:, :, j] * values[:, i, None]
    g = JointColumnsSensitivity(jac_q, values, joint, columns, k)
    assert g.shape == (n, 3, k)
    np.testing.assert_allclose(np.asarray(g), dense, rtol=1e-14, atol=0)
    rows = np.array([5, 2099, 0, 2048, 77])
    np.testing.assert_allclose(g.rows(rows), dense[rows], rtol=1e-14, atol=0)
    residual = rng.standard_normal((n, 3))
    np.testing.assert_allclose(g.transposed_times(residual, None), np.einsum("nrk,nr->k", dense, residual),
                               rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(g.transposed_times(residual[rows], rows),
                               np.einsum("nrk,nr->k", dense[rows], residual[rows]), rtol=1e-12, atol=1e-12)
    theta = rng.standard_normal((k, 2))
    theta[4] = 0.0  # a joint's run with one column at zero still counts the others
    np.testing.assert_allclose(g.times(theta), np.einsum("nrk,km->nrm", dense, theta), rtol=1e-10, atol=1e-12)


def test_an_effects_nonlinearity_is_read_at_scales_times_minus_one_to_one(tool_changer):
    """A toy effect that turns each joint by p_j - w_j p_j^2 (w = 1 on the first joint, 2 on the last, 0 between;
    typical size 0.2): its basis is linearised at 0 (the map p_j exactly), and its nonlinearity is read at the
    probe p = 0.2 x (-1, -0.6, ..., 1): max |w p^2| / max |p - w p^2| = 0.08 / 0.24, written out here. Seen
    failing on the probe's ``np.linspace(-1.0, 1.0, k)`` turned to ``linspace(- 0.0, 1.0, k)``, to
    ``linspace(1.0, 1.0, k)`` (the minus removed) and to ``linspace(-1.0, 0.0, k)``."""
    from tcr_accuracy.diagnosis.bases import EffectBasis, Part, position_jacobians
    from tcr_accuracy.effects.base import Effect, EffectOutput, make_effect, plugged_in
    from tcr_accuracy.model.context import MeasurementContext
    from tcr_accuracy.model.errors import ErrorModel

    weights = np.array([1.0, 0.0, 0.0, 0.0, 0.0, 2.0])

    class Bowed(Effect):
        name = "toy_bowed"

        def parameter_names(self):
            return [f"toy_bowed.{j}" for j in self.robot.joint_names]

        def parameter_units(self):
            return ["1"] * self.robot.n_joints

        def parameter_scales(self):
            return np.full(self.robot.n_joints, 0.2)

        def perturb(self, params, q, context):
            params = self.check_params(params)
            return EffectOutput(dq=np.broadcast_to(params - weights * params**2, np.atleast_2d(q).shape).copy())

    robot = tool_changer
    q = np.random.default_rng(1103).uniform(*robot.joint_bounds(), size=(5, robot.n_joints))
    context = MeasurementContext(np.zeros(5), np.full(5, 20.0), np.zeros((5, robot.n_joints)))
    part = Part(robot, q, np.zeros((5, 3)), context, "tool")
    with plugged_in(Bowed):
        basis = EffectBasis(make_effect("toy_bowed", robot), part, ErrorModel(robot), position_jacobians(robot, q))
    probe = 0.2 * np.array([-1.0, -0.6, -0.2, 0.2, 0.6, 1.0])
    expected = np.max(np.abs(weights * probe**2)) / np.max(np.abs(probe - weights * probe**2))
    assert expected == pytest.approx(1 / 3, rel=1e-12)
    assert basis.nonlinearity == pytest.approx(expected, rel=1e-9)


def test_selection_replays_say_every_tenth_replay_counted_from_one(fitted):
    """The stability replays report progress at replays 1, 11, 21 of 21 (counted from one), and on this
    campaign, where the hidden joint offsets dominate, every replay keeps them. Seen failing on the message's
    ``replay + 1`` turned to ``replay * 1`` and on ``replay % 10 == 0`` turned to ``% 11``."""
    from tcr_accuracy.diagnosis.uncertainty import selection_frequency

    said = []
    out = selection_frequency(fitted, ["joint_offsets"], 3.0, 0.0, 21, np.random.default_rng(5), say=said.append)
    assert said == [f"selection stability: replay {k} of 21" for k in (1, 11, 21)]
    assert out["frequency"] == {"joint_offsets": 1.0} and out["sets"] == {"frames, joint_offsets": 1.0}
    assert out["n_replays"] == 21


def test_leave_one_out_rows_carry_each_effects_own_share_and_interval_in_mm(diagnosed):
    """The result's leave-one-out rows add stage 4's own share of each effect and its 95 % interval, in mm (the
    stage's metres times 1000), the interval holding its point. Seen failing on ``own[r.effect][2] * 1e3``
    turned to ``/ 1e3`` and ``own[r.effect][0] * 1e3`` turned to ``1001.0``."""
    result = diagnosed.result_
    own = result.stages.attribute.own_shares
    rows = {r["dropped"]: r for r in result.leave_one_out}
    assert set(rows) == {"joint_offsets"} and set(own) >= {"joint_offsets"}
    share, low, high = own["joint_offsets"]
    assert low <= share <= high
    assert rows["joint_offsets"]["own_share_increase_mm"] == pytest.approx(share * 1e3, rel=1e-12)
    assert rows["joint_offsets"]["own_share_interval_mm"] == pytest.approx([low * 1e3, high * 1e3], rel=1e-12)
