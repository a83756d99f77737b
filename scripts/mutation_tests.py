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
its lines only). Code run at import (module constants, class attributes, a ``def``'s signature)
runs in the context of whichever test first imported the module, or of none: its mutant runs first
the tests that run the code reading what the statement defines (every line of the package naming
the constant or attribute; for a signature, its function's body), then the rest of the module's
tests, each tier fastest first. (Run only by its own context, a constant was judged by one test
that happened to import the module, and a refusal pinned elsewhere never ran.)

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


def _names_defined(statement: ast.stmt) -> set[str]:
    """What a statement run at import defines for other code to read: a class's name (its bases,
    decorators), an assignment's targets."""
    if isinstance(statement, ast.ClassDef):
        return {statement.name}
    targets = statement.targets if isinstance(statement, ast.Assign) else \
        [statement.target] if isinstance(statement, (ast.AnnAssign, ast.AugAssign)) else []
    return {node.id for t in targets for node in ast.walk(t) if isinstance(node, ast.Name)}


def _readers(names: set[str], skip: tuple[str, int, int]) -> dict[str, set[int]]:
    """file -> lines of the package that name one of ``names`` (a Name or an attribute), other than the
    defining statement's own lines ``skip`` (file, first, last)."""
    out: dict[str, set[int]] = {}
    for module in sorted((ROOT / "src" / "tcr_accuracy").rglob("*.py")):
        relative = module.relative_to(ROOT).as_posix()
        try:
            tree = ast.parse(module.read_text())
        except SyntaxError:  # a file that does not parse names nothing here (a mutant keeps the syntax)
            continue
        for node in ast.walk(tree):
            named = node.id if isinstance(node, ast.Name) else node.attr if isinstance(node, ast.Attribute) else None
            if named in names and not (relative == skip[0] and skip[1] <= node.lineno <= skip[2]):
                out.setdefault(relative, set()).add(node.lineno)
    return out


def covering_tests(path: str, line: int, cover: dict) -> tuple[set[str], set[str]]:
    """The tests to run on a mutant of ``line`` of ``path``, in two tiers (the first run first).

    Code run in a test: the tests that ran the line (its statement), else its function's, else its
    module's. Code run at import (outside every function's body): first the tests that ran its own
    statement and any line reading what it defines (:func:`_names_defined`, :func:`_readers`; for a
    signature, its function's body), then the rest of the module's tests."""
    original = subprocess.run(["git", "show", f"HEAD:{path}"], cwd=ROOT, capture_output=True, text=True,
                              check=True, timeout=60).stdout
    tree = ast.parse(original)
    enclosing = [node for node in ast.walk(tree) if isinstance(node, ast.stmt)
                 and node.lineno <= line <= node.end_lineno]
    statement = min(enclosing, key=lambda n: n.end_lineno - n.lineno, default=None)
    functions = [n for n in enclosing if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))]
    in_body = any(f.body[0].lineno <= line for f in functions)

    def tests_of(file: str, lines) -> set[str]:
        lines_of = cover["lines"].get(file, {})
        return {cover["tests"][i] for n in lines for i in lines_of.get(str(n), ())}

    module_tests = tests_of(path, range(1, len(original.splitlines()) + 1))
    if in_body or statement is None:
        spans = [(statement.lineno, statement.end_lineno)] if statement is not None else [(line, line)]
        if functions:
            function = min(functions, key=lambda n: n.end_lineno - n.lineno)
            spans.append((function.lineno, function.end_lineno))
        for first, last in spans:
            found = tests_of(path, range(first, last + 1))
            if found:
                return found, set()
        return module_tests, set()
    first_tier = tests_of(path, range(statement.lineno, statement.end_lineno + 1))
    if isinstance(statement, (ast.FunctionDef, ast.AsyncFunctionDef)):
        first_tier |= tests_of(path, range(statement.body[0].lineno, statement.end_lineno + 1))
    # a signature's defaults are read by its body (above); its name by every caller, too wide a tier
    names = set() if isinstance(statement, (ast.FunctionDef, ast.AsyncFunctionDef)) else _names_defined(statement)
    if names:
        for file, lines in _readers(names, (path, statement.lineno, statement.end_lineno)).items():
            first_tier |= tests_of(file, lines)
    return first_tier, module_tests - first_tier


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0].replace("\n", " "))
    parser.add_argument("--map", required=True, help="the JSON of covering tests and their durations")
    parser.add_argument("--most", type=int, default=400, help="run at most this many covering tests")
    parser.add_argument("--budget", type=float, default=None, help="seconds for the tests; when spent, the mutant "
                        "counts as surviving the tests run so far (printed: 'budget spent')")
    args = parser.parse_args(argv)
    cover = json.loads(Path(args.map).read_text())
    first_tier: set[str] = set()
    second_tier: set[str] = set()
    for path, lines in changed_lines().items():
        for line in lines:
            first, second = covering_tests(path, line, cover)
            first_tier |= first
            second_tier |= second
    second_tier -= first_tier
    tests = first_tier | second_tier
    if not tests:
        print("uncovered: no test ran the mutated line")
        return 0
    seconds = cover["durations"]
    # a test the logs do not list ran faster than pytest's --durations threshold (5 ms): it goes first, not last
    ordered = [t for tier in (first_tier, second_tier)
               for t in sorted(tier, key=lambda t: (seconds.get(t, 0.0), t))][:args.most]
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
