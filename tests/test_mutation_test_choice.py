"""Which tests a mutation run runs on a mutant (``scripts/mutation_tests.py``), on a coverage map
written here for a module of the package.

Code run in a test is judged by the tests that ran it. Code run at import (a module constant, a
signature's defaults) ran in no test's context but the importing one's, so it is judged first by
the tests that ran the lines reading it (the constant's readers anywhere in the package; the
signature's function body), then by the rest of the module's tests; a run that took only its own
context judged ambiguity's ``REACH`` by the one test that happened to import the module.
"""

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MODULE = "src/tcr_accuracy/diagnosis/ambiguity.py"


def _runner():
    spec = importlib.util.spec_from_file_location("mutation_tests", ROOT / "scripts" / "mutation_tests.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _line(text: str) -> int:
    """The 1-based number of the first line of the module starting with ``text`` (after indentation)."""
    lines = (ROOT / MODULE).read_text().splitlines()
    return next(i + 1 for i, line in enumerate(lines) if line.strip().startswith(text))


def _cover():
    reach = _line("REACH = ")
    reader = _line("math.sqrt(float(np.mean(squares))) <= (1.0 + REACH)")
    choice_def = _line("def one_standard_error_choice(")
    choice_body = _line('best = min(rows, key=lambda r: r["_squares"].mean())')
    other = _line("def swap_alternatives(") + 6  # a line of another function's body
    tests = ["t_imports", "t_reads_reach", "t_choice", "t_other"]
    lines = {str(reach): [0], str(reader): [1], str(choice_body): [2], str(other): [3]}
    return {"tests": tests, "lines": {MODULE: lines}}, reach, choice_def, choice_body, other


def test_a_constant_is_judged_first_by_the_tests_of_its_readers():
    cover, reach, *_ = _cover()
    first, rest = _runner().covering_tests(MODULE, reach, cover)
    assert first == {"t_imports", "t_reads_reach"}
    assert rest == {"t_choice", "t_other"}


def test_a_signature_is_judged_first_by_its_body():
    cover, _, choice_def, _, _ = _cover()
    first, rest = _runner().covering_tests(MODULE, choice_def, cover)
    assert first == {"t_choice"}
    assert rest == {"t_imports", "t_reads_reach", "t_other"}


def test_code_run_in_a_test_is_judged_by_the_tests_that_ran_it():
    cover, _, _, choice_body, other = _cover()
    assert _runner().covering_tests(MODULE, choice_body, cover) == ({"t_choice"}, set())
    assert _runner().covering_tests(MODULE, other, cover) == ({"t_other"}, set())
