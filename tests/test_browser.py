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
import subprocess
from html.parser import HTMLParser

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")

from matplotlib import colormaps
from matplotlib.image import imread

from tcr_accuracy.model.errors import seed_budget
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
    full = scene.write_static_html(folder / "view.html")
    empty = Scene("empty").write_static_html(folder / "empty.html")
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
    index = report.write(tmp_path / "report")
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
    index = report.write(tmp_path / "report")
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
    paragraph_index = as_paragraph.write(tmp_path / "paragraph")
    taller = last_text_row(index, "pre") - last_text_row(paragraph_index, "paragraph")
    assert taller > 30, f"the printed summary is only {taller} px taller than as a paragraph"
