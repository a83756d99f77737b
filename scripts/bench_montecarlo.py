#!/usr/bin/env python3
"""Monte Carlo engine versus the plain per-sample Pinocchio loop, side by side.

Table 2 error sources of the seed paper on the built-in tool-changer at its working
pose. Prints, in one run:

- engine samples/s: the whole Monte Carlo pipeline (sampling, batched kinematics,
  statistics, reliability and tail counts), and the batched kinematics alone (on reused
  scratch arrays, as the pipeline runs it);
- loop samples/s: one perturbed Pinocchio model and one ``framesForwardKinematics``
  per sample (``tcp_poses_pinocchio``), on a subset of the same samples;
- their ratio, and the largest TCP position difference on the shared samples;
- with ``--memory``: the peak resident memory of a separate process running a
  10-million-sample Monte Carlo (chunks keep it flat);
- with ``--before REV``: the whole pipeline of this code and of the code at git revision
  REV (``git archive`` into a temporary folder), each in its own process, alternated
  ``--repeats`` times, and the median of each, so both see the same machine load.

Figures are CPU time of this process (``time.process_time``), which is what one core
delivers even when other jobs share the machine; wall-clock rates and the load
average are printed too.

    PYTHONPATH=src python scripts/bench_montecarlo.py [--samples N] [--loop-samples N]
        [--memory] [--memory-samples N] [--before REV [--repeats K]] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from tcr_accuracy.cli.staging import write_text
from tcr_accuracy.model.errors import seed_budget
from tcr_accuracy.model.kinematics import tcp_chain_soa, tcp_poses_pinocchio
from tcr_accuracy.analysis.montecarlo import run_monte_carlo, sample_rows
from tcr_accuracy.model.robot import load_robot
from tcr_accuracy.model.scratch import ScratchArrays

MEMORY_CHILD = """
import resource, sys, numpy as np
from tcr_accuracy.model.errors import seed_budget
from tcr_accuracy.analysis.montecarlo import run_monte_carlo
from tcr_accuracy.model.robot import load_robot
robot = load_robot()
result = run_monte_carlo(seed_budget(robot, "table2"), robot.working_pose, int(sys.argv[1]), 0)
print(result.n_samples, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
"""


#: One timed whole-pipeline run in a fresh process, for this code and an older revision
#: (the same calls exist in both): prints CPU and wall samples/s.
PIPELINE_CHILD = """
import sys, time
from tcr_accuracy.model.errors import seed_budget
from tcr_accuracy.analysis.montecarlo import run_monte_carlo
from tcr_accuracy.model.robot import load_robot
robot = load_robot()
budget = seed_budget(robot, "table2")
run_monte_carlo(budget, robot.working_pose, 20_000, 1)  # warm-up
n = int(sys.argv[1])
wall, cpu = time.perf_counter(), time.process_time()
run_monte_carlo(budget, robot.working_pose, n, 0)
print(n / (time.process_time() - cpu), n / (time.perf_counter() - wall))
"""
REPO = Path(__file__).resolve().parents[1]


def timed(fn):
    wall, cpu = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - wall, time.process_time() - cpu


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=1_000_000, help="engine samples (default 1e6)")
    parser.add_argument("--loop-samples", type=int, default=2000, help="loop samples (default 2000)")
    parser.add_argument("--memory", action="store_true", help="also measure a 10M-sample run's peak memory")
    parser.add_argument("--memory-samples", type=int, default=10_000_000)
    parser.add_argument("--before", default=None, metavar="REV",
                        help="also time the whole pipeline of the code at this git revision (e.g. main)")
    parser.add_argument("--repeats", type=int, default=3, help="alternated runs per code with --before (default 3)")
    parser.add_argument("--json", default=None, metavar="FILE")
    args = parser.parse_args()
    if args.before is not None:
        before_commit = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", f"{args.before}^{{commit}}"],
                                       capture_output=True, text=True)
        if before_commit.returncode != 0:
            print(f"bench_montecarlo.py: --before {args.before}: not a revision of {REPO}", file=sys.stderr)
            return 2

    robot = load_robot()
    budget = seed_budget(robot, "table2")
    em = budget.error_model
    q = robot.working_pose
    load_before = os.getloadavg()

    run_monte_carlo(budget, q, 20_000, 1)  # warm-up
    result, mc_wall, mc_cpu = timed(lambda: run_monte_carlo(budget, q, args.samples, 0))
    engine_rate = args.samples / mc_cpu

    rows = sample_rows(budget, args.loop_samples, np.random.default_rng(2))
    x = np.stack([np.broadcast_to(r, (args.loop_samples,)) for r in rows], axis=1)
    big_rows = sample_rows(budget, 200_000, np.random.default_rng(3))
    with ScratchArrays().active():  # each chunk's results dropped before the next, as in the pipeline
        _, kin_wall, kin_cpu = timed(lambda: [tcp_chain_soa(robot, q, [r if isinstance(r, float) else r[i:i + 20_000]
                                                                      for r in big_rows], em)[1].sum()
                                              for i in range(0, 200_000, 20_000)])
    kinematics_rate = 200_000 / kin_cpu
    (_, pos), _, _ = timed(lambda: tcp_chain_soa(robot, q, rows, em))
    loop, loop_wall, loop_cpu = timed(lambda: tcp_poses_pinocchio(robot, q, x, em))
    loop_rate = args.loop_samples / loop_cpu
    max_diff = float(np.abs(pos.T - loop.position).max())
    load_after = os.getloadavg()

    print("Monte Carlo of the seed's Table 2 on the tool-changer at the working pose")
    print(f"  load average (1 min) before / after: {load_before[0]:.2f} / {load_after[0]:.2f} "
          f"on {os.cpu_count()} cores")
    print(f"  {'':44s} {'samples/s (CPU)':>16s} {'samples/s (wall)':>17s}")
    print(f"  {'engine, whole pipeline (' + format(args.samples, ',') + ' samples)':44s} "
          f"{engine_rate:16,.0f} {args.samples / mc_wall:17,.0f}")
    print(f"  {'engine, kinematics only (200,000 samples)':44s} {kinematics_rate:16,.0f} "
          f"{200_000 / kin_wall:17,.0f}")
    print(f"  {'plain Pinocchio loop (' + format(args.loop_samples, ',') + ' samples)':44s} "
          f"{loop_rate:16,.0f} {args.loop_samples / loop_wall:17,.0f}")
    print(f"  ratio engine pipeline / loop: {engine_rate / loop_rate:.1f}x "
          f"(kinematics only: {kinematics_rate / loop_rate:.1f}x)")
    print(f"  max |TCP position difference| engine vs loop on {args.loop_samples} shared samples: {max_diff:.3e} m")
    payload = {
        "engine_samples_per_s": engine_rate,
        "engine_wall_samples_per_s": args.samples / mc_wall,
        "kinematics_samples_per_s": kinematics_rate,
        "loop_samples_per_s": loop_rate,
        "ratio": engine_rate / loop_rate,
        "max_diff_m": max_diff,
        "samples": args.samples,
        "loop_samples": args.loop_samples,
        "load_average_1min": [load_before[0], load_after[0]],
        "cpu_count": os.cpu_count(),
    }
    if args.memory:
        src = str(Path(__file__).resolve().parents[1] / "src")
        env = dict(os.environ, PYTHONPATH=src + os.pathsep + os.environ.get("PYTHONPATH", ""))
        out, wall, _ = timed(lambda: subprocess.run([sys.executable, "-c", MEMORY_CHILD, str(args.memory_samples)],
                                                    capture_output=True, text=True, env=env, check=True).stdout)
        n_done, max_rss_kb = (int(v) for v in out.split())
        print(f"  {n_done:,} samples in a separate process: peak RSS {max_rss_kb / 1024:.0f} MB, "
              f"{wall:.1f} s wall")
        payload.update({"memory_samples": n_done, "peak_rss_mb": max_rss_kb / 1024, "memory_run_wall_s": wall})
    if args.before is not None:
        commit = before_commit.stdout.strip()
        with tempfile.TemporaryDirectory() as folder:
            archive = subprocess.run(["git", "-C", str(REPO), "archive", commit, "src"], capture_output=True,
                                     check=True).stdout
            subprocess.run(["tar", "-x", "-C", folder], input=archive, check=True)
            label = f"code at {args.before}" + ("" if commit.startswith(args.before) else f" ({commit})")
            codes = {"this code": str(REPO / "src"), label: str(Path(folder) / "src")}
            rates = {name: [] for name in codes}
            for _ in range(args.repeats):
                for name, src in codes.items():
                    env = dict(os.environ, PYTHONPATH=src)
                    out = subprocess.run([sys.executable, "-c", PIPELINE_CHILD, str(args.samples)], env=env,
                                         capture_output=True, text=True, check=True, timeout=600).stdout
                    rates[name].append([float(v) for v in out.split()])
        load_end = os.getloadavg()
        median = {name: [statistics.median(r[k] for r in runs) for k in range(2)] for name, runs in rates.items()}
        print(f"  whole pipeline, {args.samples:,} samples, each in its own process, {args.repeats} runs "
              f"alternated (median); load average (1 min) {load_end[0]:.2f}")
        for name, (cpu_rate, wall_rate) in median.items():
            print(f"    {name:42s} {cpu_rate:16,.0f} {wall_rate:17,.0f}")
        new, old = median.values()
        print(f"    speed-up over {args.before}: {new[0] / old[0]:.2f}x (CPU)")
        payload.update({"before_revision": commit, "before_samples_per_s": old[0], "after_samples_per_s": new[0],
                        "before_runs": rates[list(codes)[1]], "after_runs": rates["this code"],
                        "load_average_1min_before_runs": load_end[0]})
    if args.json:
        write_text(Path(args.json), json.dumps(payload, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
