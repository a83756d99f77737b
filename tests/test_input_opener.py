"""The one input opener (issue 29 items 3 and 6): regular files only, a size bound per kind,
depth-limited JSON/YAML/TOML, text that is not UTF-8 in one line; and every input option of
every command read through it, enumerated from the command line's parser.

Special files are decoys: a named pipe made in ``tmp_path``, and ``/dev/zero`` (only ever read:
reading it is harmless, and the opener refuses it before reading a byte).
"""

import argparse
import json
import os
import re
import signal
from contextlib import contextmanager
from pathlib import Path

import pytest

from hostile import assert_one_line, run
from tcr_accuracy.cli import build_parser
from tcr_accuracy.cli.output_paths import OUTPUT_TYPES
from tcr_accuracy.exceptions import InputError
from tcr_accuracy.input_files import (MAX_NESTING, parse_json, parse_settings, read_input_bytes, read_input_text,
                                      read_json_file, recording_inputs)

REPO = Path(__file__).resolve().parents[1]


@contextmanager
def deadline(seconds: int = 60):
    """Fail instead of hanging: SIGALRM interrupts a blocking open or read (Python retries the
    system call after the handler only when the handler returns; ours raises)."""
    def expire(signum, frame):
        raise TimeoutError(f"no answer within {seconds} s: the command hangs on a special file")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


@pytest.fixture
def fifo(tmp_path):
    path = tmp_path / "pipe"
    os.mkfifo(path)
    return path


# ---------------------------------------------------------------------------------------
# The opener itself
# ---------------------------------------------------------------------------------------
def test_a_pipe_a_device_and_a_folder_are_refused_without_reading(fifo, tmp_path):
    with deadline(20):
        for path, kind in ((fifo, "a named pipe"), (Path("/dev/zero"), "a device"), (tmp_path, "a folder")):
            with pytest.raises(InputError, match=f"{re.escape(str(path))}: is {kind}; the measurement file must be a "
                                                 "regular file"):
                read_input_bytes(path, "measurement file", limit=100)
    with pytest.raises(InputError, match="no such measurement file"):
        read_input_bytes(tmp_path / "missing.csv", "measurement file", limit=100)


def test_a_link_to_a_special_file_is_the_special_file(fifo, tmp_path):
    link = tmp_path / "data.csv"
    link.symlink_to("/dev/zero")
    with deadline(20), pytest.raises(InputError, match="is a device"):
        read_input_bytes(link, "measurement file", limit=100)


def test_the_size_bound_holds(tmp_path):
    path = tmp_path / "big.csv"
    path.write_bytes(b"x" * 1001)
    with pytest.raises(InputError, match="larger than the 1000 bytes"):
        read_input_bytes(path, "measurement file", limit=1000)
    assert read_input_bytes(path, "measurement file", limit=1001) == b"x" * 1001


def test_binary_garbage_is_one_line_naming_the_line(tmp_path):
    path = tmp_path / "garbage.csv"
    path.write_bytes(b"j1_deg,x_mm\n1,2\n\x00\x9f\xff\xfe binary\n")
    with pytest.raises(InputError) as caught:
        read_input_text(path, "measurement file", limit=1000)
    assert str(caught.value) == (f"{path}: line 3: byte 0x9f is not UTF-8 text; the measurement file must be text "
                                 "saved as UTF-8")


def test_a_byte_order_mark_is_dropped(tmp_path):
    path = tmp_path / "bom.csv"
    path.write_bytes(b"\xef\xbb\xbfa,b\n")
    assert read_input_text(path, "table", limit=100) == "a,b\n"


@pytest.mark.parametrize("kind, text", [
    ("json", "[" * 50_000 + "]" * 50_000),
    ("json", '{"a":' * 50_000 + "1" + "}" * 50_000),
    ("json", "[" * (MAX_NESTING + 1) + "]" * (MAX_NESTING + 1)),
    ("yaml", "a: " + "[" * 50_000 + "]" * 50_000),
    ("yaml", "".join(" " * i + "- \n" for i in range(MAX_NESTING + 5))),  # block nesting: no bracket at all
    ("toml", "a = " + "[" * 50_000 + "]" * 50_000),
])
def test_nesting_is_bounded_without_a_recursion_error(kind, text):
    with pytest.raises(InputError, match="nested"):
        if kind == "json":
            parse_json(text, "deep")
        else:
            parse_settings(text, "deep", kind)


def test_nesting_up_to_the_bound_is_read():
    depth = MAX_NESTING
    assert parse_json("[" * depth + "]" * depth, "ok") is not None
    nested = []
    for _ in range(depth - 2):
        nested = [nested]
    assert parse_settings("a: " + "[" * (depth - 1) + "]" * (depth - 1), "ok") == {"a": nested}


@pytest.mark.parametrize("text, said", [
    ('{"a": NaN}', "NaN is not a number JSON allows"),
    ('{"a": -Infinity}', "-Infinity is not a number JSON allows"),
    ('{"a": 1, "a": 2}', "key 'a' is given twice"),
    ('{"a": ' + "9" * 5000 + "}", "$.a: an integer of 5000 digits is beyond the range of a number"),
    ('{"a": 1', "not JSON (line 1, column 8"),
])
def test_json_that_would_be_read_wrongly_is_refused(text, said):
    with pytest.raises(InputError, match=re.escape(said)):
        parse_json(text, "r.json")


def test_yaml_aliases_and_repeated_keys_are_refused():
    with pytest.raises(InputError, match=r"line 2: YAML aliases \(\*x\) are refused"):
        parse_settings("a: &x [1, 2]\nb: *x\n", "s.yaml")
    with pytest.raises(InputError, match="line 2: key 'a' is given twice"):
        parse_settings("a: 1\na: 2\n", "s.yaml")


def test_every_file_read_is_recorded_by_device_and_inode(tmp_path):
    path = tmp_path / "r.json"
    path.write_text("{}")
    with recording_inputs() as record:
        read_json_file(path, "result")
    st = os.stat(path)
    assert record == [(str(path), st.st_dev, st.st_ino)]


# ---------------------------------------------------------------------------------------
# Every input option of every command goes through it
# ---------------------------------------------------------------------------------------
#: Metavars (or positional names) of options that name a file the run reads.
_FILE_WORDS = re.compile(r"CSV|FILE|JSON|YAML|URDF|LOG|MEAS|DIAGNOSIS|RESULT|OLD|NEW|\.csv|\.json|\.ya?ml")


def _input_options():
    """(command words, option or positional metavar) of every input file the parser names."""
    found = set()

    def walk(parser, words):
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    walk(sub, (*words, name))
            elif action.type not in OUTPUT_TYPES and action.nargs != 0 and action.type is None:
                label = action.option_strings[0] if action.option_strings else action.metavar
                if _FILE_WORDS.search(action.metavar or action.dest.upper()):
                    found.add((" ".join(words), label))

    walk(build_parser(), ())
    return found


#: For each input: a command line reaching its read, ``@`` standing for the special file, M a
#: measurement CSV, D and D2 diagnosis JSONs, T a tracker export, OUT/DIR outputs in tmp_path.
_CASES = {
    ("pose", "--robot"): ["pose", "--robot", "@"],
    ("montecarlo", "--robot"): ["montecarlo", "--samples", "10", "--robot", "@"],
    ("montecarlo", "--config"): ["montecarlo", "--samples", "10", "--config", "@.yaml"],
    ("sensitivity", "--robot"): ["sensitivity", "--robot", "@"],
    ("sensitivity", "--config"): ["sensitivity", "--config", "@.toml"],
    ("tolerance", "--robot"): ["tolerance", "--robot", "@"],
    ("tolerance", "--config"): ["tolerance", "--config", "@.yaml"],
    ("trajectory", "--robot"): ["trajectory", "--robot", "@"],
    ("trajectory", "--config"): ["trajectory", "--config", "@.yml"],
    ("trajectory", "--file"): ["trajectory", "--file", "@"],
    ("simulate", "--robot"): ["simulate", "--random", "--out", "OUT", "--robot", "@"],
    ("simulate", "--scenario"): ["simulate", "--scenario", "@.yaml", "--out", "OUT"],
    ("simulate", "--poses"): ["simulate", "--random", "--poses", "@", "--out", "OUT"],
    ("import", "TRACKER_FILE"): ["import", "@", "--out", "OUT"],
    ("import", "--joints"): ["import", "T", "--joints", "@", "--out", "OUT"],
    ("import", "--robot"): ["import", "T", "--robot", "@", "--out", "OUT"],
    ("view", "--robot"): ["view", "--robot", "@", "--view", "OUT"],
    ("diagnose", "MEASUREMENTS.csv"): ["diagnose", "@"],
    ("diagnose", "--robot"): ["diagnose", "M", "--robot", "@"],
    ("compare", "OLD"): ["compare", "@", "D"],
    ("compare", "NEW"): ["compare", "D", "@"],
    ("compare", "--poses"): ["compare", "D", "D2", "--poses", "@"],
    ("compare", "--robot"): ["compare", "D", "D2", "--robot", "@"],
    ("plan-poses", "MEASUREMENTS.csv"): ["plan-poses", "@", "-k", "3", "--out", "OUT"],
    ("plan-poses", "--candidates"): ["plan-poses", "M", "-k", "3", "--out", "OUT", "--candidates", "@"],
    ("plan-poses", "--robot"): ["plan-poses", "M", "-k", "3", "--out", "OUT", "--robot", "@"],
    ("predict", "--train"): ["predict", "--train", "@", "--query", "M"],
    ("predict", "--query"): ["predict", "--train", "M", "--query", "@"],
    ("predict", "--robot"): ["predict", "--train", "M", "--query", "M", "--robot", "@"],
    ("compensate", "--train"): ["compensate", "--train", "@", "--targets", "M"],
    ("compensate", "--targets"): ["compensate", "--train", "M", "--targets", "@"],
    ("compensate", "--robot"): ["compensate", "--train", "M", "--targets", "M", "--robot", "@"],
    ("iso9283 plan", "--robot"): ["iso9283", "plan", "--out", "OUT", "--robot", "@"],
    ("iso9283 evaluate", "MEAS.csv"): ["iso9283", "evaluate", "@"],
    ("iso9283 evaluate", "--frame-from"): ["iso9283", "evaluate", "M", "--frame-from", "@"],
    ("iso9283 evaluate", "--model"): ["iso9283", "evaluate", "M", "--model", "@"],
    ("iso9283 evaluate", "--robot"): ["iso9283", "evaluate", "M", "--robot", "@"],
    ("report", "RESULT.json"): ["report", "@", "--out", "DIR"],
    ("export", "DIAGNOSIS.json"): ["export", "@", "--to", "DIR"],
    ("export", "--targets"): ["export", "D", "--to", "DIR", "--targets", "@"],
    ("export", "--measurements"): ["export", "D", "--to", "DIR", "--measurements", "@"],
    ("export", "--check"): ["export", "D", "--to", "DIR", "--check", "@"],
    ("iso9283 evaluate", "--path"): ["iso9283", "evaluate", "M", "--path", "@"],
    ("report", "--campaign"): ["report", "D", "--out", "DIR", "--campaign", "@.yaml"],
    ("diagnose", "--campaign"): ["diagnose", "M", "--out", "DIR", "--campaign", "@.yaml"],
    ("compare", "--campaign"): ["compare", "D", "D2", "--out", "DIR", "--campaign", "@.yaml"],
    ("iso9283 evaluate", "--campaign"): ["iso9283", "evaluate", "M", "--out", "DIR", "--campaign", "@.yaml"],
    ("export", "--program"): ["export", "D", "--to", "DIR", "--program", "@.script"],
    ("plan-poses", "--targets"): ["plan-poses", "M", "-k", "3", "--out", "OUT", "--targets", "@"],
}
# every command that loads a robot takes its own kinematics (--kinematics FILE) where it takes --robot
_CASES.update({(command, "--kinematics"): [("--kinematics" if w == "--robot" else "@.yaml" if w == "@" else w)
                                           for w in argv]
               for (command, option), argv in list(_CASES.items()) if option == "--robot"})


def test_every_input_option_has_a_case():
    """A new command or input option fails here until it is added to the cases below (and so
    tried with a pipe and a device)."""
    assert _input_options() == set(_CASES)


@pytest.fixture(scope="module")
def campaign(small_campaign, tmp_path_factory):
    csv, d = small_campaign
    d2 = tmp_path_factory.mktemp("inputs") / "d2.json"
    d2.write_bytes(d.read_bytes())
    return {"M": csv, "D": d, "D2": d2, "T": REPO / "examples" / "tracker_export.txt"}


@pytest.mark.parametrize("special", ["pipe", "device"])
@pytest.mark.parametrize("case", sorted(_CASES))
def test_every_input_refuses_a_special_file_in_one_line(case, special, campaign, tmp_path, capsys):
    argv = []
    for word in _CASES[case]:
        if word.startswith("@"):
            path = tmp_path / f"special{word[1:]}"
            if special == "pipe":
                os.mkfifo(path)
            else:
                path.symlink_to("/dev/zero")  # read only: the opener refuses it before reading
            word = path
        elif word in campaign:
            word = campaign[word]
        elif word in ("OUT", "DIR"):
            word = tmp_path / ("out.csv" if word == "OUT" else "dir")
        argv.append(str(word))
    with deadline(120):
        code, out, err = run(argv, capsys)
    assert code == 2, err
    assert_one_line(err)
    assert re.search(r"(a named pipe|a device|not a regular file)", err), err
    assert not (tmp_path / "out.csv").exists() and not (tmp_path / "dir").exists()


@pytest.mark.parametrize("argv, file, said", [
    (["export", "F", "--to", "DIR"], "deep.json", "nested more than"),
    (["report", "F", "--out", "DIR"], "deep.json", "nested more than"),
    (["compare", "F", "D"], "deep.json", "nested more than"),
    (["iso9283", "evaluate", "M", "--model", "F"], "deep.json", "nested more than"),
    (["simulate", "--scenario", "F", "--out", "OUT"], "deep.yaml", "nested too deeply"),
    (["export", "F", "--to", "DIR"], "garbage.json", "is not UTF-8 text"),
    (["report", "F", "--out", "DIR"], "garbage.json", "is not UTF-8 text"),
    (["diagnose", "F"], "garbage.csv", "is not UTF-8 text"),
    (["import", "F", "--out", "OUT"], "zeros.txt", "OUT"),
])
def test_deep_or_binary_files_are_one_line(argv, file, said, campaign, tmp_path, capsys):
    path = tmp_path / file
    if file.startswith("deep"):
        path.write_text("[" * 50_000 + "]" * 50_000 if file.endswith("json") else "a: " + "[" * 50_000 + "]" * 50_000)
    elif file.startswith("garbage"):
        path.write_bytes(bytes(range(256)) * 40)
    else:
        path.write_bytes(b"\x00" * 100_000)
    words = {"F": path, "OUT": tmp_path / "out.csv", "DIR": tmp_path / "dir", **campaign}
    with deadline(120):
        code, out, err = run([str(words.get(a, a)) for a in argv], capsys)
    assert code == 2, err
    assert_one_line(err, str(path) if said != "OUT" else "")
    if said != "OUT":
        assert said in err
    assert "unexpected error" not in err and "Recursion" not in err
    assert not (tmp_path / "out.csv").exists() and not (tmp_path / "dir").exists()


def test_a_json_result_is_read_once_however_named(campaign, tmp_path, capsys):
    """Issue 29 item 7: the same result through two paths is taken twice no more."""
    link = tmp_path / "again.json"
    link.symlink_to(campaign["D"])
    code, out, err = run(["report", campaign["D"], link, "--out", tmp_path / "r"], capsys)
    assert code == 2
    assert_one_line(err, "is given twice")
    assert json.loads(campaign["D"].read_text())  # untouched
