#!/usr/bin/env python3
"""The test command of a mutation run (``scripts/mutation_run.py``): the tests that cover the
mutated line, fastest first, stopping at the first failure.

cosmic-ray writes the mutant into the source file in place and runs this command in the
repository's root: the changed file and line are read back with ``git diff``, and the tests
that ran that line in the coverage run (``--map``, made by ``mutation_run.py`` from a pytest-cov
run with ``--cov-context=test``) are run on it. Exit status: pytest's (0: the mutant survived,
non-zero: killed); 0 with "uncovered" printed when no test ran the line (a survivor).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def changed_lines() -> dict[str, set[int]]:
    """file (relative to the repository) -> the line numbers the working tree changed."""
    diff = subprocess.run(["git", "diff", "-U0", "--", "src"], cwd=ROOT, capture_output=True, text=True,
                          check=True).stdout
    out: dict[str, set[int]] = {}
    current = None
    for line in diff.splitlines():
        if line.startswith("+++ b/"):
            current = line[6:]
        elif line.startswith("@@") and current is not None:
            old = re.match(r"@@ -(\d+)(?:,(\d+))?", line)
            start, count = int(old.group(1)), int(old.group(2) or 1)
            out.setdefault(current, set()).update(range(start, start + max(count, 1)))
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--map", required=True, help="the JSON of covering tests and their durations")
    parser.add_argument("--most", type=int, default=400, help="run at most this many covering tests")
    args = parser.parse_args(argv)
    cover = json.loads(Path(args.map).read_text())
    tests: set[str] = set()
    for path, lines in changed_lines().items():
        by_line = cover["lines"].get(path, {})
        for line in lines:
            tests.update(by_line.get(str(line), ()))
    if not tests:
        print("uncovered: no test ran the mutated line")
        return 0
    seconds = cover["durations"]
    ordered = sorted(tests, key=lambda t: (seconds.get(t, 1e9), t))[:args.most]
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    command = [sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", "-p", "no:randomly",
               "-o", "addopts=--strict-markers -p no:benchmark", *ordered]
    return subprocess.run(command, cwd=ROOT, env=env).returncode


if __name__ == "__main__":
    sys.exit(main())
