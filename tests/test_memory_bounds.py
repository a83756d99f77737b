"""Every size a user can set is held to ``--max-memory-gb`` (issue 29 item 3): each integer option
of each command, found from the parser, is tried at the largest value its type takes; it is
refused in one line before the work ("needs about ... GB"), or its bound is small enough that the
work fits (said here, with why). Sizes a file sets (an effect option, a row count) are in
``test_result_files.py`` and ``test_hostile_input.py``.
"""

import argparse
import signal

import pytest

from test_hostile_input import assert_one_line, run
from tcr_accuracy.cli import build_parser


def _count_options():
    """(command words, option, largest value) of every integer option whose largest value is at least 10^5
    (but ``--seed``: a seed, not a size)."""
    found = []

    def walk(parser, words):
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    walk(sub, (*words, name))
            elif getattr(action.type, "__name__", "") == "integer" and action.type.bounds[1] is not None and \
                    action.type.bounds[1] >= 10**5 and action.option_strings and action.dest != "seed":
                found.append((" ".join(words), action.option_strings[-1], action.type.bounds[1]))

    walk(build_parser(), ())
    return sorted(set(found))


#: (command, option) -> the command line that sets it (N: its largest value), or why its largest value fits.
_CASES = {
    ("compare", "--n-poses"): ["compare", "D", "D", "--n-poses", "N"],
    ("demo", "--samples"): ["demo", "--samples", "N", "--out", "DIR"],
    ("montecarlo", "--samples"): ["montecarlo", "--samples", "N"],
    ("montecarlo", "--tail-samples"): ["montecarlo", "--tail-samples", "N"],
    ("montecarlo", "--view-samples"): ["montecarlo", "--view-samples", "N"],
    ("montecarlo", "--chunk"): "a batch is min(--chunk, --samples) samples: --samples bounds it",
    ("sensitivity", "--sobol-samples"): ["sensitivity", "--sobol-samples", "P2"],  # a power of two
    ("simulate", "--n"): ["simulate", "--random", "--n", "N", "--out", "OUT"],
    ("tolerance", "--samples"): ["tolerance", "--samples", "N"],
    ("trajectory", "--samples"): ["trajectory", "--samples", "N"],
    ("trajectory", "--steps"): ["trajectory", "--steps", "N"],
    ("view", "--samples"): ["view", "--error-preset", "table1", "--samples", "N", "--view", "OUT"],
    ("plan-poses", "--poses"): "at most 100,000 poses of a few hundred bytes each",
    ("plan-poses", "--n-candidates"): ["plan-poses", "M", "-k", "3", "--n-candidates", "N", "--out", "OUT",
                                       "--max-memory-gb", "0.5"],
    ("iso9283 plan", "--cycles"): "at most 100,000 cycles: 500,000 rows of the plan, about 100 MB of text",
    ("iso9283 evaluate", "--planes"): "at most 100,000 planes, crossed in blocks of 4 M plane-to-reading distances "
                                      "(iso9283.path.PLANE_BLOCK): memory does not grow with --planes",
}


def test_every_large_count_option_has_a_case():
    assert {(c, o) for c, o, _ in _count_options()} == set(_CASES)


@pytest.fixture(scope="module")
def files(small_campaign):
    csv, d = small_campaign
    return {"M": csv, "D": d}


@pytest.mark.parametrize("command, option, largest", _count_options())
def test_each_count_at_its_largest_is_refused_before_the_work(command, option, largest, files, tmp_path, capsys):
    case = _CASES[(command, option)]
    if isinstance(case, str):  # bounded by its type, said why
        assert largest <= 10**5 or "min(" in case
        return
    words = {"N": str(largest), "P2": str(2 ** (largest.bit_length() - 1)), "OUT": str(tmp_path / "out.html"),
             "DIR": str(tmp_path / "dir"),
             **{k: str(v) for k, v in files.items()}}

    def expire(signum, frame):
        raise TimeoutError(f"{command} {option} {largest}: not refused within 120 s")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.alarm(120)
    try:
        code, out, err = run([words.get(a, a) for a in case], capsys)
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
    assert code == 2, err
    assert_one_line(err, "needs about", "GB of memory")
    assert list(tmp_path.iterdir()) == []


def test_compare_holds_n_poses_to_the_budget(files, capsys):
    code, out, err = run(["compare", files["D"], files["D"], "--n-poses", "100000000"], capsys)
    assert code == 2
    assert_one_line(err, "--n-poses 100000000 needs about", "more than the 4 GB allowed")
    code, out, err = run(["compare", files["D"], files["D"], "--n-poses", "300000", "--max-memory-gb", "0.1"], capsys)
    assert code == 2
    assert_one_line(err, "--n-poses 300000 needs about", "more than the 0.1 GB allowed")
