"""The fit engine's figures (``diagnosis/fitting.py``: ``FitEngine.evaluate``) against a fit written out
here: scipy's ``least_squares`` on the engine's exact residual for the optimum, a central finite-difference
Jacobian of that residual for the standard errors sqrt(diag(s^2 (J^T J)^-1)) with s^2 the cost over n - k,
each fold's one Gauss-Newton step on its training rows and its held-out rows moved by J times the step, the
training and held-out statistics as root mean squares of the rows. The data: joint offsets hidden in a
Pinocchio model, noise drawn here. Each test names a planted change it was seen to catch (issue 36)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from mutd_truth import offset_measurements
from scipy.optimize import least_squares

from tcr_accuracy.diagnosis.diagnose import GapDiagnosis
from tcr_accuracy.diagnosis.fitting import FitEngine
from tcr_accuracy.io.measurements import MeasurementSet
from tcr_accuracy.model.robot import load_robot

MODEL = ["frames", "joint_offsets"]
N_POSES = 14


@pytest.fixture(scope="module")
def diagnosis():
    """A diagnosis of 14 poses of a tool-changer whose joints are off by a few hundredths of a degree
    (the hidden truth, through Pinocchio), 30 um noise per axis."""
    robot, measured = offset_measurements(N_POSES, 36)
    return GapDiagnosis(robot=robot, effects=["joint_offsets"], folds=2, stability_replays=2).fit(measured)


@pytest.fixture(scope="module")
def engine(diagnosis):
    """A new engine on the diagnosis' rows and columns, with three folds chosen here."""
    fitted = diagnosis.engine_
    tests = np.array_split(np.random.default_rng(1).permutation(N_POSES), 3)
    folds = [(np.setdiff1d(np.arange(N_POSES), t), np.sort(t)) for t in tests]
    return FitEngine(fitted.parts, fitted.bases, folds, rank_tol=fitted.rank_tol, min_motion=fitted.min_motion), folds


def _residual(engine, cols, rows):
    def flat(phi):
        return np.concatenate([r.ravel() for r in engine.predict_residual(cols, phi, rows)])
    return flat


def _exact_fit(engine):
    """The engine's exact fit of MODEL, its residual function over every row and its optimum."""
    result = engine.evaluate(MODEL, exact=True)
    fun = _residual(engine, engine.columns(MODEL), np.arange(N_POSES))
    return result, fun, result["phi"]


def _jacobian(fun, phi, step=1e-6):
    columns = []
    for i in range(phi.size):
        e = np.zeros(phi.size)
        e[i] = step
        columns.append((fun(phi + e) - fun(phi - e)) / (2 * step))
    return np.stack(columns, axis=1)


def test_the_exact_fit_its_standard_errors_and_its_figures_are_least_squares_written_out(engine):
    """The optimum as scipy finds it (each parameter to 0.3 % of its standard error); the cost its sum of
    squares; the standard errors from the finite-difference Jacobian at the optimum and s^2 = cost / (3N - k) (to
    0.3 %: the engine's Jacobian is the linearised one); the counts; the training statistics' RMS and
    mean of the rows' norms. Seen failing on ``cost / max(fields["n_observations"] - k, 1)`` turned to
    ``+ k``, on the ``n_observations`` ``self.n_rows * p.rows_per_pose`` turned to ``+`` and on
    ``DampedSolver.standard_errors``' ``np.sqrt(variance * diag)`` turned to ``variance + diag``."""
    engine, _ = engine
    result, fun, phi = _exact_fit(engine)
    k = result["n_parameters"]
    assert k == len(engine.columns(MODEL).names) == len(result["names"]) and 10 <= k < 15
    assert result["n_observations"] == 3 * N_POSES
    jac = _jacobian(fun, phi)
    reference = least_squares(fun, phi + 0.01, jac=lambda p: _jacobian(fun, p), xtol=1e-15, ftol=1e-15,
                              gtol=1e-15, method="lm").x
    cost = float(fun(phi) @ fun(phi))
    assert result["cost"] == pytest.approx(cost, rel=1e-9)
    std = np.sqrt(np.diag(cost / (3 * N_POSES - k) * np.linalg.inv(jac.T @ jac)))
    np.testing.assert_allclose(result["phi_std"], std, rtol=3e-3)
    assert np.all(np.abs(phi - reference) < 3e-3 * std)  # each parameter within 0.3 % of its standard error
    norms = np.linalg.norm(fun(phi).reshape(-1, 3), axis=1)
    assert result["train_stats"].rms == pytest.approx(np.sqrt(np.mean(norms**2)), rel=1e-9)
    assert result["train_stats"].mean == pytest.approx(norms.mean(), rel=1e-9)
    assert result["train_stats"].max == pytest.approx(norms.max(), rel=1e-9)
    np.testing.assert_allclose(result["train_residual"], fun(phi).reshape(-1, 3), rtol=0, atol=1e-12)


def test_each_fold_is_one_gauss_newton_step_on_its_training_rows_and_scored_on_its_held_out_rows(engine):
    """Each fold's fit: the full optimum moved by -(J_t^T J_t)^-1 J_t^T r_t on its training rows (the
    finite-difference Jacobian; to 1 % of a standard error); its held-out rows: the residual at the
    optimum plus J times the step; the per-row held-out squares, and their RMS and pooled statistics.
    Seen failing on ``total_gradient - held_gradient`` turned to ``+``, on ``gram - store.held_blocks()``
    turned to ``+``, and on the held-out squares' mean over the fold assignments turned to twice their sum."""
    engine, folds = engine
    result, fun, phi = _exact_fit(engine)
    jac = _jacobian(fun, phi).reshape(N_POSES, 3, -1)
    residual = fun(phi).reshape(N_POSES, 3)
    held = np.empty((N_POSES, 3))
    for (train, test), fold_phi in zip(folds, result["fold_phi"]):
        j_train = jac[train].reshape(-1, phi.size)
        step = -np.linalg.solve(j_train.T @ j_train, j_train.T @ residual[train].ravel())
        assert np.all(np.abs(fold_phi - phi - step) < 1e-2 * result["phi_std"])
        held[test] = residual[test] + jac[test] @ step
    np.testing.assert_allclose(result["heldout_residual"], held, rtol=0, atol=1e-3 * np.abs(held).max())
    squares = np.sum(held**2, axis=1)
    np.testing.assert_allclose(result["heldout_squares"], squares, rtol=2e-3)
    norms = np.sqrt(squares)
    assert result["heldout_stats"].rms == pytest.approx(np.sqrt(np.mean(squares)), rel=2e-3)
    assert result["heldout_stats"].max == pytest.approx(norms.max(), rel=2e-3)
    assert result["heldout_stats"].rms > 1.1 * result["train_stats"].rms  # held out: worse than trained


def test_the_linear_fit_and_its_held_out_sums_are_least_squares_of_the_linear_model(engine):
    """The default (linear) fit, anchored at the frames' exact fit: the same model's optimum to within its
    curvature (5 % of each standard error here), and a model without the frames (their columns moved from
    the anchor back to zero) likewise against its exact fit; each fold's held-out sum of squares the sum
    over its held-out rows of its held-out residual; the cost the training rows'; the same counts; no
    parameter said to sit on its bound. Seen failing on ``_linear``'s ``fixed = -anchor`` turned to
    ``anchor.copy()`` and on the bound's ``span = ... * 1e-9`` turned to ``1e9``."""
    engine, folds = engine
    for model in (MODEL, ["joint_offsets"]):
        exact = engine.evaluate(model, exact=True)
        linear = engine.evaluate(model)
        assert linear["n_parameters"] == exact["n_parameters"] and linear["n_observations"] == 3 * N_POSES
        assert np.all(np.abs(linear["phi"] - exact["phi"]) < 0.05 * exact["phi_std"]), model
        assert not linear["at_bound"].any() and not exact["at_bound"].any()
        held = linear["heldout_residual"]
        for (_, test), ssq in zip(folds, linear["heldout_ssq"][0]):
            assert ssq == pytest.approx(np.sum(held[test] ** 2), rel=1e-6)
        assert linear["cost"] == pytest.approx(np.sum(linear["train_residual"] ** 2), rel=1e-6)


def test_orientation_errors_are_given_in_radians_at_the_noise_drawn():
    """Measured orientations (quaternions of Pinocchio's TCP rotation, each turned by a random rotation
    of 50 urad per axis) fitted with an orientation weight of 0.3 m/rad: the training and held-out
    orientation errors are in radians, their RMS per axis within 25 % of the 50 urad drawn (the rows
    are weighted by 0.3 m/rad inside the fit: a figure left weighted would be 0.3 times it). Seen
    failing on ``r[:, 3:] / part.orientation_weight`` turned to ``- part.orientation_weight`` and to
    ``* part.orientation_weight``."""
    from scipy.spatial.transform import Rotation

    robot = load_robot()
    rng = np.random.default_rng(5)
    low, high = robot.joint_bounds()
    n = 30
    q = rng.uniform(low, high, size=(n, robot.n_joints))
    offsets = np.radians([0.05, -0.03, 0.04, 0.0, 0.06, 0.02])
    offsets[3] = 3e-4
    model, data = robot.model, robot.model.createData()
    position, rotation = np.empty((n, 3)), np.empty((n, 3, 3))
    for i, row in enumerate(q + offsets):
        pin.framesForwardKinematics(model, data, robot.to_pinocchio_q(row))
        position[i] = data.oMf[robot.tool_frame_id].translation
        rotation[i] = data.oMf[robot.tool_frame_id].rotation
    noise = 5e-5
    position += 3e-5 * rng.standard_normal(position.shape)
    rotation = Rotation.from_rotvec(noise * rng.standard_normal((n, 3))).as_matrix() @ rotation
    xyzw = Rotation.from_matrix(rotation).as_quat()
    measured = MeasurementSet(joint_names=robot.joint_names, q=q, position=position,
                              quaternion=np.column_stack([xyzw[:, 3], xyzw[:, :3]]))
    fitted = GapDiagnosis(robot=robot, effects=["joint_offsets"], folds=3, stability_replays=2,
                          orientation_weight=0.3).fit(measured).engine_
    result = fitted.evaluate(MODEL, exact=True)
    for key in ("train_orientation", "heldout_orientation"):  # 46.8 and 50.4 urad here
        errors = result[key]
        assert errors.shape == (n, 3)
        rms = np.sqrt(np.mean(errors**2))
        assert 0.75 * noise < rms < 1.25 * noise, (key, rms)


def test_a_ladder_step_is_its_models_exact_fit_and_the_paired_z_against_the_step_before(diagnosis):
    """``GapDiagnosis.ladder``: one step per effect added, each naming the effects fitted so far, its
    parameter count and training RMS those of its model's exact fit, its held-out RMS, mean and max of
    the rows' norms, and the z of the paired mean cut in per-row squared held-out errors against the step
    before (mean over its standard error, ``ddof=1``, written out); the fold assignments, none asked
    for: min(5, round(10 000 / 14 rows)) = 5. Seen failing on the step's ``sequence[:k + 1]`` turned to
    ``[:k + 2]`` and on the repeats' ``np.clip(..., 1, 5)`` turned to ``(..., 1, 6)``."""
    assert len(diagnosis.engine_.repeats) == 5
    steps = diagnosis.ladder(["joint_offsets"])
    assert [(s.effect, s.effects) for s in steps] == [("frames", ("frames",)),
                                                       ("joint_offsets", ("frames", "joint_offsets"))]
    previous = None
    for step in steps:
        fit = diagnosis.engine_.evaluate(list(step.effects), exact=True)
        assert step.n_parameters == fit["n_parameters"]
        assert step.train_rms == pytest.approx(np.sqrt(np.mean(np.sum(fit["train_residual"] ** 2, axis=1))), rel=1e-9)
        norms = np.linalg.norm(fit["heldout_residual"], axis=1)
        assert (step.heldout.rms, step.heldout.mean, step.heldout.max) == pytest.approx(
            (np.sqrt(np.mean(norms**2)), norms.mean(), norms.max()), rel=1e-9)
        if previous is None:
            assert step.z_statistic is None
        else:
            d = np.sum(previous**2, axis=1) - norms**2
            assert step.z_statistic == pytest.approx(d.mean() / (d.std(ddof=1) / np.sqrt(d.size)), rel=1e-9)
        previous = fit["heldout_residual"]
    assert steps[1].z_statistic > 3 and steps[1].heldout.rms < 0.5 * steps[0].heldout.rms  # the offsets explain
