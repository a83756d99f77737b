#!/usr/bin/env python3
"""The test command of a mutation run (``scripts/mutation_run.py``): the tests that cover the
mutated line, fastest first, stopping at the first failure.

cosmic-ray writes the mutant into the source file in place and runs this command in the
repository's root: the changed file and line are read back with ``git diff``, and the tests
that ran that line in the coverage run (``--map``, made by ``mutation_run.py`` from a pytest-cov
run with ``--cov-context=test``) are run on it. Exit status: pytest's (0: the mutant survived,
non-zero: killed); 0 with "uncovered" printed when no test ran the line (a survivor), and 0 with
"budget spent" when the tests outlast ``--budget`` (a survivor of the tests run so far: counting
it killed, as cosmic-ray counts a timeout, would flatter the rate).

A line is looked up as its whole statement (coverage records a multi-line statement on some of
its lines only). Code run at import (module constants, default arguments) runs in no test's
context: its mutant runs the tests that cover the enclosing function, else any line of the module.

usage (cosmic-ray runs it; by hand, with a mutant written into src/)::

    python scripts/mutation_tests.py --map mutation/map.json
"""

from __future__ import annotations

import argparse
import ast
import json
import os
import re
import signal
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


def covering_tests(path: str, line: int, cover: dict) -> set[str]:
    """The tests that ran ``line`` of ``path`` (its statement), else its function's, else its module's."""
    by_line = cover["lines"].get(path, {})
    original = subprocess.run(["git", "show", f"HEAD:{path}"], cwd=ROOT, capture_output=True, text=True,
                              check=True).stdout
    enclosing = [node for node in ast.walk(ast.parse(original)) if isinstance(node, ast.stmt)
                 and node.lineno <= line <= node.end_lineno]
    statement = min(enclosing, key=lambda n: n.end_lineno - n.lineno, default=None)
    functions = [n for n in enclosing if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))]
    spans = ([(statement.lineno, statement.end_lineno)] if statement is not None else [(line, line)])
    if functions:
        function = min(functions, key=lambda n: n.end_lineno - n.lineno)
        spans.append((function.lineno, function.end_lineno))
    spans.append((1, len(original.splitlines())))
    for first, last in spans:
        found = {cover["tests"][i] for n in range(first, last + 1) for i in by_line.get(str(n), ())}
        if found:
            return found
    return set()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0].replace("\n", " "))
    parser.add_argument("--map", required=True, help="the JSON of covering tests and their durations")
    parser.add_argument("--most", type=int, default=400, help="run at most this many covering tests")
    parser.add_argument("--budget", type=float, default=None, help="seconds for the tests; when spent, the mutant "
                        "counts as surviving the tests run so far (printed: 'budget spent')")
    args = parser.parse_args(argv)
    cover = json.loads(Path(args.map).read_text())
    tests: set[str] = set()
    for path, lines in changed_lines().items():
        for line in lines:
            tests.update(covering_tests(path, line, cover))
    if not tests:
        print("uncovered: no test ran the mutated line")
        return 0
    seconds = cover["durations"]
    # a test the logs do not list ran faster than pytest's --durations threshold (5 ms): it goes first, not last
    ordered = sorted(tests, key=lambda t: (seconds.get(t, 0.0), t))[:args.most]
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    command = [sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", *ordered]
    print(f"{len(ordered)} of {len(tests)} covering tests", flush=True)
    with subprocess.Popen(command, cwd=ROOT, env=env, start_new_session=True) as tests_run:
        try:
            return tests_run.wait(timeout=args.budget)
        except subprocess.TimeoutExpired:
            os.killpg(tests_run.pid, signal.SIGKILL)
            tests_run.wait()
            print(f"budget spent: {args.budget:.0f} s, the tests run so far passed")
            return 0


if __name__ == "__main__":
    sys.exit(main())
