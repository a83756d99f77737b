#!/usr/bin/env python3
"""Real robots judge the export: every form of the calibration on real measurements, side by side.

For the real data sets under ``--data`` (their files stay there; nothing is copied into the
project), in one run:

* **UR5 under a laser tracker** (``ur5_tracker``): ``diagnose`` on the 1000 grid poses (the full
  vocabulary, and geometry and joint offsets only), ``export`` of each with ``--check`` on the 20
  random poses: every form's held-out error with its own tracker frame fitted on the grid, next to
  the geometry-only diagnosis' URDF; the targets of the issue: the calibration URDF within 0.105 mm
  mean and no worse than the geometry-only URDF;
* **Agile Justin, right hand** (``justin``): ``diagnose`` and ``export`` on the 500 poses: the
  calibration URDF against the nominal URDF on the data (in-sample, each with its own camera frame).

A data set that is not there is skipped, and said so. CPU time per step is printed (the machine
may be shared: wall time is an upper bound).

Usage::

    python scripts/real_export_check.py --data ../shared/real [--json real_export.json]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
import tempfile
import time
from pathlib import Path


def _run(argv: list[str]) -> float:
    """Run a command in this process (its printed output kept back); CPU seconds."""
    from tcr_accuracy.cli import main

    start = time.process_time()
    with contextlib.redirect_stdout(io.StringIO()):
        code = main([*argv, "--quiet"])
    if code != 0:
        raise SystemExit(f"{' '.join(argv)}: exit code {code}")
    return time.process_time() - start


def _figures(folder: Path) -> dict:
    data = json.loads((folder / "accuracy.json").read_text())
    return {(a["form"], a["on"]): a for a in data["accuracy"]}


def _table(title: str, figures: dict, order: list[str]) -> list[str]:
    lines = [title, f"  {'form':<28}{'on':<18}{'mean':>10}{'RMS':>10}{'max':>10}  [mm]"]
    for form, on in order:
        a = figures.get((form, on))
        if a is not None:
            lines.append(f"  {form:<28}{on:<18}{a['mean_mm']:>10.4f}{a['rms_mm']:>10.4f}{a['max_mm']:>10.4f}")
    return lines


def ur5(folder: Path, work: Path) -> dict:
    grid, check = folder / "ur5_grid_1000.csv", folder / "ur5_random_20.csv"
    out, lines = {}, []
    for label, effects in (("full", []), ("geometry-only", ["--effects", "joint_offsets,geometry"])):
        seconds = _run(["diagnose", str(grid), "--robot", "ur5", *effects, "--json", str(work / f"{label}.json")])
        seconds_export = _run(["export", str(work / f"{label}.json"), "--to", str(work / label), "--check", str(check)])
        out[label] = _figures(work / label)
        lines.append(f"ur5 {label}: diagnose {seconds:.1f} s CPU, export {seconds_export:.1f} s CPU")
    forms = ["full model", "URDF alone", "UR calibration file", "DH table", "MDH table", "UR DH table", "nominal"]
    lines += _table("UR5, diagnosis of the 1000 grid poses, held-out: the 20 random poses (frames fitted on the grid)",
                    out["full"], [(f, "held-out") for f in forms] + [("full model", "k-fold held-out")])
    lines += _table("UR5, geometry-only diagnosis, held-out:", out["geometry-only"],
                    [("URDF alone", "held-out"), ("full model", "held-out")])
    urdf = out["full"][("URDF alone", "held-out")]["mean_mm"]
    geometric = out["geometry-only"][("URDF alone", "held-out")]["mean_mm"]
    lines.append(f"calibration URDF {urdf:.4f} mm mean held-out: {'within' if urdf <= 0.105 else 'ABOVE'} 0.105 mm; "
                 f"geometry-only URDF {geometric:.4f} mm: the calibration URDF is "
                 f"{'no worse' if urdf <= geometric else 'WORSE'} ({urdf - geometric:+.4f} mm)")
    print("\n".join(lines))
    return {k: {f"{form} / {on}": v for (form, on), v in figures.items()} for k, figures in out.items()}


def justin(folder: Path, work: Path) -> dict:
    seconds = _run(["diagnose", str(folder / "justin_right_hand.csv"), "--robot", str(folder / "justin.urdf"),
                    "--tool", "right_marker", "--json", str(work / "justin.json")])
    seconds_export = _run(["export", str(work / "justin.json"), "--to", str(work / "justin")])
    figures = _figures(work / "justin")
    lines = [f"justin: diagnose {seconds:.1f} s CPU, export {seconds_export:.1f} s CPU"]
    lines += _table("Agile Justin, right hand: on the 500 measured poses (each form with its own camera frame)",
                    figures, [(f, "measured") for f in ("full model", "URDF alone", "DH table", "MDH table", "nominal")]
                    + [("full model", "k-fold held-out")])
    urdf = figures[("URDF alone", "measured")]["mean_mm"]
    nominal = figures[("nominal", "measured")]["mean_mm"]
    lines.append(f"calibration URDF {urdf:.2f} mm mean, nominal URDF {nominal:.2f} mm: "
                 f"{'no worse' if urdf <= nominal else 'WORSE'}")
    print("\n".join(lines))
    return {f"{form} / {on}": v for (form, on), v in figures.items()}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", required=True, type=Path, help="the folder of real data sets (../shared/real)")
    parser.add_argument("--json", type=Path, default=None, help="also write the figures here")
    args = parser.parse_args(argv)
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, check in (("ur5_tracker", ur5), ("justin", justin)):
            folder = args.data / name
            if not folder.is_dir():
                print(f"{name}: skipped ({folder} is not there)")
                continue
            work = Path(tmp) / name
            work.mkdir()
            results[name] = check(folder, work)
    if args.json:
        args.json.write_text(json.dumps(results, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
