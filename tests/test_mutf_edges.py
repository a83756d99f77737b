"""Branches of the fit core few data sets enter, each against a figure written out here with numpy
(``diagnosis/error_map.py``, ``identifiability.py``, ``least_squares.py``, ``block_fit.py``,
``ambiguity.py``): a sensitivity whose values are made when read, pivoting between columns that tie to
round-off, a factor cache emptied and filled again, a lambda search
whose fold systems need the ridge, the rival models of an ambiguity group. Fast on purpose: a mutation
run tries the fastest covering tests first. Each test names a planted change it was seen to catch
(issue 36)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from tcr_accuracy.diagnosis.error_map import ErrorMap, JointColumnsSensitivity


class _RowsWhenRead:
    """(N, k) values whose rows are made when indexed (as an angle table's are): neither an array nor a
    view of one, so products are taken a chunk of rows at a time."""

    def __init__(self, values: np.ndarray):
        self._values = values
        self.shape = values.shape

    def __getitem__(self, rows):
        return self._values[rows].copy()


def test_a_sensitivity_whose_values_are_made_when_read_multiplies_as_the_dense_product():
    """g @ theta for g[n, :, c] = jac_q[n, :, joint[c]] values[n, c] with values made when read, over 2100
    poses (two chunks of 2048): joint 1's columns a run, joint 0's scattered, joint 2's parameters all
    zero; against the dense product written out with numpy. Seen failing on ``_run``'s slice end
    ``int(index[0]) + index.size`` turned to ``-`` and on ``_gathered_times``' chunk ``start +
    ErrorMap.CHUNK`` turned to ``start - ErrorMap.CHUNK``."""
    rng = np.random.default_rng(4101)
    n, k = 2100, 8
    jac_q = rng.standard_normal((n, 3, 3))
    columns = np.array([0, 1, 2, 3, 5, 6, 7])  # column 4: no pose moves it
    joint = np.array([0, 1, 1, 1, 0, 2, 2])
    values = rng.standard_normal((n, columns.size))
    dense = np.zeros((n, 3, k))
    for i, (c, j) in enumerate(zip(columns, joint)):
        dense[:, :, c] = jac_q[:, :, j] * values[:, i, None]
    g = JointColumnsSensitivity(jac_q, _RowsWhenRead(values), joint, columns, k)
    theta = rng.standard_normal((k, 2))
    theta[[6, 7]] = 0.0  # joint 2's parameters: nothing to add
    np.testing.assert_allclose(g.times(theta), np.einsum("nrk,km->nrm", dense, theta), rtol=1e-12, atol=1e-12)
    assert ErrorMap.CHUNK < n


def test_of_two_columns_tied_to_round_off_the_earlier_is_kept():
    """A block whose first two columns are one direction at norms 1 and 1 + 1e-12 (a tie within round-off)
    and a third of its own: the first is kept, the second dropped as its duplicate, with and without the
    report, and each kept column's own motion is its norm over sqrt(N) (the tie-break weights divided out):
    a threshold 3e-10 below it keeps the column, 3e-10 above drops it and every column pivoted after it.
    Seen failing on the tie-break ``1.0 + 1e-9 * np.arange(...)`` turned to ``1e-9 ** np.arange(...)`` (the
    later column wins the tie), on ``np.abs(np.diag(rmat)) / tie_break`` turned to ``* tie_break`` and on
    ``diag[k] / math.sqrt(n_pose)`` turned to ``math.sqrt(n_pose + 1)``."""
    from tcr_accuracy.diagnosis.identifiability import identifiability

    n_poses = 6
    u, v = np.linalg.qr(np.random.default_rng(4102).standard_normal((3 * n_poses, 2)))[0].T
    columns = np.stack([1e-3 * u, (1e-3 + 1e-15) * u, 2e-3 * v], axis=1)
    block = SimpleNamespace(names=["a1", "a2", "a3"], g=columns.reshape(n_poses, 3, 3), scales=np.ones(3),
                            n_poses=n_poses)
    keep, report = identifiability({"a": block}, ["a"], 1e-6, 0.0)
    assert keep["a"].tolist() == [0, 2]
    assert [r["parameter"] for r in report["effects"]["a"]["removed"]] == ["a2"]
    assert report["effects"]["a"]["removed"][0]["duplicates"] == ["a1"]
    quiet, _ = identifiability({"a": block}, ["a"], 1e-6, 0.0, report=False)
    assert quiet["a"].tolist() == [0, 2]
    # thresholds just below and just above each kept column's own motion, its norm over sqrt(N) [m RMS]
    for norm, below, above in ((1e-3, [0, 2], [2]), (2e-3, [2], [])):
        motion = norm / np.sqrt(n_poses)
        for factor, kept in ((1 - 3e-10, below), (1 + 3e-10, above)):
            for report in (False, True):
                assert identifiability({"a": block}, ["a"], 1e-6, motion * factor, report=report)[0]["a"].tolist() \
                    == kept


def test_a_factor_cache_emptied_counts_its_bytes_from_zero_and_keeps_what_fits():
    """Three 10 x 10 factors (800 bytes each) fill a cache of 2400 bytes exactly; emptied, it holds 0 bytes,
    and filled again it holds the three, 2400 bytes; a fourth makes the least recently used go. Seen
    failing on ``clear``'s ``self._bytes = 0`` turned to ``-1``."""
    from tcr_accuracy.diagnosis.least_squares import FactorCache

    cache = FactorCache(max_bytes=3 * 800)
    for _ in range(2):
        for key in "abc":
            cache.get(key, lambda: np.eye(10))
        assert cache.nbytes() == 2400
        cache.clear()
        assert cache.nbytes() == 0
    for key in "abcd":
        cache.get(key, lambda: np.eye(10))
    assert cache.nbytes() == 2400
    made = []
    cache.get("a", lambda: made.append(1) or np.eye(10))  # "a" went first: made again
    assert made == [1]


def test_lambda_is_the_grids_argmin_where_the_training_rows_miss_a_column():
    """A penalised model whose first (unpenalised) column no row moves: every fold's training system is
    singular, so its fits take the ridge 1e-12 x the largest Gram diagonal. Lambda is the grid's argmin of
    the k-fold held-out error, each fold's fit solved here with numpy at every lambda with that ridge, from
    either end of the grid. Seen failing on the ridge branch's ``grid[i] * weights`` turned to ``grid[i] -
    weights`` and on ``ridge = 1e-12 * ...`` turned to ``1.000000000001 * ...``."""
    from tcr_accuracy.diagnosis.block_fit import choose_penalty
    from tcr_accuracy.diagnosis.gram import Quadratic

    rng = np.random.default_rng(4105)
    n, k = 60, 6
    folds = [np.arange(f, n, 4) for f in range(4)]
    jac = rng.standard_normal((n, k)) * np.array([1.0, 1.0, 0.6, 0.4, 0.3, 0.2])
    jac[:, 0] = 0.0
    truth = np.array([0.5, -1.0, 0.3, -0.2, 0.25, 0.1])
    residual = -(jac @ truth) + 0.3 * rng.standard_normal(n)
    weights = np.array([0.0, 0.0, 50.0, 100.0, 200.0, 400.0])  # far from one: lambda w is not lambda - w
    center = np.array([0.0, 0.0, 0.1, -0.1, 0.05, 0.0])

    def quadratic(rows):
        return Quadratic(jac[rows].T @ jac[rows], jac[rows].T @ residual[rows], float(residual[rows] @ residual[rows]))

    total = quadratic(np.arange(n))
    held = [(lambda rows=rows: quadratic(rows)) for rows in folds]
    grid = np.median(np.sum(jac[:, 2:] ** 2, axis=0)) * 10.0 ** np.arange(-5, 4)
    ridge = 1e-12 * np.max(np.sum(jac**2, axis=0))
    scores = []
    for lam in grid:
        score = 0.0
        for rows in folds:
            train = np.setdiff1d(np.arange(n), rows)
            system = jac[train].T @ jac[train] + lam * np.diag(weights)
            if not np.any(jac[train, 0]):
                system = system + ridge * np.eye(k)
            d = np.linalg.solve(system, -(jac[train].T @ residual[train]) - lam * weights * center)
            score += np.sum((residual[rows] + jac[rows] @ d) ** 2)
        scores.append(score)
    best = int(np.argmin(scores))
    assert 0 < best < len(grid) - 1
    for start in (0, len(grid) - 1):
        index, lam = choose_penalty(total, held, weights, center, start)
        assert index == best and lam == pytest.approx(grid[best], rel=1e-12)


def test_rival_models_pair_the_chosen_model_with_each_stand_in_in_its_place():
    """For each ambiguity group and each member after the chosen one, the fitted chosen model against the
    model with the member's effects in the chosen effect's place (the rest kept). Seen failing on ``rest +
    member["effects"]`` turned to ``rest % member["effects"]`` and on ``group["members"][1:]`` turned to
    ``[2:]``."""
    from tcr_accuracy.diagnosis.ambiguity import rival_models

    result = SimpleNamespace(selected_effects=["frames", "joint_offsets", "compliance"],
                             ambiguous=[{"chosen": "compliance",
                                         "members": [{"effects": ["compliance"]}, {"effects": ["gear_errors"]},
                                                     {"effects": ["encoder_scale", "transmission"]}]}])
    estimator = SimpleNamespace(result_=result, fitted_model=lambda effects: tuple(effects))
    assert rival_models(estimator) == [
        (("frames", "joint_offsets", "compliance"), ("frames", "joint_offsets", "gear_errors")),
        (("frames", "joint_offsets", "compliance"), ("frames", "joint_offsets", "encoder_scale", "transmission"))]


def test_a_stand_ins_shape_is_its_motion_less_what_the_models_columns_absorb():
    """stand_in_shapes over 2100 poses (two chunks of the tall-skinny QR): each unchosen effect's TCP motion at
    a draw of its typical sizes, less its least-squares fit by the chosen model's columns (scaled) on the
    position rows, written out with numpy's lstsq; an effect the chosen model holds, or one driven by the
    temperature, gives none. Seen failing on ``_least_squares_residual``'s chunk ``start + QR_CHUNK`` turned
    to ``start - QR_CHUNK`` (in either loop), on the draw ``* b.scales[b.index[0]]`` turned to ``/``, on the
    motion's position rows ``[:, :3, 0]`` turned to ``[:, :4, 0]`` and on the coefficients' ``r[:k, k:]``
    turned to ``r[:k, k + 1:]``."""
    from tcr_accuracy.diagnosis.ambiguity import stand_in_shapes
    from tcr_accuracy.diagnosis.fit_columns import Sensitivity
    from tcr_accuracy.diagnosis.identifiability import QR_CHUNK

    rng = np.random.default_rng(4106)
    n = 2100
    assert QR_CHUNK < n
    model_g = rng.standard_normal((n, 6, 3))  # the chosen model's columns (rotation rows not read)
    model_scale = np.array([1e-3, 5e-4, 2e-3])
    g = rng.standard_normal((n, 6, 2)) + model_g[:, :, :2] * 0.5  # partly absorbed by the model
    scales = np.array([1e-4, 3e-4])
    basis = SimpleNamespace(per_part=[SimpleNamespace(g=g)], scales=scales, index=[np.array([0, 1])])
    columns = SimpleNamespace(per_part=[(None, Sensitivity([(model_g, np.arange(3))]), np.arange(3))],
                              scale=model_scale)
    engine = SimpleNamespace(bases={"joint_offsets": basis, "thermal": basis, "compliance": basis},
                             columns=lambda effects: columns)
    shapes = stand_in_shapes(engine, ["frames", "compliance"], ["frames", "compliance", "joint_offsets", "thermal"],
                             np.random.default_rng(9))
    draw = np.random.default_rng(9).standard_normal(2) * scales
    motion = np.einsum("nrk,k->nr", g[:, :3], draw).ravel()
    model = (model_g[:, :3] * model_scale).reshape(-1, 3)
    left = motion - model @ np.linalg.lstsq(model, motion, rcond=None)[0]
    assert list(shapes) == ["joint_offsets"]
    np.testing.assert_allclose(shapes["joint_offsets"], left.reshape(n, 3), rtol=0, atol=1e-10 * np.abs(left).max())


@pytest.mark.parametrize("n_params", [1, 2])
def test_a_small_effects_nonlinearity_is_read_at_plus_its_scale_or_at_minus_and_plus(tool_changer, n_params):
    """A toy effect turning the first joint by p - 3 p^2 and (with two parameters) the last by p: one parameter
    is probed at +scale (0.1): |3 p^2| / |p - 3 p^2| = 0.03 / 0.07; two at (-scale, +scale): the first at
    -0.1, 0.03 / 0.13. Seen failing on ``if k > 1`` turned to ``k > 0`` (one parameter probed at -scale) and
    to ``k > 2`` (two probed at +scale), and on the size's floor ``1e-300`` turned to ``1.000000001``."""
    from tcr_accuracy.diagnosis.bases import EffectBasis, Part, position_jacobians
    from tcr_accuracy.effects.base import Effect, EffectOutput, make_effect, plugged_in
    from tcr_accuracy.model.context import MeasurementContext
    from tcr_accuracy.model.errors import ErrorModel

    robot = tool_changer

    class Bent(Effect):
        name = "toy_bent"

        def parameter_names(self):
            return [f"toy_bent.{i}" for i in range(n_params)]

        def parameter_units(self):
            return ["1"] * n_params

        def parameter_scales(self):
            return np.full(n_params, 0.1)

        def perturb(self, params, q, context):
            params = self.check_params(params)
            dq = np.zeros(np.atleast_2d(q).shape)
            dq[:, 0] = params[0] - 3.0 * params[0] ** 2
            if n_params > 1:
                dq[:, -1] = params[1]
            return EffectOutput(dq=dq)

    q = np.random.default_rng(4107).uniform(*robot.joint_bounds(), size=(4, robot.n_joints))
    context = MeasurementContext(np.zeros(4), np.full(4, 20.0), np.zeros((4, robot.n_joints)))
    part = Part(robot, q, np.zeros((4, 3)), context, "tool")
    with plugged_in(Bent):
        basis = EffectBasis(make_effect("toy_bent", robot), part, ErrorModel(robot), position_jacobians(robot, q))
    p = 0.1 if n_params == 1 else -0.1
    expected = 3.0 * p**2 / max(abs(p - 3.0 * p**2), 0.1 if n_params > 1 else 0.0)
    assert basis.nonlinearity == pytest.approx(expected, rel=1e-9)


def test_a_map_whose_column_moves_two_joints_and_its_sensitivity_made_when_read_are_the_dense_products():
    """An error map (p_em = 9, drive entries 3..6) with a fixed part, one column moving two joints (so the
    drive is stored (N, n_joints, k)) and one moving one, over 2100 poses: its errors, its sensitivity over all
    poses and some, the drive written out densely, and its sensitivity made when read (whole over two chunks
    of 2048, by rows, by one pose with a component) against the dense products here; each column's RMS
    motion over the poses on two components. Seen failing on ``sensitivity``'s drive product taken of
    ``self.drive`` for ``rows`` given (``rows is None`` turned to ``is not None``), on ``__array__``'s chunk
    ``start + ErrorMap.CHUNK`` turned to ``-``, on ``column_rms``' ``total / max(g.shape[0], 1)`` turned to
    ``g.shape[1]``, on one pose's row ``self.rows([key[0]])[0]`` turned to ``[1]`` and on ``dense_drive``'s
    ``np.arange(self.drive.shape[1])`` turned to ``shape[0]``."""
    from tcr_accuracy.diagnosis.error_map import SensitivityWhenRead, column_rms

    rng = np.random.default_rng(4108)
    n, size, drive = 2100, 9, slice(3, 7)
    fixed = np.zeros((size, 3))
    fixed[[0, 8], 0] = [0.5, -1.5]
    dq = np.zeros((n, 4, 3))
    dq[:, [0, 2], 1] = rng.standard_normal((n, 2))  # one column, two joints
    dq[:, 3, 2] = rng.standard_normal(n)
    m = ErrorMap.of(n, size, drive, fixed, dq, 3)
    assert m.drive_joint is None and m.drive.shape == (n, 4, 2)
    dense = np.broadcast_to(fixed, (n, size, 3)).copy()
    dense[:, drive] += dq
    theta = np.array([0.3, -2.0, 0.7])
    rows = np.array([2099, 5, 2048, 17])
    np.testing.assert_allclose(m.errors(theta), dense @ theta, rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(m.errors(theta, rows), dense[rows] @ theta, rtol=1e-13, atol=1e-15)
    np.testing.assert_array_equal(m.dense_drive(), dq[:, :, 1:])
    jac_x = rng.standard_normal((n, 3, size))
    g = np.einsum("nrp,npk->nrk", jac_x, dense)
    np.testing.assert_allclose(m.sensitivity(jac_x), g, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(m.sensitivity(jac_x[rows], rows), g[rows], rtol=1e-12, atol=1e-12)
    read = SensitivityWhenRead(m, jac_x)
    assert read.shape == (n, 3, 3)
    scratch = np.full(g.shape, np.nan)  # memory a new array of g's size may be given: not g's values
    del scratch
    np.testing.assert_allclose(np.asarray(read), g, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(read[rows], g[rows], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(read[2050, 1], g[2050, 1], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(column_rms(read, slice(0, 2)), np.sqrt(np.mean(np.sum(g[:, :2] ** 2, axis=1), axis=0)),
                               rtol=1e-12)
    compact = ErrorMap.of_joint_columns(n, size, drive, dq[:, 3, 2:], np.array([3]))
    np.testing.assert_array_equal(compact.dense_drive(), dq[:, :, 2:])
