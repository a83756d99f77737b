"""The one output writer (issue 29 items 1 and 2; issue 27 item 4): no write through a link
planted in an output folder, no output over an input, no two outputs on one path, nothing left
behind, and every command's outputs registered with it.

Decoy files in ``tmp_path`` stand for the files an attacker would aim at (``/etc/passwd``): each
test checks that the decoy is byte for byte what it was.
"""

import argparse
import ast
import json
import math
import os
import stat
from pathlib import Path

import pytest

from hostile import assert_one_line, run
from tcr_accuracy.cli import build_parser
from tcr_accuracy.cli.output_paths import OUTPUT_TYPES, OutputPaths, check_followable
from tcr_accuracy.cli.staging import staged_outputs, write_text
from tcr_accuracy.exceptions import InputError

import tcr_accuracy

PACKAGE = Path(tcr_accuracy.__file__).resolve().parent
DECOY = "root:x:0:0:root:/root:/bin/bash\n"


@pytest.fixture(scope="module")
def campaign(small_campaign):
    """A small simulated campaign: the measurement CSV and its diagnosis JSON (conftest)."""
    return small_campaign


@pytest.fixture
def decoy(tmp_path):
    path = tmp_path / "passwd"
    path.write_text(DECOY)
    return path


def _untouched(decoy: Path) -> None:
    assert decoy.read_text() == DECOY
    assert stat.S_ISREG(os.lstat(decoy).st_mode)


def _leftovers(folder: Path) -> list[str]:
    return [str(p) for p in folder.rglob("*.tmp")]


# ---------------------------------------------------------------------------------------
# Issue 29 item 1: export --to DIR wrote through a symlink planted in DIR
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["as_built.urdf", "as_built.yaml", "joint_offsets_tcp.csv", "mdh.csv",
                                  "mdh_base_tool.csv", "compensation.csv"])
def test_29_01_export_never_writes_through_a_link_planted_in_its_folder(name, campaign, decoy, tmp_path, capsys):
    csv, diagnosis = campaign
    folder = tmp_path / "to"
    folder.mkdir()
    (folder / name).symlink_to(decoy)
    targets = tmp_path / "targets.csv"
    targets.write_text("\n".join(line.split(",x_mm")[0] if i == 0 else ",".join(line.split(",")[:6])
                                 for i, line in enumerate(csv.read_text().splitlines()[:4])) + "\n")
    code, out, err = run(["export", diagnosis, "--to", folder, "--targets", targets], capsys)
    assert code == 2, err
    assert_one_line(err, f"{folder / name}: is a symbolic link", "inside the output folder")
    _untouched(decoy)
    assert sorted(p.name for p in folder.iterdir()) == [name]  # nothing else written
    assert _leftovers(tmp_path) == []


def test_29_01_a_link_in_a_report_or_plots_folder_is_not_followed(decoy, tmp_path, capsys):
    mc = ["montecarlo", "--samples", "100", "--tail-samples", "0", "--quiet"]
    report, plots = tmp_path / "r", tmp_path / "p"
    report.mkdir()
    (report / "index.html").symlink_to(decoy)
    code, out, err = run([*mc, "--out", report], capsys)
    assert code == 2 and "r/index.html: is a symbolic link" in err, err
    plots.mkdir()
    (plots / "cloud_3d.png").symlink_to(decoy)
    code, out, err = run([*mc, "--plots", plots], capsys)
    assert code == 2 and "p/cloud_3d.png: is a symbolic link" in err, err
    _untouched(decoy)
    assert _leftovers(tmp_path) == []


def test_a_link_on_the_way_below_a_named_folder_a_pipe_or_a_file_in_its_place_is_refused(decoy, tmp_path):
    named = tmp_path / "out"
    (named / "sub").mkdir(parents=True)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (named / "via").symlink_to(elsewhere, target_is_directory=True)
    os.mkfifo(named / "pipe.html")
    (named / "file").write_text("x")
    outputs = OutputPaths(folders={named})
    assert outputs.target(named / "sub" / "new.txt").path == named.resolve() / "sub" / "new.txt"
    for path, said in ((named / "via" / "x.png", "via: is a symbolic link"),
                       (named / "pipe.html", "pipe.html: is a device, pipe or socket"),
                       (named / "file" / "x.png", "file: is a file inside the output folder")):
        with pytest.raises(InputError, match=said):
            outputs.target(path)
    assert list(elsewhere.iterdir()) == []


def test_a_path_the_user_named_is_followed_as_named(decoy, tmp_path, capsys):
    # a symlink the user names is what they asked for (as a shell's > would): written through
    link = tmp_path / "latest.json"
    link.symlink_to(decoy)
    assert run(["pose", "--json", link], capsys)[0] == 0
    assert link.is_symlink() and '"robot": "tool_changer"' in decoy.read_text()


@pytest.mark.skipif(os.geteuid() != 0, reason="needs root to give a symlink another owner")
def test_a_link_another_user_planted_in_a_shared_folder_is_not_followed(decoy, tmp_path, capsys):
    # /tmp-like: sticky and world-writable; the kernel (fs.protected_symlinks) would not follow it
    shared = tmp_path / "shared"
    shared.mkdir()
    shared.chmod(0o1777)
    link = shared / "out.json"
    link.symlink_to(decoy)
    os.lchown(link, 4242, 4242)
    with pytest.raises(InputError, match="owned by another user"):
        check_followable(link)
    code, out, err = run(["pose", "--json", link], capsys)
    assert code == 2
    assert_one_line(err, "out.json: a symbolic link in the shared folder", "not followed")
    _untouched(decoy)


def test_outside_every_named_output_is_a_bug_refused(tmp_path):
    outputs = OutputPaths(files={tmp_path / "a.json"})
    with pytest.raises(RuntimeError, match="outside the outputs named"):
        outputs.target(tmp_path / "b.json")


def test_two_writes_on_one_real_path_in_one_run_are_refused(tmp_path):
    (tmp_path / "sub").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "sub", target_is_directory=True)
    with pytest.raises(InputError, match="would write it twice"):
        with staged_outputs(OutputPaths(folders={tmp_path})):
            write_text(tmp_path / "sub" / "x.csv", "one")
            write_text(tmp_path / "sub" / ".." / "sub" / "x.csv", "two")
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["link", "sub"]


# ---------------------------------------------------------------------------------------
# Issue 29 item 2: outputs that are inputs, two outputs on one path
# ---------------------------------------------------------------------------------------
def test_29_02_iso9283_evaluate_json_over_its_measurements(campaign, tmp_path, capsys):
    csv, _ = campaign
    copy = tmp_path / "m.csv"
    copy.write_bytes(csv.read_bytes())
    code, out, err = run(["iso9283", "evaluate", copy, "--json", copy], capsys)
    assert code == 2
    assert_one_line(err, f"--json {copy}: is also MEAS.csv")
    assert copy.read_bytes() == csv.read_bytes()


def test_29_02_iso9283_plan_out_and_json_on_one_file(tmp_path, capsys):
    code, out, err = run(["iso9283", "plan", "--out", tmp_path / "p.csv", "--json", tmp_path / "p.csv"], capsys)
    assert code == 2
    assert_one_line(err, "the same file as")
    assert list(tmp_path.iterdir()) == []


def test_29_02_iso9283_evaluate_json_and_out_on_one_path_leaves_no_tmp(campaign, tmp_path, capsys):
    csv, _ = campaign
    code, out, err = run(["iso9283", "evaluate", csv, "--json", tmp_path / "r.json", "--out", tmp_path / "r.json"],
                         capsys)
    assert code == 2
    assert_one_line(err, "the same file as")
    assert list(tmp_path.iterdir()) == []


def assert_refused_over_its_input(argv, given: Path, capsys) -> None:
    """``argv`` writes into ``given``'s folder at ``given``'s name: refused, the input and its folder as they were."""
    before, entries = given.read_bytes(), sorted(p.name for p in given.parent.iterdir())
    code, out, err = run(argv, capsys)
    assert code == 2
    assert_one_line(err, f"{given}: is also an input of this run")
    assert given.read_bytes() == before and sorted(p.name for p in given.parent.iterdir()) == entries


def test_29_02_export_over_its_own_diagnosis_or_targets(campaign, tmp_path, capsys):
    csv, diagnosis = campaign
    folder = tmp_path / "d"
    folder.mkdir()
    given = folder / "as_built.yaml"
    given.write_bytes(diagnosis.read_bytes())
    assert_refused_over_its_input(["export", given, "--to", folder], given, capsys)
    given.unlink()
    targets = folder / "compensation.csv"
    targets.write_text("j1_deg,j2_deg,j3_deg,j4_mm,j5_deg,j6_deg\n10,20,30,100,10,0\n")
    assert_refused_over_its_input(["export", diagnosis, "--to", folder, "--targets", targets], targets, capsys)


def test_29_02_report_over_its_own_result_even_through_a_hard_link(campaign, tmp_path, capsys):
    _, diagnosis = campaign
    folder = tmp_path / "rep"
    folder.mkdir()
    given = folder / "index.html"
    given.write_bytes(diagnosis.read_bytes())
    assert_refused_over_its_input(["report", given, "--out", folder], given, capsys)
    elsewhere = tmp_path / "result.json"
    os.link(given, elsewhere)  # the same file under another name: still the input
    code, out, err = run(["report", elsewhere, "--out", folder], capsys)
    assert code == 2
    assert_one_line(err, "index.html: is also an input of this run")
    assert given.read_bytes() == diagnosis.read_bytes()
    assert sorted(p.name for p in folder.iterdir()) == ["index.html"]


# ---------------------------------------------------------------------------------------
# Every command: outputs registered, nothing written around the writer
# ---------------------------------------------------------------------------------------
def _commands(parser=None, prefix=()):
    """(command words, its parser) for every command and step of the command line."""
    parser = parser or build_parser()
    found = []
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                steps = _commands(sub, (*prefix, name))
                found += steps or [((*prefix, name), sub)]
    return found


#: Words that say an option names something the run writes.
_WRITES = ("write", "report folder", "folder to write", "the test to run")
#: Options that write nothing though their help says "write", and why.
_NOT_OUTPUTS = {"--targets": "an input (target joints); its help says export then writes compensation.csv",
                "--path": "iso9283 evaluate's input (the commanded path); its help names the command that writes it",
                "--kinematics": "an input (the robot's own kinematics); its help names the files export writes",
                "--program": "export's input (robot programs); the filtered copies go under --to, an output"}


def test_every_output_option_of_every_command_is_registered_with_the_writer():
    """A new command, or a new output option, that names a path the run writes must use an
    output type (cli.output_paths.OUTPUT_TYPES): the writer refuses every path not named so."""
    commands = _commands()
    assert len(commands) >= 18, [c for c, _ in commands]
    unregistered = []
    for words, parser in commands:
        for action in parser._actions:
            if action.nargs == 0 or not action.option_strings or action.option_strings[0] in _NOT_OUTPUTS:  # flags
                continue
            says_writes = any(w in (action.help or "").lower() for w in _WRITES)
            if says_writes and action.type not in OUTPUT_TYPES:
                unregistered.append(f"{' '.join(words)} {action.option_strings[0]}")
            if action.type in OUTPUT_TYPES and not says_writes and action.dest not in ("json", "out", "view", "html"):
                unregistered.append(f"{' '.join(words)} {action.option_strings[0]}: an output whose help does not "
                                    "say what it writes")
    assert not unregistered, unregistered


#: Module -> file-system calls it may make outside the writer, and why.
_ALLOWED_WRITES = {
    "tcr_accuracy.cli.write_file": "the writer itself",
    "tcr_accuracy.cli.folder_swap": "the writer itself",
    "tcr_accuracy.cli.staging": "the writer itself",
    "tcr_accuracy.cli.output_paths": "its probe file: created and removed to test a folder before the work",
    "tcr_accuracy.view.report": "the page copied to a temporary folder for Chromium to print",
    "tcr_accuracy.cli.demo": "the report folder made before its steps check their outputs inside it",
}
#: Writing calls by receiver: a module's functions (os.replace) and any object's methods (Path.write_text).
_WRITES_OF = {"os": {"replace", "rename", "renames", "link", "symlink", "remove", "unlink", "mkdir", "makedirs",
                     "rmdir", "truncate"},
              "shutil": {"copy", "copy2", "copyfile", "copytree", "move", "rmtree"},
              "tempfile": {"mkstemp", "mkdtemp"},
              "np": {"save", "savez", "savetxt"}}
_WRITING_METHODS = {"write_text", "write_bytes", "mkdir", "unlink", "rmdir", "touch", "rename", "symlink_to",
                    "hardlink_to", "to_csv", "savefig"}


def _writes_in(path: Path) -> list[str]:
    """Calls in a module's source that write to the file system: os/shutil/tempfile functions, Path
    methods, a figure saved to anything but the in-memory ``buffer``, and open() in a writing mode
    (the writer's own functions are called by name, not as methods, and are not counted)."""
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if not isinstance(node, ast.Call):
            continue
        func = node.func
        if isinstance(func, ast.Attribute):
            receiver = func.value.id if isinstance(func.value, ast.Name) else None
            if receiver in _WRITES_OF:
                if func.attr in _WRITES_OF[receiver]:
                    found.append(f"{path.name}:{node.lineno} {receiver}.{func.attr}(")
                elif receiver == "os" and func.attr == "open" and any(
                        isinstance(a, ast.Attribute) and a.attr in ("O_WRONLY", "O_RDWR", "O_CREAT")
                        for a in ast.walk(node)):
                    found.append(f"{path.name}:{node.lineno} os.open(writing)")
                continue
            if func.attr in _WRITING_METHODS:
                first = node.args[0] if node.args else None
                if func.attr == "savefig" and isinstance(first, ast.Name) and first.id == "buffer":
                    continue  # into memory
                found.append(f"{path.name}:{node.lineno} .{func.attr}(")
                continue
        if getattr(func, "id", None) == "open" or getattr(func, "attr", None) == "open":
            mode = node.args[1] if len(node.args) > 1 else next((k.value for k in node.keywords if k.arg == "mode"),
                                                                 None)
            if isinstance(mode, ast.Constant) and any(c in str(mode.value) for c in "wax+"):
                found.append(f"{path.name}:{node.lineno} open(..., {mode.value!r})")
    return found


def test_nothing_below_the_writer_writes_a_file():
    """Only the writer (cli.staging, cli.write_file, cli.folder_swap) touches the file system for
    outputs: every other module returns what it would write."""
    offenders = {}
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        module = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        if module in _ALLOWED_WRITES:
            continue
        writes = _writes_in(path)
        if module == "tcr_accuracy.cli":  # os.dup2 of /dev/null over a closed stdout, not a file written
            writes = [w for w in writes if "os.open" not in w]
        if writes:
            offenders[module] = writes
    assert not offenders, offenders


def test_the_writer_check_finds_a_write(tmp_path):
    """The scan above is not blind: it finds each kind of write in a sample module."""
    sample = tmp_path / "sample.py"
    sample.write_text("import os\nfrom pathlib import Path\nPath('a').write_text('x')\nopen('b', 'w')\n"
                      "os.replace('a', 'b')\nos.open('c', os.O_WRONLY | os.O_CREAT)\n'x'.replace('a', 'b')\n")
    found = sorted(w.split(" ", 1)[1] for w in _writes_in(sample))
    assert found == sorted([".write_text(", "open(..., 'w')", "os.replace(", "os.open(writing)"])


# ---------------------------------------------------------------------------------------
# Issue 29 item 10: export's warning after its files, its repeated targets, an empty --to
# ---------------------------------------------------------------------------------------
def _tilted(diagnosis: Path, tmp_path: Path) -> Path:
    """The diagnosis with j3's axis tilted 0.3 mrad as built: j2 and j3, parallel by design, then
    admit no plain DH table; Hayati's beta carries them in both DH and MDH."""
    doc = json.loads(diagnosis.read_text())
    doc["effect_parameters"]["geometry"] = {"geometry.j3.ry": 2e-4, "geometry.j3.rz": 2e-4}
    doc["parameters"]["geometry"] = dict(doc["effect_parameters"]["geometry"])  # one fit, its two copies alike
    for key in ("parameter_std", "parameter_units", "parameter_interval_95"):
        if key in doc:
            doc[key]["geometry"] = {"parameter_std": {n: 1e-6 for n in doc["parameters"]["geometry"]},
                                    "parameter_units": {n: "rad" for n in doc["parameters"]["geometry"]},
                                    "parameter_interval_95": {n: [v - 2e-6, v + 2e-6] for n, v in
                                                              doc["parameters"]["geometry"].items()}}[key]
    doc["effect_options"]["geometry"] = {}
    path = tmp_path / "tilted.json"
    path.write_text(json.dumps(doc))
    return path


def test_29_10_export_warns_only_once_its_files_are_written(campaign, tmp_path, capsys):
    _, diagnosis = campaign
    tilted = _tilted(diagnosis, tmp_path)
    bad = tmp_path / "bad_targets.csv"
    bad.write_text("j1_deg,j2_deg\n1,2\n")
    code, out, err = run(["export", tilted, "--to", tmp_path / "to", "--targets", bad], capsys)
    assert code == 2
    assert_one_line(err, str(bad))  # a run that wrote nothing says only why
    assert not (tmp_path / "to").exists()
    code, out, err = run(["export", tilted, "--to", tmp_path / "to", "--quiet"], capsys)
    assert code == 0 and err == ""  # every table written: nothing to warn of
    header, *rows = (tmp_path / "to" / "dh.csv").read_text().splitlines()
    beta = header.split(",").index("beta_deg_as_built")
    tilt = max(abs(float(r.split(",")[beta])) for r in rows)
    assert tilt == pytest.approx(math.degrees(2e-4), rel=0.01)  # the 0.2 mrad about y as Hayati's beta


def test_29_10_export_answers_repeated_targets_as_compensate_does(campaign, tmp_path, capsys):
    _, diagnosis = campaign
    targets = tmp_path / "targets.csv"
    targets.write_text("j1_deg,j2_deg,j3_deg,j4_mm,j5_deg,j6_deg\n10,20,30,100,10,0\n10,20,30,100,10,0\n")
    code, out, err = run(["export", diagnosis, "--to", tmp_path / "to", "--targets", targets, "--quiet"], capsys)
    assert code == 0, err
    rows = (tmp_path / "to" / "compensation.csv").read_text().splitlines()[1:]
    assert len(rows) == 2 and rows[0].split(",")[6:12] == rows[1].split(",")[6:12]


def test_29_10_an_empty_output_folder_or_effect_list_is_refused(campaign, tmp_path, capsys, monkeypatch):
    csv, diagnosis = campaign
    monkeypatch.chdir(tmp_path)
    code, out, err = run(["export", diagnosis, "--to", ""], capsys)
    assert code == 2
    assert_one_line(err, "--to '': an empty folder name")
    assert list(tmp_path.iterdir()) == []
    code, out, err = run(["diagnose", csv, "--effects", ""], capsys)
    assert code == 2
    assert_one_line(err, "--effects '': names no effect")
