#!/usr/bin/env python3
"""Planned against random against all poses, side by side: does ``plan-poses`` buy accuracy?

UR5 (``$TCR_REAL_DATA/ur5_tracker``): per seed, 300 grid poses are held out and the other 700 are the
candidates; 20 of them, drawn at random, are measured first; then batches of ``--batch`` poses are
added either by the Bayesian I-optimal design (the prior fitted to the poses so far, the candidates as the task:
what ``plan-poses MEAS.csv -k BATCH --candidates POOL.csv`` does) or at random. At 60 and 120 poses each set
trains ``predict --method diagnosis`` (the diagnosis' fitted model, the tracker frame fitted) and, beside it,
``predict --method bayes`` (the design's own linearised Bayesian model, :class:`BayesianCalibration`); both are
scored on the 300 held-out grid poses and on the 20 random poses of ``ur5_random_20.csv`` (mean 3D miss, mm;
for bayes also the share of axis misses inside its 95 % predictive interval). All 700 candidates and 200 random
poses are the yardsticks. The stop rule is checked too: from the 60 poses, the learning curve's predicted gain
for 140 more against what the 200 give (with the design's own model, and with ``predict --method bayes``).

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


def method_scores(method, robot, q, position, tests, seed=0):
    """``predict --method METHOD`` trained on (q, position), per test set (q, position): (mean 3D held-out miss
    [mm], RMS 3D miss [mm], share of axis misses inside the 95 % predictive interval or nan)."""
    model = MeasuredErrorModel(robot=robot, estimator=make_predictor(method, robot, random_state=seed),
                               fit_frame=True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model.fit(q, position)
        out = []
        for tq, tp in tests:
            held = predict_errors(model, tq, measured=tp).held_out
            inside = np.nan if held.std is None else float(np.mean(np.abs(held.residual) <= 1.96 * held.std))
            out.append((held.mean * 1e3, held.rms * 1e3, inside))
        return out


def diagnosis_scores(robot, q, position, tests, seed=0):
    """Mean 3D held-out miss [mm] of ``predict --method diagnosis`` trained on (q, position), per test set."""
    return [mean for mean, _, _ in method_scores("diagnosis", robot, q, position, tests, seed)]


def design_prior(robot, columns, q, position, idx):
    """The design's prior fitted to the poses idx (tracker frame registered first) and their base-frame errors."""
    registration = register_tracker(robot, q[idx], position[idx])
    errors = registration.to_base(position[idx]) - tcp_poses(robot, q[idx]).position
    return fit_prior(rows(columns, idx), errors), errors


def design_model_rms(robot, columns, q, position, idx, test):
    """RMS 3D miss [mm] at the poses ``test`` of the design's own model (:class:`BayesianErrorModel` on the nominal
    robot's columns, what ``plan-poses``' stop rule predicts for) fitted to the poses ``idx``."""
    prior, errors = design_prior(robot, columns, q, position, idx)
    registration = register_tracker(robot, q[idx], position[idx])
    model = BayesianErrorModel(prior).fit(rows(columns, idx), errors)
    miss = registration.to_base(position[test]) - tcp_poses(robot, q[test]).position - model.predict(rows(columns, test))
    return float(np.sqrt(np.mean(np.sum(miss**2, axis=1))) * 1e3)


def planned_sequence(robot, columns, q, position, first, pool, total, batch):
    """first + batches chosen by the I-optimal design (prior refitted after each batch) up to ``total``."""
    measured = list(first)
    while len(measured) < total:
        idx = np.array(measured)
        prior, _ = design_prior(robot, columns, q, position, idx)
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
    print("UR5: mean 3D held-out miss [mm] of predict --method diagnosis and --method bayes; 'in 95%': share of "
          "bayes' axis misses inside its 95 % predictive interval")
    print(f"{'seed':>4} {'poses':>5} {'how':>8} {'diag grid300':>12} {'diag rand20':>11} {'bayes grid300':>13} "
          f"{'bayes rand20':>12} {'in 95%':>7} {'CPU s':>6}")
    ratios = {60: [], 120: []}
    rand20 = {60: []}
    for seed in seeds:
        permutation = np.random.default_rng(seed).permutation(len(grid.q))
        test, pool = permutation[:300], permutation[300:]
        order = np.random.default_rng(seed + 100).permutation(pool)
        first = order[:20]
        tests = [(grid.q[test], grid.position[test]), (rand.q, rand.position)]
        started = time.process_time()
        planned = planned_sequence(robot, columns, grid.q, grid.position, first, pool, 120, batch)
        plan_cpu = time.process_time() - started
        rows_out = {}
        for how, sequence, sizes in (("planned", planned, (60, 120)), ("random", order, (60, 120, 200)),
                                     ("all", pool, (len(pool),))):
            for n in sizes:
                idx = sequence[:n]
                t0 = time.process_time()
                d = method_scores("diagnosis", robot, grid.q[idx], grid.position[idx], tests)
                b = method_scores("bayes", robot, grid.q[idx], grid.position[idx], tests)
                rows_out[how, n] = (d, b)
                print(f"{seed:>4} {n:>5} {how:>8} {d[0][0]:12.4f} {d[1][0]:11.4f} {b[0][0]:13.4f} {b[1][0]:12.4f} "
                      f"{b[0][2]:7.3f} {time.process_time() - t0 + (plan_cpu if how == 'planned' and n == 60 else 0):6.1f}",
                      flush=True)
        for n in (60, 120):
            ratios[n].append((rows_out["planned", n][0][0][0] / rows_out["random", n][0][0][0],
                              rows_out["planned", n][1][0][0] / rows_out["random", n][1][0][0]))
        rand20[60].append((rows_out["planned", 60][0][1][0], rows_out["planned", 60][1][1][0],
                           rows_out["random", 60][1][1][0]))
        # the stop rule: predicted at 60 random poses for the 140 more to 200 (the design's model)
        idx = order[:60]
        prior, errors = design_prior(robot, columns, grid.q, grid.position, idx)
        curve = learning_curve(rows(columns, idx), errors, prior, np.random.default_rng(seed))
        before = task_variance(rows(columns, idx), rows(columns, test), prior)
        after = task_variance(rows(columns, order[:200]), rows(columns, test), prior)
        gain = curve.gain(before, after)
        now, then = curve.predict(before), curve.predict(after)
        measured_now, measured_then = rows_out["random", 60][1][0][1], rows_out["random", 200][1][0][1]
        design_now, design_then = (design_model_rms(robot, columns, grid.q, grid.position, order[:n], test)
                                   for n in (60, 200))
        print(f"     stop rule at 60 random poses for 140 more (held-out RMS of the 3D miss on the 300 grid poses): "
              f"predicted {now[0] * 1e3:.4f} -> {then[0] * 1e3:.4f} mm, gain {gain[0] * 1e3:.4f} mm "
              f"[{gain[1] * 1e3:.4f}, {gain[2] * 1e3:.4f}]; measured with the design's model {design_now:.4f} -> "
              f"{design_then:.4f} mm, gain {design_now - design_then:.4f} mm (predicted/measured "
              f"{gain[0] * 1e3 / (design_now - design_then):.2f}); with predict --method bayes {measured_now:.4f} -> "
              f"{measured_then:.4f} mm, gain {measured_now - measured_then:.4f} mm (predicted/measured "
              f"{gain[0] * 1e3 / (measured_now - measured_then):.2f})")
    for n in (60, 120):
        r = np.array(ratios[n])
        print(f"planned/random at {n} poses, held-out grid, mean over seeds: diagnosis {r[:, 0].mean():.3f}, "
              f"bayes {r[:, 1].mean():.3f}")
    r20 = np.array(rand20[60])
    print(f"on the 20 random poses, mean over seeds: 60 planned poses diagnosis {r20[:, 0].mean():.4f} mm, "
          f"bayes {r20[:, 1].mean():.4f} mm; 60 random poses bayes {r20[:, 2].mean():.4f} mm")


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
