"""The static 3D view and the report, opened in a real browser (headless Chromium).

Chromium draws the page and writes a screenshot; the test then looks at the pixels:
the robot's URDF paint (orange and yellow boxes, lit by meshcat's lights) and the
error cloud's viridis colours (points are unlit, so their colours are exact) must be
on screen, and the same classifiers must find nothing in an empty scene, so a blank or
broken canvas fails. The report's tables are read back from the DOM Chromium built.

Needs Chromium: on Debian/Ubuntu ``apt-get install -y chromium chromium-driver``
(``.ci/run`` installs it). Without it these tests FAIL, they do not skip. WebGL runs on
the CPU through SwiftShader (``--use-angle=swiftshader --enable-unsafe-swiftshader``).
"""

import os
import shutil
from pathlib import Path
import subprocess
from html.parser import HTMLParser

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")

from matplotlib import colormaps
from matplotlib.image import imread

from tcr_accuracy.model.errors import seed_budget
from tcr_accuracy.cli.staging import write_text
from tcr_accuracy.cli.writers import write_report
from tcr_accuracy.view.report import Report
from tcr_accuracy.view.viewer import Scene

INSTALL_HINT = ("headless Chromium is needed for the browser tests and was not found: "
                "install it with 'apt-get install -y chromium chromium-driver' (Debian/Ubuntu), "
                "or set TCR_CHROMIUM to a Chromium/Chrome executable")

# Flags for a sandboxed CI machine with no GPU and no outside network.
CHROMIUM_FLAGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
    "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--hide-scrollbars",
    "--virtual-time-budget=8000",
]
WIDTH, HEIGHT = 1000, 700


@pytest.fixture(scope="module")
def chromium():
    path = os.environ.get("TCR_CHROMIUM") or shutil.which("chromium") or shutil.which("chromium-browser")
    if path is None or not os.access(path, os.X_OK):
        pytest.fail(INSTALL_HINT, pytrace=False)
    return path


def _run(chromium, tmp_path, *args, size=(WIDTH, HEIGHT)):
    profile = tmp_path / f"profile-{len(list(tmp_path.glob('profile-*')))}"
    command = [chromium, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", f"--window-size={size[0]},{size[1]}",
               *args]
    done = subprocess.run(command, capture_output=True, text=True, timeout=180)
    assert done.returncode == 0, f"chromium failed ({done.returncode}): {done.stderr[-2000:]}"
    return done.stdout


def _screenshot(chromium, tmp_path, page, name, size=(WIDTH, HEIGHT)):
    png = tmp_path / f"{name}.png"
    _run(chromium, tmp_path, f"--screenshot={png}", page.as_uri(), size=size)
    assert png.is_file(), f"chromium wrote no screenshot of {page}"
    image = imread(png)[:, :, :3].astype(float)  # (H, W, 3) in 0..1
    assert image.shape[:2] == (size[1], size[0])
    return image


def _dom(chromium, tmp_path, page):
    return _run(chromium, tmp_path, "--dump-dom", page.as_uri())


def _paint_fraction(image):
    """Share of pixels in the orange/yellow paint of the tool-changer's arm and turret."""
    r, g, b = image[..., 0], image[..., 1], image[..., 2]
    return float(np.mean((r > 0.45) & (r > g + 0.08) & (g > b + 0.25)))


def _viridis_pixels(image, tolerance=0.03):
    """Number of pixels within `tolerance` (each channel) of a viridis colour."""
    palette = colormaps["viridis"](np.linspace(0.0, 1.0, 256))[:, :3]
    keys, counts = np.unique(_colour_keys(image), return_counts=True)
    colours = np.stack([keys >> 16, (keys >> 8) & 255, keys & 255], axis=1) / 255.0
    distance = np.abs(colours[:, None, :] - palette[None, :, :]).max(axis=2).min(axis=1)
    return int(counts[distance < tolerance].sum())


def _colour_keys(image):
    """(H*W,) one integer per pixel: its 8-bit RGB packed as 0xRRGGBB."""
    rgb = (image * 255).round().astype(np.int64).reshape(-1, 3)
    return (rgb[:, 0] << 16) | (rgb[:, 1] << 8) | rgb[:, 2]


def _legend_free(image):
    """The canvas right of the legend overlay (which sits top-left, at most 370 px wide)."""
    return image[:, 380:, :]


@pytest.fixture(scope="module")
def views(tmp_path_factory, tool_changer):
    folder = tmp_path_factory.mktemp("views")
    robot, q = tool_changer, tool_changer.working_pose
    budget = seed_budget(robot, "table2")
    scene = Scene("tool-changer with a TCP error cloud")
    scene.add_robot(robot, q, "nominal")
    scene.add_tcp_error_cloud(robot, q, budget.sample(1500, np.random.default_rng(0)), budget.error_model)
    full = write_text(folder / "view.html", scene.static_html())
    empty = write_text(folder / "empty.html", Scene("empty").static_html())
    return full, empty


def test_static_view_renders_the_robot_and_the_error_cloud(chromium, tmp_path, views):
    full, empty = views
    image = _legend_free(_screenshot(chromium, tmp_path, full, "view"))
    blank = _legend_free(_screenshot(chromium, tmp_path, empty, "empty"))
    # the classifiers find nothing in an empty scene (background and grid only) ...
    assert _paint_fraction(blank) < 1e-4
    assert _viridis_pixels(blank) < 20
    # ... and the robot's paint and the cloud's colours in the real one
    print(f"paint {_paint_fraction(image):.4f}, viridis {_viridis_pixels(image)}, "
          f"blank: paint {_paint_fraction(blank):.5f}, viridis {_viridis_pixels(blank)}")
    assert _paint_fraction(image) > 0.01, "the robot's bodies are not on the canvas"
    assert _viridis_pixels(image) > 150, "the TCP error cloud is not on the canvas"
    colours = len(np.unique(_colour_keys(image)))
    assert colours > 500, f"only {colours} distinct colours: a flat canvas"


def test_static_view_page_ran_to_the_end(chromium, tmp_path, views):
    dom = _dom(chromium, tmp_path, views[0])
    assert 'data-tcr-scene="loaded"' in dom  # the loader script ran without an exception
    assert "<canvas" in dom
    assert "TCP error |dP| [mm]" in dom and "magnified x" in dom


class _Tables(HTMLParser):
    """Rows of every <table> in a page, as lists of cell texts."""

    def __init__(self):
        super().__init__()
        self.tables, self._cell = [], None

    def handle_starttag(self, tag, attrs):
        if tag == "table":
            self.tables.append([])
        elif tag == "tr":
            self.tables[-1].append([])
        elif tag in ("td", "th"):
            self._cell = ""

    def handle_endtag(self, tag):
        if tag in ("td", "th") and self._cell is not None:
            self.tables[-1][-1].append(self._cell.strip())
            self._cell = None

    def handle_data(self, data):
        if self._cell is not None:
            self._cell += data


def test_report_shows_its_tables_and_its_3d_view(chromium, tmp_path, views, tool_changer):
    report = Report("Browser check", command=["view", "--error-preset", "table2"])
    report.add_table("TCP position error", ["axis", "std"], [["x", 0.1426], ["y", 0.0789]], units=["", "mm"])
    report.add_scene(views[0].read_text(encoding="utf-8"), "TCP error cloud", height_px=500)
    index = write_report(report, tmp_path / "report")
    tables = _Tables()
    tables.feed(_dom(chromium, tmp_path, index))
    assert tables.tables[0] == [["axis", "std [mm]"], ["x", "0.1426"], ["y", "0.0789"]]
    assert tables.tables[1][0] == ["software", "version"]
    assert ["pin", __import__("importlib.metadata").metadata.version("pin")] in tables.tables[1]
    image = _screenshot(chromium, tmp_path, index, "report", size=(1000, 1100))
    assert _paint_fraction(image) > 0.002, "the 3D view inside the report did not render"


def test_montecarlo_report_shows_its_statistics_and_its_cloud(chromium, tmp_path, capsys):
    import json

    from tcr_accuracy.cli import main

    out = tmp_path / "mc"
    assert main(["montecarlo", "--samples", "4000", "--tail-samples", "0", "--seed", "1", "--quiet",
                 "--out", str(out), "--json", str(tmp_path / "mc.json")]) == 0
    capsys.readouterr()
    data = json.loads((tmp_path / "mc.json").read_text())
    tables = _Tables()
    tables.feed(_dom(chromium, tmp_path, out / "index.html"))
    stats = next(t for t in tables.tables if t and t[0][:3] == ["error", "mean", "std"])
    rows = {r[0]: r for r in stats[1:]}
    assert set(rows) >= {"dp [mm]", "dx [mm]", "dy [mm]", "dz [mm]", "|dP| [mm]", "d_alpha (z) [rad]"}
    for key, label in (("dx", "dx [mm]"), ("norm", "|dP| [mm]")):  # the JSON's numbers, 4 digits
        assert float(rows[label][2]) == pytest.approx(data["stats_mm"][key]["std"], rel=1e-3)
    # the report's 3D view (its own page, shown in an iframe) draws the robot and the cloud
    image = _legend_free(_screenshot(chromium, tmp_path, out / "scene-1.html", "mc-scene"))
    assert _paint_fraction(image) > 0.01, "the robot is not on the report's 3D view"
    assert _viridis_pixels(image) > 150, "the TCP error cloud is not on the report's 3D view"


def test_printed_summary_renders_as_aligned_lines_in_chromium(chromium, tmp_path):
    """The diagnosis report's "Full printed summary": Chromium keeps its lines and columns."""
    import re

    summary = ("4. How far it shrinks (k-fold held-out) [mm]\n"
               "   step               params  train RMS\n"
               "   frames                  9     1.4700\n"
               "   +compliance            13     0.3195")
    report = Report("Browser check", command=["diagnose", "m.csv"])
    report.add_preformatted(summary, heading="Full printed summary")
    index = write_report(report, tmp_path / "report")
    dom = _dom(chromium, tmp_path, index)
    blocks = re.findall(r'<pre class="printed">(.*?)</pre>', dom, flags=re.S)
    assert blocks == [summary]
    # drawn line by line: the same text as a paragraph runs together into one or two lines, so
    # the page with the <pre> is taller by several lines (same content below it)
    def last_text_row(page, name):
        image = _screenshot(chromium, tmp_path, page, name, size=(1000, 1400))
        return int(np.flatnonzero((image.mean(axis=2) < 0.5).any(axis=1)).max())

    as_paragraph = Report("Browser check", command=["diagnose", "m.csv"])
    as_paragraph.add_text(summary, heading="Full printed summary")
    paragraph_index = write_report(as_paragraph, tmp_path / "paragraph")
    taller = last_text_row(index, "pre") - last_text_row(paragraph_index, "paragraph")
    assert taller > 30, f"the printed summary is only {taller} px taller than as a paragraph"


# ---------------------------------------------------------------------------------------
# Where the views put things: the scene read back from the page Chromium built
# ---------------------------------------------------------------------------------------
#: Appended to a view's page: writes, once the scene is loaded, every point cloud's points
#: (three.js objects of type Points, by meshcat node path) in the frame of the "/meshcat"
#: node's parent, i.e. the robot's base frame before the view's shift, into a <pre>.
_SCENE_DUMP = """<script>
(function () {
  var root = viewer.scene_tree.find(["meshcat"]).object;
  viewer.scene.updateMatrixWorld(true);
  var toBase = root.matrixWorld.clone();
  if (toBase.invert) { toBase.invert(); } else { toBase.getInverse(root.matrixWorld); }
  var Vector3 = root.position.constructor;
  var out = {};
  root.traverse(function (obj) {
    if (!obj.isPoints && !obj.isLineSegments) { return; }
    var path = [], node = obj;
    while (node && node !== root) { if (node.name !== "<object>" && node.name) { path.unshift(node.name); } node = node.parent; }
    path = path.join("/");
    if (!obj.isPoints && path !== "ground_grid" && path.slice(-9) !== "/segments") { return; }
    var m = toBase.clone().multiply(obj.matrixWorld), a = obj.geometry.attributes.position, pts = [];
    for (var i = 0; i < a.count; i++) {
      var v = new Vector3(a.getX(i), a.getY(i), a.getZ(i)).applyMatrix4(m);
      pts.push([v.x, v.y, v.z]);
    }
    out[path] = pts;
  });
  for (var k = 0; k < root.children.length; k++) {
    var child = root.children[k];
    if (child.name.indexOf("frame") >= 0) {
      out["matrix:" + child.name] = toBase.clone().multiply(child.matrixWorld).elements;
    }
  }
  var pre = document.createElement("pre");
  pre.id = "tcr-scene-dump";
  pre.textContent = JSON.stringify(out);
  document.body.appendChild(pre);
})();
</script>
"""


def scene_points(chromium, tmp_path, page):
    """{node path: (N, 3) points [m] in the base frame} of a view page, as Chromium built its scene."""
    import json
    import re

    probe = page.with_name(page.stem + "-probe.html")
    probe.write_text(page.read_text(encoding="utf-8").replace("</body>", _SCENE_DUMP + "</body>"), encoding="utf-8")
    dom = _dom(chromium, tmp_path, probe)
    found = re.search(r'<pre id="tcr-scene-dump">(.*?)</pre>', dom, flags=re.S)
    assert found, "the page did not dump its scene (the loader failed?)"
    text = found.group(1).replace("&quot;", '"').replace("&amp;", "&")
    out = {}
    for key, value in json.loads(text).items():
        if key.startswith("matrix:"):  # three.js stores a 4 x 4 matrix column by column
            out[key] = np.asarray(value, dtype=float).reshape(4, 4).T
        else:
            out[key.strip("/")] = np.asarray(value, dtype=float).reshape(-1, 3)
    return out


def _diagnosed_view(tmp_path, csv, robot_args):
    """``diagnose`` with --view, --json and --as-built-urdf: (view page, JSON, as-built robot)."""
    import json

    import yaml

    from tcr_accuracy.cli import main
    from tcr_accuracy.model.robot import load_robot

    view, out_json, urdf = tmp_path / "view.html", tmp_path / "d.json", tmp_path / "as_built.urdf"
    assert main(["diagnose", str(csv), *robot_args, "--quiet", "--view", str(view), "--json", str(out_json),
                 "--as-built-urdf", str(urdf)]) == 0
    side = yaml.safe_load(urdf.with_name("as_built.effects.yaml").read_text())
    return view, json.loads(out_json.read_text()), load_robot(str(urdf), side["urdf_measured_frame"])


def _check_view_frame(chromium, tmp_path, view, data, as_built, q, raw_tracker, tolerance_m):
    """The measured points the page draws sit at the as-built model's TCP at the measured joints
    (the model read back from its exported URDF, not from the diagnosis), the tracker triad where
    the JSON's tracker transform puts it, the gap segments magnified as the legend says, and
    the ground grid about the robot and the data."""
    import re

    from tcr_accuracy.model.kinematics import tcp_poses

    scene = scene_points(chromium, tmp_path, view)
    model_tcp = tcp_poses(as_built, q).position
    measured = scene["measured"]
    assert measured.shape == model_tcp.shape
    near = np.linalg.norm(measured - model_tcp, axis=1)
    raw = np.linalg.norm(raw_tracker - model_tcp, axis=1)
    print(f"measured vs model TCP: max {near.max() * 1e3:.3f} mm; raw tracker coordinates: min {raw.min():.3f} m")
    assert near.max() < tolerance_m
    assert raw.min() > 0.05  # the tracker's own coordinates would be far off: the check can fail
    np.testing.assert_allclose(scene["matrix:tracker frame"], np.linalg.inv(np.array(data["trackerMbase"])),
                               atol=1e-5)
    dom = _dom(chromium, tmp_path, view)
    factor = float(re.search(r"TCP offset only \(segments magnified x ([0-9.e+]+)[;)]", dom).group(1))
    starts = scene["gap/segments"][0::2]  # the measured cloud marks the starts: no points of their own
    drawn = np.linalg.norm(scene["gap/end"] - starts, axis=1) / factor
    # every line starts at a measured point; with more than 250 of them, an even spread of 250 has lines
    nearest = np.linalg.norm(starts[:, None, :] - measured[None, :, :], axis=2).min(axis=1)
    assert nearest.max() < 1e-6 and len(starts) == min(len(measured), 250)
    assert "gap/start" not in scene
    assert drawn.max() * 1e3 == pytest.approx(data["gap"]["max_mm"], rel=2e-3)  # the largest among them
    grid = scene["ground_grid"]
    shown = np.concatenate([measured, model_tcp, scene["matrix:tracker frame"][None, :3, 3]])
    low, high = shown.min(axis=0) - 1.0, shown.max(axis=0) + 1.0
    assert np.all(grid[:, :2] >= low[:2]) and np.all(grid[:, :2] <= high[:2]), \
        "the ground grid reaches far beyond the robot, the data and the tracker"


def test_diagnosis_view_puts_the_demo_measurements_on_the_model(chromium, tmp_path):
    from tcr_accuracy.io.measurements import read_measurements
    from tcr_accuracy.model.robot import load_robot

    csv = Path(__file__).resolve().parents[1] / "src/tcr_accuracy/data/tool_changer_cutter.csv"
    view, data, as_built = _diagnosed_view(tmp_path, csv, [])
    m = read_measurements(csv, load_robot())
    # the as-built URDF carries the geometry; compliance under the cutter (not in a URDF) is the
    # millimetre left
    _check_view_frame(chromium, tmp_path, view, data, as_built, m.q, m.position, 6e-3)


def test_diagnosis_view_of_a_ur10_whose_tracker_is_turned_half_round(chromium, tmp_path):
    from tcr_accuracy.cli import main
    from tcr_accuracy.io.measurements import read_measurements
    from tcr_accuracy.model.robot import load_robot

    scenario = tmp_path / "ur10.yaml"
    scenario.write_text("robot: ur10\neffects:\n  frames:\n    base_mm: {dx: 1800.0, dy: 600.0, dz: -200.0}\n"
                        "    base_deg: {rz: 180.0}\n    tool_mm: {dz: 150.0}\n"
                        "  geometry: {spread_mm: 0.1, spread_mrad: 0.1}\nnoise_mm: 0.02\n")
    csv = tmp_path / "ur10.csv"
    assert main(["simulate", "--robot", "ur10", "--scenario", str(scenario), "--n", "120", "--seed", "2",
                 "--out", str(csv), "--quiet"]) == 0
    view, data, as_built = _diagnosed_view(tmp_path, csv, ["--robot", "ur10", "--effects", "geometry"])
    m = read_measurements(csv, load_robot("ur10"))
    assert abs(abs(np.array(data["trackerMbase"])[0, 0]) - 1.0) < 1e-3  # the turn half round is found
    _check_view_frame(chromium, tmp_path, view, data, as_built, m.q, m.position, 0.5e-3)


def test_diagnosis_view_of_a_two_armed_robot_measured_at_both_hands(chromium, tmp_path):
    import pinocchio as pin

    from test_measured_frames import JOINTS, TWO_ARMS
    from tcr_accuracy.effects import make_effect, predict_positions
    from tcr_accuracy.model.robot import robot_from_urdf_text

    urdf = tmp_path / "two_arms.urdf"
    urdf.write_text(TWO_ARMS)
    rng = np.random.default_rng(3)
    q_all = rng.uniform(-1.0, 1.0, (90, len(JOINTS)))
    tracker = pin.SE3(pin.rpy.rpyToMatrix(0.1, -0.05, 2.5), np.array([2.0, -1.2, 0.4]))  # base -> tracker
    columns, blocks, first = [f"{j}_deg" for j in JOINTS], [np.degrees(q_all)], None
    for frame, offset in (("right_marker", [0.004, -0.002, 0.003]), ("left_marker", [-0.002, 0.003, 0.001])):
        robot = robot_from_urdf_text(TWO_ARMS, frame, name="two_arms")
        q = q_all[:, [JOINTS.index(j) for j in robot.joint_names]]
        frames = make_effect("frames", robot)
        params = np.array([dict(zip(("frames.tool.dx", "frames.tool.dy", "frames.tool.dz"), offset)).get(p, 0.0)
                           for p in frames.parameter_names()])
        base = predict_positions(robot, [frames], [params], q, None) + 1e-5 * rng.standard_normal((len(q), 3))
        blocks.append((base @ tracker.rotation.T + tracker.translation) * 1e3)
        columns += [f"{frame}.{a}_mm" for a in "xyz"]
        first = first or (q, blocks[-1] * 1e-3)
    csv = tmp_path / "hands.csv"
    table = np.concatenate(blocks, axis=1)
    csv.write_text(",".join(columns) + "\n" + "\n".join(",".join(f"{v:.12g}" for v in row) for row in table) + "\n")
    view, data, as_built = _diagnosed_view(tmp_path, csv, ["--robot", str(urdf), "--effects", "joint_offsets",
                                                            "--noise-mm", "0.01"])
    _check_view_frame(chromium, tmp_path, view, data, as_built, first[0], first[1], 0.2e-3)
