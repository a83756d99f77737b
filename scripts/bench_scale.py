#!/usr/bin/env python3
"""Scale of ``diagnose`` and ``predict``: seconds and peak memory at 10,000 and 100,000 poses.

Each size gets a simulated tool-changer (6 joints, 5 revolute + 1 telescopic) with hidden
frames, geometry, joint offsets, compliance (the 150 kg cutter on every pose) and
transmission errors and 0.02 mm tracker noise,
and a separate set of 200 query poses of the same hidden robot (``simulate --truth`` read
back with ``--scenario``). Every command runs as a user would type it, in its own process,
timed by the wall clock, its peak resident memory read from the kernel (``wait4``):

* ``diagnose`` over the whole effect vocabulary with 5-fold cross-validation;
* ``predict --method local-gp`` (Gaussian processes of joint-space neighbourhoods,
  memory linear in the poses), scored against the query poses' measured positions;
* the plain way side by side: ``predict --method gp`` (one Gaussian process over all
  poses, an n x n covariance), which the memory check refuses where it cannot fit.

Next to them, the figures of the code before the scale work (commit a33e6b4, same
machine: 2 cores, measured once; that code took 4 minutes for 10,000 poses and was not
run at 100,000).

Usage::

    scripts/bench_scale.py --json bench_scale.json            # 10,000 and 100,000 poses
    scripts/bench_scale.py --sizes 10000 --json small.json     # one size
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: The figures of commit a33e6b4 (before this benchmark's work), same 2-core machine, once:
#: ``diagnose`` of a 10,000-pose tool-changer set (hidden compliance and backlash instead of
#: compliance and transmission; the same vocabulary tried); 100,000 was not run (hours).
BEFORE = {10000: {"diagnose_seconds": 252.2, "diagnose_peak_gb": 2.40}}
#: The hidden robot: effects at their typical sizes, drawn once per size (seed 0), the
#: 150 kg cutter on every pose at one temperature, so that the methods that see joint
#: values only (gp, local-gp) are judged on what joint values can tell.
SCENARIO = """\
effects:
  frames: {}
  geometry: {}
  joint_offsets: {}
  compliance: {}
  transmission: {}
context: {payload_kg: 150, payload_fraction: 1.0, temperature_spread_c: 0, directions: none}
noise_mm: 0.02
"""
GOALS = {"diagnose": {10000: (60.0, 2.0), 100000: (600.0, None)}, "predict": {100000: (60.0, None)}}


def run(argv: list[str]) -> dict:
    """Run the command line ``tcr-accuracy argv`` in its own process: wall seconds, peak RSS
    [GB], exit code, and its last output line."""
    start = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "tcr_accuracy", *argv], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    output = proc.stdout.read()
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    seconds = time.perf_counter() - start
    lines = [line for line in output.splitlines() if line.strip()]
    return {"seconds": seconds, "peak_gb": usage.ru_maxrss * 1024 / 1e9, "exit": proc.returncode,
            "last_line": lines[-1] if lines else "", "output": output}


def heldout_mean_mm(json_path: Path) -> float | None:
    data = json.loads(json_path.read_text())
    return data.get("heldout", {}).get("mean_mm")


def bench_size(n: int, folder: Path, plain: bool) -> dict:
    train, truth, query = folder / f"train_{n}.csv", folder / f"truth_{n}.yaml", folder / f"query_{n}.csv"
    scenario = folder / "scenario.yaml"
    scenario.write_text(SCENARIO)
    made = run(["simulate", "--scenario", str(scenario), "--n", str(n), "--seed", "0",
                "--out", str(train), "--truth", str(truth), "--quiet"])
    if made["exit"] != 0:
        raise SystemExit(f"simulate failed: {made['output']}")
    run(["simulate", "--scenario", str(truth), "--n", "200", "--seed", "1", "--out", str(query), "--quiet"])
    out: dict = {"n": n}

    diag_json = folder / f"diagnose_{n}.json"
    diag = run(["diagnose", str(train), "--json", str(diag_json), "--quiet", "--max-memory-gb", "16"])
    out["diagnose"] = {k: diag[k] for k in ("seconds", "peak_gb", "exit")}
    if diag["exit"] == 0:
        d = json.loads(diag_json.read_text())
        out["diagnose"].update({"selected": d["selected_effects"], "final_heldout_rms_mm": d["final_heldout_rms_mm"],
                                "final_over_noise": d["final_over_noise"], "n_fits": d["n_fits"]})
    else:
        out["diagnose"]["error"] = diag["last_line"]

    methods = ["local-gp"] + (["gp"] if plain else [])
    for method in methods:
        pred_json = folder / f"predict_{method}_{n}.json"
        pred = run(["predict", "--train", str(train), "--query", str(query), "--method", method,
                    "--json", str(pred_json), "--quiet"])
        row = {k: pred[k] for k in ("seconds", "peak_gb", "exit")}
        if pred["exit"] == 0:
            row["heldout_mean_mm"] = heldout_mean_mm(pred_json)
        else:
            row["refused"] = pred["last_line"]
        out[f"predict_{method}"] = row
    return out


def _goal(kind: str, n: int, seconds: float, peak: float) -> str:
    goal = GOALS.get(kind, {}).get(n)
    if goal is None:
        return ""
    limit_s, limit_gb = goal
    ok = seconds < limit_s and (limit_gb is None or peak < limit_gb)
    text = f"< {limit_s:.0f} s" + (f" and < {limit_gb:.0f} GB" if limit_gb else "")
    return f"   goal {text}: {'met' if ok else 'NOT met'}"


def report(results: list[dict]) -> None:
    print("scale: simulated tool-changer (6 joints), hidden frames, geometry, joint offsets, compliance (150 kg on "
          "every pose), transmission; 0.02 mm noise; 200 separate query poses")
    for r in results:
        n, d = r["n"], r["diagnose"]
        print(f"\n{n} poses")
        if d["exit"] == 0:
            print(f"  diagnose (every effect, 5-fold CV)   {d['seconds']:7.1f} s  {d['peak_gb']:5.2f} GB peak   "
                  f"selected {', '.join(d['selected'])}; final held-out {d['final_heldout_rms_mm']:.4f} mm = "
                  f"{d['final_over_noise']:.2f} x noise floor; {d['n_fits']} fits"
                  + _goal("diagnose", n, d["seconds"], d["peak_gb"]))
        else:
            print(f"  diagnose: exit {d['exit']}: {d.get('error')}")
        before = BEFORE.get(n)
        if before:
            print(f"  diagnose before (a33e6b4, once)      {before['diagnose_seconds']:7.1f} s  "
                  f"{before['diagnose_peak_gb']:5.2f} GB peak")
        for key, label in (("predict_local-gp", "predict local-gp (ours)"), ("predict_gp", "predict gp (plain)")):
            p = r.get(key)
            if p is None:
                continue
            if p["exit"] == 0:
                print(f"  {label:37s}{p['seconds']:7.1f} s  {p['peak_gb']:5.2f} GB peak   held-out mean "
                      f"{p['heldout_mean_mm']:.4f} mm at the query poses"
                      + (_goal("predict", n, p["seconds"], p["peak_gb"]) if "local" in key else ""))
            else:
                print(f"  {label:37s}refused after {p['seconds']:.1f} s: {p['refused']}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="seconds and peak memory of diagnose and predict at scale")
    parser.add_argument("--sizes", type=int, nargs="+", default=[10000, 100000])
    parser.add_argument("--no-plain", action="store_true", help="skip predict --method gp")
    parser.add_argument("--json", default=None, metavar="FILE")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="bench_scale_") as tmp:
        results = [bench_size(n, Path(tmp), plain=not args.no_plain) for n in args.sizes]
    report(results)
    if args.json:
        Path(args.json).write_text(json.dumps({"results": results, "before": BEFORE}, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
