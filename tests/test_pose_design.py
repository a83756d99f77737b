"""Poses chosen for the prediction (``diagnosis/bayes_design.py``, ``plan-poses``): each figure against an
independent calculation -- the greedy designs against a brute-force search written here with plain
inverses, the fitted prior against the scales the data were drawn with, the learning curve against the
closed-form expected error of least squares, the campaign order against the correlations computed
here, and a first campaign from nothing against random poses on a hidden UR10 written on Pinocchio
(tests/design_truth.py), never with the effect classes the diagnosis fits."""

from __future__ import annotations

import os
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from tcr_accuracy.analysis.reachable import PoseFilter, draw_poses
from tcr_accuracy.diagnosis.bayes_design import (DesignColumns, EffectPrior, campaign_order, design_columns,
                                                 design_vocabulary, fit_prior, learning_curve, plan_design,
                                                 stop_advice, typical_prior)
from tcr_accuracy.model.robot import load_robot
from tcr_accuracy.prediction.composed import MeasuredErrorModel
from tcr_accuracy.prediction.error_prediction import predict_errors
from tcr_accuracy.prediction.methods import make_predictor

from conftest import REPO
from design_truth import hidden_ur10_errors

OWNER = np.array(["frames"] * 3 + ["compliance"] * 4 + ["transmission"] * 5)


def _columns(rng, n, scale=1e-4):
    return DesignColumns(rng.normal(size=(n, 3, len(OWNER))) * scale, OWNER, ["frames", "compliance", "transmission"])


@pytest.mark.parametrize("criterion", ["I", "G", "D"])
def test_greedy_design_picks_what_a_brute_force_search_picks(criterion):
    """Every step's pick is the candidate a search that inverts the information anew for each one would
    take: the rank-3 updates of H, Q and V lose nothing."""
    rng = np.random.default_rng(4)
    measured, candidates, task = _columns(rng, 5), _columns(rng, 40), _columns(rng, 30)
    prior = EffectPrior({"compliance": 2.0, "transmission": 0.5}, 3e-5)
    design = plan_design(measured, candidates, task, prior, 6, criterion=criterion)
    beta = 1 / prior.noise_m**2
    precision = np.array([1e-6] * 3 + [1 / 4.0] * 4 + [1 / 0.25] * 5)
    flat = measured.g.reshape(-1, 12)
    information = beta * flat.T @ flat + np.diag(precision)
    weight = sum(g.T @ g for g in task.g) / len(task.g)
    picked = []
    for _ in range(6):
        covariance = np.linalg.inv(information)
        variances = [np.trace(g @ covariance @ g.T) for g in task.g]
        worst = np.argsort(variances)[-10:]
        scores = {}
        for c in set(range(40)) - set(picked):
            after = np.linalg.inv(information + beta * candidates.g[c].T @ candidates.g[c])
            scores[c] = {"I": np.trace(weight @ (covariance - after)),
                         "D": np.linalg.slogdet(information + beta * candidates.g[c].T @ candidates.g[c])[1],
                         "G": np.mean([np.trace(task.g[t] @ (covariance - after) @ task.g[t].T) for t in worst])
                         }[criterion]
        best = max(scores, key=scores.get)
        picked.append(best)
        information = information + beta * candidates.g[best].T @ candidates.g[best]
    assert list(design.picked) == picked
    final = np.linalg.inv(information)
    assert design.task_std_after_m == pytest.approx(np.sqrt(np.mean([np.trace(g @ final @ g.T) for g in task.g])),
                                                    rel=1e-6)


def test_fitted_prior_finds_the_scales_the_errors_were_drawn_with():
    """Errors drawn as G theta + noise, theta of each effect normal with a known scale: type-II maximum
    likelihood finds the scales (a large one and a small one told apart) and the noise."""
    rng = np.random.default_rng(0)
    owner = np.array(["frames"] * 6 + ["compliance"] * 40 + ["transmission"] * 40)
    g = rng.normal(size=(600, 3, len(owner))) * 1e-5
    truth = {"compliance": 3.0, "transmission": 0.3}
    theta = np.concatenate([rng.normal(0, 100.0, 6), rng.normal(0, truth["compliance"], 40),
                            rng.normal(0, truth["transmission"], 40)])
    errors = g @ theta + rng.normal(0, 2e-5, (600, 3))
    prior = fit_prior(DesignColumns(g, owner, ["frames", "compliance", "transmission"]), errors)
    assert prior.noise_m == pytest.approx(2e-5, rel=0.05)
    # 40 draws of each scale: the sample standard deviation's spread is about 1/sqrt(80), 11 %
    for effect, tau in truth.items():
        assert prior.tau[effect] == pytest.approx(tau, rel=0.3)


def test_stop_rule_predicts_the_error_that_measuring_the_planned_poses_gives():
    """A linear truth the vocabulary expresses (random columns, each effect's parameters at a known scale):
    after 40 poses, the subsamples' calibration is about (1, 1) and the predicted held-out RMS error over
    the task once the 60 planned poses are measured is what measuring them and refitting gives, scored
    on 4000 task poses against the truth (a simulation written here); the gain lands within 30 %."""
    rng = np.random.default_rng(1)
    owner = np.array(["frames"] * 6 + ["compliance"] * 30 + ["transmission"] * 30)
    effects = ["frames", "compliance", "transmission"]

    def columns(n):
        return DesignColumns(rng.normal(size=(n, 3, len(owner))) * 1e-5, owner, effects)

    theta = np.concatenate([rng.normal(0, 50.0, 6), rng.normal(0, 2.0, 30), rng.normal(0, 0.5, 30)])
    sigma = 2e-5
    measured, candidates, task = columns(40), columns(400), columns(4000)
    errors = measured.g @ theta + rng.normal(0, sigma, (40, 3))
    prior = fit_prior(measured, errors)
    curve = learning_curve(measured, errors, prior, np.random.default_rng(2), repeats=20)
    # a right model: the subsamples' misses show about its noise and its posterior variance
    assert 0.6 < curve.noise_weight < 1.6 and 0.3 < curve.variance_weight < 3.0
    design = plan_design(measured, candidates, task, prior, 60)
    advice = stop_advice(curve, design, min_gain_m=None)
    new = DesignColumns(candidates.g[design.picked], owner, effects)

    def task_rms(columns_fit, errors_fit):
        from tcr_accuracy.diagnosis.bayes_design import BayesianErrorModel

        model = BayesianErrorModel(prior).fit(columns_fit, errors_fit)
        miss = task.g @ theta + rng.normal(0, sigma, (4000, 3)) - model.predict(task)
        return float(np.sqrt(np.mean(np.sum(miss**2, axis=1))))

    now = task_rms(measured, errors)
    both = DesignColumns(np.concatenate([measured.g, new.g]), owner, effects)
    then = task_rms(both, np.concatenate([errors, new.g @ theta + rng.normal(0, sigma, (60, 3))]))
    assert advice.now_m[0] == pytest.approx(now, rel=0.3)
    assert advice.then_m[0] == pytest.approx(then, rel=0.3)
    assert advice.gain_m[0] == pytest.approx(now - then, rel=0.3)
    assert advice.gain_m[1] <= advice.gain_m[0] <= advice.gain_m[2]
    assert stop_advice(curve, design, min_gain_m=1.0).stop  # a limit of 1 m: nothing is worth it
    assert not stop_advice(curve, design, min_gain_m=1e-9).stop
    assert "no limit given" in advice.reason


def test_campaign_order_repeats_a_reference_and_no_joint_follows_the_order():
    rng = np.random.default_rng(3)
    q = rng.uniform(-2, 2, size=(40, 6))
    q_sorted = q[np.argsort(q[:, 1])]  # given sorted in a joint: the order must undo it
    rows, reference, largest_r = campaign_order(q_sorted, 4, np.random.default_rng(0))
    assert len(rows) == 43 and sorted(set(rows)) == list(range(40))
    places = np.flatnonzero(rows == reference)
    assert list(places[[0, -1]]) == [0, 42] and len(places) == 4
    assert np.all(np.abs(np.diff(places) - 14) <= 1)  # evenly between
    once = [r for r in rows if r != reference]
    x = q_sorted[once]
    place = np.arange(len(once))
    r = [abs(np.corrcoef(place, x[:, j])[0, 1]) for j in range(6)]
    assert max(r) == pytest.approx(largest_r, abs=1e-9) and largest_r < 0.2


def _diagnosis_heldout(robot, q, measured, q_test, measured_test):
    model = MeasuredErrorModel(robot=robot, estimator=make_predictor("diagnosis", robot, random_state=0),
                               fit_frame=True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model.fit(q, measured)
        return predict_errors(model, q_test, measured=measured_test).held_out.mean


def test_first_campaign_from_nothing_reaches_what_200_random_poses_reach_on_a_hidden_ur10():
    """Issue 41: 60 poses planned with no measurement (the vocabulary at typical sizes, I-optimal over the
    robot's joint ranges) predict a hidden UR10 -- joint placements, gravity sag, gear errors, written on
    Pinocchio -- within 1.3 x the held-out error of 200 random poses, and better than 60 random ones."""
    robot = load_robot("ur10", None)
    rng = np.random.default_rng(11)
    measure = hidden_ur10_errors(robot, rng)
    pose_filter = PoseFilter.for_robot(robot)
    candidates = draw_poses(pose_filter, 2000, rng).q
    held_out = draw_poses(pose_filter, 300, rng).q
    columns = design_columns(robot, candidates, design_vocabulary())
    design = plan_design(None, columns, columns, typical_prior(columns.effects), 60)
    planned = candidates[design.picked]
    randoms = candidates[rng.permutation(len(candidates))[:200]]
    truth_test = measure(held_out, rng)
    planned_error = _diagnosis_heldout(robot, planned, measure(planned, rng), held_out, truth_test)
    random_200 = _diagnosis_heldout(robot, randoms, measure(randoms, rng), held_out, truth_test)
    random_60 = _diagnosis_heldout(robot, randoms[:60], measure(randoms[:60], rng), held_out, truth_test)
    assert planned_error <= 1.3 * random_200, (planned_error, random_200)
    assert planned_error < random_60, (planned_error, random_60)


def _run(args, tmp_path):
    env = {**os.environ, "PYTHONPATH": str(REPO / "src")}
    return subprocess.run([sys.executable, "-m", "tcr_accuracy", *map(str, args)], capture_output=True, text=True,
                          cwd=tmp_path, timeout=600, env=env)


def test_cli_first_campaign_writes_the_poses_in_order_with_references_and_is_quiet(tmp_path):
    out = tmp_path / "first.csv"
    run = _run(["plan-poses", "--robot", "ur10", "-k", "40", "--n-candidates", "600", "--out", out, "--quiet",
                "--box", "-900", "900", "-900", "900", "0", "1200"], tmp_path)
    assert run.returncode == 0, run.stderr
    assert run.stderr == ""
    assert "I-optimal" in run.stdout and "every effect at its typical size" in run.stdout
    assert f"measure the 40 poses of {out}" in run.stdout
    lines = [ln for ln in out.read_text().splitlines() if not ln.startswith("#")]
    ids = [ln.split(",")[0] for ln in lines[1:]]
    assert len(ids) == 40 + 2 and ids[0] == ids[-1] == "R" and ids.count("R") == 3
    robot = load_robot("ur10", None)
    q = np.array([[float(v) for v in ln.split(",")[1:]] for ln in lines[1:]]) / robot.display_scale
    from tcr_accuracy.model.kinematics import tcp_poses

    tcp = tcp_poses(robot, q).position * 1e3
    assert np.all(tcp[:, 2] >= -1e-6) and np.all(np.abs(tcp[:, :2]) <= 900 + 1e-6)  # in the box


def test_cli_with_measurements_prints_the_learning_curve_and_the_stop_rule(tmp_path):
    robot = load_robot("ur10", None)
    rng = np.random.default_rng(5)
    measure = hidden_ur10_errors(robot, rng)
    q = draw_poses(PoseFilter.for_robot(robot), 60, rng).q
    position = measure(q, rng)
    header = [f"{n}_deg" for n in robot.joint_names] + ["x_mm", "y_mm", "z_mm"]
    rows = np.hstack([np.degrees(q), position * 1e3])
    csv = tmp_path / "m.csv"
    csv.write_text(",".join(header) + "\n" + "\n".join(",".join(f"{v:.10g}" for v in r) for r in rows) + "\n")
    go_on = _run(["plan-poses", csv, "--robot", "ur10", "-k", "30", "--n-candidates", "500", "--out",
                  tmp_path / "n.csv", "--stop-gain-mm", "0.000001", "--quiet", "--json", tmp_path / "p.json"], tmp_path)
    assert go_on.returncode == 0, go_on.stderr
    assert "learning curve" in go_on.stdout and "prior fitted to the 60 measured poses" in go_on.stdout
    import json

    plan = json.loads((tmp_path / "p.json").read_text())
    gain = plan["stop"]["gain_mm"]
    assert gain[1] <= gain[0] <= gain[2]  # the interval holds its estimate
    stop = _run(["plan-poses", csv, "--robot", "ur10", "-k", "30", "--n-candidates", "500", "--out",
                 tmp_path / "s.csv", "--stop-gain-mm", "100", "--quiet"], tmp_path)
    assert stop.returncode == 0 and "stop:" in stop.stdout and "if you go on:" in stop.stdout
    refused = _run(["plan-poses", "--robot", "ur10", "-k", "3", "--out", tmp_path / "x.csv", "--stop-gain-mm",
                    "0.01"], tmp_path)
    assert refused.returncode == 2 and len(refused.stderr.strip().splitlines()) == 1
    assert "--stop-gain-mm" in refused.stderr and not (tmp_path / "x.csv").exists()


UR5 = Path(os.environ.get("TCR_REAL_DATA", REPO.parent / "shared" / "real")) / "ur5_tracker"


@pytest.mark.skipif(not UR5.is_dir(), reason=f"real data not here: {UR5} (set TCR_REAL_DATA)")
def test_stop_rule_on_the_ur5_predicts_what_measuring_140_more_poses_gives():
    """Issue 41: from 60 random grid poses of the UR5 (300 others held out), the stop rule's predicted drop
    of the held-out RMS error for 140 more poses is, over seeds 1 and 2, within 30 % of what measuring
    them and refitting gives on the held-out poses (the model's own expectation against the measured
    tracker points)."""
    from tcr_accuracy.diagnosis.bayes_design import BayesianErrorModel, task_variance
    from tcr_accuracy.frames.registration import register_tracker
    from tcr_accuracy.io.measurements import read_measurements
    from tcr_accuracy.model.kinematics import tcp_poses

    robot = load_robot("ur5", None)
    grid = read_measurements(UR5 / "ur5_grid_1000.csv", robot)
    columns = design_columns(robot, grid.q, design_vocabulary())

    def rows(idx):
        return DesignColumns(columns.g[idx], columns.owner, columns.effects)

    ratios = []
    for seed in (1, 2):
        permutation = np.random.default_rng(seed).permutation(len(grid.q))
        test, pool = permutation[:300], permutation[300:]
        order = np.random.default_rng(seed + 100).permutation(pool)
        measured = {}
        for n in (60, 200):
            idx = order[:n]
            registration = register_tracker(robot, grid.q[idx], grid.position[idx])
            errors = registration.to_base(grid.position[idx]) - tcp_poses(robot, grid.q[idx]).position
            prior = fit_prior(rows(idx), errors)
            model = BayesianErrorModel(prior).fit(rows(idx), errors)
            miss = (registration.to_base(grid.position[test]) - tcp_poses(robot, grid.q[test]).position
                    - model.predict(rows(test)))
            measured[n] = np.sqrt(np.mean(np.sum(miss**2, axis=1)))
            if n == 60:
                curve = learning_curve(rows(idx), errors, prior, np.random.default_rng(seed))
                predicted = curve.gain(task_variance(rows(idx), rows(test), prior),
                                       task_variance(rows(order[:200]), rows(test), prior))
        ratios.append(predicted[0] / (measured[60] - measured[200]))
    assert np.mean(ratios) == pytest.approx(1.0, abs=0.3), ratios
