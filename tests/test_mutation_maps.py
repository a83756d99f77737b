"""The mutation run's coverage maps: merged by test name, and carried from the source a map was made
on to a later source (``scripts/mutation_run.py``'s ``--map MAP@COMMIT``).

The expected maps are written out by hand here for two small files in a throw-away git repository."""

import importlib.util
import subprocess
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "mutation_run.py"


@pytest.fixture()
def mutation_run():
    spec = importlib.util.spec_from_file_location("mutation_run_under_test", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def by_name(cm):
    return {f: {line: sorted(cm["tests"][i] for i in ix) for line, ix in lines.items()}
            for f, lines in cm["lines"].items()}


def test_maps_merge_by_test_name_and_keep_the_longest_duration(mutation_run):
    """Planted: indices kept instead of names (the second map's test 0 is another test), or the
    shorter duration kept."""
    first = {"tests": ["t::a", "t::b"], "lines": {"f.py": {"1": [0], "2": [1]}},
             "durations": {"t::a": 1.0, "t::b": 2.0}, "failing": []}
    second = {"tests": ["t::c", "t::a"], "lines": {"f.py": {"2": [0], "3": [1]}, "g.py": {"9": [0]}},
              "durations": {"t::a": 3.0, "t::c": 0.5}, "failing": ["t::x"]}
    merged = mutation_run.merge_maps([first, second])
    assert by_name(merged) == {"f.py": {"1": ["t::a"], "2": ["t::b", "t::c"], "3": ["t::a"]},
                               "g.py": {"9": ["t::c"]}}
    assert merged["durations"] == {"t::a": 3.0, "t::b": 2.0, "t::c": 0.5}
    assert merged["failing"] == ["t::x"]


def test_a_map_is_carried_over_an_edit(tmp_path, monkeypatch, mutation_run):
    """Equal lines keep their tests at their new numbers; an edited line takes the tests of the
    unchanged lines around it; an unchanged file is untouched. Planted: the old line number kept,
    the neighbours taken one line off."""
    repo = tmp_path / "repo"
    (repo / "src").mkdir(parents=True)
    run = lambda *a: subprocess.run(["git", *a], cwd=repo, check=True, capture_output=True,  # noqa: E731
                                    text=True, timeout=60)
    run("init", "-q")
    (repo / "src" / "m.py").write_text("a = 1\nb = 2\nc = 3\nd = 4\n")
    (repo / "src" / "same.py").write_text("x = 0\n")
    run("add", ".")
    run("-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "old")
    commit = run("rev-parse", "HEAD").stdout.strip()
    # two lines inserted at the top, line c edited
    (repo / "src" / "m.py").write_text("import os\nimport sys\na = 1\nb = 2\nc = 30\nd = 4\n")
    old = {"tests": ["t::a", "t::b", "t::d", "t::x"],
           "lines": {"src/m.py": {"1": [0], "2": [1], "3": [1], "4": [2]}, "src/same.py": {"1": [3]}},
           "durations": {}, "failing": []}
    monkeypatch.setattr(mutation_run, "ROOT", repo)
    carried = by_name(mutation_run.carry_map(old, commit))
    assert carried["src/same.py"] == {"1": ["t::x"]}
    assert carried["src/m.py"] == {"1": ["t::a"],            # new, before line a: a's tests
                                   "2": ["t::a"],
                                   "3": ["t::a"], "4": ["t::b"],
                                   "5": ["t::b", "t::d"],    # edited: b's and d's
                                   "6": ["t::d"]}
