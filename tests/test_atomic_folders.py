"""Output folders (issue 12): one nobody can write to, root included, is refused before the work.
"""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from tcr_accuracy import atomic
from tcr_accuracy.cli import main

#: The folder holding the package under test, for the command lines run in a subprocess.
SOURCE = str(Path(atomic.__file__).resolve().parents[1])

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


def temporary_leftovers(parent: Path) -> list[str]:
    """The commit's ``.<name>.<random>.tmp`` folders and files under parent."""
    return [str(p) for p in parent.rglob(".*.tmp")]


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
        problem = (atomic.output_file_problem if option == "--json" else atomic.output_folder_problem)(target)
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
    assert atomic.output_file_problem(tmp_path / "x.json") is None
    assert atomic.output_folder_problem(tmp_path / "a" / "b") is None
    assert list(tmp_path.iterdir()) == []
