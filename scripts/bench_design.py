#!/usr/bin/env python3
"""Planned against random against all poses, side by side: does ``plan-poses`` buy accuracy?

UR5 (``$TCR_REAL_DATA/ur5_tracker``): per seed, 300 grid poses are held out and the other 700 are the
candidates; 20 of them, drawn at random, are measured first; then batches of ``--batch`` poses are
added either by the Bayesian I-optimal design (the prior fitted to the poses so far, the candidates as the task:
what ``plan-poses MEAS.csv -k BATCH --candidates POOL.csv`` does) or at random. At 60 and 120 poses each set
trains ``predict --method diagnosis`` (the diagnosis' fitted model, the tracker frame fitted) and, beside it,
the design's own linearised Bayesian model; both are scored on the 300 held-out grid poses and on the 20
random poses of ``ur5_random_20.csv`` (mean 3D miss, mm). All 700 candidates and 200 random poses are the
yardsticks. The stop rule is checked too: from the 60 poses, the learning curve's predicted gain for 140
more against what the 200 give.

Simulated UR10 (always): a hidden truth written here on Pinocchio (joint-placement errors, joint stiffness
under gravity, a two-harmonic gear error on the first three joints), never the project's effect classes;
a first campaign of 60 poses planned from nothing against 200 random ones, scored on 500 held-out poses.

Usage::

    TCR_REAL_DATA=/path/to/real PYTHONPATH=src python scripts/bench_design.py --seeds 1 2
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from tcr_accuracy.diagnosis.bayes_design import (BayesianErrorModel, DesignColumns, design_columns,
                                                 design_vocabulary, fit_prior, learning_curve, plan_design,
                                                 task_variance, typical_prior)
from tcr_accuracy.frames.registration import register_tracker
from tcr_accuracy.io.measurements import read_measurements
from tcr_accuracy.model.kinematics import tcp_poses
from tcr_accuracy.model.robot import load_robot
from tcr_accuracy.prediction.composed import MeasuredErrorModel
from tcr_accuracy.prediction.error_prediction import predict_errors
from tcr_accuracy.prediction.methods import make_predictor


def rows(columns: DesignColumns, idx) -> DesignColumns:
    return DesignColumns(columns.g[idx], columns.owner, columns.effects)


def diagnosis_scores(robot, q, position, tests, seed=0):
    """Mean 3D held-out miss [mm] of ``predict --method diagnosis`` trained on (q, position), per test set."""
    model = MeasuredErrorModel(robot=robot, estimator=make_predictor("diagnosis", robot, random_state=seed),
                               fit_frame=True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model.fit(q, position)
        return [predict_errors(model, tq, measured=tp).held_out.mean * 1e3 for tq, tp in tests]


def bayes_scores(robot, columns, q, position, idx, tests):
    """Mean 3D held-out miss [mm] of the design's linearised Bayesian model, per test set (columns, q, position)."""
    registration = register_tracker(robot, q[idx], position[idx])
    errors = registration.to_base(position[idx]) - tcp_poses(robot, q[idx]).position
    prior = fit_prior(rows(columns, idx), errors)
    model = BayesianErrorModel(prior).fit(rows(columns, idx), errors)
    out, rms = [], []
    for test_columns, test_q, test_position in tests:
        miss = registration.to_base(test_position) - tcp_poses(robot, test_q).position - model.predict(test_columns)
        out.append(float(np.linalg.norm(miss, axis=1).mean() * 1e3))
        rms.append(float(np.sqrt(np.mean(np.sum(miss**2, axis=1))) * 1e3))
    return out, prior, errors, rms


def planned_sequence(robot, columns, q, position, first, pool, total, batch):
    """first + batches chosen by the I-optimal design (prior refitted after each batch) up to ``total``."""
    measured = list(first)
    while len(measured) < total:
        idx = np.array(measured)
        registration = register_tracker(robot, q[idx], position[idx])
        errors = registration.to_base(position[idx]) - tcp_poses(robot, q[idx]).position
        prior = fit_prior(rows(columns, idx), errors)
        taken = set(measured)
        candidates = np.array([i for i in pool if i not in taken])
        design = plan_design(rows(columns, idx), rows(columns, candidates), rows(columns, pool), prior,
                             min(batch, total - len(measured)))
        measured += list(candidates[design.picked])
    return np.array(measured)


def ur5(real: Path, seeds, batch: int) -> None:
    robot = load_robot("ur5", None)
    grid = read_measurements(real / "ur5_tracker" / "ur5_grid_1000.csv", robot)
    rand = read_measurements(real / "ur5_tracker" / "ur5_random_20.csv", robot)
    effects = design_vocabulary()
    columns = design_columns(robot, grid.q, effects)
    rand_columns = design_columns(robot, rand.q, effects)
    print("UR5: mean 3D held-out miss [mm]; diagnosis = predict --method diagnosis, bayes = the design's own "
          "linearised model")
    print(f"{'seed':>4} {'poses':>5} {'how':>8} {'diag grid300':>12} {'diag rand20':>11} {'bayes grid300':>13} "
          f"{'bayes rand20':>12} {'CPU s':>6}")
    ratios = {60: [], 120: []}
    rand20 = {60: []}
    curve_checks = []
    for seed in seeds:
        permutation = np.random.default_rng(seed).permutation(len(grid.q))
        test, pool = permutation[:300], permutation[300:]
        order = np.random.default_rng(seed + 100).permutation(pool)
        first = order[:20]
        tests_d = [(grid.q[test], grid.position[test]), (rand.q, rand.position)]
        started = time.process_time()
        planned = planned_sequence(robot, columns, grid.q, grid.position, first, pool, 120, batch)
        plan_cpu = time.process_time() - started
        rows_out = {}
        for how, sequence in (("planned", planned), ("random", order)):
            for n in (60, 120) if how == "planned" else (60, 120, 200):
                idx = sequence[:n]
                t0 = time.process_time()
                d = diagnosis_scores(robot, grid.q[idx], grid.position[idx], tests_d)
                b, prior, errors, b_rms = bayes_scores(robot, columns, grid.q, grid.position, idx,
                                                [(rows(columns, test), grid.q[test], grid.position[test]),
                                                 (rand_columns, rand.q, rand.position)])
                rows_out[how, n] = (d, b, b_rms)
                print(f"{seed:>4} {n:>5} {how:>8} {d[0]:12.4f} {d[1]:11.4f} {b[0]:13.4f} {b[1]:12.4f} "
                      f"{time.process_time() - t0 + (plan_cpu if how == 'planned' and n == 60 else 0):6.1f}",
                      flush=True)
                if how == "random" and n == 60:  # the stop rule: predicted at 60 for the 140 random poses to 200
                    curve = learning_curve(rows(columns, idx), errors, prior, np.random.default_rng(seed))
                    before = task_variance(rows(columns, idx), rows(columns, test), prior)
                    after = task_variance(rows(columns, sequence[:200]), rows(columns, test), prior)
                    curve_checks.append((seed, curve.gain(before, after), curve.predict(before),
                                         curve.predict(after)))
        for n in (60, 120):
            ratios[n].append((rows_out["planned", n][0][0] / rows_out["random", n][0][0],
                              rows_out["planned", n][1][0] / rows_out["random", n][1][0]))
        rand20[60].append(rows_out["planned", 60][0][1])
        for seed_, gain, now, then in curve_checks[-1:]:
            actual = rows_out["random", 60][2][0] - rows_out["random", 200][2][0]
            diagnosis = rows_out["random", 60][0][0] - rows_out["random", 200][0][0]
            print(f"     stop rule at 60 random poses for 140 more (the design's model, held-out RMS of the 3D miss): "
                  f"predicted {now[0] * 1e3:.4f} -> {then[0] * 1e3:.4f} mm, gain {gain[0] * 1e3:.4f} mm "
                  f"[{gain[1] * 1e3:.4f}, {gain[2] * 1e3:.4f}]; measured on the 300 held-out grid poses "
                  f"{rows_out['random', 60][2][0]:.4f} -> {rows_out['random', 200][2][0]:.4f} mm, gain {actual:.4f} mm "
                  f"(predicted/measured {gain[0] * 1e3 / actual:.2f}); the diagnosis' mean miss gains {diagnosis:.4f} mm")
    d_all = diagnosis_scores(robot, grid.q[pool], grid.position[pool], tests_d)
    print(f"all 700 candidates (last seed): diagnosis {d_all[0]:.4f} / {d_all[1]:.4f} mm")
    for n in (60, 120):
        r = np.array(ratios[n])
        print(f"planned/random at {n} poses, held-out grid, mean over seeds: diagnosis {r[:, 0].mean():.3f}, "
              f"bayes {r[:, 1].mean():.3f}")
    print(f"60 planned poses on the 20 random poses (diagnosis), mean over seeds: {np.mean(rand20[60]):.4f} mm")


def ur10(seeds) -> None:
    """A first campaign from nothing against random poses, on a hidden truth written on Pinocchio."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from design_truth import hidden_ur10_errors  # the test's own truth, shared with the bench

    robot = load_robot("ur10", None)
    from tcr_accuracy.analysis.reachable import PoseFilter, draw_poses

    effects = design_vocabulary()
    print("UR10, simulated (joint placements, gravity compliance, gear errors written on Pinocchio); "
          "diagnosis scored on 500 held-out poses, mean 3D miss [mm]")
    for seed in seeds:
        rng = np.random.default_rng(seed)
        pose_filter = PoseFilter.for_robot(robot)
        candidates = draw_poses(pose_filter, 3000, rng).q
        held_out = draw_poses(pose_filter, 500, rng).q
        truth = hidden_ur10_errors(robot, rng)
        cand_columns = design_columns(robot, candidates, effects)
        design = plan_design(None, cand_columns, cand_columns, typical_prior(cand_columns.effects), 60)
        planned = candidates[design.picked]
        randoms = candidates[rng.permutation(len(candidates))[:200]]
        tests = [(held_out, truth(held_out, rng))]
        p = diagnosis_scores(robot, planned, truth(planned, rng), tests)[0]
        r = diagnosis_scores(robot, randoms, truth(randoms, rng), tests)[0]
        r60 = diagnosis_scores(robot, randoms[:60], truth(randoms[:60], rng), tests)[0]
        print(f"seed {seed}: 60 planned {p:.4f} mm, 60 random {r60:.4f} mm, 200 random {r:.4f} mm; "
              f"planned 60 / random 200 = {p / r:.3f}", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--batch", type=int, default=20, help="poses planned per batch (default 20)")
    parser.add_argument("--skip-ur5", action="store_true")
    parser.add_argument("--skip-ur10", action="store_true")
    args = parser.parse_args()
    real = os.environ.get("TCR_REAL_DATA")
    if not args.skip_ur5:
        if real is None:
            print("UR5: skipped (set TCR_REAL_DATA to the folder holding ur5_tracker/)")
        else:
            ur5(Path(real), args.seeds, args.batch)
    if not args.skip_ur10:
        ur10(args.seeds)


if __name__ == "__main__":
    main()
