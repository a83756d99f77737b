"""The meshcat scene and the HTML report, checked without a browser (see test_browser.py for that).

Body placements are compared with the TCP pose of the batched numpy engine (an independent
path from Pinocchio's geometry placements), point clouds with the closed-form
magnification and, for the TCP error cloud, with the TCP multiplied out by hand from the
URDF's numbers (conftest), report tables with the values put in.
"""

import base64
import os
import re
import socket
import sys
import urllib.request
from pathlib import Path

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")

from tcr_accuracy.view import report as report_module
from tcr_accuracy.cli import main, write_file
from tcr_accuracy.cli.staging import write_text
from tcr_accuracy.cli.writers import write_report
from tcr_accuracy.model.errors import ErrorModel, seed_budget
from tcr_accuracy.exceptions import InputError
from tcr_accuracy.model.kinematics import tcp_poses
from tcr_accuracy.view.report import Report
from tcr_accuracy.view.robot_visuals import visual_geometry
from tcr_accuracy.view.viewer import Scene, auto_magnification

from conftest import TOOL_CHANGER_JOINTS, tool_changer_tcp_by_hand

#: In the built-in tool-changer the end-effector box is centred 0.05 m along +y of the
#: TCP frame (tcr_accuracy.model.tool_changer._link_geometry), and the TCP sits at j6's origin.
END_EFFECTOR_CENTRE_IN_TCP = np.array([0.0, 0.05, 0.0])


def _matrix(command):
    return np.array(command["matrix"], dtype=float).reshape(4, 4).T  # meshcat sends column-major


def _transform(scene, path):
    found = [c for c in scene.recorded_commands() if c["type"] == "set_transform" and c["path"] == path]
    assert len(found) == 1, f"{path}: {len(found)} transforms recorded"
    return _matrix(found[0])


def _object(scene, path):
    found = [c for c in scene.recorded_commands() if c["type"] == "set_object" and c["path"] == path]
    assert len(found) == 1, f"{path}: {len(found)} objects recorded"
    return found[0]["object"]


def _positions(obj):
    attribute = obj["geometries"][0]["data"]["attributes"]["position"]
    return np.frombuffer(attribute["array"].data, dtype=np.float32).reshape(-1, 3).astype(float)


def _colors(obj):
    attribute = obj["geometries"][0]["data"]["attributes"]["color"]
    return np.frombuffer(attribute["array"].data, dtype=np.float32).reshape(-1, 3).astype(float)


def test_visual_geometry_follows_the_tcp_chain(tool_changer, ur5):
    geometry = visual_geometry(tool_changer)
    names = sorted(obj.name for obj in geometry.geometryObjects)
    assert names == sorted(f"{link}_0" for link in ("base_link", "turret", "base_arm", "extended_arm",
                                                     "telescopic_arm", "wrist", "end_effector"))
    # UR5 meshes come from example-robot-data through package:// paths
    meshes = [obj.meshPath for obj in visual_geometry(ur5).geometryObjects]
    assert meshes and all(Path(m).is_file() for m in meshes)


def test_robot_bodies_sit_on_the_nominal_and_the_as_built_kinematics(tool_changer):
    robot, q = tool_changer, tool_changer.working_pose
    budget = seed_budget(robot, "table1")
    x = 30.0 * budget.sample(1, np.random.default_rng(3))[0]  # large enough to move bodies visibly
    scene = Scene("placements")
    scene.add_robot(robot, q, "nominal")
    scene.add_robot(budget.error_model.perturbed_robot(x), q, "ghost", color=(1, 0, 0), opacity=0.3)
    for name, xi in (("nominal", None), ("ghost", x)):
        pose = tcp_poses(robot, q, xi, budget.error_model if xi is not None else None)
        expected = np.eye(4)
        expected[:3, :3] = pose.rotation[0]
        expected[:3, 3] = pose.position[0] + pose.rotation[0] @ END_EFFECTOR_CENTRE_IN_TCP
        drawn = _transform(scene, f"/meshcat/{name}/visuals/end_effector_0")
        np.testing.assert_allclose(drawn, expected, atol=1e-9)
    nominal_box = _transform(scene, "/meshcat/nominal/visuals/end_effector_0")
    ghost_box = _transform(scene, "/meshcat/ghost/visuals/end_effector_0")
    assert np.linalg.norm(nominal_box[:3, 3] - ghost_box[:3, 3]) > 0.01
    # the ghost is painted and transparent, the nominal robot keeps its URDF paint
    ghost_material = _object(scene, "/meshcat/ghost/visuals/end_effector_0")["materials"][0]
    assert ghost_material["color"] == 0xFF0000 and ghost_material["transparent"]
    assert ghost_material["opacity"] == pytest.approx(0.3)
    nominal_material = _object(scene, "/meshcat/nominal/visuals/end_effector_0")["materials"][0]
    assert nominal_material["color"] == (int(0.20 * 255) << 16) + (int(0.45 * 255) << 8) + int(0.75 * 255)


def test_point_cloud_is_magnified_about_its_centre_and_coloured_by_value():
    rng = np.random.default_rng(7)
    centre = np.array([0.5, 1.0, 1.2])
    points = centre + rng.normal(scale=1e-3, size=(40, 3))
    values = np.linalg.norm(points - centre, axis=1) * 1000.0
    scene = Scene("cloud")
    bar = scene.add_point_cloud(points, values, "cloud", "|dP| [mm]", center_m=centre, magnify=100.0)
    drawn = _positions(_object(scene, "/meshcat/cloud"))
    np.testing.assert_allclose(drawn, centre + 100.0 * (points - centre), atol=1e-6)
    colors = _colors(_object(scene, "/meshcat/cloud"))
    # viridis starts dark purple (0.267, 0.005, 0.329) and ends yellow (0.993, 0.906, 0.144)
    np.testing.assert_allclose(colors[np.argmin(values)], [0.267, 0.005, 0.329], atol=2e-3)
    np.testing.assert_allclose(colors[np.argmax(values)], [0.993, 0.906, 0.144], atol=2e-3)
    assert (bar.vmin, bar.vmax) == (pytest.approx(values.min()), pytest.approx(values.max()))
    page = scene.static_html()
    assert "|dP| [mm]" in page and "magnified x 100" in page


def test_error_segments_join_start_to_magnified_end_and_trajectory_is_a_polyline():
    start = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 1.0]])
    end = start + np.array([[1e-3, 0.0, 0.0], [0.0, -2e-3, 0.0]])
    scene = Scene("segments")
    scene.add_error_segments(start, end, magnify=50.0, name="gap")
    segments = _positions(_object(scene, "/meshcat/gap/segments"))
    np.testing.assert_allclose(segments, [[0, 0, 1], [0.05, 0, 1], [1, 0, 1], [1, -0.1, 1]], atol=1e-6)
    assert _object(scene, "/meshcat/gap/segments")["object"]["type"] == "LineSegments"
    path = np.column_stack([np.linspace(0, 1, 5), np.zeros(5), np.ones(5)])
    scene.add_trajectory(path, "path")
    np.testing.assert_allclose(_positions(_object(scene, "/meshcat/path")), path, atol=1e-6)
    assert _object(scene, "/meshcat/path")["object"]["type"] == "Line"
    assert "segments magnified x 50" in scene.static_html()
    with pytest.raises(InputError, match="start points but"):
        scene.add_error_segments(start, end[:1], magnify=2.0)
    with pytest.raises(InputError, match="NaN"):
        scene.add_trajectory([[0, 0, 0], [np.nan, 0, 0]])


def test_auto_magnification_draws_the_largest_error_at_most_0_8_m():
    assert auto_magnification(0.0337) == 20.0  # 0.8 / 0.0337 = 23.7 -> 20
    assert auto_magnification(2e-4) == 2000.0  # 4000 -> 2000
    assert auto_magnification(1e-4) == 5000.0  # 8000 -> 5000
    assert auto_magnification(2.0) == 1.0
    assert auto_magnification(0.0) == 1.0


def test_tcp_error_cloud_matches_the_kinematics(tool_changer):
    """The drawn cloud against the TCP multiplied out by hand (conftest), magnified by the
    documented rule: 1, 2 or 5 x 10^k, the largest error drawn at most 0.8 m long."""
    robot, q = tool_changer, tool_changer.working_pose
    em = ErrorModel(robot)
    rng = np.random.default_rng(11)
    n = 30
    # link length and drive errors of the seed's Table 2 kind, written into x by name
    link_errors = rng.normal(0.0, 0.2e-3, (n, 6))  # [m]
    drive_errors = rng.normal(0.0, np.radians(0.3), (n, 6))  # [rad]; j4's is metres
    drive_errors[:, 3] = rng.normal(0.0, 0.25e-3, n)
    x = np.zeros((n, em.size))
    for i, (joint, _, origin, _) in enumerate(TOOL_CHANGER_JOINTS):
        x[:, em.index(f"{joint}.{'dz' if origin[2] else 'dy'}")] = link_errors[:, i]
        x[:, em.index(f"{joint}.drive")] = drive_errors[:, i]
    scene = Scene("cloud")
    magnify = scene.add_tcp_error_cloud(robot, q, x, em)

    nominal = tool_changer_tcp_by_hand(q)[:3, 3]
    actual = np.array([tool_changer_tcp_by_hand(q, dl, dq)[:3, 3] for dl, dq in zip(link_errors, drive_errors)])
    largest = np.linalg.norm(actual - nominal, axis=1).max()
    assert 1e-3 < largest < 0.1  # millimetres to centimetres: magnified, not left at 1
    factors = sorted(m * 10.0**k for k in range(8) for m in (1, 2, 5))
    assert magnify in factors and magnify * largest <= 0.8
    assert factors[factors.index(magnify) + 1] * largest > 0.8  # and the largest such factor
    drawn = _positions(_object(scene, "/meshcat/tcp_cloud"))
    np.testing.assert_allclose(drawn, nominal + magnify * (actual - nominal), atol=1e-5)  # float32


def test_static_html_is_one_self_contained_file(tmp_path, tool_changer):
    scene = Scene("title <with> markup")
    scene.add_robot(tool_changer, tool_changer.working_pose, "nominal")
    path = write_text(tmp_path / "view.html", scene.static_html())
    page = path.read_text(encoding="utf-8")
    assert "title &lt;with&gt; markup" in page
    assert not re.search(r"<script[^>]+src=|<link[^>]+href=", page)  # nothing loaded from elsewhere
    # each recorded command is in the page, base64 of meshcat's msgpack bytes
    blobs = re.search(r"var tcrCommands = (\[.*?\]);", page, re.S).group(1)
    assert len(re.findall(r'"[A-Za-z0-9+/=]+"', blobs)) == len(scene.recorded_commands())
    assert base64.b64decode(re.findall(r'"([A-Za-z0-9+/=]+)"', blobs)[0])
    assert [p.name for p in tmp_path.iterdir()] == ["view.html"]  # no temporary file left


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="127.0.0.2 is a loopback address on Linux only")
def test_live_view_listens_on_localhost_only(tool_changer):
    scene = Scene("live")
    scene.add_robot(tool_changer, tool_changer.working_pose, "nominal")
    with scene.serve() as live:
        assert live.url.startswith("http://127.0.0.1:")
        port = int(live.url.split(":")[2].split("/")[0])
        with urllib.request.urlopen(live.url, timeout=10) as response:
            page = response.read().decode("utf-8")
        assert "tcr-legend" in page and "viewer.connect()" in page
        web, zmq = port, int(live.zmq_url.rsplit(":", 1)[1])
        # the same ports on another address of this host: a server bound to 0.0.0.0 (every
        # address) would answer there; one bound to 127.0.0.1 refuses. 127.0.0.2 is on the
        # loopback device too (Linux routes all of 127/8 there), so nothing leaves the machine.
        for other in (web, zmq):
            with pytest.raises(ConnectionRefusedError):
                socket.create_connection(("127.0.0.2", other), timeout=5).close()
        socket.create_connection(("127.0.0.1", zmq), timeout=5).close()  # and the check can tell
    assert live.process.poll() is not None


# ---------------------------------------------------------------------------------------
# Report
# ---------------------------------------------------------------------------------------
def _sample_report():
    import matplotlib.pyplot as plt

    report = Report("Sample | report", command=["montecarlo", "--seed", "3", "--out", "a b"])
    report.add_text("First paragraph.\n\nSecond <paragraph>.", heading="Setup")
    report.add_table("Position error", ["axis", "std", "n"], [["x", 0.123456, 5], ["|dP|", float("nan"), 7]],
                     units=["", "mm", ""], note="seeded")
    fig, ax = plt.subplots(figsize=(2, 2))
    ax.plot([0, 1], [0, 1])
    report.add_figure(fig, "A line")
    plt.close(fig)
    report.add_scene("<!DOCTYPE html><title>scene</title>", "The view")
    return report


def test_report_writes_tables_figures_scenes_command_and_versions(tmp_path):
    index = write_report(_sample_report(), tmp_path / "out")
    out = index.parent
    assert sorted(p.name for p in out.iterdir()) == ["figure-1.png", "index.html", "report.md", "scene-1.html"]
    page = index.read_text(encoding="utf-8")
    assert "<th>std [mm]</th>" in page and "<td>0.1235</td>" in page and "<td>NaN</td>" in page
    assert "Second &lt;paragraph&gt;." in page
    assert "tcr-accuracy montecarlo --seed 3 --out &#x27;a b&#x27;" in page
    versions = report_module.versions()
    assert versions["pin"] != "not installed" and versions["numpy"] == np.__version__
    assert f"<td>numpy</td><td>{np.__version__}</td>" in page
    assert 'src="figure-1.png"' in page and 'iframe src="scene-1.html"' in page
    assert (out / "figure-1.png").read_bytes().startswith(b"\x89PNG")
    assert not re.search(r"(src|href)=\"https?://", page)
    markdown = (out / "report.md").read_text(encoding="utf-8")
    assert "| axis | std \\[mm\\] | n |" in markdown and "| \\|dP\\| | NaN | 7 |" in markdown
    assert "![A line](figure-1.png)" in markdown


def test_report_write_failure_keeps_the_old_index_and_leaves_no_temporary_files(tmp_path, monkeypatch):
    out = tmp_path / "out"
    write_report(_sample_report(), out)
    before = (out / "index.html").read_bytes()
    real_replace = os.replace

    def interrupted(src, dst, **fds):
        if str(dst).endswith("index.html"):
            raise KeyboardInterrupt
        return real_replace(src, dst, **fds)

    monkeypatch.setattr(write_file.os, "replace", interrupted)
    with pytest.raises(KeyboardInterrupt):
        write_report(Report("new"), out)
    assert (out / "index.html").read_bytes() == before
    assert not [p.name for p in out.iterdir() if p.name.startswith(".")]


def test_report_is_byte_identical_for_the_same_content_and_source_date(tmp_path, monkeypatch):
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1700000000")
    first = write_report(_sample_report(), tmp_path / "a").parent
    second = write_report(_sample_report(), tmp_path / "b").parent
    for name in ("index.html", "report.md", "figure-1.png", "scene-1.html"):
        assert (first / name).read_bytes() == (second / name).read_bytes(), name
    assert "Written 2023-11-14 22:13:20 UTC" in (first / "index.html").read_text(encoding="utf-8")


def test_report_rejects_bad_tables_and_figures(tmp_path):
    report = Report("bad")
    with pytest.raises(InputError, match="row 2 has 1 values for 2 columns"):
        report.add_table("t", ["a", "b"], [[1, 2], [3]])
    with pytest.raises(InputError, match="2 units for 1 columns"):
        report.add_table("t", ["a"], [[1]], units=["mm", "deg"])
    with pytest.raises(InputError, match="figure 'bad': not a PNG"):
        report.add_figure(b"not a png", "bad")


# ---------------------------------------------------------------------------------------
# CLI
# ---------------------------------------------------------------------------------------
def test_view_command_writes_a_static_page_with_the_error_cloud(tmp_path, capsys):
    out = tmp_path / "v.html"
    code = main(["view", "--error-preset", "table2", "--samples", "40", "--seed", "2", "--html", str(out)])
    assert code == 0
    page = out.read_text(encoding="utf-8")
    assert "TCP error |dP| [mm]" in page and "40 samples of the seed&#x27;s table2 errors, seed 2" in page
    captured = capsys.readouterr()
    assert "3D view written to" in captured.err and captured.out == ""  # a status line, on stderr
    assert main(["view", "--html", str(out), "--quiet"]) == 0
    assert capsys.readouterr().err == ""


@pytest.mark.parametrize("argv, message", [
    (["view", "--samples", "0", "--error-preset", "table1"], "--samples 0"),
    (["view", "--magnify", "0"], "--magnify 0:"),
    (["view", "--open"], "--open needs --serve"),
    (["view", "--q", "1", "2"], "expected 6 joint values"),
    (["view", "--html", "/nonexistent-dir/v.html"],  # --html is --view's older name: the error says --view
     "--view /nonexistent-dir/v.html: the folder /nonexistent-dir does not exist"),
])
def test_view_command_bad_input_is_one_line_and_exit_2(argv, message, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


def test_view_arguments_plug_into_another_command(tmp_path, capsys, tool_changer):
    import argparse

    from tcr_accuracy.cli.view import add_view_arguments, emit_view

    parser = argparse.ArgumentParser()
    add_view_arguments(parser)
    scene = Scene("other command")
    scene.add_robot(tool_changer, tool_changer.working_pose, "nominal")
    emit_view(scene, parser.parse_args([]))  # no --view: nothing written
    assert not list(tmp_path.iterdir()) and capsys.readouterr().out == ""
    emit_view(scene, parser.parse_args(["--view", str(tmp_path / "v.html")]))
    assert "robot: nominal" in (tmp_path / "v.html").read_text(encoding="utf-8")
    assert parser.parse_args(["--view"]).view == "view.html"


def _outside_code(markdown: str) -> str:
    """The Markdown text outside fenced code blocks and inline code spans, as CommonMark reads
    them: a fence of N backticks closes at a line of at least N backticks; a span of N backticks
    closes at the next run of exactly N."""
    out, fence = [], None
    for line in markdown.splitlines():
        run = re.match(r"^(`{3,})\s*$", line)
        if fence is None and run:
            fence = run.group(1)
        elif fence is not None:
            if run and len(run.group(1)) >= len(fence):
                fence = None
        else:
            out.append(re.sub(r"(`+)(?!`).*?(?<!`)\1(?!`)", "", line))
    assert fence is None, "a fence left open"
    return "\n".join(out)


def test_29_10_report_md_shows_raw_html_from_outside_as_text():
    hostile = "<script>alert(1)</script> ``` <iframe src=x> `` [a](javascript:x)"
    report = Report(f"title {hostile}", command=["report", "--title", hostile])
    report.add_text(f"note {hostile}", heading=f"heading {hostile}")
    report.add_preformatted(f"printed\n```\n{hostile}\n````", heading="printed")
    report.add_table(f"table {hostile}", ["a", hostile], [[hostile, 1]], note=hostile)
    report.add_links("links", [(hostile, "a b).html")])
    markdown = report.markdown()
    assert "<" not in _outside_code(markdown)  # every raw tag is text (&lt;) or inside code
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in markdown
    assert "(a%20b%29.html)" in markdown  # a link target that cannot end early
    assert hostile in report.markdown()  # shown whole inside the printed block and the command
