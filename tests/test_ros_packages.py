"""ROS URDFs: ``package://`` meshes found through ``--package-dir`` and ``ROS_PACKAGE_PATH``, and a
missing package that no longer fails a run after its work (issue 20, part 5).

Every test builds, in ``tmp_path``, a small ROS package ``mypkg`` (a ``package.xml``, a binary
STL tetrahedron written here, ``urdf/robot.urdf``) and a copy of the URDF outside it, as a xacro
run writes one; the views are read back from the meshcat commands they embed.
"""

import math
import os
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hostile import assert_one_line, collada_triangle, embedded_blobs, run
from tcr_accuracy.analysis.collision import collision_checker
from tcr_accuracy.model.robot import MissingMeshWarning, load_robot
from tcr_accuracy.model.ros_packages import MAX_SEARCH_DEPTH
from tcr_accuracy.view.viewer import Scene

#: The tetrahedron's corners [m]; its four faces, outward.
CORNERS = np.array([[0.0, 0.0, 0.0], [0.05, 0.0, 0.0], [0.0, 0.05, 0.0], [0.0, 0.0, 0.05]])
FACES = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]
#: The arm: j1 about z at the base, j2 about y 0.3 m up, the tool 0.3 m further along l2's z.
LINK_LENGTH = 0.3


def stl_bytes() -> bytes:
    """A binary STL of the tetrahedron: 80-byte header, face count, then per face the normal,
    three corners and a 2-byte attribute (the format's definition, written out)."""
    out = bytearray(b"tcr-accuracy test tetrahedron".ljust(80, b" ")) + struct.pack("<I", len(FACES))
    for a, b, c in FACES:
        normal = np.cross(CORNERS[b] - CORNERS[a], CORNERS[c] - CORNERS[a])
        normal /= np.linalg.norm(normal)
        out += struct.pack("<12fH", *normal, *CORNERS[a], *CORNERS[b], *CORNERS[c], 0)
    return bytes(out)


def urdf_text(mesh: str = "package://mypkg/meshes/link.stl") -> str:
    geometry = f'<geometry><mesh filename="{mesh}"/></geometry>'
    body = f"<visual>{geometry}</visual><collision>{geometry}</collision>"
    return f"""<robot name="rosbot">
  <link name="base"/>
  <link name="l1">{body}</link>
  <link name="l2">{body}</link>
  <link name="tool"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0 0 {LINK_LENGTH}"/>
    <axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="jt" type="fixed"><parent link="l2"/><child link="tool"/><origin xyz="0 0 {LINK_LENGTH}"/></joint>
</robot>
"""


@pytest.fixture
def ros(tmp_path):
    """``ws/src/mypkg`` (package.xml, meshes/link.stl, urdf/robot.urdf) and ``robot.urdf``, the
    same URDF outside the package (``robots/arm/robot.urdf``); returns a namespace of the paths."""
    package = tmp_path / "ws" / "src" / "mypkg"
    (package / "meshes").mkdir(parents=True)
    (package / "urdf").mkdir()
    (package / "package.xml").write_text(
        '<?xml version="1.0"?>\n<package format="3"><name>mypkg</name><version>0.1.0</version>'
        "<description>test</description><maintainer email='a@b.c'>a</maintainer><license>MIT</license>"
        "</package>\n")
    (package / "meshes" / "link.stl").write_bytes(stl_bytes())
    (package / "urdf" / "robot.urdf").write_text(urdf_text())
    alone = tmp_path / "robots" / "arm" / "robot.urdf"  # may read robots/arm and robots/, not tmp_path
    alone.parent.mkdir(parents=True)
    alone.write_text(urdf_text())

    class Paths:
        root, ws, src, pkg, urdf, mesh = tmp_path, tmp_path / "ws", tmp_path / "ws" / "src", package, alone, \
            package / "meshes" / "link.stl"
    return Paths


def tool_position_by_hand(q1: float, q2: float) -> np.ndarray:
    """The TCP [m]: l2's z axis turned by q2 about y, then by q1 about z, from j2 0.3 m up."""
    return np.array([LINK_LENGTH * math.sin(q2) * math.cos(q1), LINK_LENGTH * math.sin(q2) * math.sin(q1),
                     LINK_LENGTH + LINK_LENGTH * math.cos(q2)])


def mesh_objects(commands) -> dict:
    """The mesh files a scene sends, by node path: {path: (format, bytes)}."""
    found = {}
    for command in commands:
        for geometry in (command.get("object") or {}).get("geometries", []):
            if geometry.get("type") == "_meshfile":
                found[command["path"]] = (geometry["format"], bytes(geometry["data"].data))
    return found


# ---------------------------------------------------------------------------------------
# found
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("given", ["src", "ws", "pkg"])
def test_package_dir_finds_the_package_as_parent_workspace_or_package_itself(given, ros, tmp_path, capsys):
    folder = getattr(ros, given)  # ws/src holds mypkg; ws holds it one level down; mypkg is the package
    code, out, err = run(["view", "--robot", ros.urdf, "--package-dir", folder, "--view", tmp_path / "v.html",
                          "--quiet"], capsys)
    assert code == 0, err
    assert err == ""  # no warning: every mesh was found
    assert stl_bytes() in embedded_blobs((tmp_path / "v.html").read_text())


def test_the_scene_draws_the_package_mesh_on_each_link_where_the_kinematics_puts_it(ros):
    robot = load_robot(ros.urdf, package_dirs=[ros.ws])
    assert robot.packages == {"mypkg": str(ros.pkg)}
    q = np.array([0.4, 0.5])
    scene = Scene("ros")
    scene.add_robot(robot, q, "nominal")
    commands = scene.recorded_commands()
    meshes = mesh_objects(commands)
    assert meshes == {"/meshcat/nominal/visuals/l1_0": ("stl", stl_bytes()),
                      "/meshcat/nominal/visuals/l2_0": ("stl", stl_bytes())}
    l2 = next(c for c in commands if c["type"] == "set_transform" and c["path"] == "/meshcat/nominal/visuals/l2_0")
    matrix = np.array(l2["matrix"], dtype=float).reshape(4, 4).T  # three.js: column-major
    np.testing.assert_allclose(matrix[:3, 3], [0.0, 0.0, LINK_LENGTH], atol=1e-9)  # j2's origin, whatever q
    np.testing.assert_allclose(matrix[:3, :3] @ [0.0, 0.0, LINK_LENGTH] + matrix[:3, 3],
                               tool_position_by_hand(*q), atol=1e-9)
    assert "skeleton" not in " ".join(entry.text for entry in scene.legend)


def test_ros_package_path_finds_the_package_in_a_subprocess(ros, tmp_path):
    env = dict(os.environ, ROS_PACKAGE_PATH=f"{tmp_path / 'nowhere'}{os.pathsep}{ros.ws}",
               PYTHONPATH=os.pathsep.join([str(Path(__file__).resolve().parents[1] / "src"),
                                           os.environ.get("PYTHONPATH", "")]))
    done = subprocess.run([sys.executable, "-m", "tcr_accuracy", "view", "--robot", str(ros.urdf), "--view",
                           str(tmp_path / "v.html"), "--quiet"], env=env, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stderr == ""
    assert stl_bytes() in embedded_blobs((tmp_path / "v.html").read_text())


def test_a_package_is_found_by_the_name_in_its_package_xml_not_its_folder(ros, monkeypatch):
    renamed = ros.src / "mypkg-checkout"  # a clone whose folder is not the package's name
    ros.pkg.rename(renamed)
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(ros.ws))
    robot = load_robot(ros.urdf)
    assert robot.packages == {"mypkg": str(renamed)}
    meshes = [Path(obj.meshPath) for obj in robot.visual_model().geometryObjects]
    assert meshes == [renamed / "meshes" / "link.stl"] * 2


@pytest.mark.parametrize("levels, found", [(MAX_SEARCH_DEPTH, True), (MAX_SEARCH_DEPTH + 1, False)])
def test_a_workspace_is_searched_down_to_the_depth_said(levels, found, ros, tmp_path):
    deep = tmp_path / "deep"
    target = deep.joinpath(*[f"d{k}" for k in range(levels - 1)], "mypkg")  # mypkg `levels` folders down
    target.parent.mkdir(parents=True)
    ros.pkg.rename(target)
    if found:
        assert load_robot(ros.urdf, package_dirs=[deep]).packages == {"mypkg": str(target)}
    else:
        with pytest.warns(MissingMeshWarning, match="'mypkg' not found"):
            assert load_robot(ros.urdf, package_dirs=[deep]).packages == {}


def test_a_urdf_inside_its_own_package_finds_its_meshes_without_options(ros, monkeypatch):
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    robot = load_robot(ros.pkg / "urdf" / "robot.urdf")
    assert [Path(obj.meshPath) for obj in robot.visual_model().geometryObjects] == [ros.mesh] * 2


def test_relative_and_file_urls_keep_working(ros, tmp_path):
    relative = ros.pkg / "urdf" / "relative.urdf"
    relative.write_text(urdf_text("../meshes/link.stl"))
    absolute = ros.pkg / "urdf" / "absolute.urdf"
    absolute.write_text(urdf_text(f"file://{ros.mesh}"))
    for urdf in (relative, absolute):
        geometry = load_robot(urdf).visual_model()
        assert [Path(obj.meshPath).resolve() for obj in geometry.geometryObjects] == [ros.mesh] * 2


def test_collision_bodies_come_from_the_package(ros):
    checker = collision_checker(load_robot(ros.urdf, package_dirs=[ros.src]))
    assert checker.geometry.ngeoms == 2
    assert [Path(obj.meshPath) for obj in checker.geometry.geometryObjects] == [ros.mesh] * 2


# ---------------------------------------------------------------------------------------
# missing
# ---------------------------------------------------------------------------------------
def test_view_without_the_package_draws_the_skeleton_and_says_so_once(ros, tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    q_deg = (23.0, 29.0)
    code, out, err = run(["view", "--robot", ros.urdf, "--q", *q_deg, "--view", tmp_path / "v.html", "--quiet"],
                         capsys)
    assert code == 0, err
    assert_one_line(err, "warning", str(ros.urdf), "package://mypkg/meshes/link.stl", "'mypkg' not found",
                    "--package-dir", "ROS_PACKAGE_PATH", "skeleton")
    html = (tmp_path / "v.html").read_text()
    assert stl_bytes() not in embedded_blobs(html)
    assert "skeleton: meshes missing for links l1, l2" in html
    # the same skeleton in a scene: segments base -> j1 -> j2 -> TCP at the joints' places by hand
    with pytest.warns(MissingMeshWarning, match="mypkg"):
        robot = load_robot(ros.urdf)
    q = np.radians(q_deg)
    scene = Scene("skeleton")
    scene.add_robot(robot, q, "nominal")
    assert mesh_objects(scene.recorded_commands()) == {}
    links = next(c for c in scene.recorded_commands() if c["path"] == "/meshcat/nominal/links")
    attribute = links["object"]["geometries"][0]["data"]["attributes"]["position"]
    drawn = np.frombuffer(attribute["array"].data, dtype=np.float32).reshape(-1, 3)
    up = [0.0, 0.0, LINK_LENGTH]
    np.testing.assert_allclose(drawn, [[0, 0, 0], [0, 0, 0], [0, 0, 0], up, up, tool_position_by_hand(*q)],
                               atol=1e-6)


def test_diagnose_without_the_package_writes_its_report_with_the_skeleton(ros, tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    csv = tmp_path / "m.csv"
    code, out, err = run(["simulate", "--robot", ros.urdf, "--random", "--n", "30", "--seed", "1", "--out", csv,
                          "--quiet"], capsys)
    assert code == 0, err
    assert_one_line(err, "'mypkg' not found")  # told at load, before any work
    code, out, err = run(["diagnose", csv, "--robot", ros.urdf, "--effects", "joint_offsets", "--out",
                          tmp_path / "rep", "--quiet"], capsys)
    assert code == 0, err
    assert_one_line(err, "'mypkg' not found", "--package-dir", "skeleton")  # once, though loaded twice
    assert (tmp_path / "rep" / "index.html").is_file()
    scenes = sorted((tmp_path / "rep").glob("scene-*.html"))
    assert scenes and "skeleton: meshes missing for links l1, l2" in scenes[0].read_text()


def test_collision_check_without_the_package_leaves_the_bodies_out(ros, monkeypatch):
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    with pytest.warns(MissingMeshWarning, match="collision checks leave them out"):
        robot = load_robot(ros.urdf)
    assert collision_checker(robot) is None  # no body left: unchecked, as for a URDF without collisions


def test_one_mesh_missing_from_a_found_package_keeps_the_other(ros, tmp_path):
    urdf = ros.urdf
    urdf.write_text(urdf_text().replace("package://mypkg/meshes/link.stl", "package://mypkg/meshes/gone.stl", 2))
    with pytest.warns(MissingMeshWarning, match=r"'package://mypkg/meshes/gone.stl'\): not in package 'mypkg'"):
        robot = load_robot(urdf, package_dirs=[ros.src])
    scene = Scene("half")
    scene.add_robot(robot, np.zeros(2), "nominal")
    assert list(mesh_objects(scene.recorded_commands())) == ["/meshcat/nominal/visuals/l2_0"]
    assert any(c["path"] == "/meshcat/nominal/links" for c in scene.recorded_commands())
    assert "skeleton: meshes missing for link l1" in scene.legend[0].text


# ---------------------------------------------------------------------------------------
# refused
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("what", ["missing", "file"])
def test_a_package_dir_that_is_no_folder_is_refused_before_any_work(what, ros, tmp_path, capsys):
    folder = tmp_path / "nope" if what == "missing" else ros.urdf
    code, out, err = run(["view", "--robot", ros.urdf, "--package-dir", ros.src, "--package-dir", folder,
                          "--view", tmp_path / "v.html"], capsys)
    assert code == 2 and out == ""
    assert_one_line(err, f"--package-dir {folder}", "does not exist" if what == "missing" else "not a folder")
    assert not (tmp_path / "v.html").exists()


def test_a_texture_outside_the_package_folder_is_refused(ros, tmp_path, capsys):
    private = tmp_path / "private"
    private.mkdir()
    (private / "s.png").write_bytes(b"SECRET-OUTSIDE-THE-PACKAGE")
    # from ws/src/mypkg/meshes, four levels up is tmp_path: outside the package folder
    (ros.pkg / "meshes" / "t.dae").write_text(collada_triangle("../../../../private/s.png"))
    ros.urdf.write_text(urdf_text("package://mypkg/meshes/t.dae"))
    code, out, err = run(["view", "--robot", ros.urdf, "--package-dir", ros.src, "--view", tmp_path / "v.html"],
                         capsys)
    assert code == 2
    assert_one_line(err, "mesh 'package://mypkg/meshes/t.dae' references '../../../../private/s.png'",
                    "lies outside the URDF's folder and package folders")
    assert not (tmp_path / "v.html").exists()


def test_a_package_mesh_name_that_climbs_out_of_the_package_is_refused(ros, tmp_path, capsys):
    (tmp_path / "private").mkdir()
    (tmp_path / "private" / "x.stl").write_bytes(stl_bytes())
    ros.urdf.write_text(urdf_text("package://mypkg/../../../private/x.stl"))
    code, out, err = run(["view", "--robot", ros.urdf, "--package-dir", ros.src, "--view", tmp_path / "v.html"],
                         capsys)
    assert code == 2
    assert_one_line(err, "link l1: mesh 'package://mypkg/../../../private/x.stl' lies outside")
    assert not (tmp_path / "v.html").exists()


def test_an_as_built_urdf_of_a_named_robot_finds_its_meshes_anywhere(tmp_path):
    # export writes a UR10's as-built URDF with the package:// names of example-robot-data,
    # which is installed with the tool: loaded from any folder, every mesh is found (warnings
    # are errors in this suite) and the scene embeds the same mesh files as the named robot's
    import warnings

    from tcr_accuracy.asbuilt.urdf import as_built_urdf
    from tcr_accuracy.model.errors import ErrorModel

    named = load_robot("ur10")
    x = 1e-4 * np.random.default_rng(0).standard_normal(len(ErrorModel(named).parameters))
    text, tool_frame = as_built_urdf(named, x)
    path = tmp_path / "elsewhere" / "as_built.urdf"
    path.parent.mkdir()
    path.write_text(text)
    assert "package://example-robot-data/" in text
    with warnings.catch_warnings():
        warnings.simplefilter("error", MissingMeshWarning)
        loaded = load_robot(str(path), tool_frame)
    assert loaded.missing_mesh_message() in (None, "")
    assert sorted(p.name for p in loaded.mesh_places()) == sorted(p.name for p in named.mesh_places())


def test_29_10_a_search_passes_over_folders_it_cannot_read_and_follows_no_link(ros, tmp_path, monkeypatch):
    """``--package-dir /`` met /proc/1/cwd (no permission, even for root in a container) and
    /proc/*/cwd links back to /: a folder that cannot be read is passed over, a link not followed."""
    from tcr_accuracy.model import ros_packages

    top = tmp_path / "top"
    (top / "locked").mkdir(parents=True)
    (top / "loop").symlink_to(top, target_is_directory=True)  # followed, the walk would see itself again
    (top / "elsewhere").symlink_to(ros.src, target_is_directory=True)  # the package, only through a link
    real_scandir = os.scandir

    def scandir(path):
        if Path(path).name == "locked":
            raise PermissionError(13, "Permission denied", str(path))
        return real_scandir(path)

    monkeypatch.setattr(ros_packages.os, "scandir", scandir)
    assert ros_packages.packages_below(top, {"mypkg"}) == {}
    (top / "open").mkdir()
    ros.pkg.rename(top / "open" / "mypkg")
    assert ros_packages.packages_below(top, {"mypkg"}) == {"mypkg": top / "open" / "mypkg"}
