#!/usr/bin/env python3
"""Speed of ``diagnose``: 1,000 measurements, every effect, 5-fold cross-validation.

Ours: the whole diagnosis (identifiability, forward selection and backward elimination
over k-fold held-out error, leave-one-out, where/structure analyses), with the
identification Jacobian from Pinocchio chained with the effects' parameter maps, one
Gauss-Newton step from a warm start, then scipy least_squares polishing.

The plain way, side by side: one fit of the final model with scipy least_squares and
finite-difference Jacobians from zero (``jac='2-point'``), evaluating the effects with
``predict_positions`` each time; times the number of fits the diagnosis made gives what
the same search would cost done plainly.

Usage::

    PYTHONPATH=src python scripts/bench_diagnose.py --json bench.json
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

from tcr_accuracy.cli.staging import write_text
from tcr_accuracy.diagnosis.diagnose import diagnose
from tcr_accuracy.effects import make_effect, predict_positions
from tcr_accuracy.model.robot import load_robot
from tcr_accuracy.analysis.simulate import random_scenario, simulate_measurements


def plain_fit(robot, result, mset, effect_names) -> tuple[float, float]:
    """One finite-difference least-squares fit of the final model; (seconds, RMS [m])."""
    effects = [make_effect(e, robot) for e in effect_names]
    kept = [[i for i, n in enumerate(e.parameter_names()) if n in result.parameters.get(e.name, {})]
            for e in effects]
    sizes = [len(k) for k in kept]
    scales = np.concatenate([e.parameter_scales()[k] for e, k in zip(effects, kept)])
    rot, trans = result.registration
    target = (mset.position - trans) @ rot
    context = mset.context

    def residual(phi):
        params, offset = [], 0
        for e, k, size in zip(effects, kept, sizes):
            full = np.zeros(e.n_params)
            full[k] = phi[offset:offset + size] * scales[offset:offset + size]
            params.append(full)
            offset += size
        return (predict_positions(robot, effects, params, mset.q, context) - target).ravel()

    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):  # same BLAS setting as diagnose
        start = time.perf_counter()
        fit = least_squares(residual, np.zeros(scales.size), jac="2-point", method="lm")
        seconds = time.perf_counter() - start
    return seconds, float(np.sqrt(np.mean(fit.fun.reshape(-1, 3) ** 2) * 3))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="time diagnose on 1,000 measurements")
    parser.add_argument("--n", type=int, default=1000)
    parser.add_argument("--folds", type=int, default=5)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", default=None, metavar="FILE")
    args = parser.parse_args(argv)
    robot = load_robot()
    rng = np.random.default_rng(args.seed)
    scenario = random_scenario(robot, rng, dominant=["compliance", "backlash"])
    mset, _ = simulate_measurements(robot, scenario, args.n, rng)
    start, cpu = time.perf_counter(), time.process_time()
    result = diagnose(robot, mset, folds=args.folds, random_state=args.seed)
    seconds, cpu_seconds = time.perf_counter() - start, time.process_time() - cpu
    tried = [e for e, c in result.candidates.items() if c.get("tried")]
    plain_seconds, plain_rms = plain_fit(robot, result, mset, result.selected_effects)
    final = result.steps[-1]
    print(f"diagnose: {args.n} measurements, tool-changer, effects tried: frames + {', '.join(tried)}, "
          f"{args.folds}-fold CV")
    print(f"  ours : whole diagnosis {seconds:8.2f} s wall, {cpu_seconds:.2f} s CPU  ({result.n_fits} least-squares fits; selected "
          f"{', '.join(result.selected_effects)}; final train RMS {final.train_rms * 1e3:.4f} mm)")
    print(f"  plain: one fit of the final model with finite differences {plain_seconds:8.2f} s "
          f"(train RMS {plain_rms * 1e3:.4f} mm); x {result.n_fits} fits = {plain_seconds * result.n_fits:8.1f} s")
    print("  goal: < 60 s for the whole diagnosis")
    if args.json:
        write_text(Path(args.json), json.dumps({
            "seconds": seconds, "cpu_seconds": cpu_seconds, "n_measurements": args.n, "folds": args.folds, "n_fits": result.n_fits,
            "plain_single_fit_seconds": plain_seconds, "plain_projected_seconds": plain_seconds * result.n_fits,
            "selected_effects": result.selected_effects}, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
