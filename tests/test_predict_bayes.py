"""``predict --method bayes`` (``prediction/bayesian.py`` on ``diagnosis/bayes_design.py``'s posterior), each
figure against an independent calculation: the posterior mean, covariance, predictive standard deviation and
leave-one-out residuals against the textbook closed forms written here on raw numpy (inverses, refits without
the pose); the predictive interval's coverage, and a hidden gravity sag recovered, on robots written on
Pinocchio in the tests (tests/design_truth.py, tests/hidden_robot.py), never with the effect classes."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import warnings

import numpy as np
import pytest
from scipy import stats

from tcr_accuracy.analysis.reachable import PoseFilter, draw_poses
from tcr_accuracy.diagnosis.bayes_design import FLAT_PRECISION, BayesianErrorModel, DesignColumns, EffectPrior
from tcr_accuracy.model.kinematics import tcp_poses
from tcr_accuracy.model.robot import load_robot
from tcr_accuracy.prediction.bayesian import BayesianCalibration
from tcr_accuracy.prediction.composed import MeasuredErrorModel
from tcr_accuracy.prediction.error_prediction import predict_errors
from tcr_accuracy.prediction.methods import make_predictor

from conftest import REPO
from design_truth import NOISE_M, hidden_ur10_errors
from hidden_robot import HiddenRobot

OWNER = np.array(["geometry"] * 3 + ["compliance"] * 4 + ["transmission"] * 5)
TAU = {"compliance": 2.0, "transmission": 0.5}


def _small_model(rng, n=15):
    g = rng.normal(size=(n, 3, len(OWNER))) * 1e-4
    theta = rng.normal(size=len(OWNER))
    errors = g @ theta + rng.normal(0, 3e-5, (n, 3))
    return DesignColumns(g, OWNER, ["geometry", "compliance", "transmission"]), errors


def test_posterior_mean_covariance_and_predictive_std_are_the_closed_form():
    """Bishop 3.53-3.59 with a per-column prior precision: Sigma = (G^T G / s^2 + diag(lambda))^-1,
    mean = Sigma G^T y / s^2, predictive variance g Sigma g^T + s^2 -- written here with np.linalg.inv."""
    rng = np.random.default_rng(3)
    columns, errors = _small_model(rng)
    noise = 3e-5
    model = BayesianErrorModel(EffectPrior(dict(TAU), noise)).fit(columns, errors)
    precision = np.array([FLAT_PRECISION] * 3 + [1 / 2.0**2] * 4 + [1 / 0.5**2] * 5)
    flat = columns.g.reshape(-1, len(OWNER))
    sigma = np.linalg.inv(flat.T @ flat / noise**2 + np.diag(precision))
    mean = sigma @ flat.T @ errors.ravel() / noise**2
    np.testing.assert_allclose(model.theta_, mean, rtol=1e-7, atol=1e-9 * np.abs(mean).max())
    np.testing.assert_allclose(model.covariance_, sigma, rtol=1e-6, atol=1e-9 * np.abs(sigma).max())
    query, _ = _small_model(rng, n=7)
    predicted, std = model.predict(query, return_std=True)
    g = query.g.reshape(-1, len(OWNER))
    np.testing.assert_allclose(predicted.ravel(), g @ mean, rtol=1e-7, atol=1e-12)
    np.testing.assert_allclose(std.ravel() ** 2, np.einsum("rp,pq,rq->r", g, sigma, g) + noise**2, rtol=1e-7)


def test_leave_one_out_residuals_are_those_of_refits_without_each_pose():
    rng = np.random.default_rng(4)
    columns, errors = _small_model(rng)
    prior = EffectPrior(dict(TAU), 3e-5)
    loo = BayesianErrorModel(prior).fit(columns, errors).leave_one_out(columns, errors)
    precision = np.array([FLAT_PRECISION] * 3 + [1 / 2.0**2] * 4 + [1 / 0.5**2] * 5)
    for i in range(len(errors)):
        keep = np.arange(len(errors)) != i
        flat = columns.g[keep].reshape(-1, len(OWNER))
        theta = np.linalg.solve(flat.T @ flat / 3e-5**2 + np.diag(precision), flat.T @ errors[keep].ravel() / 3e-5**2)
        np.testing.assert_allclose(loo[i], errors[i] - columns.g[i] @ theta, rtol=1e-6, atol=1e-12)


def test_predictive_interval_covers_95_percent_of_held_out_measurements_on_a_hidden_ur10():
    """A UR10 written on Pinocchio (joint placements, gravity sag, gear errors of two harmonics, a tracker with
    0.02 mm noise, its frame unknown): trained on 120 poses, the 95 % predictive interval of ``bayes`` holds
    about 95 % of the 3 x 400 held-out axis misses (the binomial 99.9 % band of a calibrated interval, widened
    by 0.02 for the frame fit and the linearisation), and the miss is near the tracker's own noise."""
    robot = load_robot("ur10", None)
    rng = np.random.default_rng(21)
    measure = hidden_ur10_errors(robot, rng)
    pose_filter = PoseFilter.for_robot(robot)
    q_train, q_test = draw_poses(pose_filter, 120, rng).q, draw_poses(pose_filter, 400, rng).q
    model = MeasuredErrorModel(robot=robot, estimator=make_predictor("bayes", robot), fit_frame=True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model.fit(q_train, measure(q_train, rng))
    result = predict_errors(model, q_test, measured=measure(q_test, rng))
    assert result.uncertainty == "Bayesian posterior predictive standard deviation"
    z = stats.norm.ppf(0.975)
    covered = float(np.mean(np.abs(result.held_out.residual) <= z * result.std))
    n = result.std.size
    low, high = stats.binom.ppf([0.0005, 0.9995], n, 0.95) / n
    assert low - 0.02 <= covered <= high + 0.02, (covered, low, high)
    rms_axis = np.sqrt(np.mean(result.held_out.residual**2))
    assert rms_axis < 1.5 * NOISE_M, rms_axis  # what 120 poses leave of mm-sized errors: near the tracker's 0.02 mm
    own = model.estimator_.loo_rmse_  # the predictor's own statement of its accuracy, per axis
    assert np.all((own > 0.6 * rms_axis) & (own < 1.6 * rms_axis)), (own, rms_axis)


def test_a_hidden_gravity_sag_is_recovered_and_its_effect_found_large():
    """Only a joint stiffness sag (delta_q = -C g(q), g from pin.computeGeneralizedGravity, C 3-8 urad/Nm):
    the fitted prior finds ``compliance`` large (tau > 1 typical size) and every other non-geometric effect
    small (< 0.1), and the posterior mean predicts the sag's TCP displacement at 300 held-out poses within 6 %
    RMS (against Pinocchio's), where the geometry alone leaves more than half of it."""
    robot = load_robot("ur10", None)
    rng = np.random.default_rng(5)
    hidden = HiddenRobot(robot)
    compliance = rng.uniform(3e-6, 8e-6, robot.n_joints)

    def sag_error(q):
        real = q - compliance * hidden.holding_torque(q, np.zeros(len(q)))
        return hidden.positions(real, [robot.tool_frame])[robot.tool_frame] - tcp_poses(robot, q).position

    pose_filter = PoseFilter.for_robot(robot)
    q_train, q_test = draw_poses(pose_filter, 100, rng).q, draw_poses(pose_filter, 300, rng).q
    truth_test = sag_error(q_test)
    errors = sag_error(q_train) + rng.normal(0, NOISE_M, (100, 3))
    estimator = BayesianCalibration(robot=robot).fit(q_train, errors)
    taus = estimator.prior_.tau
    assert taus["compliance"] > 1.0 and all(v < 0.1 for k, v in taus.items() if k != "compliance"), taus

    def rms(a):
        return np.sqrt(np.mean(np.sum(a**2, axis=1)))

    size = rms(truth_test)
    geometry = BayesianCalibration(robot=robot, effects=["frames", "joint_offsets", "geometry"]).fit(q_train, errors)
    assert size > 0.2e-3 and rms(estimator.predict(q_test) - truth_test) < 0.06 * size, size
    assert rms(geometry.predict(q_test) - truth_test) > 0.5 * size


def test_cli_predict_and_compensate_offer_bayes_with_its_standard_deviation(tmp_path):
    """``--method bayes`` in both commands; predict's JSON carries the std in mm and its kind."""
    robot = load_robot("ur10", None)
    rng = np.random.default_rng(8)
    measure = hidden_ur10_errors(robot, rng)
    pose_filter = PoseFilter.for_robot(robot)
    q = draw_poses(pose_filter, 70, rng).q
    positions = measure(q, rng)
    names = [f"{n}_deg" for n in robot.joint_names]

    def write(path, q_rows, p_rows=None):
        header = names + (["x_mm", "y_mm", "z_mm"] if p_rows is not None else [])
        body = np.degrees(q_rows) if p_rows is None else np.hstack([np.degrees(q_rows), p_rows * 1e3])
        path.write_text(",".join(header) + "\n" + "\n".join(",".join(f"{v:.10g}" for v in r) for r in body) + "\n")

    write(tmp_path / "train.csv", q[:60], positions[:60])
    write(tmp_path / "query.csv", q[60:], positions[60:])
    env = {**os.environ, "PYTHONPATH": str(REPO / "src")}
    run = subprocess.run([sys.executable, "-m", "tcr_accuracy", "predict", "--robot", "ur10", "--train", "train.csv",
                          "--query", "query.csv", "--method", "bayes", "--json", "out.json"], capture_output=True,
                         text=True, cwd=tmp_path, timeout=600, env=env)
    assert run.returncode == 0, run.stderr
    payload = json.loads((tmp_path / "out.json").read_text())
    assert payload["method"] == "bayes" and payload["uncertainty"].startswith("Bayesian posterior predictive")
    std = np.array(payload["predicted_std_mm"])
    assert std.shape == (10, 3) and np.all(std >= NOISE_M * 1e3 * 0.5)  # mm at the edge: at least the noise
    run = subprocess.run([sys.executable, "-m", "tcr_accuracy", "compensate", "--robot", "ur10", "--train",
                          "train.csv", "--targets", "query.csv", "--method", "bayes", "--json", "comp.json"],
                         capture_output=True, text=True, cwd=tmp_path, timeout=600, env=env)
    assert run.returncode == 0, run.stderr
    comp = json.loads((tmp_path / "comp.json").read_text())
    assert comp["method"] == "bayes" and comp["n_converged"] == 10


@pytest.mark.parametrize("bad", [{"tracker_noise": -1.0}, {"effects": ["no_such_effect"]}, {"effects": ["drift"]}])
def test_bad_hyper_parameters_are_one_input_error(bad):
    from tcr_accuracy.exceptions import InputError

    robot = load_robot("ur10", None)
    q = np.zeros((10, 6)) + np.linspace(0, 1, 10)[:, None]
    with pytest.raises(InputError):
        BayesianCalibration(robot=robot, **bad).fit(q, np.zeros((10, 3)))
