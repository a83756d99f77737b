"""Every size a user can set is held to ``--max-memory-gb`` (issue 29 item 3): each integer option
of each command, found from the parser, is tried at the largest value its type takes; it is
refused in one line before the work ("needs about ... GB"), or its bound is small enough that the
work fits (said here, with why). Below them, the memory refusals of issues 12 and 22 (rows 12:13,
12:14, 22:7): a trillion samples, a CSV too tall, each command's estimate before its work, and the
refusal under an address-space limit. Sizes a file sets (an effect option) are in
``test_result_files.py``.
"""

import argparse
import signal

import pytest

from hostile import assert_one_line, must_not_run, run
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


# ---------------------------------------------------------------------------------------
# Memory, estimated before the work and refused above --max-memory-gb (12: 13, 14; 22: 7)
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("argv, fragment", [
    (["montecarlo", "--samples", "1000000000000"], "--samples 1000000000000 in chunks of 20000 needs about"),
    (["montecarlo", "--view-samples", "1000000000"], "--view-samples 1000000000"),
    (["simulate", "--random", "--n", "1000000000", "--out", "x.csv"], "--n 1000000000 needs about"),
    (["sensitivity", "--sobol-samples", str(2**30)], f"--sobol-samples {2**30} over"),
    (["tolerance", "--samples", "1000000000"], "--samples 1000000000 needs about"),
    (["trajectory", "--samples", "100000000"], "--samples 100000000 along 121 steps"),
    (["view", "--error-preset", "table1", "--samples", "1000000000"], "--samples 1000000000 needs about"),
])
def test_12_13_large_work_is_refused_before_it_starts(argv, fragment, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, out, err = run(argv, capsys)
    assert code == 2
    assert_one_line(err, fragment, "more than the 4 GB allowed", "--max-memory-gb")
    assert list(tmp_path.iterdir()) == []


def test_12_13_max_memory_gb_sets_the_budget(tmp_path, capsys):
    argv = ["simulate", "--random", "--n", "200", "--out", tmp_path / "st.csv"]
    code, out, err = run([*argv, "--max-memory-gb", "0.0001"], capsys)  # 100 kB: 200 poses do not fit
    assert code == 2
    assert_one_line(err, "--n 200 needs about", "more than the 0.0001 GB allowed")
    assert not (tmp_path / "st.csv").exists()
    assert run([*argv, "--max-memory-gb", "0.5"], capsys)[0] == 0
    assert (tmp_path / "st.csv").exists()


def test_12_13_refusals_hold_under_an_address_space_limit(tmp_path):
    # under ulimit -v 3 GB, a trillion samples is our one-line refusal, not a MemoryError
    import resource
    import subprocess
    import sys

    def limit():
        resource.setrlimit(resource.RLIMIT_AS, (3 * 2**30, 3 * 2**30))

    src = str(__import__("pathlib").Path(__import__("tcr_accuracy").__file__).parents[1])
    result = subprocess.run([sys.executable, "-m", "tcr_accuracy", "montecarlo", "--samples", "1000000000000"],
                            preexec_fn=limit, capture_output=True, text=True, cwd=tmp_path, timeout=120,
                            env={"PYTHONPATH": src, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1",
                                 "PATH": "/usr/bin:/bin"})
    assert result.returncode == 2, result.stderr
    assert_one_line(result.stderr, "needs about", "--max-memory-gb")


@pytest.fixture(scope="module")
def tall_csv(measurements, tmp_path_factory):
    """The fixture's rows repeated to 200,000 rows (about 30 MB)."""
    header, *rows = measurements.read_text().splitlines()
    path = tmp_path_factory.mktemp("tall") / "tall.csv"
    body = "\n".join(rows) + "\n"
    path.write_text(header + "\n" + body * (200_000 // len(rows)))
    return path


@pytest.mark.parametrize("argv, fragment", [
    (["predict", "--train", "TALL", "--query", "M", "--method", "gp"],
     "use fewer training rows, or --method local-gp"),
    (["diagnose", "TALL", "--max-memory-gb", "1"], "diagnosing"),
])
def test_12_14_a_huge_csv_is_refused_before_it_is_read(argv, fragment, tall_csv, measurements, capsys, monkeypatch):
    from tcr_accuracy.io import measurements as reader

    monkeypatch.setattr(reader, "read_user_text", must_not_run)
    argv = [str(tall_csv) if a == "TALL" else str(measurements) if a == "M" else a for a in argv]
    code, out, err = run(argv, capsys)
    assert code == 2
    assert_one_line(err, str(tall_csv), "rows) needs about", fragment)


@pytest.mark.parametrize("argv, fragment", [
    (["import", "TRACKER", "--out", "T/m.csv", "--max-memory-gb", "0.000001"],
     "importing TRACKER (2 rows) needs about"),
    (["plan-poses", "M", "-k", "3", "--out", "T/p.csv", "--n-candidates", "1000000"],
     "--n-candidates 1000000 needs about"),
    (["plan-poses", "M", "-k", "3", "--out", "T/p.csv", "--max-memory-gb", "0.001"], "planning poses from M (61 rows)"),
    (["demo", "--out", "T/demo", "--max-memory-gb", "0.001"], "needs about"),
])
def test_22_07_work_is_estimated_and_refused_before_it_starts(argv, fragment, m60, tmp_path, capsys, monkeypatch):
    from tcr_accuracy.io import tracker_import
    from tcr_accuracy.diagnosis import diagnose

    monkeypatch.setattr(tracker_import, "import_tracker", must_not_run)
    monkeypatch.setattr(diagnose, "diagnose", must_not_run)
    tracker = tmp_path / "tracker.csv"
    tracker.write_text("X,Y,Z\n1,2,3\n")

    def spelt(a):
        return a.replace("TRACKER", str(tracker)).replace("M", str(m60)) if a in ("TRACKER", "M") or " " in a \
            else a.replace("T/", f"{tmp_path}/")

    code, out, err = run([spelt(a) for a in argv], capsys)
    assert code == 2 and out == ""
    assert_one_line(err, spelt(fragment), "--max-memory-gb")
    assert [p.name for p in tmp_path.iterdir()] == ["tracker.csv"]
