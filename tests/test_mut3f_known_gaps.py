"""The fit core's well-posedness verdict, its dense-or-factored choice, its frames' row count and the
folded columns of no effect (``diagnosis/block_fit.py``, ``bases.py``, ``gram.py``,
``identifiability.py``), each against a computation written out here with numpy: the Cholesky pivots of
the unit-diagonal system, the byte count of the dense sensitivity, the R of one QR. Each test names a
planted change it was seen to catch (issue 36)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from tcr_accuracy.diagnosis.block_fit import PIVOT_FLOOR, SharedBlock, free_step
from tcr_accuracy.diagnosis.least_squares import FactorCache


def _unit_pivot_ratio(system: np.ndarray, order: np.ndarray) -> float:
    """min / max of the Cholesky pivots of D^-1 A D^-1 (D = sqrt(diag A)) with its columns in ``order``."""
    d = np.sqrt(np.diag(system))
    unit = system / np.outer(d, d)
    pivots = np.diag(np.linalg.cholesky(unit[np.ix_(order, order)]))
    return float(pivots.min() / pivots.max())


def _scaled_system(rng, k: int, norms: np.ndarray, tie: float | None = None) -> np.ndarray:
    """D C D: C a unit-diagonal system of k random columns (the last one the first's copy but for a part
    ``tie`` of a new direction, when given), D = diag(norms)."""
    x = rng.standard_normal((60, k))
    if tie is not None:
        x[:, -1] = x[:, 0] + tie * x[:, -1]
    x /= np.linalg.norm(x, axis=0)
    return (x.T @ x) * np.outer(norms, norms)


def test_a_shared_blocks_well_posedness_is_judged_on_the_unit_diagonal_system_whatever_the_column_norms():
    """The penalised columns 10^4 times the others' norms: the step through their kept factor (Schur
    complement on the others) is numpy's solve where the unit-diagonal system's pivots (numpy's Cholesky
    here) are within :data:`PIVOT_FLOOR` of each other, None where one falls below it, exactly as the
    step without the shared block judges. Seen failing on ``np.diagonal(factor_p) / norms[p]`` turned
    to ``* norms[p]`` (a well-posed system refused: pivots 10^8 apart)."""
    assert PIVOT_FLOOR == 1e-7
    rng = np.random.default_rng(3001)
    k, positions = 7, np.arange(0, 4)
    norms = np.array([1e4, 2e4, 5e3, 1e4, 1.0, 2.0, 0.5])
    others = np.arange(4, k)
    order = np.concatenate([positions, others])
    for tie, posed in ((None, True), (3e-6, True), (2e-8, False)):
        system = _scaled_system(rng, k, norms, tie)
        ratio = _unit_pivot_ratio(system, order)
        assert (ratio > PIVOT_FLOOR) is posed  # the case is on the side of the floor it is meant to be
        gradient = rng.standard_normal(k) * norms
        shared = SharedBlock(FactorCache(), tuple(range(50, 54)), positions)
        step = free_step(system.copy(), gradient, shared, shared.key("all", 1.0))
        plain = free_step(system.copy(), gradient)
        if posed:
            expected = np.linalg.solve(system, -gradient)
            for got in (step, plain):
                assert got is not None
                np.testing.assert_allclose(got, expected, rtol=1e-3 if tie else 1e-10,  # the tie: cond ~ 1e11
                                           atol=1e-12 * np.abs(expected).max())
        else:
            assert step is None and plain is None


def test_a_shared_blocks_pivots_are_scaled_by_their_own_columns_norms():
    """The other way round: penalised columns 10^-8 of the others' norms and a near-dependence among the
    others (pivot ratio ~3e-8 of the unit system, below the floor): refused; the same system with the
    dependence loosened to 10^-3 is solved as numpy solves it. Seen
    failing on ``np.diagonal(factor_s) / norms[o]`` turned to ``* norms[o]`` and on ``factor_p`` to
    ``* norms[p]`` (the unit pivots rescaled by norms^2, 10^16 apart)."""
    rng = np.random.default_rng(3002)
    k, positions = 6, np.array([2, 3, 4])
    norms = np.array([1e4, 3e4, 1e-4, 2e-4, 1e-4, 2e4])
    others = np.array([0, 1, 5])
    order = np.concatenate([positions, others])
    for tie, posed in ((1e-3, True), (3e-8, False)):
        system = _scaled_system(rng, k, norms, tie)
        assert (_unit_pivot_ratio(system, order) > PIVOT_FLOOR) is posed
        gradient = rng.standard_normal(k)
        shared = SharedBlock(FactorCache(), (7, 8, 9), positions)
        step = free_step(system.copy(), gradient, shared, shared.key("all", 0.5))
        if posed:
            expected = np.linalg.solve(system, -gradient)
            np.testing.assert_allclose(step, expected, rtol=1e-7, atol=1e-12 * np.abs(expected).max())
        else:
            assert step is None


@pytest.mark.parametrize("name,made_when_read", [("geometry", "SensitivityWhenRead"),
                                                 ("joint_offsets", "JointColumnsSensitivity")])
def test_an_effects_sensitivity_is_dense_up_to_its_byte_limit_and_not_one_byte_beyond(ur5, monkeypatch, name,
                                                                                       made_when_read):
    """The dense TCP sensitivity (N, r, P) of 8-byte floats is held while N r P 8 <= DENSE_BYTES
    (written out here: 40 poses x 3 rows x P x 8) and made when read or held as its factors one byte
    beyond; the same numbers either way. Seen failing on ``n * r * ... * 8`` turned to ``n / r`` and to
    ``* 9``."""
    from tcr_accuracy.diagnosis import bases as bases_module
    from tcr_accuracy.diagnosis.bases import EffectBasis, Part, position_jacobians
    from tcr_accuracy.effects.base import make_effect
    from tcr_accuracy.model.context import MeasurementContext
    from tcr_accuracy.model.errors import ErrorModel

    rng = np.random.default_rng(3003)
    n = 40
    q = rng.uniform(-2.5, 2.5, (n, ur5.n_joints))
    context = MeasurementContext(np.full(n, 2.0), np.full(n, 20.0), np.ones((n, ur5.n_joints)))
    part = Part(ur5, q, np.zeros((n, 3)), context, "tool0")
    effect = make_effect(name, ur5)
    em = ErrorModel(ur5)
    jac_x = position_jacobians(ur5, q)
    nbytes = n * 3 * effect.n_params * 8
    monkeypatch.setattr(bases_module, "DENSE_BYTES", float(nbytes))
    dense = EffectBasis(effect, part, em, jac_x).g
    assert isinstance(dense, np.ndarray) and dense.shape == (n, 3, effect.n_params)
    monkeypatch.setattr(bases_module, "DENSE_BYTES", float(nbytes - 1))
    held = EffectBasis(effect, part, em, jac_x).g
    assert type(held).__name__ == made_when_read
    np.testing.assert_allclose(np.asarray(held[:]), dense, rtol=1e-12, atol=1e-15)


def _part(n: int):
    return SimpleNamespace(q=np.zeros((n, 6)), rows_per_pose=3, whitening=None)


def test_fold_grams_refuse_frames_measured_on_different_numbers_of_rows():
    """A fold holds out the same rows of every measured frame: frames of 12 and 10 rows are refused with
    both counts named, whichever comes first (the store read the first frame's count and silently left
    the later frames' extra rows out)."""
    from tcr_accuracy.diagnosis.gram import FoldGrams

    for counts in ((12, 10), (10, 12), (10, 10, 12)):
        with pytest.raises(ValueError, match=r"different numbers of rows: \[10, 12\]"):
            FoldGrams([_part(c) for c in counts], {}, [])


def test_fold_grams_of_two_frames_sum_both_frames_rows():
    """Two frames of 7 rows, one effect of 2 columns: the total Gram block is the sum over both frames'
    rows of (g * scale)^T (g * scale), each fold's the same over its held-out rows, written out here.
    Seen failing on ``n_rows`` read as ``len(rows) != 2`` / ``!= 0`` (every store refused)."""
    from tcr_accuracy.diagnosis.gram import FoldGrams

    rng = np.random.default_rng(3004)
    n, k = 7, 2
    gs = [rng.standard_normal((n, 3, k)) for _ in range(2)]
    scales = np.array([0.5, 3.0])
    basis = SimpleNamespace(names=["a", "b"], scales=scales, fit_lower=-np.ones(k), fit_upper=np.ones(k),
                            penalty=np.zeros(k), index=[np.arange(k)] * 2,
                            per_part=[SimpleNamespace(g=g) for g in gs])
    folds = [(np.array([2, 3, 4, 5, 6]), np.array([0, 1])), (np.array([0, 1, 4, 5, 6]), np.array([2, 3])),
             (np.array([0, 1, 2, 3]), np.array([4, 5, 6]))]
    store = FoldGrams([_part(n), _part(n)], {"e": basis}, [folds])
    assert store.n_rows == n

    def gram(rows):
        blocks = [(g[rows] * scales).reshape(-1, k) for g in gs]
        return sum(b.T @ b for b in blocks)

    np.testing.assert_allclose(store.total, gram(np.arange(n)), rtol=1e-13)
    for (_, test), block in zip(folds, store.held[0]):
        np.testing.assert_allclose(block, gram(test), rtol=1e-13)


def test_the_folded_columns_of_no_effect_are_none_and_of_one_pose_are_its_rows_r():
    """No effect: nothing to fold (it raised IndexError on the first effect's name); one pose of 3 rows
    and 2 columns: R of numpy's QR of g * scales, |R| entries equal, read over 1 pose. Seen failing on
    ``max(..., 1)`` turned to ``max(..., 2)`` (one pose read as two: a reshape of too few rows)."""
    from tcr_accuracy.diagnosis.identifiability import SensitivityColumns, compressed

    assert compressed({}) == {}
    g = np.array([[[1.0, 2.0], [0.5, -1.0], [2.0, 0.0]]])
    scales = np.array([2.0, 0.5])
    out = compressed({"e": SensitivityColumns(["a", "b"], g, scales)})
    r = np.linalg.qr(g[0] * scales, mode="r")
    assert out["e"].n_poses == 1
    np.testing.assert_allclose(np.abs(out["e"].g[:, 0, :]), np.abs(r), rtol=1e-13, atol=1e-15)


def test_the_report_of_no_effect_judged_states_a_threshold_of_zero():
    """No effect in the order: nothing kept, and the report's threshold is 0 mm (the largest of no
    thresholds), not negative. Seen failing on ``max(thresholds.values(), default=0.0)`` turned to
    ``default=-1.0`` (-1000 mm)."""
    from tcr_accuracy.diagnosis.identifiability import identifiability

    for min_motion in (2e-5, {}):
        keep, report = identifiability({}, [], min_motion=min_motion)
        assert keep == {} and report == {"rank_tol": 1e-6, "min_motion_mm": 0.0, "effects": {}}


def test_an_angle_table_of_one_mode_per_joint_has_its_gram_block_from_its_designs():
    """The coarsest angle table (4 intervals: one mode per joint, each joint's group one column): the total
    Gram block taken from its B-spline designs is that of its dense columns, J^T J written out with numpy.
    Seen failing on the group's joint ``g.joint[positions[0]]`` turned to ``positions[1]`` (a group of one
    column has no second)."""
    from test_mutf_gram_layout import _basis

    from tcr_accuracy.diagnosis.error_map import JointColumnsSensitivity
    from tcr_accuracy.diagnosis.gram import FoldGrams
    from tcr_accuracy.effects import make_effect
    from tcr_accuracy.model.robot import load_robot

    rng = np.random.default_rng(3008)
    n = 60
    robot = load_robot("ur10")
    q = rng.uniform(*robot.joint_bounds(), (n, 6))
    table = make_effect("angle_table", robot, intervals=4)
    assert table.modes_per_joint == 1
    values, joint = table.joint_column_values(q)
    k = table.n_params
    g = JointColumnsSensitivity(rng.standard_normal((n, 3, 6)), values, joint, np.arange(k), k)
    basis = _basis(rng, g, k)
    store = FoldGrams([SimpleNamespace(q=q, rows_per_pose=3, whitening=None)], {"angle_table": basis},
                      [[(np.arange(30, n), np.arange(30)), (np.arange(30), np.arange(30, n))]])
    assert store._structured(0, "angle_table") is g
    jacobian = (np.asarray(g) * basis.scales).reshape(-1, k)
    expected = jacobian.T @ jacobian
    np.testing.assert_allclose(store.total, expected, rtol=0, atol=1e-11 * np.abs(expected).max())
