#!/usr/bin/env python3
"""Real robots as the judge: the diagnosis and the predictors on every real data set in a folder.

For each data set under ``--data`` (a folder per robot: measurements, a URDF or a robot name,
and the data's README with what a good calibration reaches), in one run:

1. ``diagnose`` on the measurements (the command's own JSON), and the same data's ladder in
   the order of the published reference (frames -> joint offsets -> geometry -> compliance ->
   lateral compliance), printed next to the reference figures;
2. ``predict`` with every method, trained on one part of the data and asked for the other
   (the query's measured positions judge it: held-out mean and max), then ``compensate`` with
   the best method on the same split.

Data sets this script knows (their file names, robot and reference figures are below) are read
as they are; any other folder is used when it holds a ``dataset.yaml`` (keys ``robot``,
``tool``, ``measurements``, ``query`` or ``train_fraction``, ``noise_mm``) or exactly one CSV
and one URDF whose leaf link names the measured frame; anything else is skipped, and said so.
The real data never enter the project: this script reads them where they lie.

Usage::

    python scripts/real_benchmark.py --data ../shared/real --json real.json
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]

#: The data sets this project was developed on; figures are the data READMEs'.
KNOWN = {
    "justin": {
        "robot": "justin.urdf", "tool": "right_marker", "measurements": "justin_right_hand.csv",
        "train_fraction": 0.8,
        "reference": {
            "source": "an independent fit of the same effect classes, 5-fold CV, held-out mean (data README)",
            "ladder_mm": {"frames": 21.4, "joint_offsets": 18.0, "geometry": 10.8, "compliance": 4.9,
                          "lateral_compliance": 3.9},
            "published": "DLR's paper, both hands, protocol not stated: 21.33 -> 18.18 -> 10.5 -> 5.64 -> 3.12 mm",
            "goal": "diagnose <= 4.5 mm held-out mean (goal 3.9); predict's best <= 5.5 mm on a 400/100 split",
        },
    },
    "ur5_tracker": {
        "robot": "ur5", "measurements": "ur5_grid_1000.csv", "query": "ur5_random_20.csv",
        "reference": {
            "source": "data README (commit dbe29a3 of this project, FIGAROH 1.0.2, the thesis' hybrid method)",
            "ladder_mm": {"frames": 0.628, "geometry": 0.148, "joint_offsets": 0.104, "transmission": 0.091,
                          "encoder_scale": 0.087},
            "query_mm": {"published hybrid (thesis)": 0.1549, "FIGAROH geometric calibration": 0.1070,
                         "geometry-only calibration": 0.1005, "as-built URDF of the full diagnosis": 0.0849},
            "goal": "predict trained on the grid < 0.085 mm mean on the 20 random poses",
        },
    },
}
#: Ladder order for data sets without a reference ladder of their own.
REFERENCE_ORDER = ["joint_offsets", "geometry", "compliance", "lateral_compliance"]


def discover(data: Path) -> list[tuple[str, dict | None, str]]:
    """(name, settings or None, why skipped) for every folder under data."""
    out = []
    for folder in sorted(p for p in data.iterdir() if p.is_dir()):
        manifest = folder / "dataset.yaml"
        if manifest.is_file():
            import yaml

            out.append((folder.name, {**yaml.safe_load(manifest.read_text()), "folder": folder}, ""))
        elif folder.name in KNOWN:
            out.append((folder.name, {**KNOWN[folder.name], "folder": folder}, ""))
        else:
            settings, why = _guess(folder)
            out.append((folder.name, settings, why))
    return out


def _guess(folder: Path) -> tuple[dict | None, str]:
    """One CSV and one URDF: the measured frame is the CSV's <frame>.x_mm prefix or a leaf link."""
    from tcr_accuracy.io.measurements import measured_frames
    from tcr_accuracy.model.urdf import parse_urdf_xml

    csvs, urdfs = sorted(folder.glob("*.csv")), sorted(folder.glob("*.urdf"))
    if len(csvs) != 1 or len(urdfs) != 1:
        return None, (f"{len(csvs)} CSV and {len(urdfs)} URDF files and no dataset.yaml: cannot tell which to "
                      "use (write a dataset.yaml with robot, tool, measurements)")
    frames = measured_frames(csvs[0])
    tool = frames[0] if frames else None
    if tool is None:
        root = parse_urdf_xml(urdfs[0].read_text(), str(urdfs[0]))
        parents = {j.find("parent").get("link") for j in root.findall("joint") if j.find("parent") is not None}
        leaves = [link.get("name") for link in root.findall("link") if link.get("name") not in parents]
        if len(leaves) != 1:
            return None, (f"the URDF has {len(leaves)} leaf links ({', '.join(leaves[:5])}): say which one is "
                          "measured in a dataset.yaml (tool: ...)")
        tool = leaves[0]
    return {"robot": urdfs[0].name, "tool": tool, "measurements": csvs[0].name, "train_fraction": 0.8,
            "folder": folder}, ""


def _run(argv: list[str]) -> tuple[int, float]:
    """Run a tcr-accuracy command as a user would; its printed results are not shown (its JSON is read)."""
    import contextlib
    import io

    from tcr_accuracy.cli import main

    start = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()):
        code = main(argv)
    return code, time.perf_counter() - start


def _robot_args(settings: dict) -> list[str]:
    folder = settings["folder"]
    robot = settings["robot"]
    robot = str(folder / robot) if (folder / robot).is_file() else robot
    return ["--robot", robot] + (["--tool", settings["tool"]] if settings.get("tool") else [])


def diagnose_set(name: str, settings: dict, work: Path) -> dict:
    from tcr_accuracy.diagnosis.diagnose import GapDiagnosis
    from tcr_accuracy.io.measurements import measured_frames, read_measurements
    from tcr_accuracy.model.robot import load_robot

    path = settings["folder"] / settings["measurements"]
    out = work / f"{name}_diagnose.json"
    noise = ["--noise-mm", str(settings["noise_mm"])] if settings.get("noise_mm") else []
    code, seconds = _run(["diagnose", str(path), *_robot_args(settings), *noise, "--json", str(out), "--quiet"])
    if code != 0:
        return {"error": f"diagnose exited with {code}"}
    d = json.loads(out.read_text())
    # the same data along the reference's order (the fitted engine, same folds and identifiability)
    robot_arg = _robot_args(settings)[1]
    robot = load_robot(robot_arg, settings.get("tool"))
    ladder = []
    if not measured_frames(path):
        mset = read_measurements(path, robot)
        noise_m = settings.get("noise_mm") and settings["noise_mm"] * 1e-3
        fit = GapDiagnosis(robot=robot, tracker_noise=noise_m).fit(mset)
        order = [e for e in settings.get("reference", {}).get("ladder_mm", {}) if e != "frames"] or REFERENCE_ORDER
        usable = [e for e in order if e in fit.engine_.bases]
        ladder = [{"effect": s.effect, "heldout_mean_mm": s.heldout.mean * 1e3, "heldout_rms_mm": s.heldout.rms * 1e3,
                   "n_parameters": s.n_parameters} for s in fit.ladder(usable)]
    return {"seconds": seconds, "selected_effects": d["selected_effects"], "primary_effect": d["primary_effect"],
            "steps": [{k: s[k] for k in ("effect", "n_parameters", "heldout_mean_mm", "heldout_rms_mm",
                                         "heldout_max_mm")} for s in d["steps"]],
            "leave_one_out": [{k: r[k] for k in ("dropped", "heldout_mean_mm", "own_share_heldout_mean_mm")}
                              for r in d["leave_one_out"]],
            "noise": d.get("noise"), "structure_remains": d["structure_remains"], "reference_order_ladder": ladder,
            "primary_group": d.get("primary_group", []), "selection_frequency": d.get("selection_frequency", {}),
            "n_parameters": sum(len(p) for p in d.get("parameters", {}).values()),
            "pinned": [p["parameter"] for e in d.get("physical", {}).values() for p in e.get("pinned", [])],
            "outside_physics": [f["effect"] for f in d.get("outside_physics", [])],
            "train_rms_mm": [s["train_rms_mm"] for s in d["steps"]]}


def split(settings: dict, work: Path, name: str) -> tuple[Path, Path, str]:
    """Training and query CSVs: the data set's own query file, or a seeded random split."""
    folder = settings["folder"]
    train = folder / settings["measurements"]
    if settings.get("query"):
        return train, folder / settings["query"], f"train {train.name}, query {settings['query']}"
    lines = [line for line in train.read_text().splitlines() if line.strip() and not line.startswith("#")]
    header, rows = lines[0], lines[1:]
    order = np.random.default_rng(0).permutation(len(rows))
    n_train = int(round(settings.get("train_fraction", 0.8) * len(rows)))
    paths = []
    for label, chosen in (("train", order[:n_train]), ("query", order[n_train:])):
        path = work / f"{name}_{label}.csv"
        path.write_text("\n".join([header] + [rows[i] for i in sorted(chosen)]) + "\n")
        paths.append(path)
    return paths[0], paths[1], f"seeded random split {n_train}/{len(rows) - n_train} of {train.name}"


def predict_set(name: str, settings: dict, work: Path, methods: list[str]) -> dict:
    train, query, how = split(settings, work, name)
    results = {}
    for method in methods:
        out = work / f"{name}_{method}.json"
        code, seconds = _run(["predict", "--train", str(train), "--query", str(query), "--method", method,
                              *_robot_args(settings), "--json", str(out), "--quiet"])
        if code != 0:
            results[method] = {"error": f"exit {code}"}
            continue
        held = json.loads(out.read_text()).get("heldout") or {}
        results[method] = {"mean_mm": held.get("mean_mm"), "max_mm": held.get("max_mm"), "seconds": seconds}
    scored = {m: r for m, r in results.items() if r.get("mean_mm") is not None}
    best = min(scored, key=lambda m: scored[m]["mean_mm"]) if scored else None
    compensation = None
    if best is not None:
        out = work / f"{name}_compensate.json"
        code, seconds = _run(["compensate", "--train", str(train), "--targets", str(query), "--method", best,
                              *_robot_args(settings), "--json", str(out), "--quiet"])
        compensation = ({"method": best, "seconds": seconds, **_compensation_figures(json.loads(out.read_text()))}
                        if code == 0 else {"error": f"exit {code}"})
    return {"split": how, "methods": results, "best": best, "compensation": compensation}


def _compensation_figures(payload: dict) -> dict:
    keys = ("predicted_error_before_mean_mm", "predicted_error_before_max_mm", "predicted_miss_mean_mm",
            "predicted_miss_max_mm", "n_converged", "n_targets")
    out = {k: payload[k] for k in keys if k in payload}
    if payload.get("heldout"):
        out["heldout_mean_mm"] = payload["heldout"]["mean_mm"]  # what compensation would leave, about
    return out


def report(name: str, settings: dict, diagnosis: dict, prediction: dict | None) -> None:
    ref = settings.get("reference", {})
    print(f"\n=== {name} ({settings['measurements']}, robot {settings['robot']}) ===")
    if "error" in diagnosis:
        print(f"  diagnose: {diagnosis['error']}")
    else:
        primary = diagnosis["primary_effect"] or "one of {" + ", ".join(diagnosis["primary_group"]) + "}"
        print(f"  diagnose: {diagnosis['seconds']:.1f} s (intervals and stability included); primary effect "
              f"{primary}; noise {diagnosis['noise']['per_axis_mm']:.4f} mm per axis from "
              f"{diagnosis['noise']['source']}")
        train = diagnosis["train_rms_mm"]
        rises = sum(b > a * (1 + 1e-9) for a, b in zip(train, train[1:]))
        print(f"  physics: {diagnosis['n_parameters']} parameters, all inside their physical ranges; "
              f"{len(diagnosis['pinned'])} held on a bound; fitted only outside physics: "
              f"{', '.join(diagnosis['outside_physics']) or 'nothing'}; train RMS rises along the ladder: {rises}")
        print("  stability (share of bootstrap replays choosing it): " + ", ".join(
            f"{e} {f:.0%}" for e, f in diagnosis["selection_frequency"].items() if f > 0))
        print(f"  {'step (order of explanation)':28s} {'params':>6s} {'held-out mean':>14s} {'max':>9s}")
        for s in diagnosis["steps"]:
            print(f"  {s['effect']:28s} {s['n_parameters']:6d} {s['heldout_mean_mm']:14.3f} {s['heldout_max_mm']:9.3f}")
        if diagnosis["reference_order_ladder"]:
            print(f"  {'ladder in the reference order':28s} {'params':>6s} {'ours: mean [mm]':>16s} "
                  f"{'reference [mm]':>15s}")
            for s in diagnosis["reference_order_ladder"]:
                r = ref.get("ladder_mm", {}).get(s["effect"])
                print(f"  {s['effect']:28s} {s['n_parameters']:6d} {s['heldout_mean_mm']:16.3f} "
                      f"{'' if r is None else format(r, '15.3f')}")
        elif ref.get("ladder_mm"):
            print("  reference ladder [mm]: " + " -> ".join(f"{k} {v}" for k, v in ref["ladder_mm"].items()))
        print("  leave one out (held-out mean without it, others refitted / own share): " + "; ".join(
            f"{r['dropped']} {r['heldout_mean_mm']:.3f} / {r['own_share_heldout_mean_mm']:.3f}"
            for r in diagnosis["leave_one_out"]))
    if ref.get("source"):
        print(f"  reference: {ref['source']}")
    if ref.get("published"):
        print(f"  published: {ref['published']}")
    if prediction is not None:
        print(f"  predict ({prediction['split']}): held-out |predicted - measured| [mm]")
        for method, r in prediction["methods"].items():
            text = r.get("error") or f"mean {r['mean_mm']:.4f}, max {r['max_mm']:.4f}  ({r['seconds']:.1f} s)"
            print(f"    {method:16s} {text}")
        for label, value in ref.get("query_mm", {}).items():
            print(f"    {'reference':16s} {label}: mean {value}")
        comp = prediction["compensation"]
        if comp and "error" in comp:
            print(f"  compensate with {prediction['best']}: {comp['error']}")
        elif comp:
            print(f"  compensate with {prediction['best']} ({comp['n_converged']}/{comp['n_targets']} converged): "
                  f"predicted error before {comp['predicted_error_before_mean_mm']:.3f} mm mean "
                  f"(max {comp['predicted_error_before_max_mm']:.3f}), predicted miss after "
                  f"{comp['predicted_miss_mean_mm']:.4f} mm mean (max {comp['predicted_miss_max_mm']:.4f}); "
                  f"held-out miss of the prediction at the targets {comp.get('heldout_mean_mm', float('nan')):.3f} mm")
    if ref.get("goal"):
        print(f"  goal: {ref['goal']}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", default=str(REPO.parent / "shared" / "real"), metavar="DIR",
                        help="folder holding one folder per real data set (default ../shared/real)")
    parser.add_argument("--json", default=None, metavar="FILE", help="write every figure as JSON")
    parser.add_argument("--methods", default="diagnosis+gp,diagnosis,calibration+gp,calibration,gp,kriging-pf,kriging",
                        help="comma-separated predict methods (default: %(default)s)")
    parser.add_argument("--no-predict", action="store_true", help="diagnose only")
    parser.add_argument("--only", default=None, metavar="NAMES", help="comma-separated data set folders to run")
    args = parser.parse_args(argv)
    data = Path(args.data)
    if not data.is_dir():
        print(f"real_benchmark: no data folder {data}: nothing to measure (skipped)")
        return 0
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        for name, settings, why in discover(data):
            if args.only and name not in args.only.split(","):
                continue
            if settings is None:
                print(f"\n=== {name}: skipped: {why}")
                results[name] = {"skipped": why}
                continue
            missing = [settings[k] for k in ("measurements", "query") if settings.get(k)
                       and not (settings["folder"] / settings[k]).is_file()]
            if missing:
                print(f"\n=== {name}: skipped: {', '.join(missing)} not found")
                results[name] = {"skipped": f"{', '.join(missing)} not found"}
                continue
            diagnosis = diagnose_set(name, settings, work)
            prediction = None if args.no_predict else predict_set(name, settings, work, args.methods.split(","))
            report(name, settings, diagnosis, prediction)
            results[name] = {"diagnosis": diagnosis, "prediction": prediction,
                             "reference": settings.get("reference")}
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2, default=_plain) + "\n")
    return 0


def _plain(value):
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, float) and not math.isfinite(value):
        return None
    raise TypeError(type(value))


if __name__ == "__main__":
    sys.exit(main())
