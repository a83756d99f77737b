#!/usr/bin/env python3
"""Issue 28's simulated robots, diagnosed as a user would, judged by the issue's "Done when".

Each scenario of ``tests/independent_truths.py`` (measurements written by a forward model on
Pinocchio, without the project's effect classes) is built into a temporary folder (the CSV,
and the URDF where the robot needs reflector frames); ``tcr-accuracy diagnose CSV --robot ...
--json OUT --quiet`` runs on it in its own process (this checkout's ``src`` first on
PYTHONPATH, a timeout per run), with the instrument's noise given (``--noise-mm``) except where
the data carry their own figure (three reflectors: their distances). One table follows: the
selected effects, the primary effect (or group) and family, each selected effect's mechanism,
the final held-out RMS against the noise floor, each scenario's criterion from the issue and
whether today's code meets it, and the wall and CPU time of each run (upper bounds on a loaded
machine).

Measured on this machine (docs/attribution-baseline.md has the tables): at 607ba0f 5 of 8
scenarios met their criterion ((d) named encoder scale, no drift; (e) changed its answer with
--seed); at 0c712a7 and 5642618 8 of 8 with data seed 0, 7 of 8 with data seed 1 ((e) --seed 3
answers backlash alone); (c) ends at 58-62 x the noise floor everywhere; each diagnosis 2-4 s CPU.

Usage::

    PYTHONPATH=src python scripts/attribution_scenarios.py                 # every scenario, data seed 0
    PYTHONPATH=src python scripts/attribution_scenarios.py --only a,e --keep /tmp/runs --json table.json
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))  # the builders live with the tests that hold them

from independent_truths import BUILDERS  # noqa: E402

#: scenarios whose noise the diagnosis takes from the data (the reflectors' distances), not --noise-mm
NOISE_FROM_DATA = {"e_sweeps_three_reflectors"}
#: diagnosis seeds (--seed) per scenario; the others run with seed 0
SEEDS = {"e_sweeps_three_reflectors": (0, 1, 2, 3)}
#: the issue's general line: held-out within this many noise floors in every scenario
GENERAL_FLOOR = 1.5


# ---------------------------------------------------------------------------------------
# Reading a diagnosis' JSON
# ---------------------------------------------------------------------------------------
def selected(d: dict) -> list[str]:
    return [e for e in d.get("selected_effects", []) if e != "frames"]


def primary(d: dict) -> str:
    if d.get("primary_effect"):
        return d["primary_effect"]
    group = d.get("primary_group") or []
    return f"one of {{{', '.join(group)}}}" if group else "-"


def mechanisms(d: dict) -> list[dict]:
    return [m for m in d.get("mechanisms") or [] if m.get("effect") != "frames"]


def mechanism_text(m: dict) -> str:
    keys = "/".join(m.get("mechanism_keys") or []) or m.get("mechanism", "")[:40]
    return f"{m.get('effect')}: {keys}{'' if m.get('physical', True) else ' (not physical)'}"


def names_mechanism(d: dict, effects: set, keys: set, words: str) -> bool:
    """A mechanisms entry of one of ``effects`` (any effect if empty) whose keys hold one of ``keys``
    or whose words match the regular expression ``words``."""
    for m in mechanisms(d):
        if effects and m.get("effect") not in effects and m.get("family") not in effects:
            continue
        if keys & set(m.get("mechanism_keys") or []) or re.search(words, m.get("mechanism", ""), re.I):
            return True
    return False


def kept(d: dict, effects: set, family: str) -> bool:
    """One of ``effects`` selected, or a selected effect of ``family`` (JSON ``families``)."""
    chosen = set(selected(d))
    in_family = {e for f in d.get("families") or [] if f.get("family") == family for e in f.get("effects", [])}
    return bool(chosen & (effects | in_family))


def over_floor(d: dict) -> float:
    value = d.get("final_over_noise")
    return math.nan if value is None else float(value)


# ---------------------------------------------------------------------------------------
# The "Done when", one criterion per scenario: (text, judge(list of JSON) -> (pass, why))
# ---------------------------------------------------------------------------------------
def judge_a(runs):
    d = runs[0]
    ratio, named = over_floor(d), names_mechanism(d, set(), {"gravity_compensation"}, r"gravity.compensation")
    return ratio <= 1.2 and named, f"final {ratio:.2f} x floor (<= 1.2), gravity compensation named: {named}"


def judge_b(runs):
    d = runs[0]
    keep = kept(d, {"backlash"}, "direction")
    named = names_mechanism(d, {"backlash", "direction"}, {"lost_motion_compensation"}, r"lost.motion compensation")
    return keep and named, f"direction term kept: {keep}, lost-motion compensation named: {named}"


def judge_c(runs):
    d = runs[0]
    keep = kept(d, {"thermal"}, "thermal")
    named = names_mechanism(d, {"thermal"}, {"instrument_scale", "session_difference"},
                            r"instrument|between (the )?sessions|session difference")
    return keep and named, f"temperature scale kept: {keep}, instrument/session named: {named}"


def judge_d(runs):
    d = runs[0]
    drift = kept(d, {e for e in selected(d) if "drift" in e}, "time")
    confounding = bool(d.get("confounding")) or any(re.search(r"cannot be told (apart )?from|confound", n, re.I)
                                                    for n in d.get("notes", []))
    scale = ("encoder_scale" in selected(d) or d.get("primary_effect") == "encoder_scale"
             or "encoder_scale" in (d.get("primary_group") or []))
    return (drift or confounding) and not scale, (f"drift selected: {drift}, confounding reported: {confounding}, "
                                                 f"encoder scale named: {scale}")


def judge_e(runs):
    answers = [(tuple(sorted(selected(d))), primary(d), d.get("primary_family")) for d in runs]
    geometric = all({"geometry", "joint_offsets"} & set(selected(d)) for d in runs)
    same = len(set(answers)) == 1
    return geometric and same, (f"geometry or offsets in every seed: {geometric}, same answer for seeds "
                                f"{len(runs)}: {same}")


def judge_f(runs):
    d = runs[0]
    invented = selected(d)
    return not invented, f"effects invented: {', '.join(invented) or 'none'}"


CRITERIA = {
    "a": ("final held-out within 1.2 x the noise floor, mechanism naming the gravity compensation", judge_a),
    "b": ("the direction term kept, named lost-motion compensation", judge_b),
    "c": ("the temperature length scale kept, named instrument scale or session difference", judge_c),
    "d": ("drift selected or the confounding reported, encoder scale not named", judge_d),
    "e": ("geometry or offsets selected, the same answer for --seed 0-3", judge_e),
    "f": ("nothing invented", judge_f),
}


# ---------------------------------------------------------------------------------------
# Running
# ---------------------------------------------------------------------------------------
def child_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def run_diagnosis(csv_path: Path, robot_args: list, out: Path, seed: int, noise_mm: float | None,
                  timeout: float, src: Path) -> tuple[dict | None, float, float, str]:
    """(JSON or None, wall [s], CPU [s], error line) of one ``diagnose`` in its own process."""
    command = [sys.executable, "-m", "tcr_accuracy", "diagnose", str(csv_path), *robot_args, "--json", str(out),
               "--quiet", "--seed", str(seed)]
    if noise_mm is not None:
        command += ["--noise-mm", f"{noise_mm:g}"]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(src), os.environ.get("PYTHONPATH", "")]))
    cpu, start = child_cpu(), time.perf_counter()
    try:
        done = subprocess.run(command, capture_output=True, text=True, timeout=timeout, env=env)
    except subprocess.TimeoutExpired:
        return None, time.perf_counter() - start, child_cpu() - cpu, f"timed out after {timeout:g} s"
    wall, cpu = time.perf_counter() - start, child_cpu() - cpu
    if done.returncode != 0:
        lines = (done.stderr.strip() or done.stdout.strip() or "no output").splitlines()
        return None, wall, cpu, f"exit {done.returncode}: {lines[-1]}"
    return json.loads(out.read_text()), wall, cpu, ""


def truth_line(truth: dict) -> str:
    """The hidden sizes a reader compares the answer with."""
    parts = [truth.get("mechanism", "")]
    parts += [f"{k.removesuffix('_m')} {v * 1e3:.3f} mm" for k, v in truth.items() if k.endswith("_rms_m")]
    if "reference_heldout_m" in truth:
        parts += [f"independent held-out after {k} {v * 1e3:.3f} mm" for k, v in truth["reference_heldout_m"].items()]
    return "; ".join(parts)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", default=None, help="comma-separated scenario letters or names (default: all)")
    parser.add_argument("--data-seed", type=int, default=0, help="seed of the builders (default 0)")
    parser.add_argument("--timeout", type=float, default=1800.0, help="per diagnosis [s] (default 1800)")
    parser.add_argument("--keep", default=None, help="folder to keep the CSVs, URDFs and JSONs in")
    parser.add_argument("--json", default=None, help="write the table as JSON to this file")
    parser.add_argument("--src", default=str(REPO / "src"),
                        help="the package source the diagnoses run (default: this checkout's src; e.g. an exported "
                             "commit's, to compare two versions on the same data)")
    args = parser.parse_args(argv)
    wanted = None if args.only is None else [w.strip() for w in args.only.split(",") if w.strip()]
    names = [n for n in BUILDERS if wanted is None or any(n == w or n.startswith(f"{w}_") for w in wanted)]
    if not names:
        parser.error(f"--only {args.only}: no such scenario (known: {', '.join(BUILDERS)})")
    folder_context = tempfile.TemporaryDirectory(prefix="attribution_") if args.keep is None else None
    folder = Path(args.keep or folder_context.name)
    folder.mkdir(parents=True, exist_ok=True)
    rows = []
    for name in names:
        scenario = BUILDERS[name](args.data_seed)
        csv_path, robot_args = scenario.write(folder)
        noise_mm = None if name in NOISE_FROM_DATA else scenario.noise_m * 1e3
        runs = []
        for seed in SEEDS.get(name, (0,)):
            out = folder / f"{name}.seed{seed}.json"
            d, wall, cpu, error = run_diagnosis(csv_path, robot_args, out, seed, noise_mm, args.timeout,
                                                Path(args.src))
            runs.append({"seed": seed, "json": d, "wall_s": wall, "cpu_s": cpu, "error": error})
            print(f"  {name} --seed {seed}: {wall:.1f} s wall, {cpu:.1f} s CPU {error}", file=sys.stderr, flush=True)
        letter = name[0]
        text, judge = CRITERIA[letter]
        good = [r["json"] for r in runs if r["json"] is not None]
        verdict, why = (judge(good) if len(good) == len(runs) else
                        (False, "; ".join(r["error"] for r in runs if r["error"])))
        rows.append({"scenario": name, "criterion": text, "pass": bool(verdict), "why": why,
                     "truth": truth_line(scenario.truth), "noise_given_mm": noise_mm,
                     "true_floor_mm": math.sqrt(3) * scenario.noise_m * 1e3, "runs": [
                         {k: v for k, v in r.items() if k != "json"} | (_summary(r["json"]) if r["json"] else {})
                         for r in runs]})
    print(f"diagnoses by the package in {args.src}; data seed {args.data_seed}")
    print_table(rows)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1) + "\n")
    if folder_context is not None:
        folder_context.cleanup()
    return 0


def _summary(d: dict) -> dict:
    return {"selected": selected(d), "primary": primary(d), "primary_family": d.get("primary_family"),
            "families": [(f.get("family"), f.get("share_mm")) for f in d.get("families") or []],
            "mechanisms": [mechanism_text(m) for m in mechanisms(d)],
            "final_mm": d.get("final_heldout_rms_mm"), "floor_mm": d.get("noise_floor_mm"),
            "over_floor": over_floor(d), "structure": d.get("structure_verdict"),
            "clearance_notes": [n for n in d.get("notes", []) if "clearance" in n.lower()]}


def print_table(rows: list) -> None:
    header = (f"{'scenario':28s} {'seed':>4s}  {'selected':40s} {'primary':32s} {'family':10s} "
              f"{'final mm':>8s} {'floor mm':>8s} {'x floor':>7s} {'x true':>7s} {'<=1.5':>5s} {'wall s':>7s} "
              f"{'CPU s':>7s}")
    print(header)
    print("-" * len(header))
    for row in rows:
        for r in row["runs"]:
            if "selected" not in r:
                print(f"{row['scenario']:28s} {r['seed']:4d}  {r['error']}")
                continue
            true_ratio = r["final_mm"] / row["true_floor_mm"]
            print(f"{row['scenario']:28s} {r['seed']:4d}  {', '.join(r['selected']) or '(frames only)':40s} "
                  f"{r['primary']:32s} {str(r['primary_family'] or '-'):10s} {r['final_mm']:8.4f} "
                  f"{r['floor_mm']:8.4f} {r['over_floor']:7.2f} {true_ratio:7.2f} "
                  f"{'yes' if true_ratio <= GENERAL_FLOOR else 'NO':>5s} {r['wall_s']:7.1f} {r['cpu_s']:7.1f}")
            if r["mechanisms"]:
                print(f"{'':34s}mechanisms: {'; '.join(r['mechanisms'])}")
        claims = sorted({n for r in row["runs"] for n in r.get("clearance_notes", [])})
        for note in claims:  # no scenario hides joint play: a note that names it is a wrong cause
            print(f"{'':34s}wrong cause claimed: {note[:150]}")
        print(f"{'':34s}hidden: {row['truth']}")
        print(f"{'':34s}criterion: {row['criterion']}")
        print(f"{'':34s}{'PASS' if row['pass'] else 'FAIL'}: {row['why']}")
    passed = sum(r["pass"] for r in rows)
    print(f"\n{passed}/{len(rows)} scenarios meet the issue's criterion; 'x floor': final held-out RMS over the "
          f"diagnosis' noise floor, 'x true': over sqrt(3) x the simulated noise; '<=1.5': the issue's general "
          f"line (held-out within {GENERAL_FLOOR} x the noise floor). Times are upper bounds (shared machine).")


if __name__ == "__main__":
    sys.exit(main())
