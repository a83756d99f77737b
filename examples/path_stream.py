#!/usr/bin/env python3
"""A simulated tracker stream of a robot running the ISO 9283 test paths, for trying
``tcr-accuracy iso9283 evaluate --path`` without a robot.

    python examples/path_stream.py PATH_PLAN.csv --robot ur10 --scenario truth.yaml --out stream.csv

The hidden robot is the scenario's (give a ``simulate --truth`` file to run the same robot a
calibration set was simulated with). Each path and speed of the plan is run ``--cycles`` times:
the commanded points timed by the plan's ``time_s``, the hidden robot's TCP at their joints, a
servo lag (a first-order low-pass of time constant ``--lag-ms`` on the position: corners are
rounded, circles shrink a little at speed), a per-cycle offset (``--scatter-mm``, the
repeatability) and the tracker's noise, sampled at ``--rate-hz``. SI inside, mm in the file.
"""

import argparse

import numpy as np

import tcr_accuracy as tcr
from tcr_accuracy.analysis.scenario import load_scenario
from tcr_accuracy.iso9283.path_evaluate import commanded_runs

parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
parser.add_argument("plan", help="the commanded paths (iso9283 plan --path)")
parser.add_argument("--robot", default=None)
parser.add_argument("--scenario", required=True, help="hidden effects: a scenario YAML or a simulate --truth file")
parser.add_argument("--cycles", type=int, default=10)
parser.add_argument("--rate-hz", type=float, default=1000.0)
parser.add_argument("--lag-ms", type=float, default=4.0)
parser.add_argument("--scatter-mm", type=float, default=0.01)
parser.add_argument("--noise-mm", type=float, default=0.005)
parser.add_argument("--seed", type=int, default=0)
parser.add_argument("--out", required=True)
args = parser.parse_args()

robot = tcr.load_robot(args.robot)
commanded = tcr.read_measurements(args.plan, robot, require_position=False, repeats_allowed=True)
# the hidden robot at every commanded sample, seen from the tracker (no noise here: added per reading)
hidden, _ = tcr.simulate_measurements(robot, load_scenario(args.scenario), 0, random_state=args.seed, noise_m=0.0,
                                      q=commanded.q, context=commanded.context)
rng = np.random.default_rng(args.seed)
lines = ["time_s,x_mm,y_mm,z_mm,path,speed_pct,cycle"]
clock, row = 0.0, 0
for run in commanded_runs(robot, commanded):
    rows = slice(row, row + len(run.points))
    row += len(run.points)
    attained = hidden.position[rows]
    for cycle in range(1, args.cycles + 1):
        t = np.arange(0.0, run.times[-1] + 10 * args.lag_ms * 1e-3, 1.0 / args.rate_hz)
        s = np.interp(t, run.times, run.s)  # the commanded progress along the path, holding at its end
        target = np.stack([np.interp(s, run.s, attained[:, a]) for a in range(3)], axis=1)
        alpha = 1.0 - np.exp(-1.0 / (args.rate_hz * args.lag_ms * 1e-3))  # first-order lag, sampled
        p = np.empty_like(target)
        p[0] = target[0]
        for k in range(1, len(t)):
            p[k] = p[k - 1] + alpha * (target[k] - p[k - 1])
        p += rng.normal(0.0, args.scatter_mm * 1e-3, 3) + rng.normal(0.0, args.noise_mm * 1e-3, p.shape)
        for tk, pk in zip(t, p * 1e3):
            lines.append(f"{clock + tk:.6f},{pk[0]:.5f},{pk[1]:.5f},{pk[2]:.5f},{run.path},{run.speed_pct:g},{cycle}")
        clock += t[-1] + 5.0
with open(args.out, "w", encoding="utf-8") as out:
    out.write("\n".join(lines) + "\n")
print(f"{len(lines) - 1} readings of {robot.name} on the paths of {args.plan} -> {args.out}")
