"""The outputs a run writes, under attack (issues 12 and 22): paths checked before the work, an
output over an input or another output, and what a failed or stopped run leaves behind
(nothing, or every file). Signals are sent to an in-process stand-in of Python's signal
module (``fake_signals``) or inside a child process the test starts, never to pytest itself.

The rules every test here holds the command to, and the helpers, are in ``hostile.py``.
"""

import json
import signal

import pytest
from hypothesis import given, settings, strategies as st

from hostile import assert_one_line, m60_rows, must_not_run, run


# ---------------------------------------------------------------------------------------
# Output paths checked before the work (12: 1; 22: 6)
# ---------------------------------------------------------------------------------------
_MC = ["montecarlo", "--samples", "200", "--tail-samples", "0", "--view-samples", "20", "--quiet"]


def test_12_01_output_paths_are_checked_before_any_work(tmp_path, capsys, monkeypatch):
    from tcr_accuracy.analysis import montecarlo

    monkeypatch.setattr(montecarlo, "run_monte_carlo", must_not_run)
    (tmp_path / "f").write_text("a file")
    code, out, err = run([*_MC, "--json", tmp_path / "mc.json", "--view", tmp_path / "v.html",
                          "--plots", tmp_path / "pl", "--out", tmp_path / "f"], capsys)
    assert code == 2
    assert_one_line(err, f"--out {tmp_path / 'f'}: exists and is not a folder")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f"]


@pytest.mark.parametrize("option, make", [
    ("--json", lambda d: d / "missing" / "x.json"),  # its folder does not exist
    ("--json", lambda d: d),  # a folder where a file is wanted
    ("--view", lambda d: d / "missing" / "v.html"),
    ("--plots", lambda d: d / "file" / "sub"),  # under a file
])
def test_12_01_bad_output_paths_are_refused_first(option, make, tmp_path, capsys):
    (tmp_path / "file").write_text("x")
    target = make(tmp_path)
    code, out, err = run([*_MC, option, target], capsys)
    assert code == 2
    assert_one_line(err, f"{option} {target}: ")
    assert any(w in err for w in ("does not exist", "is a folder", "is a file")), err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]


@pytest.mark.parametrize("argv, fragment", [
    (["diagnose", "IN", "--json", "IN"], "--json IN: is also MEASUREMENTS.csv IN, an input"),
    (["simulate", "--n", "5", "--out", "T/s.csv", "--truth", "T/s.csv"], "--truth T/s.csv: the same file as --out"),
    (["diagnose", "IN", "--json", "T/x", "--as-built-urdf", "T/x"], "--json T/x: the same file as --as-built-urdf"),
    (["diagnose", "IN", "--json", "T/x.effects.yaml", "--as-built-urdf", "T/x.urdf"],
     "the same file as --as-built-urdf's side file"),
    (["compensate", "--train", "IN", "--targets", "IN2", "--csv", "IN2"], "--csv IN2: is also --targets IN2"),
    (["plan-poses", "IN", "-k", "3", "--out", "IN"], "--out IN: is also MEASUREMENTS.csv IN"),
    (["import", "IN2", "--joints", "IN", "--out", "IN"], "--out IN: is also --joints IN"),
])
def test_22_06_an_output_over_an_input_or_another_output_is_refused(argv, fragment, m60, tmp_path, capsys):
    import shutil

    shutil.copy(m60, tmp_path / "in.csv")
    shutil.copy(m60, tmp_path / "in2.csv")
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}

    def spelt(a):
        return a.replace("IN2", str(tmp_path / "in2.csv")).replace("IN", str(tmp_path / "in.csv")).replace(
            "T/", f"{tmp_path}/")

    code, out, err = run([spelt(a) for a in argv], capsys)
    assert code == 2 and out == ""
    assert_one_line(err, spelt(fragment))
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before


@settings(max_examples=60, deadline=None, derandomize=True)
@given(st.sampled_from(["./", "sub/../", "", "ABS", "LINK/"]), st.sampled_from(["./", "sub/../", "", "ABS", "LINK/"]),
       st.booleans(), st.booleans())
def test_fuzz_22_06_two_spellings_of_one_file_collide_two_names_do_not(first, second, same_name, exists):
    import os
    import tempfile
    from pathlib import Path

    from tcr_accuracy.cli import build_parser
    from tcr_accuracy.cli.output_paths import outputs_of_command
    from tcr_accuracy.exceptions import InputError

    with tempfile.TemporaryDirectory() as folder:
        base = Path(folder)
        (base / "sub").mkdir()
        (base / "link").symlink_to(base)
        if exists:
            (base / "a.csv").write_text("x")

        def spell(prefix, name):
            prefix = prefix.replace("ABS", f"{base}/").replace("LINK/", f"{base}/link/")
            return prefix + name

        cwd = os.getcwd()
        os.chdir(base)
        try:
            args = build_parser().parse_args(["simulate", "--out", spell(first, "a.csv"),
                                              "--truth", spell(second, "a.csv" if same_name else "b.csv")])
            try:
                outputs_of_command(build_parser(), args)
            except InputError as exc:
                assert same_name, exc
                assert str(exc).startswith("--truth ") and "\n" not in str(exc)
                return
            assert not same_name
        finally:
            os.chdir(cwd)


# ---------------------------------------------------------------------------------------
# What a failed run leaves behind (12: 2, 3; 22: 3, 19, 25, 26, 32)
# ---------------------------------------------------------------------------------------
def test_12_02_a_failed_diagnose_leaves_no_as_built_urdf(measurements, tmp_path, capsys, monkeypatch):
    def fail(payload, target):  # the JSON, written after the as-built URDF, cannot be written
        raise OSError(28, "No space left on device")

    monkeypatch.setattr("tcr_accuracy.cli.output.emit_json", fail)
    code, out, err = run(["diagnose", measurements, "--effects", "joint_offsets", "--quiet",
                          "--as-built-urdf", tmp_path / "ab.urdf", "--json", tmp_path / "d.json"], capsys)
    assert code in (1, 2)
    assert list(tmp_path.iterdir()) == []  # neither ab.urdf nor ab.effects.yaml


def test_12_03_a_failed_simulate_leaves_no_csv(tmp_path, capsys, monkeypatch):
    code, out, err = run(["simulate", "--random", "--n", "20", "--out", tmp_path / "st.csv",
                          "--truth", tmp_path / "nowhere" / "t.yaml"], capsys)
    assert code == 2
    assert_one_line(err, "--truth", "does not exist")

    def fail(truth, path):
        raise RuntimeError("truth could not be written")

    monkeypatch.setattr("tcr_accuracy.analysis.simulate.truth_text", fail)
    code, out, err = run(["simulate", "--random", "--n", "20", "--out", tmp_path / "st.csv",
                          "--truth", tmp_path / "t.yaml"], capsys)
    assert code == 1
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("argv", [
    ["diagnose", "M", "--effects", "joint_offsets", "--json", "/dev/full", "--as-built-urdf", "T/ab.urdf"],
    ["diagnose", "M", "--effects", "joint_offsets", "--out", "T/rep", "--json", "/dev/full"],
    ["predict", "--train", "M", "--query", "P", "--method", "kriging", "--csv", "T/p.csv", "--json", "/dev/full"],
    ["simulate", "--n", "5", "--out", "/dev/full", "--truth", "T/t.yaml"],
])
def test_22_03_19_a_full_device_fails_before_any_regular_file_lands(argv, m60, tmp_path, capsys):
    from conftest import REPO

    poses = REPO / "examples" / "poses.csv"  # commanded joints only: a query, not a training pose re-measured
    code, out, err = run([str(m60) if a == "M" else str(poses) if a == "P" else a.replace("T/", f"{tmp_path}/")
                          for a in argv], capsys)
    assert code == 2 and out == ""
    assert_one_line(err, "/dev/full: cannot write (No space left on device)")  # no "written to" line first
    assert list(tmp_path.iterdir()) == []


def test_22_25_json_on_stdout_only_once_the_files_are_written(m60, capsys):
    code, out, err = run(["diagnose", m60, "--effects", "joint_offsets", "--json", "-", "--quiet",
                          "--as-built-urdf", "/dev/full"], capsys)
    assert code == 2 and out == ""
    code, out, err = run(["diagnose", m60, "--effects", "joint_offsets", "--json", "-", "--quiet"], capsys)
    assert code == 0 and json.loads(out)["steps"]


def test_22_26_an_as_built_urdf_on_a_device_or_with_its_side_file_unwritable_is_refused(m60, tmp_path, capsys):
    import os

    code, out, err = run(["diagnose", m60, "--as-built-urdf", "/dev/null"], capsys)
    assert code == 2
    assert_one_line(err, "--as-built-urdf /dev/null: not a regular file", "null.effects.yaml")
    assert not os.path.lexists("/dev/null.effects.yaml")
    (tmp_path / "ab.effects.yaml").mkdir()
    code, out, err = run(["diagnose", m60, "--as-built-urdf", tmp_path / "ab.urdf"], capsys)
    assert code == 2
    assert_one_line(err, f"--as-built-urdf {tmp_path / 'ab.urdf'}: its side file", "is a folder")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ab.effects.yaml"]


def test_22_32_warnings_and_status_lines_are_held_until_the_run_succeeds(m60, tmp_path, capsys):
    from conftest import REPO

    query = tmp_path / "q.csv"  # j1 = 400 deg in the last row: outside its limits, a warning
    lines = (REPO / "examples" / "poses.csv").read_text().splitlines()
    query.write_text("\n".join([*lines[:-1], "400," + lines[-1].split(",", 1)[1]]) + "\n")
    tracker = tmp_path / "t.csv"
    tracker.write_text("X [mm];Y [mm];Z [mm];j1_deg;j2_deg;j3_deg;j4_mm;j5_deg;j6_deg\n"
                       + "".join(f"{x};{y};{z};{j.replace(',', ';')}\n" for x, y, z, j in m60_rows(m60, 10)))
    for argv in (["montecarlo", "--q", "0", "0", "0", "900", "0", "0", "--samples", "200", "--tail-samples", "0"],
                 ["predict", "--train", m60, "--query", query, "--method", "kriging"],
                 ["compensate", "--train", m60, "--targets", query, "--method", "kriging"],
                 ["import", tracker, "--out", "/dev/full"]):
        target = [] if argv[0] == "import" else ["--json", "/dev/full"]
        code, out, err = run([*argv, *target], capsys)
        assert code == 2 and out == ""
        assert_one_line(err, "/dev/full: cannot write")
        code, out, err = run([*argv[:-2], "--out", tmp_path / "m.csv"] if argv[0] == "import" else argv, capsys)
        assert code == 0, err
        assert ("tcr-accuracy: warning:" in err) == (argv[0] != "import")  # shown when the run succeeds
        assert ("written to" in err) == (argv[0] == "import")


# ---------------------------------------------------------------------------------------
# What a stopped run leaves behind (12: 4; 22: 27)
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["SIGTERM", "SIGHUP"])  # a kill; the terminal closed
def test_12_04_22_27_a_stop_signal_mid_run_is_an_interrupt_that_leaves_nothing(name, tmp_path, capsys, monkeypatch,
                                                                             fake_signals):
    from tcr_accuracy.analysis import simulate

    real = simulate.truth_text
    signum = getattr(fake_signals, name)

    def stopped(truth, path):  # the CSV is written (staged) when the signal comes
        fake_signals.send(signum)
        return real(truth, path)

    monkeypatch.setattr(simulate, "truth_text", stopped)
    code, out, err = run(["simulate", "--random", "--n", "20", "--out", tmp_path / "st.csv",
                          "--truth", tmp_path / "t.yaml"], capsys)
    assert fake_signals.sent == [signum]
    assert code == 130
    assert_one_line(err, "interrupted")
    assert list(tmp_path.rglob("*")) == []  # no CSV, truth or temporary file
    assert fake_signals.handlers == {fake_signals.SIGINT: signal.default_int_handler,  # the defaults back
                                     fake_signals.SIGTERM: fake_signals.SIG_DFL,
                                     fake_signals.SIGHUP: fake_signals.SIG_DFL}


def test_12_04_sigterm_during_the_commit_leaves_nothing(tmp_path, capsys, monkeypatch, fake_signals):
    # the commit writes its temporary files after the command returns: SIGTERM then is still
    # an interrupt that removes them, not a death (SignalDeath) that leaves them beside the targets
    from tcr_accuracy.cli import staging

    real = staging.prepare

    def terminated(target, data):
        fake_signals.send(fake_signals.SIGTERM)
        return real(target, data)

    monkeypatch.setattr(staging, "prepare", terminated)
    code, out, err = run(["pose", "--json", tmp_path / "p.json"], capsys)
    assert fake_signals.sent == [fake_signals.SIGTERM]
    assert code == 130, err
    assert list(tmp_path.iterdir()) == []


def test_12_04_a_signal_during_the_renames_waits_for_them(tmp_path, monkeypatch, fake_signals):
    # SIGTERM arriving while a run's files are renamed into place: all of them land, then it stops
    import os

    from tcr_accuracy.cli import staging, write_file

    renamed = []
    real_replace = os.replace

    def replace(src, dst, **fds):
        if not renamed:
            fake_signals.send(fake_signals.SIGTERM)  # held until the commit is done
        renamed.append(dst)
        real_replace(src, dst, **fds)

    monkeypatch.setattr(write_file.os, "replace", replace)
    stopped = []
    fake_signals.signal(fake_signals.SIGTERM, lambda *a: stopped.append(len(renamed)))
    with staging.staged_outputs():
        for name in ("a.png", "b.png", "index.html"):
            staging.write_text(tmp_path / name, name)
    assert stopped == [3]  # delivered after the third rename, not after the first
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.png", "b.png", "index.html"]


def test_22_27_a_signal_during_the_renames_ends_the_run_with_exit_0(tmp_path, capsys, monkeypatch, fake_signals):
    import os

    from tcr_accuracy.cli import write_file

    real_replace = os.replace

    def replace(src, dst, **fds):  # SIGTERM in the commit window: held, delivered after the renames
        fake_signals.send(fake_signals.SIGTERM)
        real_replace(src, dst, **fds)

    monkeypatch.setattr(write_file.os, "replace", replace)
    code, out, err = run(["pose", "--json", tmp_path / "p.json"], capsys)
    assert fake_signals.sent == [fake_signals.SIGTERM]
    assert fake_signals.raised == [fake_signals.SIGTERM]  # held in the renames, raised again after them
    assert code == 0, err
    assert "interrupted" not in err
    assert json.loads((tmp_path / "p.json").read_text())["robot"] == "tool_changer"
    assert [p.name for p in tmp_path.iterdir()] == ["p.json"]


#: A child process that stops itself with a real signal mid-run and during the renames (the
#: stand-in above aside, the one check that Python delivers them as the stand-in does); prints
#: what each run returned and left, as JSON.
_SIGNALLED_CHILD = r"""
import json, os, signal, sys
from pathlib import Path
from tcr_accuracy.analysis import simulate
from tcr_accuracy.cli import main, write_file

folder = Path(sys.argv[1])
real_truth, real_replace = simulate.truth_text, os.replace

def terminated(truth, path):
    os.kill(os.getpid(), signal.SIGTERM)
    return real_truth(truth, path)

def replace(src, dst, **fds):
    os.kill(os.getpid(), signal.SIGTERM)
    real_replace(src, dst, **fds)

simulate.truth_text = terminated
mid_run = main(["simulate", "--random", "--n", "20", "--out", str(folder / "a" / "st.csv"),
                "--truth", str(folder / "a" / "t.yaml")])
simulate.truth_text, write_file.os.replace = real_truth, replace
renames = main(["pose", "--json", str(folder / "b" / "p.json")])
print(json.dumps({"mid_run": [mid_run, sorted(p.name for p in (folder / "a").iterdir())],
                  "renames": [renames, sorted(p.name for p in (folder / "b").iterdir())],
                  "sigterm_default": signal.getsignal(signal.SIGTERM) == signal.SIG_DFL}))
"""


def test_12_04_22_27_a_real_sigterm_in_a_child_process_is_an_interrupt_or_waits_for_the_renames(tmp_path):
    import subprocess
    import sys

    import tcr_accuracy

    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    src = str(__import__("pathlib").Path(tcr_accuracy.__file__).parents[1])
    done = subprocess.run([sys.executable, "-c", _SIGNALLED_CHILD, str(tmp_path)], capture_output=True, text=True,
                          timeout=180, env={"PYTHONPATH": src, "OPENBLAS_NUM_THREADS": "1", "PATH": "/usr/bin:/bin"})
    assert done.returncode == 0, done.stderr[-2000:]
    said = json.loads(done.stdout.splitlines()[-1])
    assert said == {"mid_run": [130, []], "renames": [0, ["p.json"]], "sigterm_default": True}, said
    assert done.stderr.splitlines() == ["tcr-accuracy: interrupted"]


def test_22_27_leftovers_of_a_killed_run_are_cleaned_by_the_next_run_on_the_same_target(tmp_path, capsys):
    import subprocess
    import sys

    dead = 2**22 + 12345  # above Linux's largest pid (4194304): no such process
    (tmp_path / f".p.json.{dead}.abc123.tmp").write_text("half a file")
    (tmp_path / f".rep.{dead}.x1y2.tmp").mkdir()
    (tmp_path / f".rep.{dead}.x1y2.tmp" / "index.html").write_text("half a report")
    concurrent = subprocess.Popen([sys.executable, "-c", "import sys; sys.stdin.read()"], stdin=subprocess.PIPE)
    try:  # a concurrent run (a child of this test, alive until its stdin closes): its file is kept
        live = f".p.json.{concurrent.pid}.zz9.tmp"
        (tmp_path / live).write_text("being written")
        (tmp_path / f".other.json.{dead}.q.tmp").write_text("another target's: not this run's business")
        assert run(["pose", "--json", tmp_path / "p.json"], capsys)[0] == 0
    finally:
        concurrent.communicate(timeout=60)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([f".other.json.{dead}.q.tmp", live, "p.json",
                                                                 f".rep.{dead}.x1y2.tmp"])
    code, out, err = run(["montecarlo", "--samples", "100", "--tail-samples", "0", "--quiet", "--plots",
                          tmp_path / "rep"], capsys)
    assert code == 0, err
    assert not (tmp_path / f".rep.{dead}.x1y2.tmp").exists() and (tmp_path / "rep").is_dir()


# ---------------------------------------------------------------------------------------
# Special files, symbolic links and modes (12: 5)
# ---------------------------------------------------------------------------------------
def test_12_05_special_files_symlinks_and_modes(tmp_path, capsys):
    import os
    import stat
    import threading

    # a named pipe is written into, not renamed over
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    received = []
    reader = threading.Thread(target=lambda: received.append(fifo.read_bytes()))
    reader.start()
    code, out, err = run(["pose", "--json", fifo], capsys)
    reader.join(timeout=30)
    assert code == 0, err
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    assert json.loads(received[0])["robot"] == "tool_changer"
    # a symlink is written through; a private file stays private
    real = tmp_path / "real.json"
    real.write_text("{}")
    real.chmod(0o600)
    link = tmp_path / "link.json"
    link.symlink_to(real)
    assert run(["pose", "--json", link], capsys)[0] == 0
    assert link.is_symlink() and json.loads(real.read_text())["robot"] == "tool_changer"
    assert stat.S_IMODE(real.stat().st_mode) == 0o600
    # a new file follows the umask
    old = os.umask(0o027)
    try:
        assert run(["pose", "--json", tmp_path / "new.json"], capsys)[0] == 0
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "new.json").stat().st_mode) == 0o640
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link.json", "new.json", "pipe", "real.json"]
