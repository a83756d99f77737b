"""The 3D views of diagnose, predict, compensate and montecarlo, read back from headless Chromium.

Per view, from the page Chromium built (as tests/test_browser.py reads a scene): the drawn robot's
bounding box, projected by the page's own camera, lies inside the canvas and the canvas beside the
legend, not under it, at two window shapes; the legend's swatches have one colour per entry; the
ring that marks the pose the robot is drawn at sits on the measured point of that pose, within a
few millimetres of the model TCP computed here by Pinocchio from the CSV row the legend names (or
the as-built URDF the diagnosis exported). The Monte Carlo colour bar spans the |dP| of the
samples its table counts (the JSON's statistics), and a diagnosis of more than 250 poses draws
the lines of an even spread of 250, the largest gap among them.

Needs Chromium (as tests/test_browser.py): without it these tests FAIL, they do not skip.
"""

import json
import re
from pathlib import Path

import numpy as np
import pytest

from conftest import REPO, pinocchio_kinematics, run_command
from test_browser import _dom, chromium, scene_points  # noqa: F401 (fixture)

#: Window shapes the views are checked at [px]: a laptop's and a narrow one (the canvas taller
#: than wide beside the legend).
WINDOWS = ((1200, 760), (800, 640))

#: Appended to a view's page: the canvas' and the legend's boxes, the legend's swatch colours and,
#: projected by the page's camera, the screen box of the bounding boxes of every mesh under the
#: nodes whose names start with ROBOT (the robot drawn), into a <pre>.
_LAYOUT = """<script>
(function () {
  viewer.scene.updateMatrixWorld(true);
  var camera = viewer.camera;
  camera.updateMatrixWorld(true);
  camera.updateProjectionMatrix();
  var canvas = viewer.renderer.domElement.getBoundingClientRect();
  var legend = document.getElementById("tcr-legend").getBoundingClientRect();
  var root = viewer.scene_tree.find(["meshcat"]).object, box = null, meshes = 0;
  root.children.forEach(function (node) {
    if (node.name.indexOf(ROBOT) !== 0) { return; }
    node.traverse(function (obj) {
      if (!obj.isMesh) { return; }
      meshes += 1;
      obj.geometry.computeBoundingBox();
      var b = obj.geometry.boundingBox, V = obj.position.constructor;
      [b.min.x, b.max.x].forEach(function (x) { [b.min.y, b.max.y].forEach(function (y) {
        [b.min.z, b.max.z].forEach(function (z) {
          var v = new V(x, y, z).applyMatrix4(obj.matrixWorld).project(camera);
          var px = canvas.left + (v.x + 1) / 2 * canvas.width, py = canvas.top + (1 - v.y) / 2 * canvas.height;
          box = box ? [Math.min(box[0], px), Math.min(box[1], py), Math.max(box[2], px), Math.max(box[3], py)]
                    : [px, py, px, py];
        }); }); });
    });
  });
  var swatches = [];
  document.querySelectorAll("#tcr-legend .tcr-entry").forEach(function (entry) {
    var swatch = entry.querySelector(".tcr-swatch");
    if (swatch.classList.contains("tcr-none")) { return; }
    swatches.push([entry.textContent, getComputedStyle(swatch).backgroundColor]);
  });
  var pre = document.createElement("pre");
  pre.id = "tcr-layout";
  pre.textContent = JSON.stringify({canvas: [canvas.left, canvas.top, canvas.right, canvas.bottom],
    legend: [legend.left, legend.top, legend.right, legend.bottom], robot: box, meshes: meshes,
    swatches: swatches});
  document.body.appendChild(pre);
})();
</script>
"""


def _layout(chromium, tmp_path, page: Path, robot_prefix: str, size) -> dict:
    """The page's layout (see _LAYOUT) as Chromium lays it out in a window of ``size``."""
    import subprocess

    from test_browser import CHROMIUM_FLAGS

    probe = page.with_name(page.stem + f"-layout-{size[0]}.html")
    script = _LAYOUT.replace("ROBOT", json.dumps(robot_prefix))
    probe.write_text(page.read_text(encoding="utf-8").replace("</body>", script + "</body>"), encoding="utf-8")
    profile = tmp_path / f"profile-layout-{size[0]}-{len(list(tmp_path.glob('profile-*')))}"
    done = subprocess.run([chromium, *CHROMIUM_FLAGS, f"--user-data-dir={profile}",
                           f"--window-size={size[0]},{size[1]}", "--dump-dom", probe.as_uri()],
                          capture_output=True, text=True, timeout=180)
    assert done.returncode == 0, done.stderr[-2000:]
    found = re.search(r'<pre id="tcr-layout">(.*?)</pre>', done.stdout, flags=re.S)
    assert found, "the layout probe did not run (the page's loader failed?)"
    return json.loads(found.group(1).replace("&quot;", '"').replace("&amp;", "&"))


def _check_layout(chromium, tmp_path, page: Path, robot_prefix: str) -> list:
    """The robot inside the canvas and clear of the legend at both window shapes; one colour per
    legend entry. Returns the legend's entries with a swatch."""
    for size in WINDOWS:
        laid = _layout(chromium, tmp_path, page, robot_prefix, size)
        left, top, right, bottom = laid["canvas"]
        assert laid["meshes"] > 0 and laid["robot"] is not None, f"no robot named {robot_prefix!r} drawn"
        x0, y0, x1, y1 = laid["robot"]
        print(f"{page.name} {size}: canvas {laid['canvas']}, robot box {[round(v) for v in laid['robot']]}")
        assert left - 1 <= x0 < x1 <= right + 1 and top - 1 <= y0 < y1 <= bottom + 1, (size, laid)
        assert laid["legend"][2] <= left + 1, "the canvas starts under the legend"
        assert x1 - x0 > 0.05 * (right - left), "the robot is a speck"
    colours = [tuple(int(v) for v in re.findall(r"\d+", c)[:3]) for _, c in laid["swatches"]]
    for i, a in enumerate(colours):
        for b in colours[i + 1:]:
            assert max(abs(u - v) for u, v in zip(a, b)) >= 40, f"two legend entries alike: {laid['swatches']}"
    return [text for text, _ in laid["swatches"]]


def _marker(chromium, tmp_path, page: Path) -> np.ndarray:
    """The centre of the ring that marks the drawn pose (base frame) [m]."""
    from test_browser import _SCENE_DUMP

    probe_dump = _SCENE_DUMP.replace('path !== "ground_grid" && path.slice(-9) !== "/segments"',
                                     'path !== "ground_grid" && path.slice(-9) !== "/segments" && '
                                     'path.slice(-5) !== "/ring"')
    probe = page.with_name(page.stem + "-ring.html")
    probe.write_text(page.read_text(encoding="utf-8").replace("</body>", probe_dump + "</body>"), encoding="utf-8")
    dom = _dom(chromium, tmp_path, probe)
    text = re.search(r'<pre id="tcr-scene-dump">(.*?)</pre>', dom, flags=re.S).group(1)
    ring = np.asarray(json.loads(text.replace("&quot;", '"').replace("&amp;", "&"))["marked pose/ring"], float)
    return ring.reshape(-1, 3).mean(axis=0)


def _row(dom: str, pattern: str) -> int:
    """The CSV row (1-based, header = 1) the legend names."""
    return int(re.search(pattern, dom).group(1))


def _csv_q(csv: Path, robot, row: int, row_column: str | None = None) -> np.ndarray:
    """Joint values [rad, m] of line ``row`` of a CSV file (counted in the file, the header's line
    included), or of the row whose ``row_column`` holds ``row``, from its ``<joint>_deg``/``_mm``
    columns."""
    lines = csv.read_text().splitlines()
    header_line = next(i for i, line in enumerate(lines) if line.strip() and not line.startswith("#"))
    header = lines[header_line].split(",")
    if row_column is None:
        values = dict(zip(header, lines[row - 1].split(",")))
    else:
        rows = [dict(zip(header, line.split(","))) for line in lines[header_line + 1:] if line.strip()]
        values = next(r for r in rows if int(float(r[row_column])) == row)
    q = []
    for joint, kind in zip(robot.joint_names, robot.joint_kinds):
        if f"{joint}_deg" in values:
            q.append(np.radians(float(values[f"{joint}_deg"])))
        else:
            q.append(float(values[f"{joint}_mm"]) * 1e-3)
    return np.array(q)


# ---------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    """A UR10 whose tracker is turned half round, 400 poses (more than the 250 lines a view draws),
    and 40 other poses as queries and targets."""
    from tcr_accuracy.cli import main

    folder = tmp_path_factory.mktemp("views")
    scenario = folder / "ur10.yaml"
    scenario.write_text("robot: ur10\neffects:\n  frames:\n    base_mm: {dx: 1800.0, dy: 600.0, dz: -200.0}\n"
                        "    base_deg: {rz: 180.0}\n    tool_mm: {dz: 2.0}\n"
                        "  geometry: {spread_mm: 0.3, spread_mrad: 0.3}\nnoise_mm: 0.02\n")
    for name, n, seed in (("train.csv", 400, 2), ("query.csv", 40, 5)):
        assert main(["simulate", "--robot", "ur10", "--scenario", str(scenario), "--n", str(n), "--seed", str(seed),
                     "--out", str(folder / name), "--quiet"]) == 0
    return folder


def test_diagnosis_view_frames_robot_and_points_marks_its_pose_and_thins_the_lines(chromium, tmp_path, simulated,
                                                                                  capsys):
    from tcr_accuracy.cli import main
    from tcr_accuracy.model.robot import load_robot

    view, urdf = tmp_path / "d.html", tmp_path / "as_built.urdf"
    assert main(["diagnose", str(simulated / "train.csv"), "--robot", "ur10", "--effects", "geometry", "--quiet",
                 "--view", str(view), "--json", str(tmp_path / "d.json"), "--as-built-urdf", str(urdf)]) == 0
    capsys.readouterr()
    entries = _check_layout(chromium, tmp_path, view, "nominal robot")
    assert any(e.startswith("the measured point of row") for e in entries)
    dom = _dom(chromium, tmp_path, view)
    row = _row(dom, r"the measured point of row (\d+), the pose")
    import yaml

    side = yaml.safe_load(urdf.with_name("as_built.effects.yaml").read_text())
    as_built = load_robot(str(urdf), side["urdf_measured_frame"])
    q = _csv_q(simulated / "train.csv", as_built, row)
    _, model_tcp = pinocchio_kinematics(as_built, q)
    ring = _marker(chromium, tmp_path, view)
    miss = np.linalg.norm(ring - model_tcp.translation)
    print(f"marked point vs as-built model TCP at row {row}: {miss * 1e3:.3f} mm")
    assert miss < 3e-3
    scene = scene_points(chromium, tmp_path, view)
    assert len(scene["measured"]) == 400  # every measured point drawn ...
    starts = scene["gap/segments"][0::2]  # ... and the lines of an even spread of 250
    assert len(starts) == 250
    assert np.linalg.norm(starts[:, None] - scene["measured"][None], axis=2).min(axis=1).max() < 1e-6
    # the spread: every measured point has a line within a few of the grid's spacings
    spacing = np.ptp(scene["measured"], axis=0).max() / 400 ** (1 / 3)
    assert np.linalg.norm(scene["measured"][:, None] - starts[None], axis=2).min(axis=1).max() < 2.5 * spacing
    data = json.loads((tmp_path / "d.json").read_text())
    factor = float(re.search(r"segments magnified x ([0-9.e+]+);", dom).group(1))
    drawn = np.linalg.norm(scene["gap/end"] - starts, axis=1) / factor
    assert drawn.max() * 1e3 == pytest.approx(data["gap"]["max_mm"], rel=2e-3)  # the largest among them


def test_predict_view_frames_the_robot_marks_its_query_and_shows_distinct_colours(chromium, tmp_path, simulated,
                                                                                  capsys):
    from tcr_accuracy.cli import main
    from tcr_accuracy.model.robot import load_robot

    view = tmp_path / "p.html"
    assert main(["predict", "--robot", "ur10", "--train", str(simulated / "train.csv"), "--query",
                 str(simulated / "query.csv"), "--method", "calibration", "--view", str(view), "--quiet"]) == 0
    capsys.readouterr()
    entries = _check_layout(chromium, tmp_path, view, "nominal robot")
    assert "measured (tracker frame fitted, base frame)" in entries
    assert not any(e.startswith("model TCP at the query joints") for e in entries[1:])  # the cloud marks them
    dom = _dom(chromium, tmp_path, view)
    row = _row(dom, r"the query point of row (\d+), the pose")
    robot = load_robot("ur10")
    _, nominal = pinocchio_kinematics(robot, _csv_q(simulated / "query.csv", robot, row))
    miss = np.linalg.norm(_marker(chromium, tmp_path, view) - nominal.translation)
    print(f"marked query point vs nominal TCP at row {row}: {miss * 1e3:.3f} mm (the fitted 2 mm TCP offset)")
    assert miss < 4e-3


def test_compensate_view_frames_the_robot_and_marks_the_target_it_is_drawn_for(chromium, tmp_path, simulated,
                                                                               capsys):
    from tcr_accuracy.cli import main
    from tcr_accuracy.model.robot import load_robot

    view, commands = tmp_path / "c.html", tmp_path / "compensated.csv"
    assert main(["compensate", "--robot", "ur10", "--train", str(simulated / "train.csv"), "--targets",
                 str(simulated / "query.csv"), "--method", "calibration", "--view", str(view), "--csv",
                 str(commands), "--quiet"]) == 0
    capsys.readouterr()
    _check_layout(chromium, tmp_path, view, "robot at the compensated command")
    dom = _dom(chromium, tmp_path, view)
    row = _row(dom, r"the target of row (\d+), the pose")
    robot = load_robot("ur10")
    _, drawn_tcp = pinocchio_kinematics(robot, _csv_q(commands, robot, row, "target_row"))  # the command drawn
    miss = np.linalg.norm(_marker(chromium, tmp_path, view) - drawn_tcp.translation)
    print(f"marked target vs the drawn robot's nominal TCP at row {row}: {miss * 1e3:.3f} mm")
    assert miss < 4e-3


def test_montecarlo_view_colours_by_the_samples_its_table_counts(chromium, tmp_path, capsys):
    from tcr_accuracy.cli import main
    from tcr_accuracy.model.robot import load_robot

    view, out = tmp_path / "mc.html", tmp_path / "mc.json"
    assert main(["montecarlo", "--robot", "ur5", "--samples", "6000", "--chunk", "2500", "--view-samples", "1500",
                 "--tail-samples", "0", "--seed", "4", "--view", str(view), "--json", str(out), "--quiet"]) == 0
    capsys.readouterr()
    _check_layout(chromium, tmp_path, view, "nominal")
    data = json.loads(out.read_text())
    dom = _dom(chromium, tmp_path, view)
    ticks = re.search(r'<div class="tcr-bar-ticks"><span>([^<]+)</span><span>[^<]+</span><span>([^<]+)</span>', dom)
    low, high = float(ticks.group(1)), float(ticks.group(2))
    assert high == pytest.approx(data["stats_mm"]["norm"]["max"], rel=1e-3)  # the table's largest |dP|
    assert low == pytest.approx(data["stats_mm"]["norm"]["min"], rel=1e-3)
    robot = load_robot("ur5")
    _, nominal = pinocchio_kinematics(robot, np.array(data["q_si"]))
    assert np.linalg.norm(_marker(chromium, tmp_path, view) - nominal.translation) < 1e-4
    assert "the first 1500 of the 6000 samples of the table" in dom
