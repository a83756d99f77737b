"""The fit engine (``diagnosis/fitting.py``, issue 36): the exact (nonlinear) refit's PATH, not only its
optimum — the iterates of ``FitEngine._minimise`` with its evaluation cap set low against a Levenberg-Marquardt
with Nielsen's damping update written out here on numpy (the same constant Jacobian, damping on the columns'
squared norms, the first damping 1e-3 of the largest eigenvalue of the column-scaled Gram matrix, the growth
doubling after each failed step); the start points the refit is given (a nested model's optimum with the new
parameters at zero, the anchor's warm start) read with the cap at zero, where the fit is its start; and the
engine's rules few data sets reach (the exact fit's fold steps, the curvature that calls for a Gauss-Newton
step, rows no fold holds out, a penalised lambda reused, identifiability re-judged at fitted sizes, a model
with nothing kept, an ambiguity row's figures). The data: joint offsets hidden in a Pinocchio model
(tests/mutd_truth.py), in some tests seen through a measurement frame turned by up to 0.37 rad (far from the
nominal, so that an undamped step fails and the damping matters). Fast on purpose: a mutation run tries the
fastest covering tests first. Each test names a planted change it was seen to catch."""

from __future__ import annotations

import copy
import dataclasses

import numpy as np
import pinocchio as pin
import pytest
from mutd_truth import offset_measurements
from scipy.spatial.transform import Rotation

from tcr_accuracy.diagnosis.diagnose import GapDiagnosis
from tcr_accuracy.diagnosis.fitting import FitEngine

N = 14
#: residual evaluations of the Levenberg-Marquardt path compared
EVALUATIONS = 26
#: the measurement frame: targets seen turned by this rotation vector [rad] and moved by this [m]
TURN, SHIFT = np.array([0.1, -0.2, 0.3]), np.array([0.05, -0.02, 0.03])


@pytest.fixture(scope="module")
def diagnosed():
    """(robot, measurements, a diagnosis' engine) on 14 poses with hidden joint offsets, 30 um noise."""
    robot, measured = offset_measurements(N, 4200)
    fitted = GapDiagnosis(robot=robot, effects=["joint_offsets"], folds=2, stability_replays=2).fit(measured)
    return robot, measured, fitted.engine_


def _engine(fitted, parts=None, bases=None):
    """A new engine (three folds chosen here) on the diagnosis' parts and bases (or the given ones)."""
    tests = np.array_split(np.random.default_rng(4201).permutation(N), 3)
    folds = [(np.setdiff1d(np.arange(N), t), np.sort(t)) for t in tests]
    return FitEngine(parts or fitted.parts, bases or fitted.bases, folds, rank_tol=fitted.rank_tol,
                     min_motion=fitted.min_motion)


def _turned(fitted):
    """The diagnosis' parts with their targets seen through the turned and moved measurement frame."""
    turn = Rotation.from_rotvec(TURN).as_matrix()
    return [dataclasses.replace(p, target=p.target @ turn.T + SHIFT) for p in fitted.parts]


def _frames_fit(fitted):
    """(a new engine, the measurement frame's columns, their chained Jacobians, the Jacobian (3N, k) they
    make, the residual (3N,) as a function of phi): nothing bounds these columns, so every step is the plain
    Levenberg-Marquardt step."""
    engine = _engine(fitted)
    cols = engine.columns(["frames"])
    assert np.all(np.isinf(cols.lower)) and np.all(np.isinf(cols.upper))
    jacs = engine._jacobians(cols)
    k = cols.scale.size
    jacobian = np.concatenate([j.block(slice(None)).reshape(-1, k) for j in jacs])
    every = np.arange(N)

    def residual(phi):
        return np.concatenate([r.ravel() for r in engine.predict_residual(cols, phi, every)])

    return engine, cols, jacs, jacobian, residual


def _levenberg_marquardt(residual, jacobian, start, evaluations, tolerance):
    """Levenberg-Marquardt written out: the steps d solving (J^T J + mu diag(J^T J)) d = -J^T r with J held
    constant, a step kept when the cost |r|^2 falls, mu then multiplied by max(1/3, 1 - (2 rho - 1)^3) for
    rho = actual / predicted gain (Nielsen 1999), else mu set to 1e-3 of the largest eigenvalue of the
    column-scaled J^T J (mu was 0: the first step is Gauss-Newton's) or multiplied by nu, nu doubling while
    steps fail and 2 again after one is kept. The iterates after each evaluation, and the dampings."""
    gram = jacobian.T @ jacobian
    norms = np.sqrt(np.diag(gram))
    first = 1e-3 * np.linalg.eigvalsh(gram / np.outer(norms, norms))[-1]
    phi, r = start.copy(), residual(start)
    cost, mu, nu, path, dampings = r @ r, 0.0, 2.0, [], []
    for _ in range(evaluations):
        g = jacobian.T @ r
        d = np.linalg.solve(gram + mu * np.diag(np.diag(gram)), -g)
        predicted = -(2.0 * g @ d + d @ gram @ d)
        if predicted <= tolerance * cost:
            break
        r_trial = residual(phi + d)
        if r_trial @ r_trial < cost:
            gain = cost - r_trial @ r_trial
            phi, r, cost = phi + d, r_trial, r_trial @ r_trial
            mu, nu = mu * max(1.0 / 3.0, 1.0 - (2.0 * gain / predicted - 1.0) ** 3), 2.0
        else:
            mu, nu = (first if mu == 0.0 else mu * nu), 2.0 * nu
        path.append(phi.copy())
        dampings.append(mu)
    return path, dampings


def test_each_levenberg_marquardt_iterate_is_nielsens_update_written_out(diagnosed):
    """The measurement frame's fit started 3.4 rad away, the Jacobian held at the nominal: after each of its
    first 26 residual evaluations (the cap set to 1, 2, ..., 26) the engine's parameters are the written-out
    Levenberg-Marquardt's to 1e-9 (they move by hundreds). Its path: four failed steps (the damping set to
    its first value, then grown 4, 8, 16 times), 13 kept ones whose Nielsen factor runs from above 1 to the
    1/3 floor, five failed ones (the growth back at 2 after a kept step), four kept. Seen failing on the
    floor ``1.0 / 3.0`` turned to ``1.0 / 2.0``, on ``1.0 - (2.0 * gain ...`` turned to ``2.0 - ...``, on the
    first damping ``1e-3 * top`` turned to ``1e-2``, on the growth's ``growth *= 2.0`` turned to ``3.0`` and
    on its reset after a kept step, ``growth = 2.0``, turned to ``3.0``."""
    engine, cols, jacs, jacobian, residual = _frames_fit(diagnosed[2])
    every = np.arange(N)
    start = np.zeros(cols.scale.size)
    start[:6] = [-2.33, 17.31, 3.52, -313.0, -134.2, -40.76]  # the base frame's twist [1 cm, 0.01 rad]
    path, dampings = _levenberg_marquardt(residual, jacobian, start, EVALUATIONS, FitEngine.COST_TOLERANCE)
    kept = "".join("s" if np.any(p != q) else "f" for p, q in zip(path, [start] + path[:-1]))
    assert kept == "ffff" + 13 * "s" + 5 * "f" + 4 * "s"
    # four failed steps first, the damping growing, five more later after it was reset
    np.testing.assert_allclose(np.array(dampings[1:4]) / dampings[:3], [4.0, 8.0, 16.0], rtol=1e-12)
    np.testing.assert_allclose(np.array(dampings[17:22]) / dampings[16:21], [2.0, 4.0, 8.0, 16.0, 32.0], rtol=1e-12)
    factors = np.array(dampings[5:17]) / np.array(dampings[4:16])
    assert factors.max() > 1.0 and np.isclose(factors.min(), 1.0 / 3.0, rtol=1e-12, atol=0)
    for m in range(1, EVALUATIONS + 1):
        engine.MAX_EVALUATIONS = m
        phi, _ = engine._minimise(cols, jacs, None, jacobian.T @ jacobian, start,
                                  engine.predict_residual(cols, start, every))
        np.testing.assert_allclose(phi, path[m - 1], rtol=0, atol=1e-9, err_msg=f"after {m} evaluations")
    assert np.max(np.abs(path[-1] - start)) > 300


def test_a_fit_that_has_not_converged_stops_after_40_residual_evaluations(diagnosed):
    """The measurement frame's fit started where Levenberg-Marquardt crawls (the base turned by 4.2 rad, the
    Jacobian held at the nominal; each step still moves it by 0.006): with the default cap the engine's
    parameters are the written-out iterate after 40 evaluations, to 1e-9, not the 39th's or the 41st's.
    Seen failing on ``MAX_EVALUATIONS = 40`` turned to ``39`` and to ``41``."""
    engine, cols, jacs, jacobian, residual = _frames_fit(diagnosed[2])
    every = np.arange(N)
    start = np.zeros(cols.scale.size)
    start[:6] = [-2.0, -12.0, -13.0, -311.0, 202.0, 187.0]
    path, _ = _levenberg_marquardt(residual, jacobian, start, 41, FitEngine.COST_TOLERANCE)
    assert len(path) == 41 and np.max(np.abs(path[39] - path[38])) > 1e-3 < np.max(np.abs(path[40] - path[39]))
    phi, _ = engine._minimise(cols, jacs, None, jacobian.T @ jacobian, start,
                              engine.predict_residual(cols, start, every))
    np.testing.assert_allclose(phi, path[39], rtol=0, atol=1e-9)

def test_a_nested_models_exact_fit_starts_at_the_inner_optimum_with_the_new_parameters_at_zero(diagnosed):
    """Nothing anchors the linear model (the nominal's residual) and the measurement frame is turned by
    0.37 rad: the linear fit of frames + joint offsets is far from its optimum, and the exact fit of frames
    alone, with the joint offsets at zero, is a better start. With the evaluation cap at zero the larger
    model's exact fit is its start: exactly that point, whose cost, computed here with Pinocchio, is the
    reported one and below the linear fit's. Seen failing on ``known.get(n, 0.0)`` turned to
    ``known.get(n, 1.0)``."""
    robot, measured, fitted = diagnosed
    engine = _engine(fitted, _turned(fitted))
    engine.reset(anchor=())
    inner = engine.evaluate(["frames"], exact=True)
    engine.MAX_EVALUATIONS = 0
    outer = engine.evaluate(["frames", "joint_offsets"], exact=True)
    assert outer["names"][:len(inner["names"])] == inner["names"] and len(outer["names"]) > len(inner["names"])
    expected = np.concatenate([inner["phi"], np.zeros(len(outer["names"]) - len(inner["names"]))])
    np.testing.assert_array_equal(outer["phi"], expected)
    # the cost at that start: the measurement frame's fit written out on Pinocchio's forward kinematics
    # (the base frame a twist exp6(d, r) on the left, the tool offset d in the tool's frame)
    theta = dict(zip(inner["names"], inner["phi"] * inner["scale"]))
    base = pin.exp6(np.array([theta[f"frames.base.{c}"] for c in ("dx", "dy", "dz", "rx", "ry", "rz")]))
    tool = np.array([theta[f"frames.tool.d{a}"] for a in "xyz"])
    model, data = robot.model, robot.model.createData()
    cost = 0.0
    for q, target in zip(measured.q, _turned(fitted)[0].target):
        pin.framesForwardKinematics(model, data, robot.to_pinocchio_q(q))
        tcp = data.oMf[robot.tool_frame_id]
        cost += float(np.sum((base.act(tcp.act(tool)) - target) ** 2))
    assert outer["cost"] == pytest.approx(cost, rel=1e-6)
    linear = engine.evaluate(["frames", "joint_offsets"])
    assert linear["cost"] > 100 * outer["cost"]


def test_the_anchor_fit_starts_from_the_last_fitted_values_and_else_from_zero(diagnosed):
    """The anchor's exact fit (the measurement frame) with the evaluation cap at zero is its start: on a new
    engine the nominal (every parameter zero, its residual the nominal robot's tool positions from Pinocchio
    less the targets), and after an exact fit and a reset, that fit's parameters. Seen failing on
    ``self._last.get(n, 0.0)`` turned to ``self._last.get(n, 1.0)``."""
    robot, measured, fitted = diagnosed
    parts = _turned(fitted)
    engine = _engine(fitted, parts)
    engine.MAX_EVALUATIONS = 0
    anchor = engine.grams().anchor
    assert anchor.effects == ("frames",)
    np.testing.assert_array_equal(anchor.phi, np.zeros(anchor.phi.size))
    model, data = robot.model, robot.model.createData()
    nominal = []
    for q in measured.q:
        pin.framesForwardKinematics(model, data, robot.to_pinocchio_q(q))
        nominal.append(data.oMf[robot.tool_frame_id].translation.copy())
    np.testing.assert_allclose(anchor.residual[0], np.array(nominal) - parts[0].target, rtol=0, atol=1e-12)

    warm = _engine(fitted, parts)
    fit = warm.evaluate(["frames"], exact=True)
    assert np.max(np.abs(fit["phi"])) > 1.0  # far from zero: 0.37 rad, 5 cm
    warm.reset()
    warm.MAX_EVALUATIONS = 0
    again = warm.grams().anchor
    index = warm.grams().layout.indices(["frames"], warm.kept(("frames",)))
    np.testing.assert_array_equal(again.phi[index], fit["phi"])


def test_a_model_with_nothing_identifiable_has_no_standard_errors_and_the_nominals_residual(diagnosed):
    """The measurement frame with none of its parameters kept, fitted exactly: no parameter, an empty array
    of standard errors, and its training residual the nominal robot's (Pinocchio's tool positions less the
    targets): RMS, mean and max of the norms. Seen failing on the empty standard errors' ``np.zeros(0)``
    turned to ``np.zeros(-1)``."""
    robot, measured, fitted = diagnosed
    engine = _engine(fitted)
    result = engine.evaluate(["frames"], keep={"frames": np.zeros(0, dtype=int)}, exact=True)
    assert result["n_parameters"] == 0
    std = result["phi_std"]
    assert isinstance(std, np.ndarray) and std.shape == (0,)
    model, data = robot.model, robot.model.createData()
    norms = []
    for q, target in zip(measured.q, fitted.parts[0].target):
        pin.framesForwardKinematics(model, data, robot.to_pinocchio_q(q))
        norms.append(np.linalg.norm(data.oMf[robot.tool_frame_id].translation - target))
    norms = np.array(norms)
    stats = result["train_stats"]
    np.testing.assert_allclose([stats.rms, stats.mean, stats.max],
                               [np.sqrt(np.mean(norms**2)), norms.mean(), norms.max()], rtol=1e-9)


def test_an_ambiguity_rows_held_out_figures_are_its_per_row_squares_in_millimetres(diagnosed):
    """The ambiguity check's row of the chosen effect (one fold assignment): its held-out RMS, mean and max
    [mm] are 1000 sqrt(mean(e^2)), 1000 mean(e) and 1000 max(e) of the per-row held-out error norms e that
    its squares carry, its parameter count the model's, its z against itself 0. Seen failing on
    ``held.mean * 1e3`` turned to ``held.mean * 1001.0``."""
    from tcr_accuracy.diagnosis.ambiguity import swap_alternatives

    engine = _engine(diagnosed[2])
    groups = swap_alternatives(engine, ["frames", "joint_offsets"], ["frames", "joint_offsets"], 2.0)
    assert list(groups) == ["joint_offsets"] and len(groups["joint_offsets"]) == 1
    row = groups["joint_offsets"][0]
    norms = np.sqrt(row["_squares"])
    assert norms.size == N and row["effects"] == ["joint_offsets"] and row["z_worse_than_chosen"] == 0.0
    np.testing.assert_allclose([row["heldout_rms_mm"], row["heldout_mean_mm"], row["heldout_max_mm"]],
                               [1e3 * np.sqrt(np.mean(norms**2)), 1e3 * norms.mean(), 1e3 * norms.max()],
                               rtol=1e-12)
    assert row["n_parameters"] == engine.evaluate(["frames", "joint_offsets"])["n_parameters"] == 12


def test_identifiability_is_judged_again_only_for_effects_fitted_above_their_typical_size(diagnosed):
    """Fitted sizes of at most once the typical one change nothing (no re-judging); one just above it does,
    and an effect fitted at f times its typical size is judged with a motion threshold f times smaller
    (min_motion / f), the others at min_motion. Seen failing on ``if f > 1.0`` turned to ``f > 2.0`` and on
    ``self.min_motion / self.size_factors.get(e, 1.0)`` turned to ``* ...`` and to ``get(e, 2.0)``."""
    fitted = diagnosed[2]
    engine = FitEngine(fitted.parts, fitted.bases, [], rank_tol=fitted.rank_tol, min_motion=2e-5)
    assert not engine.resize({"joint_offsets": 1.0, "frames": 0.5}) and engine.size_factors == {}
    assert engine.resize({"joint_offsets": 1.5, "frames": 1.0})
    assert engine.size_factors == {"joint_offsets": 1.5}
    assert not engine.resize({"joint_offsets": 1.5})  # the same sizes: nothing to judge again
    assert engine._thresholds(["frames", "joint_offsets"]) == {"frames": 2e-5, "joint_offsets": 2e-5 / 1.5}


def test_a_large_model_takes_lambda_chosen_last_for_the_same_penalised_effects(diagnosed):
    """Joint offsets given a smoothness penalty (weights 0.5 to 2) and every model counted as large: the
    joint offsets alone, fitted after frames + joint offsets, take that model's lambda without a search
    (the same penalised effects, whatever else is in the model), where fitted first they find their own,
    another point of the grid. Seen failing on the penalised effects' ``layout.penalty[...] > 0`` turned to
    ``> -1`` (every effect of the model taken as penalised: no reuse)."""
    fitted = diagnosed[2]
    bases = dict(fitted.bases)
    offsets = copy.copy(bases["joint_offsets"])
    offsets.penalty = np.linspace(0.5, 2.0, len(offsets.names))
    bases["joint_offsets"] = offsets

    def engine():
        made = _engine(fitted, bases=bases)
        made.LARGE_MODEL = 0
        return made

    alone = engine().evaluate(["joint_offsets"])["penalty"]["full"]
    after = engine()
    larger = after.evaluate(["frames", "joint_offsets"])["penalty"]["full"]
    assert after.evaluate(["joint_offsets"])["penalty"]["full"] == larger
    assert max(alone, larger) > 5 * min(alone, larger)  # another grid point (a factor 10 apart)


def test_rows_no_fold_holds_out_keep_the_full_fits_residual_as_their_held_out_error(diagnosed):
    """Three folds holding out rows 0-11 of 14: rows 12 and 13 are in no fold, and their held-out error is
    the full fit's training residual itself, where every other row's differs from it (its fold's fit).
    Seen failing on the label of rows in no fold, ``np.full(self.n_rows, -1)``, turned to ``0`` and to
    ``1``."""
    fitted = diagnosed[2]
    tests = np.array_split(np.arange(12), 3)
    folds = [(np.setdiff1d(np.arange(N), t), t) for t in tests]
    engine = FitEngine(fitted.parts, fitted.bases, folds, rank_tol=fitted.rank_tol, min_motion=fitted.min_motion)
    result = engine.evaluate(["frames", "joint_offsets"])
    train, held = result["train_residual"], result["heldout_residual"]
    np.testing.assert_array_equal(held[12:], train[12:])
    assert np.all(np.linalg.norm(held[:12] - train[:12], axis=1) > 1e-9)


@pytest.mark.parametrize("turn, curved", [(5e-4, False), (1e-3, True)])
def test_the_linear_model_takes_a_gauss_newton_step_where_it_misses_the_exact_residual_by_1e_4(
        diagnosed, turn, curved):
    """Nothing anchors the linear model (the nominal) and the measurement frame is turned by 0.5 or 1 mrad:
    the curvature judged is |r(d) - r0 - J d|^2 / |r0 + J d|^2 for the least-squares step d of every effect
    from the nominal (r0 the nominal residual, J the constant Jacobian), written out here with numpy, to
    1e-6; it is 6e-5 and 4.5e-4, and only the second is above the tolerance 1e-4, where the linear fits take
    the Gauss-Newton step on the exact kinematics (``second_order_at`` set). Seen failing on
    ``CURVATURE_TOLERANCE = 1e-4`` turned to ``1.0001`` and to ``-0.9999``."""
    fitted = diagnosed[2]
    direction = np.array([1.0, -2.0, 3.0]) / np.sqrt(14.0)
    rotation = Rotation.from_rotvec(turn * direction).as_matrix()
    parts = [dataclasses.replace(p, target=p.target @ rotation.T) for p in fitted.parts]
    engine = _engine(fitted, parts)
    engine.reset(anchor=())
    result = engine.evaluate(["frames", "joint_offsets"])
    cols = engine.columns(["frames", "joint_offsets"])
    k = cols.scale.size
    jacobian = np.concatenate([j.block(slice(None)).reshape(-1, k) for j in engine._jacobians(cols)])
    every = np.arange(N)

    def residual(phi):
        return np.concatenate([r.ravel() for r in engine.predict_residual(cols, phi, every)])

    r0 = residual(np.zeros(k))
    step = np.linalg.lstsq(jacobian, -r0, rcond=None)[0]
    expected = np.sum((residual(step) - r0 - jacobian @ step) ** 2) / np.sum((r0 + jacobian @ step) ** 2)
    assert engine.grams().curvature == pytest.approx(expected, rel=1e-6)
    assert bool(expected > 1e-4) is curved and (result["second_order_at"] is not None) is curved


def test_each_fold_of_the_exact_fit_is_one_gauss_newton_step_on_its_training_rows(diagnosed):
    """Frames + joint offsets fitted on the exact kinematics, three folds: each fold's parameters are the
    full fit's moved by one Gauss-Newton step on the fold's training rows, d = -(J_t^T J_t)^-1 J_t^T r_t (J the
    constant Jacobian, r the residual at the full fit), written out with numpy, to 1e-9 of the step. Fast on
    purpose (the slower diagnoses' tests cover it too, past a mutation run's time budget). Seen failing on
    the training gradient ``total_gradient - held_gradient`` turned to ``total_gradient * held_gradient``."""
    engine = _engine(diagnosed[2])
    model = ["frames", "joint_offsets"]
    result = engine.evaluate(model, exact=True)
    cols = engine.columns(model)
    k = cols.scale.size
    jacobian = np.concatenate([j.block(slice(None)).reshape(N, -1, k) for j in engine._jacobians(cols)], axis=1)
    residual = np.concatenate(engine.predict_residual(cols, result["phi"], np.arange(N)), axis=1)
    for (train, _), phi_k in zip(engine.folds, result["fold_steps"][0]):
        j_t = jacobian[train].reshape(-1, k)
        step = -np.linalg.solve(j_t.T @ j_t, j_t.T @ residual[train].ravel())
        np.testing.assert_allclose(phi_k, result["phi"] + step, rtol=0, atol=1e-9 * np.abs(step).max())
