"""The page around a meshcat scene: recorded in memory, written as static HTML or served live.

meshcat's Python client sends drawing commands to a window object; its own window
talks ZeroMQ to a server subprocess, which keeps the scene tree and is the only thing
that can export a static page. Here the commands go to a :class:`RecordingWindow` that
keeps the same scene tree (meshcat's own ``SceneTree``) in memory, so a static page
(:func:`static_page`) needs no server, no port and no subprocess; :func:`serve_page`
starts meshcat's server bridge bound to 127.0.0.1 only (:mod:`tcr_accuracy.view._meshcat_server`;
meshcat's own ``meshcat-server`` listens on all interfaces) and replays the tree into it.

meshcat draws no text, so legends (colour bars, magnification factors) are HTML
(:func:`legend_html`) in a column beside the canvas (:data:`LEGEND_WIDTH_PX`), never over the
scene, in the page this module writes around meshcat's viewer. The page moves the camera along
its line of sight so that the sphere the scene frames fits the canvas it gets, whatever the
window's shape (``fit``).
It also holds the two colour forms the view speaks (:func:`meshcat_color` for meshcat
materials, :func:`css_color` for the legend) and the import of meshcat with its install
hint. What the scene holds is :class:`tcr_accuracy.view.viewer.Scene`'s business.
"""

from __future__ import annotations

import atexit
import base64
import html
import json
import os
import subprocess
import sys
import time
from pathlib import Path

from ..exceptions import InputError

INSTALL_HINT = "the 3D viewer needs meshcat: pip install meshcat (or pip install tcr-accuracy)"


def import_meshcat():
    """meshcat and its geometry module, or an InputError with the install hint."""
    try:
        import meshcat
        import meshcat.geometry as mg
    except ImportError as exc:  # pragma: no cover - meshcat is a declared dependency
        raise InputError(f"{INSTALL_HINT} ({exc})") from None
    return meshcat, mg


def _rgb255(rgb) -> tuple[int, int, int]:
    r, g, b = (int(round(255 * min(max(float(c), 0.0), 1.0))) for c in rgb[:3])
    return r, g, b


def meshcat_color(rgb) -> int:
    """An RGB triple in 0..1 (clipped) as a meshcat material colour, 0xRRGGBB."""
    r, g, b = _rgb255(rgb)
    return (r << 16) + (g << 8) + b


def css_color(rgb) -> str:
    """An RGB triple in 0..1 (clipped) as a CSS colour, ``rgb(r,g,b)``."""
    r, g, b = _rgb255(rgb)
    return f"rgb({r},{g},{b})"


# ---------------------------------------------------------------------------------------
# Recording window: meshcat's command stream kept in memory
# ---------------------------------------------------------------------------------------
class RecordingWindow:
    """Stands in for ``meshcat.visualizer.ViewerWindow``: keeps every command in a scene tree.

    The tree update rules are those of meshcat's server bridge
    (``meshcat.servers.zmqserver.ZMQWebSocketBridge.handle_zmq``), so the page built from
    it shows what a live meshcat server would show.
    """

    web_url = None

    def __init__(self):
        from meshcat.servers.tree import SceneTree

        self.tree = SceneTree()

    def send(self, command) -> None:
        import umsgpack
        from meshcat.servers.tree import SceneTree, find_node

        data = command.lower()
        kind = data["type"]
        path = [p for p in data["path"].split("/") if p]
        packed = umsgpack.packb(data)
        if kind == "set_transform":
            find_node(self.tree, path).transform = packed
        elif kind == "set_object":
            node = find_node(self.tree, path)
            node.object = packed
            node.properties = []
        elif kind == "set_property":
            find_node(self.tree, path).properties.append(packed)
        elif kind == "set_animation":
            find_node(self.tree, path).animation = packed
        elif kind == "delete":
            if path:
                parent = find_node(self.tree, path[:-1])
                parent.pop(path[-1], None)
            else:
                self.tree = SceneTree()

    def packed_commands(self) -> list[bytes]:
        """All commands (msgpack bytes) in the order meshcat's server replays them."""
        from meshcat.servers.tree import walk

        out: list[bytes] = []
        for node in walk(self.tree):
            if node.object is not None:
                out.append(node.object)
            out.extend(node.properties)
            if node.transform is not None:
                out.append(node.transform)
            if node.animation is not None:
                out.append(node.animation)
        return out

    # meshcat API the Pinocchio visualizer may probe
    def get_image(self):  # pragma: no cover - never called for a recording
        raise NotImplementedError("a recorded scene has no image; open its static HTML in a browser")


# ---------------------------------------------------------------------------------------
# The page: legend, static HTML, live view
# ---------------------------------------------------------------------------------------
def legend_html(title: str, color_bars, entries, notes) -> str:
    """The legend overlay: title, colour bars (:class:`~tcr_accuracy.view.viewer.ColorBar`),
    swatches with text (:class:`~tcr_accuracy.view.viewer.LegendEntry`) and notes, as HTML."""
    parts = [f'<div class="tcr-title">{html.escape(title)}</div>']
    for bar in color_bars:
        stops = ", ".join(css_color(c) for c in bar.colors)
        parts.append(
            '<div class="tcr-bar">'
            f'<div class="tcr-bar-label">{html.escape(bar.label)}</div>'
            f'<div class="tcr-bar-gradient" style="background: linear-gradient(to right, {stops});"></div>'
            f'<div class="tcr-bar-ticks"><span>{bar.vmin:.4g}</span>'
            f'<span>{0.5 * (bar.vmin + bar.vmax):.4g}</span><span>{bar.vmax:.4g}</span></div>'
            "</div>")
    for entry in entries:
        swatch = (f'<span class="tcr-swatch" style="background:{css_color(entry.color)}"></span>'
                  if entry.color is not None else '<span class="tcr-swatch tcr-none"></span>')
        parts.append(f'<div class="tcr-entry">{swatch}{html.escape(entry.text)}</div>')
    for note in notes:
        parts.append(f'<div class="tcr-note">{html.escape(note)}</div>')
    return '<div id="tcr-legend">' + "".join(parts) + "</div>"


#: Width of the legend's column left of the canvas [CSS px].
LEGEND_WIDTH_PX = 330


def _page(title: str, legend: str, scene_script: str, meshcat_script: str, fit: dict | None = None) -> str:
    """The HTML page: the legend's column, meshcat's viewer filling the rest of the window, then the
    script that loads the scene (``scene_script``) into the viewer that ``meshcat_script`` defines
    and, with ``fit`` (``points_m``, what the view must hold, about the view's centre in three.js's
    axes; ``margin``, ``fov_deg``), puts the camera at the nearest distance that holds them on the canvas."""
    return _PAGE.format(
        title=html.escape(title),
        css=_CSS.replace("LEGEND_WIDTH", str(LEGEND_WIDTH_PX)),
        legend=legend,
        meshcat_script=meshcat_script,
        scene_script=scene_script + (_FIT_CAMERA.replace("FIT", json.dumps(fit)) if fit else ""),
    )


def static_page(window: RecordingWindow, title: str, legend: str, fit: dict | None = None) -> str:
    """One self-contained HTML page (meshcat's viewer, the recorded scene, the legend); no server needed."""
    from meshcat.servers.zmqserver import VIEWER_ROOT

    main_js = (Path(VIEWER_ROOT) / "main.min.js").read_text(encoding="utf-8")
    commands = [base64.b64encode(c).decode("ascii") for c in window.packed_commands()]
    scene_script = _STATIC_LOADER.format(commands=json.dumps(commands))
    # "</script" inside the inlined bundle would end the script element early
    main_js = main_js.replace("</script", "<\\/script")
    return _page(title, legend, scene_script, f"<script>{main_js}</script>", fit)


def serve_page(window: RecordingWindow, title: str, legend: str, open_browser: bool = False,
               fit: dict | None = None) -> "LiveView":
    """Serve the recorded scene live on 127.0.0.1 (a meshcat server subprocess) as a :class:`LiveView`."""
    live = LiveView.start(_page(title, legend, _LIVE_LOADER, '<script src="static/main.min.js"></script>', fit))
    live.replay(window)
    if open_browser:
        import webbrowser

        webbrowser.open(live.url, new=2)
    return live


# ---------------------------------------------------------------------------------------
# Live server on localhost
# ---------------------------------------------------------------------------------------
class LiveView:
    """A meshcat server subprocess bound to 127.0.0.1 holding one scene."""

    def __init__(self, process: subprocess.Popen, zmq_url: str, url: str):
        self.process = process
        self.zmq_url = zmq_url
        self.url = url

    @classmethod
    def start(cls, page: str, timeout_s: float = 20.0) -> "LiveView":
        import_meshcat()
        env = dict(os.environ)
        import tcr_accuracy

        # the folder that holds the package, whatever module starts the server
        src = str(Path(tcr_accuracy.__file__).resolve().parents[1])
        env["PYTHONPATH"] = os.pathsep.join(p for p in (src, env.get("PYTHONPATH", "")) if p)
        process = subprocess.Popen(
            [sys.executable, "-u", "-m", "tcr_accuracy.view._meshcat_server"],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, env=env,
            start_new_session=True)
        assert process.stdin is not None and process.stdout is not None
        process.stdin.write(page.encode("utf-8"))
        process.stdin.close()
        deadline = time.monotonic() + timeout_s
        zmq_url = web_url = None
        while time.monotonic() < deadline and (zmq_url is None or web_url is None):
            line = process.stdout.readline().decode("utf-8").strip()
            if not line and process.poll() is not None:
                break
            if line.startswith("zmq_url="):
                zmq_url = line.split("=", 1)[1]
            elif line.startswith("web_url="):
                web_url = line.split("=", 1)[1]
        if zmq_url is None or web_url is None:
            process.kill()
            process.wait()
            process.stdout.close()
            from ..exceptions import AnalysisError

            raise AnalysisError("the meshcat server did not start")
        live = cls(process, zmq_url, web_url)
        atexit.register(live.close)
        return live

    def replay(self, window: RecordingWindow) -> None:
        import zmq

        socket = zmq.Context.instance().socket(zmq.REQ)
        socket.connect(self.zmq_url)
        try:
            from meshcat.servers.tree import walk

            for node_path, packed in _walk_with_paths(window.tree, walk):
                kind = _command_type(packed)
                socket.send_multipart([kind.encode(), node_path.encode(), packed])
                socket.recv()
        finally:
            socket.close(linger=0)

    def close(self) -> None:
        """Stop the server (it ends with this process anyway)."""
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        if self.process.stdout is not None:
            self.process.stdout.close()

    def __enter__(self) -> "LiveView":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _command_type(packed: bytes) -> str:
    import umsgpack

    return umsgpack.unpackb(packed)["type"]


def _walk_with_paths(tree, walk):
    """(path, packed command) pairs of a recorded tree, in replay order."""
    import umsgpack

    for node in walk(tree):
        for packed in ([node.object] if node.object is not None else []) + list(node.properties) + \
                [c for c in (node.transform, node.animation) if c is not None]:
            yield umsgpack.unpackb(packed).get("path", ""), packed


# ---------------------------------------------------------------------------------------
# Page template
# ---------------------------------------------------------------------------------------
_CSS = """
body { margin: 0; font-family: system-ui, -apple-system, "Segoe UI", sans-serif; overflow: hidden; }
/* the legend in its own column left of the canvas: it never covers the scene */
#meshcat-pane { position: absolute; left: LEGEND_WIDTHpx; right: 0; top: 0; height: 100vh; overflow: hidden; }
#tcr-legend { position: absolute; left: 0; top: 0; width: LEGEND_WIDTHpx; height: 100vh; box-sizing: border-box;
  overflow-y: auto; padding: 8px 10px; background: #fbfbfc; border-right: 1px solid #bbb;
  font-size: 13px; color: #222; line-height: 1.35; }
.tcr-title { font-weight: 600; margin-bottom: 4px; }
.tcr-bar { margin: 4px 0 6px 0; }
.tcr-bar-gradient { height: 12px; border: 1px solid #777; }
.tcr-bar-ticks { display: flex; justify-content: space-between; font-size: 11px; }
.tcr-swatch { display: inline-block; width: 11px; height: 11px; margin-right: 6px;
  border: 1px solid #555; vertical-align: -1px; }
.tcr-none { background: repeating-linear-gradient(45deg, #ddd, #ddd 2px, #fff 2px, #fff 4px); }
.tcr-note { font-size: 11px; color: #444; margin-top: 3px; }
"""

_PAGE = """<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>{title}</title>
<style>{css}</style>
</head>
<body>
<div id="meshcat-pane"></div>
{legend}
{meshcat_script}
<script>
var viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));
{scene_script}
</script>
</body>
</html>
"""

# The commands are the msgpack blobs meshcat's server would send over its websocket;
# decoding them synchronously (not through fetch() of data: URLs as meshcat's own export
# does) keeps their order and lets a page screenshot see the finished scene.
_STATIC_LOADER = """var tcrCommands = {commands};
for (var i = 0; i < tcrCommands.length; i++) {{
  var raw = atob(tcrCommands[i]);
  var bytes = new Uint8Array(raw.length);
  for (var k = 0; k < raw.length; k++) {{ bytes[k] = raw.charCodeAt(k); }}
  viewer.handle_command_bytearray(bytes);
}}
document.body.setAttribute("data-tcr-scene", "loaded");
"""

_LIVE_LOADER = """try { viewer.connect(); } catch (e) { console.info("no meshcat server: ", e); }
"""

# The camera looks at the scene's centre (the origin, the scene shifted) from the direction the scene
# set; here it moves along that line to the nearest distance at which every point the view must
# hold lies within the canvas's field of view (vertical: meshcat's; horizontal: from the canvas's
# aspect), each with the margin: a point c at depth d - c.u (u: the unit vector to the camera)
# needs |c.right| <= tan(h/2) (d - c.u) / margin and |c.up| <= tan(v/2) (d - c.u) / margin.
# A live view receives its camera later: the fit runs again once the scene has arrived.
_FIT_CAMERA = """
(function () {
  var fit = FIT;
  function fitCamera() {
    var pane = document.getElementById("meshcat-pane"), camera = viewer.camera, p = camera.position;
    var length = p.length();
    if (!(length > 0)) { return; }
    var aspect = pane.offsetWidth / Math.max(window.innerHeight, 1);
    var tanV = Math.tan(fit.fov_deg * Math.PI / 360), tanH = tanV * aspect;
    var u = [p.x / length, p.y / length, p.z / length];
    var r = [-u[2], 0, u[0]], rn = Math.hypot(r[0], r[2]) || 1;  // right = u x (0, 1, 0), y up
    r = [r[0] / rn, 0, r[2] / rn];
    var up = [u[1] * r[2] - u[2] * r[1], u[2] * r[0] - u[0] * r[2], u[0] * r[1] - u[1] * r[0]];
    var distance = 0;
    fit.points_m.forEach(function (c) {
      var along = c[0] * u[0] + c[1] * u[1] + c[2] * u[2];
      var side = Math.abs(c[0] * r[0] + c[1] * r[1] + c[2] * r[2]);
      var high = Math.abs(c[0] * up[0] + c[1] * up[1] + c[2] * up[2]);
      distance = Math.max(distance, along + fit.margin * side / tanH, along + fit.margin * high / tanV);
    });
    if (distance > 0) { p.multiplyScalar(distance / length); }
    viewer.set_3d_pane_size();
    viewer.set_dirty();
  }
  fitCamera();
  window.addEventListener("resize", fitCamera);
  if (viewer.connection !== undefined) { setTimeout(fitCamera, 1500); }
})();
"""
