"""Folders written whole (issue 12, "every file of a run staged and committed together"): a
report or plots folder is prepared beside the old one and swapped in at once, the user's
other files carried over; a failure or a kill leaves it all old or all new, never mixed; and
an output folder nobody can write to, root included, is refused before the work.
"""

import os
import signal
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from tcr_accuracy.cli import folder_swap, main, output_paths, staging
from tcr_accuracy.exceptions import InputError

#: The folder holding the package under test, for the command lines run in a subprocess.
SOURCE = str(Path(staging.__file__).resolve().parents[2])

_MC = ["montecarlo", "--samples", "200", "--tail-samples", "0", "--view-samples", "20", "--quiet"]


def run(argv, capsys):
    """(exit code, stdout, stderr) of the command line run in-process."""
    try:
        code = main([str(a) for a in argv])
    except SystemExit as exc:
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def run_cli(*argv):
    """The command line in a subprocess of its own: (exit code, stdout, stderr)."""
    env = {**os.environ, "PYTHONPATH": SOURCE + os.pathsep + os.environ.get("PYTHONPATH", "")}
    result = subprocess.run([sys.executable, "-m", "tcr_accuracy", *map(str, argv)], capture_output=True,
                            text=True, env=env, timeout=300)
    return result.returncode, result.stdout, result.stderr


def snapshot(folder: Path) -> dict:
    """Every entry under folder: relative path -> (kind, mode, bytes or link target)."""
    entries = {}
    for path in sorted(folder.rglob("*")):
        st = path.lstat()
        content = os.readlink(path) if path.is_symlink() else path.read_bytes() if path.is_file() else None
        entries[str(path.relative_to(folder))] = (stat.S_IFMT(st.st_mode), stat.S_IMODE(st.st_mode), content)
    return entries


def temporary_leftovers(parent: Path) -> list[str]:
    """The commit's ``.<name>.<random>.tmp`` folders and files under parent."""
    return [str(p) for p in parent.rglob(".*.tmp")]


def write_report(folder: Path, generation: str, names=("index.html", "report.md", "figure-1.png")) -> None:
    """A stand-in report: every file says which generation wrote it."""
    with staging.staged_outputs():
        staging.stage_folder(folder)
        for name in names:
            staging.write_text(folder / name, f"{generation} {name}")


@pytest.fixture
def old_report(tmp_path):
    """An old report with the user's own files beside it: a note, a subfolder, a symlink."""
    folder = tmp_path / "report"
    write_report(folder, "old")
    (folder / "notes.txt").write_text("mine")
    (folder / "mine").mkdir(mode=0o700)
    (folder / "mine" / "data.csv").write_text("1,2\n")
    (folder / "latest.html").symlink_to("index.html")
    return folder


# ---------------------------------------------------------------------------------------
# (a) committed over an old report: every file new, the user's files still there
# ---------------------------------------------------------------------------------------
def test_a_folder_is_swapped_in_whole_and_keeps_the_users_files(old_report):
    note = (old_report / "notes.txt").stat()
    folder_before = old_report.stat().st_ino
    write_report(old_report, "new")
    assert old_report.stat().st_ino != folder_before  # a new folder took its place, not file by file
    for name in ("index.html", "report.md", "figure-1.png"):
        assert (old_report / name).read_text() == f"new {name}"
    assert (old_report / "notes.txt").read_text() == "mine"
    assert (old_report / "notes.txt").stat().st_ino == note.st_ino  # carried as a hard link
    assert (old_report / "mine" / "data.csv").read_text() == "1,2\n"
    assert stat.S_IMODE((old_report / "mine").stat().st_mode) == 0o700
    assert os.readlink(old_report / "latest.html") == "index.html"
    assert temporary_leftovers(old_report.parent) == []


def test_a_report_run_over_an_old_report_keeps_a_user_file(tmp_path, capsys):
    out = tmp_path / "r"
    assert run([*_MC, "--seed", "1", "--out", out], capsys)[0] == 0
    old = {p.name: p.read_bytes() for p in out.iterdir()}
    (out / "notes.txt").write_text("mine")
    folder_before = out.stat().st_ino
    code, _, err = run([*_MC, "--seed", "2", "--out", out, "--plots", out / "plots"], capsys)
    assert code == 0, err
    assert out.stat().st_ino != folder_before  # swapped in whole, plots inside it
    new = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()}
    assert set(old) <= set(new)
    assert all(new[name] != old[name] for name in old), "a file of the old report survived"
    assert b"--seed 2" in new["index.html"] and b"--seed 2" in new["report.md"]
    assert new["notes.txt"] == b"mine"
    assert sorted(p.suffix for p in (out / "plots").iterdir()) == [".png", ".png"]
    plots_before = (out / "plots").stat().st_ino
    assert run([*_MC, "--seed", "3", "--plots", out / "plots"], capsys)[0] == 0
    assert (out / "plots").stat().st_ino != plots_before  # --plots alone: its folder swapped in whole
    assert temporary_leftovers(tmp_path) == []


def test_a_new_folder_follows_the_umask_a_replaced_one_keeps_its_mode(tmp_path):
    old_umask = os.umask(0o027)
    try:
        write_report(tmp_path / "new" / "deep", "new")
        (tmp_path / "private").mkdir(mode=0o700)
        write_report(tmp_path / "private", "new")
    finally:
        os.umask(old_umask)
    assert stat.S_IMODE((tmp_path / "new" / "deep").stat().st_mode) == 0o750
    assert stat.S_IMODE((tmp_path / "new" / "deep" / "index.html").stat().st_mode) == 0o640
    assert stat.S_IMODE((tmp_path / "private").stat().st_mode) == 0o700
    assert temporary_leftovers(tmp_path) == []


def test_a_symlinked_folder_is_written_through(old_report, tmp_path):
    link = tmp_path / "link"
    link.symlink_to(old_report)
    write_report(link, "new")
    assert link.is_symlink() and os.readlink(link) == str(old_report)
    assert (old_report / "index.html").read_text() == "new index.html"
    assert (old_report / "notes.txt").read_text() == "mine"
    assert temporary_leftovers(tmp_path) == []


def test_without_an_atomic_exchange_the_folder_is_renamed_aside_and_in(old_report, monkeypatch):
    monkeypatch.setattr(folder_swap, "_exchange", lambda a, b: False)  # another OS, or a filesystem without it
    write_report(old_report, "new")
    assert (old_report / "index.html").read_text() == "new index.html"
    assert (old_report / "notes.txt").read_text() == "mine"
    assert temporary_leftovers(old_report.parent) == []


def test_the_exchange_swaps_two_folders_or_says_it_cannot(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "x").write_text("a")
    (tmp_path / "b").mkdir()
    if folder_swap._exchange(tmp_path / "a", tmp_path / "b"):
        assert (tmp_path / "b" / "x").read_text() == "a" and not (tmp_path / "a" / "x").exists()
    else:  # nothing done: the caller renames twice
        assert (tmp_path / "a" / "x").read_text() == "a" and not (tmp_path / "b" / "x").exists()


def test_nested_folders_are_one_swap_and_other_files_under_them_join_it(tmp_path):
    out = tmp_path / "demo"
    with staging.staged_outputs():
        staging.stage_folder(out / "accuracy")
        staging.write_text(out / "accuracy" / "index.html", "inner")
        staging.write_text(out / "accuracy.json", "{}")
        staging.stage_folder(out)
        staging.write_text(out / "index.html", "outer")
    assert snapshot(out).keys() == {"accuracy", "accuracy/index.html", "accuracy.json", "index.html"}
    assert temporary_leftovers(tmp_path) == []


def test_the_current_folder_is_written_file_by_file(old_report, monkeypatch):
    monkeypatch.chdir(old_report)  # a swap would leave this process (and a shell) in the removed folder
    folder_before = old_report.stat().st_ino
    write_report(Path("."), "new")
    assert old_report.stat().st_ino == folder_before
    assert (old_report / "index.html").read_text() == "new index.html"
    assert (old_report / "notes.txt").read_text() == "mine"
    assert temporary_leftovers(old_report.parent) == []


def test_outside_a_staged_run_files_are_written_one_by_one(old_report):
    folder_before = old_report.stat().st_ino
    staging.stage_folder(old_report)  # nothing to declare it to: a no-op
    staging.write_text(old_report / "index.html", "direct")
    assert old_report.stat().st_ino == folder_before
    assert (old_report / "index.html").read_text() == "direct"


def test_a_file_where_the_old_folder_has_a_folder_is_refused(old_report):
    before = snapshot(old_report)
    with pytest.raises(InputError, match=f"{old_report / 'mine'}: is a folder"):
        write_report(old_report, "new", names=("index.html", "mine"))
    with pytest.raises(InputError, match=f"{old_report / 'notes.txt'}: is a file"):
        write_report(old_report, "new", names=("index.html", "notes.txt/x.png"))
    assert snapshot(old_report) == before
    assert temporary_leftovers(old_report.parent) == []


# ---------------------------------------------------------------------------------------
# (b) a failure during the commit: the old folder byte-identical, no .tmp folder left
# ---------------------------------------------------------------------------------------
def _swap_fails(monkeypatch):
    def fail(new, target):
        raise InputError(f"{target}: cannot write (Device or resource busy)")

    monkeypatch.setattr(folder_swap, "_swap_in", fail)


def _disk_full_at_the_second_file(monkeypatch):
    real, calls = folder_swap.write_flushed, []

    def write(fd, data):
        calls.append(fd)
        if len(calls) == 2:
            os.close(fd)
            raise OSError(28, "No space left on device")
        real(fd, data)

    monkeypatch.setattr(folder_swap, "write_flushed", write)


def _ctrl_c_while_carrying(monkeypatch):
    def interrupted(old, new, device):
        raise KeyboardInterrupt

    monkeypatch.setattr(folder_swap, "_carry", interrupted)


@pytest.mark.parametrize("failure, error", [
    (_swap_fails, InputError), (_disk_full_at_the_second_file, InputError),
    (_ctrl_c_while_carrying, KeyboardInterrupt),
])
def test_b_a_failed_commit_leaves_the_old_folder_as_it_was(failure, error, old_report, monkeypatch):
    before = snapshot(old_report)
    failure(monkeypatch)
    with pytest.raises(error):
        write_report(old_report, "new")
    assert snapshot(old_report) == before
    assert temporary_leftovers(old_report.parent) == []


def test_b_a_failed_commit_of_a_new_folder_leaves_nothing(tmp_path, monkeypatch):
    _swap_fails(monkeypatch)
    with pytest.raises(InputError):
        write_report(tmp_path / "a" / "b" / "report", "new")
    assert list(tmp_path.iterdir()) == []  # nor the parents made for it


def test_b_sigterm_while_the_new_folder_is_prepared_leaves_the_old_one(tmp_path, capsys, monkeypatch,
                                                                      fake_signals):
    out = tmp_path / "r"
    assert run([*_MC, "--out", out], capsys)[0] == 0
    (out / "notes.txt").write_text("mine")
    before = snapshot(out)
    real = folder_swap._carry

    def terminated(old, new, device):  # the CLI turns SIGTERM into an interrupt
        fake_signals.send(fake_signals.SIGTERM)  # were its handler gone: SignalDeath fails the test
        return real(old, new, device)

    monkeypatch.setattr(folder_swap, "_carry", terminated)
    code, _, err = run([*_MC, "--seed", "5", "--out", out], capsys)
    assert fake_signals.sent == [fake_signals.SIGTERM]
    assert code == 130, err
    assert snapshot(out) == before
    assert temporary_leftovers(tmp_path) == []


# ---------------------------------------------------------------------------------------
# (c) a kill (SIGKILL: no clean-up at all) at each step of the commit
# ---------------------------------------------------------------------------------------
_CHILD = r"""
import os, signal, sys
from pathlib import Path
from tcr_accuracy.cli import folder_swap, staging

target, generation, kill_point = Path(sys.argv[1]), sys.argv[2], sys.argv[3]
calls = []


def die_at(name, call, *, after, where=folder_swap):
    real = getattr(where, name)

    def wrapper(*args, **kwargs):
        calls.append(name)
        if not after and calls.count(name) == call:
            os.kill(os.getpid(), signal.SIGKILL)
        result = real(*args, **kwargs)
        if after and calls.count(name) == call:
            os.kill(os.getpid(), signal.SIGKILL)
        return result

    setattr(where, name, wrapper)


if kill_point.startswith("fallback"):
    folder_swap._exchange = lambda a, b: False
if kill_point == "mid-prepare":
    die_at("_write_new_file", 5, after=True)
elif kill_point == "before-swap":
    die_at("_swap_in", 1, after=False)
elif kill_point == "after-exchange":
    die_at("_exchange", 1, after=True)
elif kill_point == "before-old-removed":
    die_at("_remove_tree", 1, after=False)
elif kill_point == "after-first-rename":  # of any kind: where file-by-file renames would mix two runs
    for where, name in ((os, "replace"), (os, "rename"), (folder_swap, "_exchange")):
        die_at(name, 1, after=True, where=where)
elif kill_point == "fallback-after-aside":
    die_at("rename", 1, after=True, where=os)
elif kill_point == "fallback-after-swap":
    die_at("rename", 2, after=True, where=os)

with staging.staged_outputs():
    staging.stage_folder(target)
    for i in range(10):
        staging.write_text(target / f"figure-{i}.png", generation)
    staging.write_text(target / "index.html", generation)
"""


def _commit_in_a_child(target: Path, generation: str, kill_point: str) -> int:
    env = {**os.environ, "PYTHONPATH": SOURCE + os.pathsep + os.environ.get("PYTHONPATH", "")}
    return subprocess.run([sys.executable, "-c", _CHILD, str(target), generation, kill_point], env=env,
                          timeout=120).returncode


def _generation(folder: Path) -> str:
    """'old' or 'new' when every report file of folder says so; 'mixed' otherwise."""
    found = {(folder / f"figure-{i}.png").read_text() for i in range(10)} | {(folder / "index.html").read_text()}
    assert (folder / "notes.txt").read_text() == "mine"
    return found.pop() if len(found) == 1 else "mixed"


@pytest.mark.parametrize("kill_point, expected", [
    ("mid-prepare", "old"), ("before-swap", "old"), ("after-exchange", "new"), ("after-first-rename", "new"),
    ("before-old-removed", "new"),
    ("fallback-after-swap", "new"), ("fallback-after-aside", "missing, both beside"),
])
def test_c_a_kill_at_any_step_leaves_the_folder_all_old_or_all_new(kill_point, expected, tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    if kill_point in ("after-exchange", "after-first-rename") and not folder_swap._exchange(tmp_path / "a",
                                                                                     tmp_path / "b"):
        expected = "old"  # no RENAME_EXCHANGE here: killed before the fallback's renames
    target = tmp_path / "report"
    assert _commit_in_a_child(target, "old", "none") == 0
    (target / "notes.txt").write_text("mine")
    assert _commit_in_a_child(target, "new", kill_point) == -signal.SIGKILL
    assert not [p for p in target.rglob("*") if p.name.endswith(".tmp")]  # never inside the folder
    if expected == "missing, both beside":  # the fallback's one gap (documented): nothing lost
        leftovers = [p for p in tmp_path.iterdir() if p.name.startswith(".report.")]
        assert not target.exists() and sorted(map(_generation, leftovers)) == ["new", "old"]
    else:
        assert _generation(target) == expected


# ---------------------------------------------------------------------------------------
# (d) a folder where no file can be created, for root too: refused before the work
# ---------------------------------------------------------------------------------------
def _can_create_a_file_in(folder: Path) -> bool:
    """The truth, by trying."""
    try:
        os.close(os.open(folder / "attempt", os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
    except OSError:
        return False
    os.unlink(folder / "attempt")
    return True


def _must_not_run(*args, **kwargs):
    raise AssertionError("the work started before the output paths were checked")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc is Linux's")
@pytest.mark.parametrize("option, target", [
    ("--json", "/proc/tcr-accuracy-mc.json"),  # procfs: no file can be created, root included (ENOENT)
    ("--out", "/proc/tcr-accuracy-report"),
    ("--plots", "/proc/self/tcr-accuracy-plots/sub"),
])
def test_d_a_folder_root_cannot_write_either_is_refused_before_the_work(option, target):
    assert not _can_create_a_file_in(Path("/proc"))
    code, out, err = run_cli("montecarlo", "--samples", "50", option, target)
    assert code == 2, err
    lines = err.splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    assert f"{option} {target}: the folder /proc" in lines[0] and "is not writable" in lines[0], err
    assert out == "" and not os.path.lexists(target)


def test_d_the_check_comes_before_the_work(capsys, monkeypatch):
    from tcr_accuracy.analysis import montecarlo

    monkeypatch.setattr(montecarlo, "run_monte_carlo", _must_not_run)
    code, _, err = run([*_MC, "--json", "/proc/tcr-accuracy-mc.json"], capsys)
    assert code == 2 and "not writable" in err, err


@pytest.mark.parametrize("option, name", [("--json", "mc.json"), ("--out", "report"), ("--plots", "")])
def test_d_a_read_only_folder_is_refused_unless_files_can_be_created_there(option, name, tmp_path):
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o555)
    try:
        writable = _can_create_a_file_in(folder)  # False for a user; True for root, who ignores the bits
        target = folder / name if name else folder
        problem = (output_paths.output_file_problem if option == "--json" else output_paths.output_folder_problem)(target)
        assert (problem is None) == writable, problem
        code, out, err = run_cli(*_MC, "--samples", "50", option, target)
        if writable:
            assert code == 0, err
            written = {"--json": target, "--out": target / "index.html", "--plots": target / "cloud_3d.png"}
            assert written[option].is_file()
        else:
            assert code == 2, err
            assert len(err.splitlines()) == 1 and f"{option} {target}: the folder {folder} is not writable" in err
            assert list(folder.iterdir()) == []
        assert temporary_leftovers(tmp_path) == []
    finally:
        folder.chmod(0o755)


def test_d_the_probe_leaves_nothing_behind(tmp_path):
    assert output_paths.output_file_problem(tmp_path / "x.json") is None
    assert output_paths.output_folder_problem(tmp_path / "a" / "b") is None
    assert list(tmp_path.iterdir()) == []
