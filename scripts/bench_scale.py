#!/usr/bin/env python3
"""Scale of ``diagnose`` and ``predict``: seconds and peak memory at 10,000 and 100,000 poses, side by
side with a previous version of the code in the same run.

Each size gets a simulated UR10 (the real-size case of a campaign of 12,000 poses) whose
strain-wave joints carry cyclic errors of 15-25 cycles per revolution and a few hundred
microradians, with hidden frames (a reflector 28 cm off the flange, the tracker 2 m away),
geometry, joint compliance at its typical size and 0.02 mm tracker noise, and a separate set of
200 query poses of the same hidden robot (``simulate --truth`` read back with ``--scenario``).
Every command runs as a user would type it, in its own process: wall seconds, CPU seconds (user +
system of the process, what the 2-core machine's load does not inflate) and peak resident memory,
read from the kernel (``wait4``):

* ``diagnose`` over the whole effect vocabulary (5-fold cross-validation, its stability replays,
  intervals and everything else it does), by this checkout and, side by side, by a previous
  version of the code (``--previous REF``, default the release before the repeated folds: its
  ``src/`` taken out of git into a temporary folder);
* ``predict --method local-gp`` (Gaussian processes of joint-space neighbourhoods, memory linear
  in the poses), scored against the query poses' measured positions, and the plain way side by
  side: ``predict --method gp`` (one Gaussian process over all poses, an n x n covariance), which
  the memory check refuses where it cannot fit.

Usage::

    scripts/bench_scale.py --json bench_scale.json             # 10,000 and 100,000 poses
    scripts/bench_scale.py --sizes 10000 --json small.json      # one size
    scripts/bench_scale.py --sizes 10000 --previous none        # this checkout only
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
#: the version compared with by default: the release before the diagnosis' stages and repeated folds
PREVIOUS = "9a9c4ea"
#: The hidden robot (examples/scenario_cyclic_ur10.yaml, with compliance at its typical size).
SCENARIO = """\
robot: ur10
effects:
  frames:
    base_mm: {dx: 2100.0, dy: 350.0, dz: -600.0}
    base_deg: {rz: 180.0}
    tool_mm: {dx: 100.0, dy: -80.0, dz: 250.0}
  geometry: {spread_mm: 0.2, spread_mrad: 0.2}
  compliance: {}
  cyclic:
    parameters:
      cyclic.shoulder_pan_joint.a16: 2.2e-4
      cyclic.shoulder_lift_joint.b20: 2.6e-4
      cyclic.shoulder_lift_joint.a23: 1.0e-4
      cyclic.elbow_joint.a22: 2.2e-4
      cyclic.wrist_1_joint.b22: 2.3e-4
      cyclic.wrist_2_joint.b21: -2.2e-4
      cyclic.wrist_3_joint.a15: 1.8e-4
noise_mm: 0.02
"""
#: issue 32's goals: (seconds, GB) per size, diagnose on two cores
GOALS = {"diagnose": {10000: (45.0, 0.8), 100000: (None, 2.0)}, "predict": {100000: (60.0, None)}}


def previous_source(ref: str, folder: Path) -> Path:
    """``src/`` of git ref ``ref`` of this repository, unpacked into ``folder``."""
    archive = folder / "previous.tar"
    with open(archive, "wb") as out:
        subprocess.run(["git", "-C", str(REPO), "archive", ref, "src"], stdout=out, check=True, timeout=120)
    with tarfile.open(archive) as tar:
        tar.extractall(folder / "previous", filter="data")
    return folder / "previous" / "src"


def run(argv: list[str], source: Path | None = None) -> dict:
    """Run the command line ``tcr-accuracy argv`` in its own process (the code in ``source``, or this
    checkout's): wall and CPU seconds, peak RSS [GB], exit code, and its last output line."""
    env = dict(os.environ)
    env["PYTHONPATH"] = str(source if source is not None else REPO / "src")
    start = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "tcr_accuracy", *argv], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, env=env)
    output = proc.stdout.read()
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    seconds = time.perf_counter() - start
    lines = [line for line in output.splitlines() if line.strip()]
    return {"seconds": seconds, "cpu_seconds": usage.ru_utime + usage.ru_stime,
            "peak_gb": usage.ru_maxrss * 1024 / 1e9, "exit": proc.returncode,
            "last_line": lines[-1] if lines else "", "output": output}


def heldout_mean_mm(json_path: Path) -> float | None:
    data = json.loads(json_path.read_text())
    return data.get("heldout", {}).get("mean_mm")


def _diagnose(train: Path, out_json: Path, source: Path | None) -> dict:
    diag = run(["diagnose", str(train), "--robot", "ur10", "--json", str(out_json), "--quiet", "--max-memory-gb", "16"],
               source)
    row = {k: diag[k] for k in ("seconds", "cpu_seconds", "peak_gb", "exit")}
    if diag["exit"] == 0:
        d = json.loads(out_json.read_text())
        row.update({"selected": d["selected_effects"], "final_heldout_rms_mm": d["final_heldout_rms_mm"],
                    "final_over_noise": d["final_over_noise"], "n_fits": d["n_fits"]})
    else:
        row["error"] = diag["last_line"]
    return row


def bench_size(n: int, folder: Path, plain: bool, previous: Path | None) -> dict:
    train, truth, query = folder / f"train_{n}.csv", folder / f"truth_{n}.yaml", folder / f"query_{n}.csv"
    scenario = folder / "scenario.yaml"
    scenario.write_text(SCENARIO)
    made = run(["simulate", "--robot", "ur10", "--scenario", str(scenario), "--n", str(n), "--seed", "0",
                "--out", str(train), "--truth", str(truth), "--quiet"])
    if made["exit"] != 0:
        raise SystemExit(f"simulate failed: {made['output']}")
    run(["simulate", "--robot", "ur10", "--scenario", str(truth), "--n", "200", "--seed", "1", "--out", str(query),
         "--quiet"])
    out: dict = {"n": n, "diagnose": _diagnose(train, folder / f"diagnose_{n}.json", None)}
    if previous is not None:
        out["diagnose_previous"] = _diagnose(train, folder / f"diagnose_previous_{n}.json", previous)
    methods = ["local-gp"] + (["gp"] if plain else [])
    for method in methods:
        pred_json = folder / f"predict_{method}_{n}.json"
        pred = run(["predict", "--robot", "ur10", "--train", str(train), "--query", str(query), "--method", method,
                    "--json", str(pred_json), "--quiet"])
        row = {k: pred[k] for k in ("seconds", "cpu_seconds", "peak_gb", "exit")}
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
    ok = (limit_s is None or seconds < limit_s) and (limit_gb is None or peak < limit_gb)
    text = " and ".join(t for t in ((f"< {limit_s:.0f} s" if limit_s else ""), (f"< {limit_gb:g} GB" if limit_gb
                                                                                   else "")) if t)
    return f"   goal {text}: {'met' if ok else 'NOT met'}"


def _diagnose_line(label: str, d: dict, n: int, goal: bool) -> str:
    if d["exit"] != 0:
        return f"  {label:34s} exit {d['exit']}: {d.get('error')}"
    return (f"  {label:34s} {d['seconds']:7.1f} s wall {d['cpu_seconds']:7.1f} s CPU {d['peak_gb']:5.2f} GB peak   "
            f"selected {', '.join(d['selected'])}; final held-out {d['final_heldout_rms_mm']:.4f} mm = "
            f"{d['final_over_noise']:.2f} x noise floor; {d['n_fits']} fits"
            + (_goal("diagnose", n, d["seconds"], d["peak_gb"]) if goal else ""))


def report(results: list[dict], previous: str | None) -> None:
    print("scale: simulated UR10, hidden frames (reflector 28 cm off the flange), geometry, compliance, cyclic joint "
          f"errors (15-25 cycles per revolution); 0.02 mm noise; 200 separate query poses; load average "
          f"{os.getloadavg()[0]:.2f} at the end (2 cores)")
    for r in results:
        n = r["n"]
        print(f"\n{n} poses")
        print(_diagnose_line("diagnose (this checkout)", r["diagnose"], n, True))
        if "diagnose_previous" in r:
            print(_diagnose_line(f"diagnose ({previous})", r["diagnose_previous"], n, False))
        for key, label in (("predict_local-gp", "predict local-gp (ours)"), ("predict_gp", "predict gp (plain)")):
            p = r.get(key)
            if p is None:
                continue
            if p["exit"] == 0:
                print(f"  {label:34s} {p['seconds']:7.1f} s wall {p['cpu_seconds']:7.1f} s CPU {p['peak_gb']:5.2f} GB "
                      f"peak   held-out mean {p['heldout_mean_mm']:.4f} mm at the query poses"
                      + (_goal("predict", n, p["seconds"], p["peak_gb"]) if "local" in key else ""))
            else:
                print(f"  {label:34s}refused after {p['seconds']:.1f} s: {p['refused']}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="seconds and peak memory of diagnose and predict at scale")
    parser.add_argument("--sizes", type=int, nargs="+", default=[10000, 100000])
    parser.add_argument("--no-plain", action="store_true", help="skip predict --method gp")
    parser.add_argument("--previous", default=PREVIOUS, metavar="REF",
                        help=f"git ref of the code to compare diagnose with (default {PREVIOUS}; 'none': skip)")
    parser.add_argument("--json", default=None, metavar="FILE")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="bench_scale_") as tmp:
        previous = None if args.previous == "none" else previous_source(args.previous, Path(tmp))
        results = [bench_size(n, Path(tmp), plain=not args.no_plain, previous=previous) for n in args.sizes]
    report(results, None if args.previous == "none" else args.previous)
    if args.json:
        Path(args.json).write_text(json.dumps({"results": results, "previous": args.previous}, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
