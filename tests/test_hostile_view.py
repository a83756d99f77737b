"""The 3D view under attack (issues 12 and 22): files a mesh references outside the robot's
folder (COLLADA images, OBJ material libraries and textures, links out of it) are refused,
not embedded; the live view answers only requests naming localhost (DNS rebinding).

The rules every test here holds the command to, and the helpers, are in ``hostile.py``.
"""

import base64
import json
from pathlib import Path

import pytest

from hostile import assert_one_line, collada_triangle, embedded_blobs, run, two_joint_urdf
from tcr_accuracy.cli import main


# ---------------------------------------------------------------------------------------
# Files a mesh references (12: 22; 22: 1)
# ---------------------------------------------------------------------------------------
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


SECRET = b"SECRET-CONTENT-22-01\n"


TRIANGLE_OBJ = "v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nf 1 2 3\n"


@pytest.fixture
def secret(tmp_path):
    """A file outside every robot folder of the tests below."""
    folder = tmp_path / "private"
    folder.mkdir()
    path = folder / "s.png"
    path.write_bytes(SECRET)
    return path


def robot_with_mesh(tmp_path, mesh_name: str, files: dict) -> Path:
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
# The live view against DNS rebinding (22: 28)
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
