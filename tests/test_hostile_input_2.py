"""The reproductions of issue 22 (a second attack on the command line), one test or more each.

As in round one (``test_hostile_input.py``): every bad input ends in ONE line on stderr naming
the file, row, column or option at fault, exit code 2, no traceback and nothing left behind.
The numbers in the test names (``test_22_01_...``) are the rows of the issue's table.
"""

import base64
import json
import re

import pytest

from test_hostile_input import _INERTIAL, assert_one_line, run, two_joint_urdf
from tcr_accuracy.cli import main


# ---------------------------------------------------------------------------------------
# 1: files a mesh references (COLLADA images, an OBJ's material library and its textures)
# ---------------------------------------------------------------------------------------
SECRET = b"SECRET-CONTENT-22-01\n"


def collada_triangle(image: str | None) -> str:
    """A valid COLLADA file with one triangle and, with ``image``, one image ``<init_from>``."""
    images = (f"<library_images><image id='img' name='img'><init_from>{image}</init_from></image>"
              "</library_images>") if image is not None else ""
    return f"""<?xml version="1.0" encoding="utf-8"?>
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
  <asset><unit name="meter" meter="1"/><up_axis>Z_UP</up_axis></asset>{images}
  <library_geometries><geometry id="tri" name="tri"><mesh>
    <source id="p"><float_array id="pa" count="9">0 0 0 0.1 0 0 0 0.1 0</float_array>
      <technique_common><accessor source="#pa" count="3" stride="3"><param name="X" type="float"/>
        <param name="Y" type="float"/><param name="Z" type="float"/></accessor></technique_common></source>
    <vertices id="v"><input semantic="POSITION" source="#p"/></vertices>
    <triangles count="1"><input semantic="VERTEX" source="#v" offset="0"/><p>0 1 2</p></triangles>
  </mesh></geometry></library_geometries>
  <library_visual_scenes><visual_scene id="s"><node id="n"><instance_geometry url="#tri"/></node>
  </visual_scene></library_visual_scenes>
  <scene><instance_visual_scene url="#s"/></scene>
</COLLADA>
"""


TRIANGLE_OBJ = "v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nf 1 2 3\n"


@pytest.fixture
def secret(tmp_path):
    """A file outside every robot folder of the tests below."""
    folder = tmp_path / "private"
    folder.mkdir()
    path = folder / "s.png"
    path.write_bytes(SECRET)
    return path


def robot_with_mesh(tmp_path, mesh_name: str, files: dict) -> "Path":  # noqa: F821
    """``ws/bot/r.urdf`` whose link l1 is drawn with ``ws/bot/meshes/<mesh_name>``; ``files`` are
    written under ``ws/bot/meshes`` first. The robot may read ``ws`` (its package folder), not
    ``tmp_path``."""
    meshes = tmp_path / "ws" / "bot" / "meshes"
    meshes.mkdir(parents=True)
    for name, text in files.items():
        (meshes / name).write_text(text)
    urdf = tmp_path / "ws" / "bot" / "r.urdf"
    urdf.write_text(two_joint_urdf(
        l1_visual=f'<visual><geometry><mesh filename="meshes/{mesh_name}"/></geometry></visual>'))
    return urdf


def embedded_blobs(html: str) -> bytes:
    """Everything a static view embeds, its base64 commands decoded and joined."""
    return b"".join(base64.b64decode(b) for b in re.findall(r'"([A-Za-z0-9+/=]{64,})"', html))


def _outside_cases(secret):
    rel = "../../../private/s.png"  # from ws/bot/meshes
    return {
        "dae absolute image": ("t.dae", {"t.dae": collada_triangle(str(secret))}, str(secret)),
        "dae relative image": ("t.dae", {"t.dae": collada_triangle(rel)}, rel),
        "dae file url image": ("t.dae", {"t.dae": collada_triangle(f"file://{secret}")}, f"file://{secret}"),
        "dae http image": ("t.dae", {"t.dae": collada_triangle("http://evil.example/x.png")}, "http://evil"),
        "obj mtllib": ("t.obj", {"t.obj": f"mtllib {rel[:-5]}m.mtl\n" + TRIANGLE_OBJ}, "m.mtl"),
        "obj map_Kd": ("t.obj", {"t.obj": "mtllib m.mtl\n" + TRIANGLE_OBJ,
                                 "m.mtl": f"newmtl a\nmap_Kd -s 1 1 1 {secret}\n"}, str(secret)),
        "obj bump with tabs": ("t.obj", {"t.obj": "mtllib\tm.mtl\n" + TRIANGLE_OBJ,
                                         "m.mtl": f"newmtl a\nbump\t-bm 2 {rel}\n"}, rel),
    }


@pytest.mark.parametrize("case", ["dae absolute image", "dae relative image", "dae file url image",
                                  "dae http image", "obj mtllib", "obj map_Kd", "obj bump with tabs"])
def test_22_01_a_file_a_mesh_references_outside_the_robot_is_refused(case, secret, tmp_path, capsys):
    if case == "obj mtllib":  # the library outside exists, so it would be read
        (secret.parent / "m.mtl").write_text("newmtl a\n")
    mesh, files, named = _outside_cases(secret)[case]
    urdf = robot_with_mesh(tmp_path, mesh, files)
    code, out, err = run(["view", "--robot", urdf, "--view", tmp_path / "v.html"], capsys)
    assert code == 2 and out == ""
    assert_one_line(err, str(urdf), f"mesh 'meshes/{mesh}' references", named)
    assert not (tmp_path / "v.html").exists()


@pytest.mark.parametrize("command", [
    ["montecarlo", "--samples", "200", "--tail-samples", "0", "--view-samples", "20", "--view", "OUT/mc.html"],
    ["diagnose", "CSV", "--effects", "joint_offsets", "--out", "OUT/rep"],
    ["view", "--serve", "--quiet"],
])
def test_22_01_every_command_that_draws_the_robot_refuses_it(command, secret, tmp_path, capsys):
    urdf = robot_with_mesh(tmp_path, "t.dae", {"t.dae": collada_triangle(str(secret))})
    (tmp_path / "out").mkdir()
    csv = tmp_path / "m.csv"  # simulate does not draw the robot
    assert main(["simulate", "--robot", str(urdf), "--random", "--n", "30", "--seed", "1", "--out", str(csv),
                 "--quiet"]) == 0
    argv = [a.replace("OUT", str(tmp_path / "out")).replace("CSV", str(csv)) for a in command]
    code, out, err = run([*argv, "--robot", urdf, "--quiet"], capsys)
    assert code == 2
    assert_one_line(err, str(urdf), "mesh 'meshes/t.dae' references", str(secret))
    assert list((tmp_path / "out").iterdir()) == []


def test_22_01_images_inside_the_robot_folder_are_embedded(tmp_path, capsys):
    texture = b"A-TEXTURE-INSIDE-THE-ROBOT-FOLDER"
    urdf = robot_with_mesh(tmp_path, "t.dae", {"t.dae": collada_triangle("../textures/t.png")})
    (tmp_path / "ws" / "bot" / "textures").mkdir()
    (tmp_path / "ws" / "bot" / "textures" / "t.png").write_bytes(texture)
    code, out, err = run(["view", "--robot", urdf, "--view", tmp_path / "v.html", "--quiet"], capsys)
    assert code == 0, err
    assert base64.b64encode(texture) in embedded_blobs((tmp_path / "v.html").read_text())


def test_22_01_a_symlink_out_of_the_folder_is_outside(secret, tmp_path, capsys):
    urdf = robot_with_mesh(tmp_path, "t.dae", {"t.dae": collada_triangle("link.png")})
    (tmp_path / "ws" / "bot" / "meshes" / "link.png").symlink_to(secret)
    code, out, err = run(["view", "--robot", urdf, "--view", tmp_path / "v.html"], capsys)
    assert code == 2
    assert_one_line(err, "references 'link.png', which lies outside")


def test_22_01_a_mesh_format_whose_references_are_unknown_is_not_drawn(tmp_path, capsys):
    urdf = robot_with_mesh(tmp_path, "t.gltf", {"t.gltf": json.dumps({"buffers": [{"uri": "/etc/passwd"}]})})
    code, out, err = run(["view", "--robot", urdf, "--view", tmp_path / "v.html"], capsys)
    assert code == 2
    assert_one_line(err, str(urdf), "format '.gltf' is not drawn")


def test_22_01_nothing_unchecked_is_embedded(secret, tmp_path, monkeypatch):
    # with both checks made blind, the view's own loader still embeds only the files it was
    # handed as checked (here none): the image Pinocchio's loader would have read stays out
    from tcr_accuracy.model import robot as robot_module
    from tcr_accuracy.model.robot import load_robot
    from tcr_accuracy.view import robot_visuals
    from tcr_accuracy.view.viewer import Scene

    urdf = robot_with_mesh(tmp_path, "t.dae", {"t.dae": collada_triangle(str(secret))})
    monkeypatch.setattr(robot_module, "check_mesh_references", lambda *a: [])
    monkeypatch.setattr(robot_visuals, "check_mesh_references", lambda *a: [])
    robot = load_robot(str(urdf))
    scene = Scene()
    scene.add_robot(robot, robot.working_pose, "nominal")
    scene.add_robot(robot, robot.working_pose, "ghost", color=(1, 0, 0), opacity=0.5)
    blobs = embedded_blobs(scene.static_html())
    assert b"<COLLADA" in blobs  # the mesh itself is drawn
    assert base64.b64encode(SECRET) not in blobs and SECRET not in blobs


# ---------------------------------------------------------------------------------------
# 2, 31: YAML aliases (a "billion laughs" of nodes) and repeated keys
# ---------------------------------------------------------------------------------------
def alias_bomb() -> str:
    """548 bytes standing for 10^9 nodes: nine levels of aliases, each a list of ten of the previous one."""
    levels = ["      - &a0 [x,x,x,x,x,x,x,x,x,x]"]
    levels += [f"      - &a{i} [" + ",".join([f"*a{i - 1}"] * 10) + "]" for i in range(1, 10)]
    return "groups:\n  link_length:\n    std_m: 0.0001\n    junk:\n" + "\n".join(levels) + "\n"


@pytest.mark.parametrize("argv", [["montecarlo", "--config", "F", "--samples", "100", "--quiet"],
                                  ["simulate", "--scenario", "F", "--n", "5", "--out", "OUT/o.csv"]])
def test_22_02_a_yaml_alias_bomb_is_refused_at_once(argv, tmp_path):
    # in a child process with a timeout: were the bomb walked, the test fails instead of hanging
    bomb = tmp_path / "bomb.yaml"
    bomb.write_text(alias_bomb())
    (tmp_path / "out").mkdir()
    result = cli_process([str(bomb) if a == "F" else a.replace("OUT", str(tmp_path / "out")) for a in argv],
                         cwd=tmp_path, timeout=60)
    assert result.returncode == 2 and result.stdout == ""
    assert_one_line(result.stderr, f"{bomb}: line 6: YAML aliases (*a0) are refused")
    assert list((tmp_path / "out").iterdir()) == []


def cli_process(argv, *, cwd, timeout=120, **popen):
    """``python -m tcr_accuracy argv`` in a child process, with this checkout's sources; (text) result."""
    import subprocess
    import sys
    from pathlib import Path

    import tcr_accuracy

    src = str(Path(tcr_accuracy.__file__).parents[1])
    return subprocess.run([sys.executable, "-m", "tcr_accuracy", *map(str, argv)], capture_output=True, text=True,
                          cwd=cwd, timeout=timeout, env={"PYTHONPATH": src, "OPENBLAS_NUM_THREADS": "1",
                                                         "PATH": "/usr/bin:/bin"}, **popen)


@pytest.mark.parametrize("text, line, key", [
    ("groups:\n  drive:\n    std_m: 0.001\n    std_rad: 0.001\n    std_m: 0.002\n", 5, "std_m"),
    ("groups:\n  drive: {std_m: 0.001, std_rad: 0.001}\ngroups: {}\n", 3, "groups"),
])
def test_22_31_a_key_given_twice_is_refused(text, line, key, tmp_path, capsys):
    path = tmp_path / "dup.yaml"
    path.write_text(text)
    code, out, err = run(["montecarlo", "--config", path, "--samples", "100", "--quiet"], capsys)
    assert code == 2
    assert_one_line(err, f"{path}: line {line}: key '{key}' is given twice")


from hypothesis import given, settings, strategies as st  # noqa: E402


@settings(max_examples=60, deadline=None, derandomize=True)
@given(st.lists(st.sampled_from(["a", "b", "c", "std_m"]), min_size=1, max_size=6))
def test_fuzz_22_31_repeated_keys_are_refused_unique_ones_read(keys):
    from tcr_accuracy.exceptions import InputError
    from tcr_accuracy.io.budget_file import parse_table

    text = "t:\n" + "".join(f"  {k}: {i}\n" for i, k in enumerate(keys))
    try:
        data = parse_table(text, "s.yaml")
    except InputError as exc:
        assert len(set(keys)) < len(keys)
        first_repeat = next(i for i, k in enumerate(keys) if k in keys[:i])
        assert str(exc).startswith(f"s.yaml: line {first_repeat + 2}: key '{keys[first_repeat]}'")
        return
    assert len(set(keys)) == len(keys) and data == {"t": {k: i for i, k in enumerate(keys)}}


# ---------------------------------------------------------------------------------------
# 8, 9, 10: hidden crashes (exit 1 "unexpected error")
# ---------------------------------------------------------------------------------------
def mimic_urdf(finger_multiplier: str | None = None) -> str:
    """[B]: a 3-link arm whose j3 follows j2 (``-1 x j2 + 0.1``), with, given a multiplier, a
    50 kg prismatic finger following j2 too."""
    links = "".join(f'<link name="l{i}">{_INERTIAL}</link>' for i in range(4))
    limit = 'effort="1" velocity="1"'
    text = f"""<robot name="mim"><link name="base"/>{links}<link name="tool"/>
<joint name="j0" type="fixed"><parent link="base"/><child link="l0"/></joint>
<joint name="j1" type="revolute"><parent link="l0"/><child link="l1"/><origin xyz="0 0 0.3"/><axis xyz="0 0 1"/>
  <limit lower="-3" upper="3" {limit}/></joint>
<joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0 0 0.3"/><axis xyz="1 0 0"/>
  <limit lower="-2" upper="2" {limit}/></joint>
<joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/><origin xyz="0 0.4 0"/><axis xyz="1 0 0"/>
  <limit lower="-2.2" upper="2.2" {limit}/><mimic joint="j2" multiplier="-1" offset="0.1"/></joint>
<joint name="jt" type="fixed"><parent link="l3"/><child link="tool"/><origin xyz="0 0.3 0"/></joint>
"""
    if finger_multiplier is not None:
        text += (f'<link name="finger"><inertial><mass value="50"/><inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" '
                 f'iyz="0"/></inertial></link><joint name="finger" type="prismatic"><parent link="l3"/>'
                 f'<child link="finger"/><origin xyz="0 0.1 0"/><axis xyz="0 0 1"/><limit lower="0" upper="0.05" '
                 f'{limit}/><mimic joint="j2" multiplier="{finger_multiplier}"/></joint>')
    return text + "</robot>"


@pytest.fixture(scope="module")
def m60(tmp_path_factory):
    """``simulate --scenario examples/scenario_compliance.yaml --n 60 --seed 2``."""
    from conftest import REPO

    path = tmp_path_factory.mktemp("m60") / "m60.csv"
    assert main(["simulate", "--scenario", str(REPO / "examples" / "scenario_compliance.yaml"), "--n", "60",
                 "--seed", "2", "--out", str(path), "--quiet"]) == 0
    return path


def test_22_08_positions_x10_without_the_mimic_joints_column_is_the_unit_message(tmp_path, capsys):
    import csv

    urdf = tmp_path / "mim2.urdf"
    urdf.write_text(mimic_urdf())
    full = tmp_path / "mm.csv"
    assert main(["simulate", "--robot", str(urdf), "--tool", "tool", "--random", "--n", "60", "--seed", "3",
                 "--out", str(full), "--quiet"]) == 0
    rows = list(csv.DictReader(full.read_text().splitlines()))
    path = tmp_path / "no_j3_x10.csv"
    with path.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["j1_deg", "j2_deg", "x_mm", "y_mm", "z_mm"])
        # j3 follows its rule, so that no joint leaves its limits
        writer.writerows([r["j1_deg"], r["j2_deg"], *(float(r[a]) * 10 for a in ("x_mm", "y_mm", "z_mm"))]
                         for r in rows)
    code, out, err = run(["diagnose", path, "--robot", urdf, "--tool", "tool"], capsys)
    assert code == 2
    assert_one_line(err, f"{path}: columns x_mm, y_mm, z_mm", "times); check the position units",
                    "j3 (its <mimic> rule)")


@pytest.mark.parametrize("command", [["diagnose", "M"], ["plan-poses", "M", "-k", "3"]])
@pytest.mark.parametrize("value", ["1e-300", "1e-7", "1e6"])
def test_22_09_30_an_instrument_noise_out_of_range_is_refused(command, value, m60, capsys):
    code, out, err = run([str(m60) if a == "M" else a for a in command] + ["--noise-mm", value], capsys)
    assert code == 2 and out == ""
    assert_one_line(err, f"--noise-mm {value}", "want a number >= 1e-06 mm and <= 1000 mm")


@pytest.mark.parametrize("attribute, fragment", [
    ('multiplier="1e308"', "multiplier=1e308 is outside [-1000, 1000]"),
    ('multiplier="nan"', "multiplier='nan' is not a finite number"),
    ('multiplier="1" offset="1e5"', "offset=1e5 is outside [-10000, 10000]"),
    ('multiplier="1_0"', "multiplier='1_0' is not a finite number"),
])
def test_22_10_a_mimic_rule_is_bounded_like_other_urdf_numbers(attribute, fragment, tmp_path, capsys):
    path = tmp_path / "mim.urdf"
    path.write_text(mimic_urdf("1").replace('multiplier="1"/>', attribute + "/>"))
    code, out, err = run(["pose", "--robot", path, "--tool", "tool"], capsys)
    assert code == 2
    assert_one_line(err, f"{path}: joint finger: <mimic>: {fragment}")


def test_22_10_a_bounded_mimic_rule_is_read(tmp_path, capsys):
    from tcr_accuracy.model.robot import load_robot

    path = tmp_path / "mim.urdf"
    path.write_text(mimic_urdf("2.5"))
    robot = load_robot(str(path), "tool")
    assert (robot.mimic["finger"].multiplier, robot.mimic["j3"].multiplier, robot.mimic["j3"].offset) == (2.5, -1, 0.1)


# ---------------------------------------------------------------------------------------
# 3, 19, 25, 26, 27: what a failed or stopped run leaves behind
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("argv", [
    ["diagnose", "M", "--effects", "joint_offsets", "--json", "/dev/full", "--as-built-urdf", "T/ab.urdf"],
    ["diagnose", "M", "--effects", "joint_offsets", "--out", "T/rep", "--json", "/dev/full"],
    ["predict", "--train", "M", "--query", "M", "--method", "kriging", "--csv", "T/p.csv", "--json", "/dev/full"],
    ["simulate", "--n", "5", "--out", "/dev/full", "--truth", "T/t.yaml"],
])
def test_22_03_19_a_full_device_fails_before_any_regular_file_lands(argv, m60, tmp_path, capsys):
    code, out, err = run([str(m60) if a == "M" else a.replace("T/", f"{tmp_path}/") for a in argv], capsys)
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


def test_22_27_a_signal_during_the_renames_ends_the_run_with_exit_0(tmp_path, capsys, monkeypatch):
    import os
    import signal

    from tcr_accuracy.cli import write_file

    real_replace = os.replace

    def replace(src, dst, **fds):  # SIGTERM in the commit window: held, delivered after the renames
        os.kill(os.getpid(), signal.SIGTERM)
        real_replace(src, dst, **fds)

    monkeypatch.setattr(write_file.os, "replace", replace)
    code, out, err = run(["pose", "--json", tmp_path / "p.json"], capsys)
    assert code == 0, err
    assert "interrupted" not in err
    assert json.loads((tmp_path / "p.json").read_text())["robot"] == "tool_changer"
    assert [p.name for p in tmp_path.iterdir()] == ["p.json"]


def test_22_27_sighup_mid_run_is_an_interrupt_that_leaves_nothing(tmp_path, capsys, monkeypatch):
    import os
    import signal

    from tcr_accuracy.analysis import simulate

    real = simulate.truth_text

    def hung_up(truth, path):  # the terminal closes while the CSV is staged
        os.kill(os.getpid(), signal.SIGHUP)
        return real(truth, path)

    monkeypatch.setattr(simulate, "truth_text", hung_up)
    before = signal.getsignal(signal.SIGHUP)
    code, out, err = run(["simulate", "--random", "--n", "20", "--out", tmp_path / "st.csv",
                          "--truth", tmp_path / "t.yaml"], capsys)
    assert code == 130
    assert_one_line(err, "interrupted")
    assert list(tmp_path.rglob("*")) == []
    assert signal.getsignal(signal.SIGHUP) == before


def test_22_27_leftovers_of_a_killed_run_are_cleaned_by_the_next_run_on_the_same_target(tmp_path, capsys):
    import os

    dead = 2**22 + 12345  # above Linux's largest pid (4194304): no such process
    (tmp_path / f".p.json.{dead}.abc123.tmp").write_text("half a file")
    (tmp_path / f".rep.{dead}.x1y2.tmp").mkdir()
    (tmp_path / f".rep.{dead}.x1y2.tmp" / "index.html").write_text("half a report")
    live = f".p.json.{os.getppid()}.zz9.tmp"  # a concurrent run's, still alive: kept
    (tmp_path / live).write_text("being written")
    (tmp_path / f".other.json.{dead}.q.tmp").write_text("another target's: not this run's business")
    assert run(["pose", "--json", tmp_path / "p.json"], capsys)[0] == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([f".other.json.{dead}.q.tmp", live, "p.json",
                                                                 f".rep.{dead}.x1y2.tmp"])
    code, out, err = run(["montecarlo", "--samples", "100", "--tail-samples", "0", "--quiet", "--plots",
                          tmp_path / "rep"], capsys)
    assert code == 0, err
    assert not (tmp_path / f".rep.{dead}.x1y2.tmp").exists() and (tmp_path / "rep").is_dir()


def test_22_18_19_import_options_are_checked_before_the_work(tmp_path, capsys):
    (tmp_path / "t.csv").write_text("X,Y,Z\n1,2,3\n")
    for argv, fragment in [(["--tolerance-ms", "\u0665\u0660"], "--tolerance-ms \u0665\u0660: not a number"),
                           (["--tolerance-ms", "1_000"], "--tolerance-ms 1_000: not a number"),
                           (["--out", tmp_path / "nowhere" / "m.csv"], "does not exist"),
                           (["--out", tmp_path], "is a folder")]:
        argv = ["import", tmp_path / "t.csv", *argv]
        if "--out" not in argv:
            argv += ["--out", tmp_path / "m.csv"]
        code, out, err = run(argv, capsys)
        assert code == 2
        assert_one_line(err, fragment)
    assert [p.name for p in tmp_path.iterdir()] == ["t.csv"]


# ---------------------------------------------------------------------------------------
# 6: an output that is an input or another output
# ---------------------------------------------------------------------------------------
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
# 28: view --serve against DNS rebinding
# ---------------------------------------------------------------------------------------
def _status(port: int, path: str, headers: dict) -> int:
    import http.client

    connection = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
    try:
        connection.putrequest("GET", path, skip_host=True)
        for key, value in headers.items():
            connection.putheader(key, value)
        connection.endheaders()
        return connection.getresponse().status
    finally:
        connection.close()


def test_22_28_the_live_view_answers_only_requests_naming_localhost():
    from tcr_accuracy.model.robot import load_robot
    from tcr_accuracy.view.viewer import Scene

    robot = load_robot()
    scene = Scene("live")
    scene.add_robot(robot, robot.working_pose, "nominal")
    upgrade = {"Upgrade": "websocket", "Connection": "Upgrade", "Sec-WebSocket-Version": "13",
               "Sec-WebSocket-Key": "dGhlIHNhbXBsZSBub25jZQ=="}
    with scene.serve() as live:
        port = int(live.url.split(":")[2].split("/")[0])
        local = f"127.0.0.1:{port}"
        assert _status(port, "/view", {"Host": local}) == 200
        assert _status(port, "/view", {"Host": f"localhost:{port}"}) == 200
        assert _status(port, "/view", {"Host": f"evil.example:{port}"}) == 403
        assert _status(port, "/view", {}) in (400, 403)  # HTTP/1.1 without Host: tornado refuses it first
        assert _status(port, "/static/", {"Host": "evil.example"}) == 403
        # the WebSocket carrying the scene: opened from the page itself, and not from another site's
        assert _status(port, "/", {"Host": local, "Origin": f"http://{local}", **upgrade}) == 101
        assert _status(port, "/", {"Host": local, "Origin": "http://evil.example:7000", **upgrade}) == 403
        assert _status(port, "/", {"Host": f"evil.example:{port}", "Origin": f"http://evil.example:{port}",
                                   **upgrade}) == 403


# ---------------------------------------------------------------------------------------
# 4: an exact fit through every training pose
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("command", [
    ["predict", "--method", "calibration+local-gp", "--train", "T7", "--query", "POSES"],
    ["compensate", "--method", "calibration", "--train", "T7", "--targets", "POSES"],
])
def test_22_04_a_calibration_on_as_many_equations_as_parameters_is_refused(command, tmp_path, capsys):
    from conftest import REPO

    t7 = tmp_path / "t7.csv"  # 3 comment lines, the header and 7 rows
    t7.write_text("".join((REPO / "examples" / "measured.csv").read_text().splitlines(keepends=True)[:11]))
    argv = [str(t7) if a == "T7" else str(REPO / "examples" / "poses.csv") if a == "POSES" else a for a in command]
    code, out, err = run(argv, capsys)
    assert code == 2 and out == ""
    assert_one_line(err, f"{t7}: GeometricCalibration: 7 poses give 21 equations for 21 identifiable parameters",
                    "too few to check the fit")


def test_22_04_with_enough_poses_the_calibration_still_fits():
    import numpy as np

    from tcr_accuracy.model.robot import load_robot
    from tcr_accuracy.prediction.calibration import GeometricCalibration

    robot = load_robot()
    rng = np.random.default_rng(0)
    X = robot.working_pose + rng.uniform(-0.5, 0.5, size=(16, robot.n_joints))
    model = GeometricCalibration(robot=robot).fit(X, rng.normal(0.0, 1e-3, size=(16, 3)))
    assert 3 * 16 >= 2 * model.identifiable_.size > 0


# ---------------------------------------------------------------------------------------
# 5: candidate poses the robot cannot take
# ---------------------------------------------------------------------------------------
def test_22_05_a_candidate_outside_the_joint_limits_is_refused_with_its_row(m60, tmp_path, capsys):
    header = "j1_deg,j2_deg,j3_deg,j4_mm,j5_deg,j6_deg\n"
    bad = tmp_path / "cand.csv"
    bad.write_text("# candidates\n" + header + "10,20,30,100,10,0\n10,20,-40,5000,10,0\n0,0,0,0,0,0\n")
    code, out, err = run(["plan-poses", m60, "-k", "3", "--candidates", bad, "--out", tmp_path / "p.csv",
                          "--effects", "joint_offsets"], capsys)
    assert code == 2 and out == ""
    assert_one_line(err, f"{bad}: row 4: joint j4 = 5000 mm is outside its limits [0, 600] mm")
    assert not (tmp_path / "p.csv").exists()
    good = tmp_path / "good.csv"
    good.write_text(header + "10,20,30,100,10,0\n11,21,31,100,10,0\n0,0,0,0,0,0\n5,5,5,5,5,5\n")
    code, out, err = run(["plan-poses", m60, "-k", "3", "--candidates", good, "--out", tmp_path / "p.csv",
                          "--effects", "joint_offsets"], capsys)
    assert code == 0, err
    assert len((tmp_path / "p.csv").read_text().splitlines()) >= 4


# ---------------------------------------------------------------------------------------
# 7: every command estimates its memory before the work
# ---------------------------------------------------------------------------------------
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

    monkeypatch.setattr(tracker_import, "import_tracker", _must_not_run)
    monkeypatch.setattr(diagnose, "diagnose", _must_not_run)
    tracker = tmp_path / "tracker.csv"
    tracker.write_text("X,Y,Z\n1,2,3\n")

    def spelt(a):
        return a.replace("TRACKER", str(tracker)).replace("M", str(m60)) if a in ("TRACKER", "M") or " " in a \
            else a.replace("T/", f"{tmp_path}/")

    code, out, err = run([spelt(a) for a in argv], capsys)
    assert code == 2 and out == ""
    assert_one_line(err, spelt(fragment), "--max-memory-gb")
    assert [p.name for p in tmp_path.iterdir()] == ["tracker.csv"]


def _must_not_run(*args, **kwargs):
    raise AssertionError("the work started before its memory was estimated")


# ---------------------------------------------------------------------------------------
# 11, 13-17, 20: tracker exports and joint logs
# ---------------------------------------------------------------------------------------
JOINTS = "j1_deg,j2_deg,j3_deg,j4_mm,j5_deg,j6_deg"


def _m60_rows(m60, n):
    """The first n rows of m60 as (x, y, z, joints-as-CSV-text), positions and joints that agree."""
    import csv

    rows = list(csv.DictReader(m60.read_text().splitlines()))[:n]
    return [(r["x_mm"], r["y_mm"], r["z_mm"], ",".join(r[j] for j in JOINTS.split(","))) for r in rows]


def _exports(tmp_path, tracker_times, log_rows, tracker_header="Time", m60=None):
    """A tracker file (one point per time: m60's positions when given) and a joint log
    (``(time, joints)`` rows)."""
    points = _m60_rows(m60, len(tracker_times)) if m60 is not None else [
        (f"{1000 + i}.5", "200", "300", "") for i in range(len(tracker_times))]
    tracker = tmp_path / "tracker.csv"
    tracker.write_text(f"Point;{tracker_header};X [mm];Y [mm];Z [mm]\n" + "".join(
        f"P{i};{t};{x.replace('.', ',')};{y.replace('.', ',')};{z.replace('.', ',')}\n"
        for i, (t, (x, y, z, _)) in enumerate(zip(tracker_times, points))))
    log = tmp_path / "log.csv"
    log.write_text(f"time,{JOINTS}\n" + "".join(f"{t},{joints}\n" for t, joints in log_rows))
    return tracker, log


def _import(tracker, log, capsys, *extra):
    out = tracker.parent / "m.csv"
    code, stdout, err = run(["import", tracker, "--joints", log, "--out", out, "--quiet", *extra], capsys)
    return code, err, out


def _first_column(path):
    return [float(r.split(",")[0]) for r in path.read_text().splitlines()[2:]]


def test_22_11_the_time_unit_in_the_header_is_honoured(m60, tmp_path, capsys):
    joints = [j for *_, j in _m60_rows(m60, 3)]
    tracker, log = _exports(tmp_path, [1000, 1020, 1040], list(zip([1000, 1020, 1040], joints)),
                            tracker_header="Time [ms]", m60=m60)
    log.write_text(log.read_text().replace("time,", "time [ms],", 1))
    code, err, out = _import(tracker, log, capsys)
    assert code == 0, err
    assert _first_column(out) == pytest.approx([float(j.split(",")[0]) for j in joints])
    # a log in seconds against a tracker in milliseconds: joined as the units say
    log.write_text(f"time_s,{JOINTS}\n" + "".join(f"{t},{j}\n" for t, j in zip([1.0, 1.02, 1.04], joints)))
    code, err, out = _import(tracker, log, capsys)
    assert code == 0, err
    assert _first_column(out) == pytest.approx([float(j.split(",")[0]) for j in joints])
    tracker.write_text(tracker.read_text().replace("Time [ms]", "Time [mm]"))
    code, err, out = _import(tracker, log, capsys)
    assert code == 2
    assert_one_line(err, "column 'Time [mm]': unit 'mm' is not a unit of time")


def test_22_13_two_log_samples_at_one_time_with_different_joints_are_refused(tmp_path, capsys):
    tracker, log = _exports(tmp_path, [10.0], [(10.0, "1,2,3,4,5,6"), (10.0, "9,2,3,4,5,6")])
    code, err, out = _import(tracker, log, capsys)
    assert code == 2
    assert_one_line(err, f"{log}: rows 2 and 3 have the same time '10.0' but different joint values")
    assert not out.exists()
    log.write_text(f"time,{JOINTS}\n10.0,1,2,3,4,5,6\n10.0,1,2,3,4,5,6\n")  # a repeated line: harmless
    assert _import(tracker, log, capsys)[0] == 0


def test_22_14_times_of_day_wrap_at_midnight(tmp_path, capsys):
    tracker, log = _exports(tmp_path, ["23:59:59,990"], [("00:00:00.010", "1,2,3,4,5,6"),
                                                         ("12:00:00.000", "9,2,3,4,5,6")])
    code, err, out = _import(tracker, log, capsys)
    assert code == 0, err
    assert out.read_text().splitlines()[2].startswith("1,")


def test_22_15_one_source_column_mapped_twice_is_refused(tmp_path, capsys):
    tracker, log = _exports(tmp_path, [10.0], [(10.0, "1,2,3,4,5,6")])
    code, err, out = _import(tracker, log, capsys, "--map", "x_mm=X [mm]", "y_mm=X [mm]")
    assert code == 2
    assert_one_line(err, "--map 'y_mm=X [mm]': column 'X [mm]' is already mapped to x_mm")


@settings(max_examples=80, deadline=None, derandomize=True)
@given(st.integers(0, 120), st.integers(0, 120), st.integers(0, 120), st.integers(0, 999))
def test_fuzz_22_16_a_clock_time_is_a_time_of_day_or_refused(h, m, s, ms):
    from pathlib import Path

    from tcr_accuracy.exceptions import InputError
    from tcr_accuracy.io.tracker_import import Table, parse_time

    text = f"{h:02d}:{m:02d}:{s:02d},{ms:03d}"
    table = Table(Path("t.csv"), ["Time"], [[text]], [5], ";", True)
    try:
        seconds, kind = parse_time(table, 0, 0)
    except InputError as exc:
        assert h > 23 or m > 59 or s > 59
        assert str(exc).startswith(f"t.csv: row 5, column 'Time': '{text}' is not a time")
        return
    assert h <= 23 and m <= 59 and s <= 59 and kind == "clock"
    assert seconds == pytest.approx(h * 3600 + m * 60 + s + ms / 1000)


@pytest.mark.parametrize("separator", ["\u2028", "\u0085", "\x0c"])
def test_22_17_a_line_separator_inside_a_cell_does_not_shift_the_row_numbers(separator, tmp_path, capsys):
    tracker = tmp_path / "tracker.csv"
    tracker.write_text(f"X;Y;Z;Note\n1;2;3;a{separator}b\n1;2;x;c\n", encoding="utf-8")
    code, out, err = run(["import", tracker, "--out", tmp_path / "m.csv"], capsys)
    assert code == 2
    assert_one_line(err, f"{tracker}: row 3, column 'Z': 'x' is not a number")


def _tracker_with_joints(m60, n, decimal=","):
    header = f"X [mm];Y [mm];Z [mm];{JOINTS.replace(',', ';')}\n"
    return header + "".join(f"{x.replace('.', decimal)};{y};{z};{j.replace(',', ';')}\n"
                            for x, y, z, j in _m60_rows(m60, n))


def test_22_20_utf16_exports_joint_columns_and_directions(m60, tmp_path, capsys):
    tracker = tmp_path / "t16.csv"
    tracker.write_bytes(_tracker_with_joints(m60, 5).encode("utf-16"))  # with a byte-order mark, as Windows writes
    code, out, err = run(["import", tracker, "--out", tmp_path / "m.csv", "--quiet"], capsys)
    assert code == 0, err
    header, first = (tmp_path / "m.csv").read_text().splitlines()[1:3]
    x, y, z, joints = _m60_rows(m60, 1)[0]
    assert header.split(",")[3:] == JOINTS.split(",")  # the tracker file's own joint columns are kept
    assert [float(v) for v in first.split(",")] == pytest.approx([float(v) for v in (x, y, z, *joints.split(","))])
    # a direction with a unit is no direction
    tracker, log = _exports(tmp_path, [10.0], [(10.0, "1,2,3,4,5,6")])
    log.write_text(f"time,{JOINTS},j1_dir\n10.0,1,2,3,4,5,6,1 mm\n")
    code, err, out = _import(tracker, log, capsys)
    assert code == 2
    assert_one_line(err, "column 'j1_dir': a direction is +1 or -1, got '1 mm'")


def test_22_20_a_decimal_comma_after_row_50_is_recognised(m60, tmp_path, capsys):
    tracker = tmp_path / "late.csv"
    rows = _tracker_with_joints(m60, 56, decimal=".").splitlines(keepends=True)
    last = rows[-1].split(";")
    last[0] = last[0].replace(".", ",")
    tracker.write_text("".join(rows[:-1]) + ";".join(last))
    code, out, err = run(["import", tracker, "--out", tmp_path / "m.csv", "--quiet"], capsys)
    assert code == 0, err
    assert float((tmp_path / "m.csv").read_text().splitlines()[-1].split(",")[0]) == pytest.approx(
        float(_m60_rows(m60, 56)[-1][0]))


@settings(max_examples=150, deadline=None, derandomize=True)
@given(st.text(alphabet="0123456789.,-+eE _mi\u0665\uff11 ", max_size=10), st.booleans())
def test_fuzz_22_18_20_an_import_cell_is_a_plain_number_or_one_refusal(cell, decimal_comma):
    import math
    import re
    from pathlib import Path

    from tcr_accuracy.exceptions import InputError
    from tcr_accuracy.io.tracker_import import Table, parse_time, parse_value

    def table(header):
        return Table(Path("t.csv"), [header], [[cell]], [4], ";" if decimal_comma else ",", decimal_comma)

    for header, parse in (("X [mm]", lambda: parse_value(table("X [mm]"), 0, 0, "mm")),
                          ("Time", lambda: parse_time(table("Time"), 0, 0)[0])):
        try:
            value = parse()
        except InputError as exc:
            assert str(exc).startswith(f"t.csv: row 4, column '{header}': ") and "\n" not in str(exc)
            continue
        assert math.isfinite(value)
        assert re.fullmatch(r"[0-9.,+\-eE ]*[a-z]*\s*", cell.strip(), re.ASCII), cell  # no other digits got in


# ---------------------------------------------------------------------------------------
# 12, 31: values of a measurement CSV held to ranges, as settings files' are
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("column, value, fragment", [
    ("payload_kg", "1e300", "1e+300 kg is beyond the 1e+06 kg"),
    ("temperature_c", "1e300", "1e+300 degC is beyond the 1000 degC"),
    ("j1_deg", "1e300", "1e+300 deg is beyond"),
    ("j4_mm", "1e12", "1e+12 mm is beyond the 1e+07 mm"),
    ("x_mm", "-1e300", "-1e+300 mm is beyond the 1e+06 mm"),
])
def test_22_12_a_huge_csv_value_is_refused_with_its_row_and_column(column, value, fragment, m60, tmp_path, capsys):
    lines = m60.read_text().splitlines()
    header = lines[0].split(",")
    cells = lines[5].split(",")
    cells[header.index(column)] = value
    lines[5] = ",".join(cells)
    path = tmp_path / "huge.csv"
    path.write_text("\n".join(lines) + "\n")
    code, out, err = run(["diagnose", path, "--json", tmp_path / "d.json"], capsys)
    assert code == 2 and out == ""
    assert_one_line(err, f"{path}: row 6, column {column}: {fragment}")
    assert [p.name for p in tmp_path.iterdir()] == ["huge.csv"]


@settings(max_examples=60, deadline=None, derandomize=True)
@given(st.sampled_from(["payload_kg", "temperature_c", "j2_deg", "j4_mm", "y_mm"]),
       st.floats(allow_nan=False, allow_infinity=False, width=64))
def test_fuzz_22_12_a_csv_value_is_in_range_or_one_refusal(column, value):
    import math
    import warnings

    from tcr_accuracy.exceptions import InputError
    from tcr_accuracy.io.measurements import parse_measurements
    from tcr_accuracy.model.robot import load_robot

    header = ["j1_deg", "j2_deg", "j3_deg", "j4_mm", "j5_deg", "j6_deg", "x_mm", "y_mm", "z_mm", "payload_kg",
              "temperature_c"]
    rows = [[10, 20, -10, 100, 5, 0, 100, 1500, 1200, 10, 20], [12, 22, -8, 120, 7, 2, 110, 1510, 1190, 10, 20]]
    rows[1][header.index(column)] = repr(value)
    text = ",".join(header) + "\n" + "\n".join(",".join(map(str, r)) for r in rows) + "\n"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # joint limits: warned, not at issue here
        try:
            mset = parse_measurements(text, load_robot(), source="f.csv")
        except InputError as exc:
            assert str(exc).startswith("f.csv: row 3") and "\n" not in str(exc), exc
            return
    assert all(math.isfinite(v) for v in [*mset.q.ravel(), *mset.position.ravel(), *mset.payload_kg,
                                          *mset.temperature_c])
    assert abs(value) <= 1e6


# ---------------------------------------------------------------------------------------
# 21: a <mimic> joint follows its rule in simulated and planned poses
# ---------------------------------------------------------------------------------------
def test_22_21_simulate_and_plan_poses_apply_the_mimic_rule(tmp_path, capsys):
    import csv
    import math

    urdf = tmp_path / "mim2.urdf"
    urdf.write_text(mimic_urdf())
    measured = tmp_path / "mm.csv"
    assert run(["simulate", "--robot", urdf, "--tool", "tool", "--random", "--n", "40", "--seed", "4",
                "--out", measured, "--quiet"], capsys)[0] == 0
    planned = tmp_path / "plan.csv"
    code, out, err = run(["plan-poses", measured, "--robot", urdf, "--tool", "tool", "-k", "4",
                          "--effects", "joint_offsets", "--n-candidates", "300", "--out", planned], capsys)
    assert code == 0, err
    offset_deg = math.degrees(0.1)
    for path, n in ((measured, 40), (planned, 4)):
        rows = list(csv.DictReader(line for line in path.read_text().splitlines() if not line.startswith("#")))
        assert len(rows) == n
        for row in rows:  # j3 = -1 x j2 + 0.1 rad, and within its limits
            assert float(row["j3_deg"]) == pytest.approx(-float(row["j2_deg"]) + offset_deg, abs=1e-6)
            assert abs(float(row["j3_deg"])) <= math.degrees(2.2) + 1e-9


# ---------------------------------------------------------------------------------------
# 22, 23: measured-frame columns
# ---------------------------------------------------------------------------------------
def _renamed_positions(m60, tmp_path, frame):
    lines = m60.read_text().splitlines()
    lines[0] = lines[0].replace("x_mm,y_mm,z_mm", f"{frame}.x_mm,{frame}.y_mm,{frame}.z_mm")
    path = tmp_path / f"{frame}.csv"
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.parametrize("command", [
    ["predict", "--train", "F", "--query", "M", "--method", "kriging"],
    ["plan-poses", "F", "-k", "3", "--effects", "joint_offsets", "--out", "T/p.csv"],
])
def test_22_22_one_measured_frame_that_is_the_tcp_is_read(command, m60, tmp_path, capsys):
    path = _renamed_positions(m60, tmp_path, "tool")
    argv = [str(path) if a == "F" else str(m60) if a == "M" else a.replace("T/", f"{tmp_path}/") for a in command]
    code, out, err = run(argv, capsys)
    assert code == 0, err
    code, out, err = run(argv + ["--tool", "j5"], capsys)  # another TCP: the file's frame is named
    assert code == 2
    assert_one_line(err, f"{path}: columns tool.x_mm ...: measures frame tool, not the robot's TCP frame j5; "
                         "give --tool tool")


def test_22_23_a_frame_the_robot_lacks_is_named_by_its_column(m60, tmp_path, capsys):
    path = _renamed_positions(m60, tmp_path, "nosuch")
    code, out, err = run(["diagnose", path], capsys)
    assert code == 2
    assert_one_line(err, f"{path}: column nosuch.x_mm: no such frame in built-in tool_changer")
    assert "--tool" not in err


# ---------------------------------------------------------------------------------------
# 24: the actual argument and cause
# ---------------------------------------------------------------------------------------
def test_22_24_messages_name_the_actual_argument_and_cause(m60, tmp_path, capsys, monkeypatch):
    import os

    monkeypatch.chdir(tmp_path)
    (tmp_path / "f").write_text("a file")
    os.mkfifo(tmp_path / "fifo")
    mixed = tmp_path / "mix.csv"
    lines = m60.read_text().splitlines()
    mixed.write_text("\n".join([lines[0].replace("z_mm", "z_m"), *lines[1:]]) + "\n")
    for argv, fragment in [
        (["view", "--error-preset", "table2", "--robot", "ur5", "--view", "v.html"],
         "--error-preset table2: the seed's Table 2 lists the tool-changer's joints"),
        (["pose", "--json", "f/x.json"], "--json f/x.json: the folder f is a file"),
        (["pose", "--robot", "."], "--robot .: a folder; give a URDF file"),
        (["pose", "--robot", "/dev/zero"], "--robot /dev/zero: not a regular file"),
        (["pose", "--robot", "fifo"], "--robot fifo: not a regular file"),
        (["diagnose", mixed], f"{mixed}: row 1: position columns mix units (x_mm, y_mm, z_m)"),
    ]:
        code, out, err = run(argv, capsys)
        assert code == 2, err
        assert_one_line(err, fragment)
        assert "--preset " not in err and "no such file" not in err and "does not exist" not in err


# ---------------------------------------------------------------------------------------
# 29: repeated poses are legitimate where they are asked about, not measured
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("command", [["predict", "--train", "M", "--query", "Q", "--method", "kriging"],
                                     ["compensate", "--train", "M", "--targets", "Q", "--method", "kriging"]])
def test_22_29_repeated_query_or_target_poses_are_answered(command, m60, tmp_path, capsys):
    from conftest import REPO

    poses = (REPO / "examples" / "poses.csv").read_text().splitlines()
    query = tmp_path / "q.csv"
    query.write_text("\n".join([*poses, poses[-1], poses[-1]]) + "\n")  # the last pose asked three times
    argv = [str(m60) if a == "M" else str(query) if a == "Q" else a for a in command]
    code, out, err = run([*argv, "--csv", tmp_path / "out.csv"], capsys)
    assert code == 0, err
    lines = (tmp_path / "out.csv").read_text().splitlines()
    header = lines[0].split(",")
    # the same answer each time (compensate's CSV also names each target's row in the file)
    keep = [i for i, name in enumerate(header) if name != "target_row"]
    rows = [[line.split(",")[i] for i in keep] for line in lines]
    assert rows[-1] == rows[-2] == rows[-3]
    # a training file keeps refusing a copied row
    train = tmp_path / "t.csv"
    lines = m60.read_text().splitlines()
    train.write_text("\n".join([*lines, lines[-1]]) + "\n")
    argv = [str(train) if a == "M" else str(query) if a == "Q" else a for a in command]
    code, out, err = run(argv, capsys)
    assert code == 2
    assert_one_line(err, f"{train}: row 62 repeats row 61 exactly")


# ---------------------------------------------------------------------------------------
# 30: answers that were no numbers, or numbers the data cannot give
# ---------------------------------------------------------------------------------------
def test_22_30_refused_rather_than_nan_or_an_unearned_certainty(m60, tmp_path, capsys):
    zero = tmp_path / "zero.yaml"
    zero.write_text("groups:\n  drive:\n    std_rad: 0.0\n    std_m: 0.0\n")
    for argv, fragment in [
        (["sensitivity", "--config", zero, "--sobol-samples", "64"], "no error source moves the TCP"),
        (["diagnose", m60, "--effects", ","], "--effects ',': names no effect"),
        (["diagnose", m60, "--effects", " , ,"], "names no effect"),
        (["tolerance", "--target-prob", "0.9999999", "--samples", "2000"],
         "--target-prob 0.9999999: 2000 samples cannot tell it from 1"),
    ]:
        code, out, err = run(argv, capsys)
        assert code == 2 and out == "", err
        assert_one_line(err, fragment)
        assert "nan" not in err


# ---------------------------------------------------------------------------------------
# 31: options that would be ignored, a data set of one pose
# ---------------------------------------------------------------------------------------
def test_22_31_ignored_options_and_one_pose_are_refused(m60, tmp_path, capsys):
    from conftest import REPO

    lines = m60.read_text().splitlines()
    header, row = lines[0].split(","), lines[1].split(",")
    one_pose = tmp_path / "one_pose.csv"  # 20 measurements of one pose, the tracker's noise apart
    x = header.index("x_mm")
    one_pose.write_text("\n".join([lines[0]] + [",".join(row[:x] + [f"{float(row[x]) + 0.01 * i:.4f}"] + row[x + 1:])
                                                 for i in range(20)]) + "\n")
    poses = REPO / "examples" / "poses.csv"
    for argv, fragment in [
        (["simulate", "--poses", poses, "--n", "5", "--out", tmp_path / "s.csv"], "--n with --poses"),
        (["simulate", "--poses", poses, "--box", "0", "1", "0", "1", "0", "1", "--out", tmp_path / "s.csv"],
         "--box with --poses"),
        (["view", "--magnify", "5", "--view", tmp_path / "v.html"], "--magnify 5: only with --error-preset"),
        (["diagnose", one_pose], f"{one_pose}: 20 rows at 1 distinct pose(s)"),
    ]:
        code, out, err = run(argv, capsys)
        assert code == 2 and out == "", err
        assert_one_line(err, fragment)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["one_pose.csv"]
    code, out, err = run(["simulate", "--poses", poses, "--out", tmp_path / "s.csv", "--quiet"], capsys)
    assert code == 0, err


# ---------------------------------------------------------------------------------------
# 32: a failed run says one line, not its warnings and status lines first
# ---------------------------------------------------------------------------------------
def test_22_32_warnings_and_status_lines_are_held_until_the_run_succeeds(m60, tmp_path, capsys):
    from conftest import REPO

    query = tmp_path / "q.csv"  # j1 = 400 deg in the last row: outside its limits, a warning
    lines = (REPO / "examples" / "poses.csv").read_text().splitlines()
    query.write_text("\n".join([*lines[:-1], "400," + lines[-1].split(",", 1)[1]]) + "\n")
    tracker = tmp_path / "t.csv"
    tracker.write_text("X [mm];Y [mm];Z [mm];j1_deg;j2_deg;j3_deg;j4_mm;j5_deg;j6_deg\n"
                       + "".join(f"{x};{y};{z};{j.replace(',', ';')}\n" for x, y, z, j in _m60_rows(m60, 10)))
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


def test_22_20_a_metadata_line_naming_the_columns_and_a_second_x_column(m60, tmp_path, capsys):
    tracker = tmp_path / "meta.csv"
    tracker.write_text("Leica export\nColumns: X;Y;Z\n\n" + _tracker_with_joints(m60, 5))
    code, out, err = run(["import", tracker, "--out", tmp_path / "m.csv", "--quiet"], capsys)
    assert code == 0, err  # the real header, below the metadata line, is found
    assert len((tmp_path / "m.csv").read_text().splitlines()) == 2 + 5
    dev = tmp_path / "dev.csv"
    dev.write_text("X [mm];Dev X;Y [mm];Z [mm]\n1000;0,1;200;300\n")
    code, out, err = run(["import", dev, "--out", tmp_path / "d.csv"], capsys)
    assert code == 2
    assert_one_line(err, f"{dev}: columns 'X [mm]', 'Dev X' could each be the x position")
