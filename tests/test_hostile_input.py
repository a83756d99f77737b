"""The reproductions of issue 12 (an attack on the command line), one test or more each.

Every bad input must end in ONE line on stderr naming the file, row, column or option at
fault, exit code 2, no traceback and no file left behind. The numbers in the test names
(``test_12_09_...``) are the rows of the issue's table.
"""

import json

import pytest

from tcr_accuracy.cli import main


def run(argv, capsys):
    """(exit code, stdout, stderr) of the command line run in-process."""
    try:
        code = main([str(a) for a in argv])
    except SystemExit as exc:  # argparse usage errors
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def assert_one_line(err: str, *fragments: str) -> None:
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert "Traceback" not in err
    for fragment in fragments:
        assert fragment in lines[0], err


@pytest.fixture(scope="module")
def measurements(tmp_path_factory):
    """A small simulated measurement CSV of the tool-changer (24 poses)."""
    path = tmp_path_factory.mktemp("hostile") / "m.csv"
    assert main(["simulate", "--n", "24", "--random", "--seed", "2", "--out", str(path), "--quiet"]) == 0
    return path


# ---------------------------------------------------------------------------------------
# 9, 19, 20: option values
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("argv, fragment", [
    (["diagnose", "M", "--seed", "-1"], "--seed -1: want a seed"),
    (["predict", "--train", "M", "--query", "M", "--seed", "-1"], "--seed -1: want a seed"),
    (["compensate", "--train", "M", "--targets", "M", "--seed", "-1"], "--seed -1: want a seed"),
])
def test_12_09_negative_seed_is_one_line(argv, fragment, measurements, capsys):
    argv = [str(measurements) if a == "M" else a for a in argv]
    code, out, err = run(argv, capsys)
    assert code == 2 and out == ""
    assert_one_line(err, fragment)


@pytest.mark.parametrize("option, value", [
    ("--threshold-mm", "nan"), ("--threshold-mm", "inf"), ("--threshold-mm", "-1"), ("--threshold-mm", "1e999"),
    ("--threshold-mm", "1_5"), ("--threshold-mm", "\uff11\uff15"), ("--max-iter", "1_5"), ("--max-iter", "0"),
])
def test_12_20_compensate_options_must_be_finite_and_in_range(option, value, measurements, capsys):
    code, out, err = run(["compensate", "--train", measurements, "--targets", measurements, option, value], capsys)
    assert code == 2 and out == ""
    assert_one_line(err, f"{option} ")


@pytest.mark.parametrize("argv", [
    ["montecarlo", "--samples", "1_000"],
    ["montecarlo", "--samples", "\uff11\uff10\uff10"],
    ["montecarlo", "--tol", "nan"],
    ["montecarlo", "--angle-tol", "inf"],
    ["montecarlo", "--q", "0", "0", "0", "0", "0", "nan"],
    ["pose", "--q", "0", "0", "0", "0", "0", "1_0"],
    ["tolerance", "--target-prob", "nan"],
    ["tolerance", "--target-tol=-inf"],
    ["view", "--magnify", "nan"],
    ["simulate", "--noise-mm", "nan", "--out", "x.csv"],
    ["simulate", "--box", "nan", "1", "0", "1", "0", "1", "--out", "x.csv"],
    ["diagnose", "m.csv", "--noise-mm", "1e300"],
    ["diagnose", "m.csv", "--folds", "0x10"],
])
def test_12_20_every_numeric_option_is_finite_and_in_range(argv, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, out, err = run(argv, capsys)
    option = next(a for a in argv if a.startswith("--")).partition("=")[0]
    assert code == 2 and out == ""
    assert_one_line(err, f"{option} ")
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------------------------------
# 10: nothing identifiable
# ---------------------------------------------------------------------------------------
def test_12_10_diagnose_with_every_parameter_unidentifiable(measurements, tmp_path, capsys):
    # at 1 m tracker noise nothing is identifiable: the diagnosis must say so, not crash
    target = tmp_path / "d.json"
    code, out, err = run(["diagnose", measurements, "--noise-mm", "1000", "--effects", "joint_offsets",
                          "--quiet", "--json", target], capsys)
    assert code == 0, err
    steps = json.loads(target.read_text())["steps"]
    assert steps[0]["n_parameters"] == 0
    # no parameter fitted: the held-out residual is the training residual
    assert steps[0]["heldout_rms_mm"] == pytest.approx(steps[0]["train_rms_mm"])


# ---------------------------------------------------------------------------------------
# 18, 19: measurement CSV cells and row numbers
# ---------------------------------------------------------------------------------------
def _with_comments(measurements, tmp_path, edit):
    """The fixture's CSV behind three comment lines, its data rows changed by ``edit(rows)``;
    returns (path, line of data row k = k + 4)."""
    header, *rows = measurements.read_text().splitlines()
    rows = [r.split(",") for r in rows]
    edit(header.split(","), rows)
    path = tmp_path / "c.csv"
    path.write_text("# tracker: a comment\n#\n# another one\n" + header + "\n"
                    + "\n".join(",".join(r) for r in rows) + "\n")
    return path


@pytest.mark.parametrize("cell", ["1_5", "\uff11\uff15", "0x1f", "1e999"])
def test_12_19_strict_numbers_in_a_measurement_csv(cell, measurements, tmp_path, capsys):
    def edit(header, rows):
        rows[2][header.index("x_mm")] = cell

    path = _with_comments(measurements, tmp_path, edit)
    code, out, err = run(["diagnose", path, "--effects", "joint_offsets"], capsys)
    assert code == 2
    assert_one_line(err, f"{path}: row 7, column x_mm")


def test_12_19_strict_numbers_in_a_trajectory_csv(tmp_path, capsys):
    path = tmp_path / "t.csv"
    path.write_text("t_s,j1_deg,j2_deg,j3_deg,j4_mm,j5_deg,j6_deg\n0,0,0,0,0,0,0\n1,1_5,0,0,0,0,0\n")
    code, out, err = run(["trajectory", "--file", path, "--samples", "10"], capsys)
    assert code == 2
    assert_one_line(err, f"{path}: row 3, column 'j1_deg'")


def test_12_18_duplicate_training_poses_are_named_by_file_line(measurements, tmp_path, capsys):
    def edit(header, rows):  # data row 12 takes data row 5's joint values, with another position
        joints = [i for i, h in enumerate(header) if h.startswith("j") and h.endswith(("_deg", "_mm"))]
        for i in joints:
            rows[11][i] = rows[4][i]
        rows[11][header.index("x_mm")] = str(float(rows[4][header.index("x_mm")]) + 0.5)

    path = _with_comments(measurements, tmp_path, edit)
    code, out, err = run(["predict", "--train", path, "--query", path, "--method", "kriging"], capsys)
    assert code == 2
    last = err.splitlines()[-1]
    assert "rows 9 and 16 have the same joint values" in last, err


# ---------------------------------------------------------------------------------------
# 6, 8, 15, 16, 17, 22: URDF
# ---------------------------------------------------------------------------------------
_INERTIAL = ('<inertial><mass value="1"/><inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" iyz="0"/>'
             '</inertial>')


def two_joint_urdf(*, j1_origin="0 0 0.5", j1_axis="0 0 1", j1_limit='lower="-1" upper="1"', j2_type="revolute",
                   extra="", l1_visual=""):
    """A two-joint arm base -j1-> l1 -j2-> l2; each argument replaces one piece of it."""
    return f"""<robot name="r">
  <link name="base"/>{extra}
  <link name="l1">{l1_visual}{_INERTIAL}</link>
  <link name="l2">{_INERTIAL}</link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="{j1_origin}"/>
    <axis xyz="{j1_axis}"/><limit {j1_limit} effort="1" velocity="1"/></joint>
  <joint name="j2" type="{j2_type}"><parent link="l1"/><child link="l2"/><origin xyz="0 0.5 0"/>
    <axis xyz="1 0 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
</robot>"""


def test_the_two_joint_urdf_itself_is_fine(tmp_path, capsys):
    path = tmp_path / "ok.urdf"
    path.write_text(two_joint_urdf())
    code, out, err = run(["pose", "--robot", path, "--json"], capsys)
    assert code == 0, err
    assert json.loads(out)["position_m"] == pytest.approx([0.0, 0.5, 0.5])


@pytest.mark.parametrize("case, urdf, fragment", [
    ("6 link without a name", two_joint_urdf(extra="<link/>"), "link #2 (<link> element 2) has no name"),
    ("8 huge origin", two_joint_urdf(j1_origin="0 1e308 0"), "joint j1 <origin>: xyz='0 1e308 0': 1e308 is beyond"),
    ("8 inf origin", two_joint_urdf(j1_origin="0 inf 0"), "joint j1 <origin>: xyz='0 inf 0': 'inf' is not a finite"),
    ("15 nan origin", two_joint_urdf(j1_origin="0 nan 0"), "'nan' is not a finite number"),
    ("15 text in an origin", two_joint_urdf(j1_origin="0 abc 0"), "'abc' is not a finite number"),
    ("15 two numbers", two_joint_urdf(j1_origin="0 1"), "needs three numbers"),
    ("15 text in a limit", two_joint_urdf(j1_limit='lower="-1" upper="x"'), "joint j1: <limit>: upper='x'"),
    ("15 nan in an axis", two_joint_urdf(j1_axis="0 nan 1"), "joint j1: <axis>"),
    ("15 duplicate links", two_joint_urdf(extra='<link name="l2"/>'), "link l2 is defined twice"),
    ("15 a loop", two_joint_urdf(extra='<joint name="back" type="fixed"><parent link="l2"/><child link="base"/>'
                                       '</joint>'), "a loop through link"),
    ("15 unknown joint type", two_joint_urdf(j2_type="spinning"), "joint j2: type 'spinning' is not a URDF joint"),
    ("16 planar joint", two_joint_urdf(j2_type="planar"), "joint j2: joint type JointModelPlanar is not supported"),
    ("16 floating joint", two_joint_urdf(j2_type="floating"), "joint j2: joint type JointModelFreeFlyer"),
    ("17 zero-length axis", two_joint_urdf(j1_axis="0 0 0"), "joint j1: <axis xyz=...> has zero length"),
    ("17 lower above upper", two_joint_urdf(j1_limit='lower="1" upper="-1"'), "joint j1: <limit> lower 1 is above"),
])
def test_12_06_08_15_16_17_bad_urdf_is_one_line(case, urdf, fragment, tmp_path, capfd):
    path = tmp_path / "bad.urdf"
    path.write_text(urdf)
    try:
        code = main(["pose", "--robot", str(path)])
    except SystemExit as exc:
        code = exc.code
    out, err = capfd.readouterr()  # file descriptors: urdfdom writes to fd 2 itself
    assert code == 2 and out == ""
    assert_one_line(err, str(path), fragment)


def test_12_15_urdfdom_complaints_stay_one_line(tmp_path, capfd):
    # passes our checks, but urdfdom refuses it (a revolute joint without <limit>) on fd 2
    text = two_joint_urdf().replace('<limit lower="-1" upper="1" effort="1" velocity="1"/></joint>\n</robot>',
                                    "</joint>\n</robot>")
    path = tmp_path / "nolimit.urdf"
    path.write_text(text)
    code = main(["pose", "--robot", str(path)])
    out, err = capfd.readouterr()
    assert code == 2
    assert_one_line(err, "Pinocchio cannot build a model", "does not specify limits")


def test_12_15_a_huge_list_of_leaf_links_stays_short(tmp_path, capsys):
    leaves = "".join(f'<link name="leaf{i}"/><joint name="f{i}" type="fixed"><parent link="base"/>'
                     f'<child link="leaf{i}"/></joint>' for i in range(900))
    path = tmp_path / "many.urdf"
    path.write_text(two_joint_urdf(extra=leaves))
    code, out, err = run(["pose", "--robot", path], capsys)
    assert code == 2
    assert_one_line(err, "leaf links", "in all)")
    assert len(err) < 600


def test_12_22_a_mesh_outside_the_urdf_folder_is_refused(tmp_path, capsys):
    secret = tmp_path / "secret"
    secret.mkdir()
    (secret / "x.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n# SECRET-CONTENT\n")
    robot_dir = tmp_path / "a" / "b"
    robot_dir.mkdir(parents=True)
    visual = '<visual><geometry><mesh filename="{}"/></geometry></visual>'
    bad = robot_dir / "bad.urdf"
    bad.write_text(two_joint_urdf(l1_visual=visual.format("../../secret/x.obj")))
    code, out, err = run(["view", "--robot", bad, "--html", tmp_path / "v.html"], capsys)
    assert code == 2
    assert_one_line(err, str(bad), "link l1: mesh '../../secret/x.obj' lies outside")
    assert not (tmp_path / "v.html").exists()
    # the same mesh inside the URDF's folder is drawn
    (robot_dir / "x.obj").write_text((secret / "x.obj").read_text())
    good = robot_dir / "good.urdf"
    good.write_text(two_joint_urdf(l1_visual=visual.format("x.obj")))
    code, out, err = run(["view", "--robot", good, "--html", tmp_path / "v.html", "--quiet"], capsys)
    assert code == 0, err
    assert (tmp_path / "v.html").exists()


# ---------------------------------------------------------------------------------------
# 11, 12, 21: config and scenario files
# ---------------------------------------------------------------------------------------
_DEEP = "[" * 5000 + "]" * 5000


def _short_id(value):
    return value[:40] if isinstance(value, str) else None


@pytest.mark.parametrize("name, text, fragment", [
    ("int-key.yaml", "1: 2\n", "1: keys must be names, not int"),
    ("huge.yaml", "groups:\n  drive:\n    std_m: 1.0e+300\n    std_rad: 0.001\n",
     "groups.drive.std_m: 1e+300 is outside"),
    ("huge.toml", "[groups.drive]\nstd_m = 1e300\nstd_rad = 0.001\n", "groups.drive.std_m: 1e+300 is outside"),
    ("nan.yaml", "groups:\n  drive:\n    std_m: .nan\n    std_rad: 0.001\n", "groups.drive.std_m: expected a finite"),
    ("text.yaml", "groups:\n  drive:\n    std_m: wide\n    std_rad: 0.001\n", "groups.drive.std_m: expected a number"),
    ("deep.yaml", f"name: {_DEEP}\n", "nested too deeply"),
    ("deep.toml", f"name = {_DEEP}\n", "nested too deeply"),
], ids=_short_id)
def test_12_11_bad_config_files_are_one_line(name, text, fragment, tmp_path, capsys):
    path = tmp_path / name
    path.write_text(text)
    code, out, err = run(["montecarlo", "--config", path, "--samples", "100", "--quiet"], capsys)
    assert code == 2 and out == ""
    assert_one_line(err, str(path), fragment)


@pytest.mark.parametrize("text, fragment", [
    ("context:\n  payload_fraction: abc\n", "context.payload_fraction: expected a number, got 'abc'"),
    ("context:\n  payload_fraction: null\n", "context.payload_fraction: expected a number, got None"),
    ("context:\n  payload_kg: heavy\n", "context.payload_kg: expected a number"),
    ("context:\n  temperature_c: hot\n", "context.temperature_c: expected a number"),
    ("context: [1]\n", "context: a mapping"),
    ("1: 2\n", "1: keys must be names"),
    (f"noise_mm: {_DEEP}\n", "nested too deeply"),
    ("context:\n  payload_kg: -150\n", "context.payload_kg: -150 is outside"),  # 21
    ("context:\n  temperature_spread_c: -5\n", "context.temperature_spread_c: -5 is outside"),  # 21
    ("effects:\n  geometry:\n    tcp_rms_mm: -1\n", "effects.geometry.tcp_rms_mm: -1 is outside"),  # 21
    ("effects:\n  compliance:\n    options:\n      link_mass_factors: abc\n", "effects.compliance.options"),
], ids=_short_id)
def test_12_12_12_21_bad_scenario_files_are_one_line_and_write_nothing(text, fragment, tmp_path, capsys):
    path = tmp_path / "s.yaml"
    path.write_text(text if text.startswith("effects") else "effects:\n  geometry: {}\n" + text)
    code, out, err = run(["simulate", "--scenario", path, "--n", "5", "--out", tmp_path / "o.csv"], capsys)
    assert code == 2 and out == ""
    assert_one_line(err, str(path), fragment)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.yaml"]


def test_12_21_an_empty_or_inverted_box_is_refused(tmp_path, capsys):
    code, out, err = run(["simulate", "--random", "--box", "500", "-500", "0", "100", "0", "100",
                          "--out", tmp_path / "o.csv"], capsys)
    assert code == 2
    assert_one_line(err, "--box")
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------------------------------
# 1-5: outputs
# ---------------------------------------------------------------------------------------
_MC = ["montecarlo", "--samples", "200", "--tail-samples", "0", "--view-samples", "20", "--quiet"]


def test_12_01_output_paths_are_checked_before_any_work(tmp_path, capsys, monkeypatch):
    from tcr_accuracy.analysis import montecarlo

    monkeypatch.setattr(montecarlo, "run_monte_carlo", _must_not_run)
    (tmp_path / "f").write_text("a file")
    code, out, err = run([*_MC, "--json", tmp_path / "mc.json", "--view", tmp_path / "v.html",
                          "--plots", tmp_path / "pl", "--out", tmp_path / "f"], capsys)
    assert code == 2
    assert_one_line(err, f"--out {tmp_path / 'f'}: exists and is not a folder")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f"]


def _must_not_run(*args, **kwargs):
    raise AssertionError("the work started before the output paths were checked")


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


def test_12_04_sigterm_mid_run_leaves_nothing(tmp_path, capsys, monkeypatch):
    import os
    import signal

    from tcr_accuracy.analysis import simulate

    real = simulate.truth_text

    def terminated(truth, path):  # the CSV is written (staged) when the kill comes
        os.kill(os.getpid(), signal.SIGTERM)
        return real(truth, path)

    monkeypatch.setattr(simulate, "truth_text", terminated)
    before = signal.getsignal(signal.SIGTERM)
    code, out, err = run(["simulate", "--random", "--n", "20", "--out", tmp_path / "st.csv",
                          "--truth", tmp_path / "t.yaml"], capsys)
    assert code == 130
    assert list(tmp_path.rglob("*")) == []  # no CSV, truth or temporary file
    assert signal.getsignal(signal.SIGTERM) == before


def test_12_04_sigterm_during_the_commit_leaves_nothing(tmp_path, capsys, monkeypatch):
    # the commit writes its temporary files after the command returns: SIGTERM then is still
    # an interrupt that removes them, not a death that leaves them beside the targets
    import os
    import signal

    from tcr_accuracy.cli import staging

    real = staging.prepare

    def terminated(target, data):
        os.kill(os.getpid(), signal.SIGTERM)
        return real(target, data)

    monkeypatch.setattr(staging, "prepare", terminated)
    previous = signal.signal(signal.SIGTERM, lambda *a: None)  # were the CLI's handler gone: no death
    try:
        code, out, err = run(["pose", "--json", tmp_path / "p.json"], capsys)
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert code == 130, err
    assert list(tmp_path.iterdir()) == []


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


# ---------------------------------------------------------------------------------------
# 13, 14: memory, estimated before the work and refused above --max-memory-gb
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

    monkeypatch.setattr(reader, "read_user_text", _must_not_run)
    argv = [str(tall_csv) if a == "TALL" else str(measurements) if a == "M" else a for a in argv]
    code, out, err = run(argv, capsys)
    assert code == 2
    assert_one_line(err, str(tall_csv), "rows) needs about", fragment)


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


def _chain_urdf(n):
    links = "".join(f'<link name="l{i}">{_INERTIAL}</link>' for i in range(n + 1))
    joints = "".join(f'<joint name="j{i}" type="revolute"><parent link="l{i}"/><child link="l{i + 1}"/>'
                     f'<origin xyz="0 0 0.01"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" '
                     f'velocity="1"/></joint>' for i in range(n))
    return f'<robot name="chain">{links}{joints}</robot>'


@pytest.mark.parametrize("n, fragment", [(3000, "3000 joints, more than the 1000"),
                                         (300, "300 joints move this frame")])
def test_12_07_a_chain_too_long_is_refused(n, fragment, tmp_path, capsys):
    path = tmp_path / "chain.urdf"
    path.write_text(_chain_urdf(n))
    code, out, err = run(["pose", "--robot", path], capsys)
    assert code == 2
    assert_one_line(err, str(path), fragment)


def test_12_15_an_error_line_is_one_bounded_line(tmp_path, capsys, monkeypatch):
    # whatever an exception says (here many lines and megabytes), the user gets one short line
    from tcr_accuracy.cli import pose

    def huge(args):
        raise ValueError("line one\n" + "x" * 5_000_000 + "\nline three")

    monkeypatch.setattr(pose, "_run_pose", huge)
    code, out, err = run(["pose"], capsys)
    assert code == 1
    assert_one_line(err, "tcr-accuracy pose: unexpected error: ValueError: line one x")
    assert len(err) <= 1001


def test_12_04_a_signal_during_the_renames_waits_for_them(tmp_path, monkeypatch):
    # SIGTERM arriving while a run's files are renamed into place: all of them land, then it stops
    import os
    import signal

    from tcr_accuracy.cli import staging, write_file

    renamed = []
    real_replace = os.replace

    def replace(src, dst, **fds):
        if not renamed:
            os.kill(os.getpid(), signal.SIGTERM)  # held until the commit is done
        renamed.append(dst)
        real_replace(src, dst, **fds)

    monkeypatch.setattr(write_file.os, "replace", replace)
    stopped = []
    previous = signal.signal(signal.SIGTERM, lambda *a: stopped.append(len(renamed)))
    try:
        with staging.staged_outputs():
            for name in ("a.png", "b.png", "index.html"):
                staging.write_text(tmp_path / name, name)
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert stopped == [3]  # delivered after the third rename, not after the first
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.png", "b.png", "index.html"]


# ---------------------------------------------------------------------------------------
# Fuzz: option values, settings files, URDF origins (hypothesis, derandomized)
# ---------------------------------------------------------------------------------------
from hypothesis import given, settings, strategies as st  # noqa: E402

FUZZ = settings(max_examples=200, deadline=None, derandomize=True)


@FUZZ
@given(st.text(max_size=30))
def test_fuzz_a_numeric_option_is_a_finite_number_in_range_or_one_refusal(text):
    import argparse
    import math
    import re

    from tcr_accuracy.cli.common import number

    convert = number(low=0, low_open=True, high=1e6, unit="mm")
    try:
        value = convert(text)
    except argparse.ArgumentTypeError as exc:
        assert "\n" not in str(exc) or "\n" in text
        return
    assert math.isfinite(value) and 0 < value <= 1e6
    # only plain ASCII decimals get through: no 1_5, no full-width digits, no hex, no inf/nan
    assert re.fullmatch(r"\s*[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?\s*", text, re.ASCII)


@settings(max_examples=40, deadline=None, derandomize=True)
@given(st.recursive(st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=8),
                    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(
                        st.integers() | st.text(max_size=6), inner, max_size=3), max_leaves=12))
def test_fuzz_any_yaml_value_in_a_scenario_context_is_accepted_or_one_input_error(value):
    import yaml

    from tcr_accuracy.analysis.scenario import scenario_from_dict
    from tcr_accuracy.exceptions import InputError
    from tcr_accuracy.io.budget_file import parse_table

    text = yaml.safe_dump({"effects": {"geometry": {}}, "context": {"payload_fraction": value}})
    try:
        scenario_from_dict(parse_table(text, "s.yaml"), source="s.yaml")
    except InputError as exc:
        assert str(exc).startswith("s.yaml: ") and "\n" not in str(exc)


@settings(max_examples=80, deadline=None, derandomize=True)
@given(st.lists(st.text(alphabet="0123456789.eE+-_nainf x\uff11", max_size=6), min_size=1, max_size=4))
def test_fuzz_an_origin_is_three_finite_numbers_or_one_input_error(parts):
    from tcr_accuracy.exceptions import InputError
    from tcr_accuracy.model.robot import robot_from_urdf_text

    try:
        robot = robot_from_urdf_text(two_joint_urdf(j1_origin=" ".join(parts)), None, source="f.urdf")
    except InputError as exc:
        assert str(exc).startswith("f.urdf: ") and "\n" not in str(exc)
        return
    assert all(abs(v) <= 1e4 for v in robot.model.jointPlacements[1].translation)
