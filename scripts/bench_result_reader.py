#!/usr/bin/env python3
"""Time the one reader of result files on large diagnoses, against jsonschema alone (issue 37 item 12).

    python scripts/bench_result_reader.py DIAGNOSIS.json [--mb 3 60] [--plain-up-to-mb 10]

Each size is the diagnosis JSON inflated with valid content (compliance parameters with their
standard errors, units and intervals, and notes), written to a temporary folder. For each, the
CPU time and peak memory of ``read_result_document`` (jsonschema-rs for the schema, jsonschema
for the words of an error, one scan for control characters, the figures' checks) and, up to
``--plain-up-to-mb``, of the plain way this project used before: ``jsonschema`` walking every
element (``best_match(Draft202012Validator(schema).iter_errors(doc))``). Each run in its own
process, so that the peak memory is its own.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CHILD = r"""
import json, resource, sys, time
sys.path.insert(0, {src!r})
from tcr_accuracy.results.files import read_result_document, schema_of, PAGE_KEYS
path, how = sys.argv[1], sys.argv[2]
start = time.process_time()
if how == "ours":
    read_result_document(path)
else:
    import jsonschema
    doc = json.loads(open(path).read())
    schema = schema_of("diagnosis")
    schema["required"] = list(dict.fromkeys([*schema["required"], *PAGE_KEYS]))
    assert jsonschema.exceptions.best_match(jsonschema.Draft202012Validator(schema).iter_errors(doc)) is None
print(json.dumps({{"cpu_s": time.process_time() - start,
                   "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}}))
"""


def inflate(doc: dict, megabytes: float) -> dict:
    """``doc`` with valid content added until its JSON is about ``megabytes`` MB: parameters (a fifth
    of the size) and notes of 500 characters."""
    doc = json.loads(json.dumps(doc))
    n = int(megabytes * 1e6 * 0.2 / 150)
    names = [f"compliance.x{i:06d}" for i in range(min(n, 99_000))]
    for key, value in (("parameters", 1e-9), ("parameter_std", 1e-10), ("parameter_units", "rad/Nm"),
                       ("parameter_interval_95", [0.0, 2e-9])):
        doc[key].setdefault("compliance", {}).update(dict.fromkeys(names, value))
    doc["steps"][-1]["n_parameters"] += len(names)
    doc["effect_parameters"].setdefault("compliance", {})
    note = "a note of the diagnosis, " * 20
    doc["notes"] = doc["notes"] + [note] * min(99_000, int(megabytes * 1e6 * 0.8 / len(note)))
    return doc


def run(path: Path, how: str) -> dict:
    done = subprocess.run([sys.executable, "-c", CHILD.format(src=str(ROOT / "src")), str(path), how],
                          capture_output=True, text=True, check=True)
    return json.loads(done.stdout.splitlines()[-1])


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("diagnosis", type=Path, help="a diagnose --json result with compliance among its effects")
    parser.add_argument("--mb", type=float, nargs="+", default=[3.0, 60.0], help="sizes to time [MB]")
    parser.add_argument("--plain-up-to-mb", type=float, default=10.0,
                        help="time jsonschema alone up to this size (minutes beyond)")
    args = parser.parse_args(argv)
    base = json.loads(args.diagnosis.read_text())
    print(f"{'size':>9}  {'read_result_document':>24}  {'jsonschema alone':>24}")
    with tempfile.TemporaryDirectory() as folder:
        for megabytes in args.mb:
            path = Path(folder) / "big.json"
            path.write_text(json.dumps(inflate(base, megabytes)))
            size = path.stat().st_size / 1e6
            ours = run(path, "ours")
            plain = run(path, "plain") if megabytes <= args.plain_up_to_mb else None
            said = "not run" if plain is None else f"{plain['cpu_s']:7.1f} s CPU {plain['peak_mb']:6.0f} MB"
            print(f"{size:6.1f} MB  {ours['cpu_s']:7.1f} s CPU {ours['peak_mb']:6.0f} MB  {said:>24}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
