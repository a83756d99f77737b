#!/usr/bin/env python3
r"""A mutation run over the packages that compute the figures: how many planted bugs that change
a number the tests catch.

Mutants are made and run by cosmic-ray (each written into its source file in place, the tests
run, the file restored). The mutants counted are those that change a number: a numeric literal
(``NumberReplacer``), an arithmetic operator swapped for another (+ - * / // % **), a unary minus
removed or turned. They are thousands over ``frames/``, ``effects/``, ``diagnosis/`` and
``iso9283/``, and each runs the tests that cover its line, so the run takes a uniform random
sample of them (``--sample``; the kill rate's 95 % interval is printed beside it). The covering
tests come from a coverage run with test contexts (``--coverage``: pytest-cov's ``.coverage``
from ``pytest --cov=tcr_accuracy --cov-context=test``), run fastest first (``--durations``: the
log of that run with ``--durations=0``) and stopped at the first failure.

usage (from the repository root, on a clean working tree; cosmic-ray and pytest-cov installed)::

    python -m pytest -n 2 --cov=tcr_accuracy --cov-context=test --cov-report= --durations=0 > cov.log
    python scripts/mutation_run.py --coverage .coverage --durations cov.log --sample 150 --out mutation/
    # after tests written for the survivors: their coverage, then the survivors run again
    COVERAGE_FILE=.coverage.new python -m pytest --cov=tcr_accuracy --cov-context=test --cov-report= \
        --durations=0 tests/test_new.py > cov.new.log
    python scripts/mutation_run.py --rerun --coverage .coverage .coverage.new --durations cov.log cov.new.log
    python scripts/mutation_run.py --report-only    # the counts again, after judging equivalents
    # a map made on an older source (a full coverage run takes an hour), carried to today's source,
    # with the coverage of the tests written since
    python scripts/mutation_run.py --map old/map.json@COMMIT --coverage .coverage.new --durations cov.new.log ...

Writes ``OUT/session.sqlite`` (cosmic-ray's), ``OUT/report.json`` and prints the counts and each
survivor's diff. A survivor is either a gap in the tests or an equivalent mutant (one that
changes no figure: ``x * 1.0`` -> ``x / 1.0``); read each.
"""

from __future__ import annotations

import argparse
import fnmatch
import json
import math
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("frames", "effects", "diagnosis", "iso9283")
ARITHMETIC = ("Add", "Sub", "Mul", "Div", "FloorDiv", "Mod", "Pow")
#: the operators whose mutants change a number
#: (a unary minus turned into a plus is the same mutant as one removed: only the removal is counted)
NUMBER_OPERATORS = re.compile(r"core/(NumberReplacer|ReplaceUnaryOperator_Delete_USub|ReplaceBinaryOperator_("
                              + "|".join(ARITHMETIC) + ")_(" + "|".join(ARITHMETIC) + "))$")


def coverage_map(coverage_files, durations_logs, packages) -> dict:
    """{"tests": [test ids], "lines": {file: {line: [indices into tests]}}, "durations": {test id: seconds}}
    over the packages' files, from a coverage run with test contexts (pytest-cov's
    ``--cov-context=test``) and the log of that run with ``--durations=0``."""
    import coverage

    data = coverage.CoverageData(no_disk=True)
    for coverage_file in coverage_files:
        more = coverage.CoverageData(basename=str(coverage_file))
        more.read()
        data.update(more)
    tests: dict[str, int] = {}
    lines: dict = {}
    prefixes = tuple(f"src/tcr_accuracy/{p}/" for p in packages)
    for measured in data.measured_files():
        try:
            relative = Path(measured).resolve().relative_to(ROOT).as_posix()
        except ValueError:
            continue
        if not relative.startswith(prefixes):
            continue
        by_line = {}
        for line, contexts in data.contexts_by_lineno(measured).items():
            names = sorted({c.split("|")[0] for c in contexts if c and "::" in c})
            if names:
                by_line[str(line)] = [tests.setdefault(name, len(tests)) for name in names]
        lines[relative] = by_line
    # a test that fails on the unmutated code would "kill" every mutant it runs: left out of the map
    failing = {m.group(1) for log in durations_logs
               for m in re.finditer(r"^(?:FAILED|ERROR) (\S+)", log.read_text(), re.MULTILINE)}
    names = list(tests)
    for by_line in lines.values():
        for line, indices in by_line.items():
            by_line[line] = [i for i in indices if names[i] not in failing]
    durations: dict = {}
    for durations_log in durations_logs:
        for match in re.finditer(r"^([\d.]+)s (?:call|setup|teardown)\s+(\S.*)$", durations_log.read_text(),
                                 re.MULTILINE):
            durations[match.group(2)] = durations.get(match.group(2), 0.0) + float(match.group(1))
    return {"tests": names, "lines": lines, "durations": durations, "failing": sorted(failing)}


def merge_maps(maps: list) -> dict:
    """One coverage map from several (each from :func:`coverage_map`): a line is covered by every
    test any of them names for it; a test's duration is the largest any of them measured."""
    tests: dict[str, int] = {}
    lines: dict = {}
    durations: dict = {}
    failing: set = set()
    for cm in maps:
        names = cm["tests"]
        for relative, by_line in cm["lines"].items():
            into = lines.setdefault(relative, {})
            for line, indices in by_line.items():
                merged = set(into.get(line, [])) | {tests.setdefault(names[i], len(tests)) for i in indices}
                into[line] = sorted(merged)
        for name, seconds in cm["durations"].items():
            durations[name] = max(durations.get(name, 0.0), seconds)
        failing.update(cm.get("failing", []))
    return {"tests": list(tests), "lines": lines, "durations": durations, "failing": sorted(failing)}


def carry_map(cm: dict, commit: str) -> dict:
    """A coverage map made on the source at ``commit``, carried to the working tree's source.

    A line equal in both (difflib's alignment of the two files) keeps its tests; a changed or new
    line gets the tests of the nearest unchanged lines before and after it, which run the code
    around it (an approximation: a survivor on such a line is to be checked by hand). Written here
    because coverage data has no notion of a source that moved on."""
    import bisect
    import difflib

    lines = {}
    for relative, by_line in cm["lines"].items():
        current = ROOT / relative
        if not current.exists():
            continue
        old = subprocess.run(["git", "show", f"{commit}:{relative}"], cwd=ROOT, capture_output=True,
                             text=True, check=True, timeout=60).stdout.splitlines()
        new = current.read_text().splitlines()
        if old == new:
            lines[relative] = by_line
            continue
        anchors = {}  # new line -> old line (1-based), over the equal blocks
        for tag, i1, i2, j1, _ in difflib.SequenceMatcher(None, old, new, autojunk=False).get_opcodes():
            if tag == "equal":
                anchors.update({j1 + k + 1: i1 + k + 1 for k in range(i2 - i1)})
        anchored = sorted(anchors)
        carried = {}
        for line in range(1, len(new) + 1):
            if line in anchors:
                tests = by_line.get(str(anchors[line]), [])
            else:
                k = bisect.bisect_left(anchored, line)
                tests = sorted({i for j in (k - 1, k) if 0 <= j < len(anchored)
                                for i in by_line.get(str(anchors[anchored[j]]), [])})
            if tests:
                carried[str(line)] = tests
        lines[relative] = carried
    return {**cm, "lines": lines}


def write_config(out: Path, budget: float) -> Path:
    """cosmic-ray's configuration: the test command and its timeout (the mutants are chosen here, not
    by ``cosmic-ray init``)."""
    config = out / "cosmic-ray.toml"
    config.write_text(f"""[cosmic-ray]
module-path = "src/tcr_accuracy"
timeout = {budget + 300}
excluded-modules = []
test-command = "{sys.executable} scripts/mutation_tests.py --map {out / 'map.json'} --budget {budget}"

[cosmic-ray.distributor]
name = "local"
""")
    return config


def number_mutants(packages) -> list:
    """Every number-changing mutant of the packages, as cosmic-ray work items in a fixed order.

    Written here rather than by ``cosmic-ray init``, which makes the mutants of all its ~100 operators
    (comparisons, keywords, ...) and would leave most to be skipped; the enumeration is cosmic-ray's
    own (its operators, ``ast_nodes``, occurrences counted per operator and module), and the job id is
    a hash of the mutant so that a seed picks the same sample again.
    """
    import hashlib

    from cosmic_ray.ast import ast_nodes, get_ast_from_path
    from cosmic_ray.ast.ast_query import ASTQuery
    from cosmic_ray.plugins import get_operator, operator_names
    from cosmic_ray.work_item import MutationSpec, WorkItem

    operators = [(name, get_operator(name)()) for name in operator_names() if NUMBER_OPERATORS.search(name)]
    items = []
    for package in packages:
        for module in sorted((ROOT / "src" / "tcr_accuracy" / package).rglob("*.py")):
            relative = module.relative_to(ROOT)
            tree = get_ast_from_path(relative)
            for name, operator in operators:
                positions = [(node, start, end) for node in ast_nodes(tree)
                             for start, end in operator.mutation_positions(node)]
                for occurrence, (node, start, end) in enumerate(positions):
                    spec = MutationSpec(module_path=str(relative), operator_name=name, operator_args={},
                                        occurrence=occurrence, start_pos=start, end_pos=end,
                                        definition_name=ASTQuery(node).get_definition_name())
                    job = hashlib.sha1(f"{relative}:{name}:{occurrence}".encode()).hexdigest()[:16]
                    items.append(WorkItem.single(job_id=job, mutation=spec))
    return items


def new_session(session: Path, items) -> None:
    from cosmic_ray.work_db import WorkDB, use_db

    session.unlink(missing_ok=True)
    with use_db(str(session), WorkDB.Mode.create) as db:
        db.add_work_items(items)


def wilson(k: int, n: int, z: float = 1.959963984540054) -> tuple[float, float]:
    """The Wilson score interval of a proportion k / n."""
    if n == 0:
        return 0.0, 1.0
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return centre - half, centre + half


def changed_line(diff: str) -> tuple[str, str]:
    """The mutated line before and after (stripped), from a mutant's unified diff."""
    before = [line[1:].strip() for line in diff.splitlines() if line.startswith("-") and not line.startswith("---")]
    after = [line[1:].strip() for line in diff.splitlines() if line.startswith("+") and not line.startswith("+++")]
    return " / ".join(before), " / ".join(after)


def outcomes(session: Path) -> dict:
    """job id -> one row per run mutant of a cosmic-ray session."""
    from cosmic_ray.work_db import WorkDB, use_db
    from cosmic_ray.work_item import TestOutcome

    rows = {}
    with use_db(str(session), WorkDB.Mode.open) as db:
        for item, result in db.completed_work_items:
            m = item.mutations[0]
            outcome = ("timeout" if result.output == "timeout" else
                       "killed" if result.test_outcome == TestOutcome.KILLED else
                       "survived" if result.test_outcome == TestOutcome.SURVIVED else "incompetent")
            before, after = changed_line(result.diff or "")
            rows[item.job_id] = {"job": item.job_id, "file": str(m.module_path), "line": m.start_pos[0],
                                 "operator": m.operator_name, "outcome": outcome, "before": before, "after": after,
                                 "uncovered": "uncovered: no test ran" in (result.output or ""),
                                 "budget_spent": "budget spent" in (result.output or ""),
                                 "diff": result.diff}
    return rows


def summarise(rows: list, equivalent: list, population: int) -> dict:
    """Kill rate over the mutants not judged equivalent, with its Wilson 95 % interval.

    A mutant is equivalent when an entry of ``equivalent`` names its file and its line before and
    after the change (line numbers move; the text does not)."""
    def why(row):
        for e in equivalent:
            if e["file"] == row["file"] and e["before"] == row["before"] and e["after"] == row["after"]:
                return e["why"]
        return None

    for row in rows:
        row["equivalent"] = why(row)
    counted = [r for r in rows if r["equivalent"] is None]
    # only a failing test kills: a cosmic-ray timeout or a test command that could not start is read as a survivor
    killed = sum(r["outcome"] == "killed" for r in counted)
    low, high = wilson(killed, len(counted))
    return {"population": population, "run": len(rows), "equivalent": len(rows) - len(counted),
            "counted": len(counted), "killed": killed, "kill_rate": killed / max(len(counted), 1),
            "interval_95": [low, high], "survivors": [r for r in counted if r["outcome"] != "killed"],
            "mutants": rows}


def print_summary(title: str, summary: dict) -> None:
    low, high = summary["interval_95"]
    print(f"{title}: {summary['run']} mutants run of {summary['population']} number-changing ones "
          f"(a uniform sample), {summary['equivalent']} judged equivalent; killed {summary['killed']} of "
          f"{summary['counted']} = {100 * summary['kill_rate']:.1f} % [Wilson 95 %: {100 * low:.1f}, "
          f"{100 * high:.1f}]")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0].replace("\n", " "),
                                     epilog=__doc__[__doc__.index("usage"):],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--coverage", type=Path, nargs="+", help="pytest-cov's .coverage file(s) with test contexts")
    parser.add_argument("--durations", type=Path, nargs="*", default=[], help="those runs' logs with --durations=0")
    parser.add_argument("--map", nargs="+", default=[], metavar="MAP[@COMMIT]",
                        help="coverage maps made before (an OUT/map.json), merged with --coverage's; @COMMIT: the "
                        "map was made on the source at that commit and is carried to today's")
    parser.add_argument("--packages", nargs="+", default=list(PACKAGES), help="under src/tcr_accuracy/ (default: "
                        + " ".join(PACKAGES) + ")")
    parser.add_argument("--files", nargs="+", default=[], metavar="PATTERN",
                        help="only the mutants of these modules (glob patterns under src/tcr_accuracy/, e.g. "
                        "'iso9283/path*.py'): a sample of one area while its tests are written")
    parser.add_argument("--sample", type=int, default=150, help="number-changing mutants to run (default 150)")
    parser.add_argument("--seed", type=int, default=0, help="of the sample (default 0)")
    parser.add_argument("--budget", type=float, default=120.0, help="seconds a mutant's tests may take (default "
                        "120); a mutant whose tests outlast it counts as a survivor")
    parser.add_argument("--out", type=Path, default=Path("mutation"), help="output folder (default mutation/)")
    parser.add_argument("--equivalent", type=Path, default=ROOT / "scripts" / "mutation_equivalent.json",
                        help="the mutants judged equivalent, each with why (default scripts/mutation_equivalent.json)")
    parser.add_argument("--rerun", action="store_true", help="run the survivors of OUT's session again "
                        "(after new tests), into OUT/rerun.sqlite")
    parser.add_argument("--report-only", action="store_true", help="only summarise OUT's sessions")
    args = parser.parse_args(argv)
    out = args.out.resolve()
    out.mkdir(parents=True, exist_ok=True)
    session, rerun = out / "session.sqlite", out / "rerun.sqlite"
    population_file = out / "population.txt"
    equivalent = json.loads(args.equivalent.read_text()) if args.equivalent.exists() else []
    if not args.report_only:
        if subprocess.run(["git", "status", "--porcelain", "--", "src"], cwd=ROOT, capture_output=True,
                          text=True).stdout.strip():
            print("the source tree has uncommitted changes: the mutants are found by git diff", file=sys.stderr)
            return 2
        if args.coverage is not None or args.map:
            maps = []
            for spec in args.map:
                path, _, commit = spec.partition("@")
                earlier = json.loads(Path(path).read_text())
                maps.append(carry_map(earlier, commit) if commit else earlier)
            if args.coverage is not None:
                maps.append(coverage_map(args.coverage, args.durations, args.packages))
            (out / "map.json").write_text(json.dumps(merge_maps(maps)))
        if not (out / "map.json").exists():
            print("--coverage is needed (no OUT/map.json yet)", file=sys.stderr)
            return 2
        config = write_config(out, args.budget)
        if args.rerun:
            first = summarise(list(outcomes(session).values()), equivalent, 0)
            jobs = {r["job"] for r in first["survivors"]}
            from cosmic_ray.work_db import WorkDB, use_db
            with use_db(str(session), WorkDB.Mode.open) as db:
                items = [item for item, _ in db.completed_work_items if item.job_id in jobs]
            new_session(rerun, items)
            subprocess.run(["cosmic-ray", "exec", str(config), str(rerun)], cwd=ROOT, check=True)
        else:
            items = number_mutants(args.packages)
            if args.files:
                items = [item for item in items
                         if any(fnmatch.fnmatch(str(item.mutations[0].module_path), f"src/tcr_accuracy/{pattern}")
                                for pattern in args.files)]
                if not items:
                    print(f"--files: no number-changing mutant in {' '.join(args.files)} under "
                          f"{' '.join(args.packages)}", file=sys.stderr)
                    return 2
            population_file.write_text(str(len(items)))
            import random
            new_session(session, random.Random(args.seed).sample(items, min(args.sample, len(items))))
            rerun.unlink(missing_ok=True)
            subprocess.run(["cosmic-ray", "exec", str(config), str(session)], cwd=ROOT, check=True)
    population = int(population_file.read_text())
    rows = outcomes(session)
    before = summarise([dict(r) for r in rows.values()], equivalent, population)
    print_summary("before the rerun" if rerun.exists() else "mutation run", before)
    result = {"before": before}
    if rerun.exists():
        rows.update(outcomes(rerun))
        after = summarise(list(rows.values()), equivalent, population)
        print_summary("after the rerun of the survivors", after)
        result["after"] = after
    last = result.get("after", before)
    (out / "report.json").write_text(json.dumps(result, indent=1))
    for r in last["mutants"]:
        if r["outcome"] != "killed":
            print(f"\n{r['outcome']}{' (no test runs the line)' if r['uncovered'] else ''}"
                  f"{' (budget spent)' if r['budget_spent'] else ''}"
                  f"{' (equivalent: ' + r['equivalent'] + ')' if r['equivalent'] else ''}: "
                  f"{r['file']}:{r['line']} {r['operator']}\n  - {r['before']}\n  + {r['after']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
