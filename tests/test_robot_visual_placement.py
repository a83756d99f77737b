"""Every body of a robot's 3D view where the URDF puts it, and drawn whole (issue 42, item 3).

The reference is yourdfpy (and trimesh under it): its own URDF parser and forward kinematics place each
link (``URDF.get_transform``, the scene graph's link frames) and each visual on it (the visual's
``<origin>`` and ``scale`` as yourdfpy read them); none of the package's kinematics is used.

* What the view sends: the placement of every visual node the scene records (meshcat's
  ``set_transform``, the mesh scale in it) equals yourdfpy's, body by body, to 1e-9 m and 1e-9 in the
  rotation, at three joint configurations of UR3, UR5, UR10, Panda, Kinova and the tool-changer.
* What the browser draws (headless Chromium, as tests/test_browser.py): every mesh under the robot's
  node has one drawable material per group (meshcat's ``merge_geometries`` handed the UR5's
  housings, meshes of two materials each, a list inside its list of materials, and three.js drew
  none of them: the blue caps and the wrist parts hung in the air), and each body's vertices, placed
  by three.js, span the box trimesh's vertices of the same file span where yourdfpy places them,
  within 1e-6 m.

(example-robot-data 6 ships no KUKA iiwa: the Kinova stands for the seventh robot.)
"""

import json
import re

import numpy as np
import pytest
import trimesh
import yourdfpy

from tcr_accuracy.model.robot import example_robot_data_dir, load_robot
from tcr_accuracy.view.robot_visuals import one_material_per_mesh
from tcr_accuracy.view.viewer import Scene

from conftest import REPO
from test_browser import _dom, chromium  # noqa: F401 (fixture)

ROBOTS = ("ur3", "ur5", "ur10", "panda", "kinova", "tool_changer")


def _robot(name):
    return load_robot(None if name == "tool_changer" else name)


def _urdf(robot, meshes: bool):
    share = example_robot_data_dir()

    def located(name):  # package://NAME/... as example-robot-data installs it; relative to the URDF otherwise
        if name.startswith("package://"):
            return str(share / name[len("package://"):])
        return str(robot.urdf_path.parent / name) if robot.urdf_path is not None else name

    path = robot.urdf_path if robot.urdf_path is not None else REPO / "robots" / "tool_changer.urdf"
    return yourdfpy.URDF.load(str(path), load_meshes=meshes, build_scene_graph=True, filename_handler=located)


def _configurations(robot, n=3):
    rng = np.random.default_rng(7)
    lo, hi = robot.joint_bounds(np.pi)
    return [robot.working_pose] + list(rng.uniform(lo, hi, (n - 1, robot.n_joints)))


def _visuals(urdf, q, names):
    """{pinocchio geometry name ``<link>_<k>``: (4, 4) base_M_visual with the mesh scale} by yourdfpy."""
    urdf.update_cfg(dict(zip(names, q)))
    out = {}
    for link_name, link in urdf.link_map.items():
        link_pose = urdf.scene.graph.get(link_name)[0]
        for k, visual in enumerate(link.visuals):
            origin = np.eye(4) if visual.origin is None else visual.origin
            scale = np.ones(3)
            mesh = visual.geometry.mesh
            if mesh is not None and mesh.scale is not None:
                scale = np.broadcast_to(np.asarray(mesh.scale, dtype=float), (3,))
            out[f"{link_name}_{k}"] = (link_pose @ origin) @ np.diag([*scale, 1.0]), mesh
    return out


def _sent_placements(scene, node="robot"):
    """{geometry name: (4, 4)} the transforms the scene recorded for the robot's visual nodes."""
    import umsgpack

    found = {}

    def walk(tree, path):
        for key, child in tree.items():
            here = path + [key]
            if child.transform is not None and len(here) >= 3 and here[-2] == "visuals" and node in here:
                found[key] = np.array(umsgpack.unpackb(child.transform)["matrix"]).reshape(4, 4).T
            walk(child, here)

    walk(scene._window.tree, [])
    return found


@pytest.mark.parametrize("name", ROBOTS)
def test_every_visual_is_placed_where_yourdfpy_places_it(name):
    robot = _robot(name)
    urdf = _urdf(robot, meshes=False)
    chain = list(robot.joint_names)
    for q in _configurations(robot):
        scene = Scene(grid=False)
        scene.add_robot(robot, q, "robot")
        sent = _sent_placements(scene)
        expected = _visuals(urdf, q, chain)
        assert set(sent) == set(expected), (name, sorted(set(sent) ^ set(expected)))
        for body, (placement, _) in expected.items():
            got = sent[body]
            assert np.abs(got[:3, 3] - placement[:3, 3]).max() < 1e-9, (name, body)
            assert np.abs(got[:3, :3] - placement[:3, :3]).max() < 1e-9, (name, body)


# ---------------------------------------------------------------------------------------
# COLLADA meshes split to one material each: same vertices, same materials, one per mesh
# ---------------------------------------------------------------------------------------
def _ur5_mesh(part, robot="ur5"):
    return example_robot_data_dir() / f"example-robot-data/robots/ur_description/meshes/{robot}/visual" / part


def test_a_mesh_of_two_materials_becomes_two_meshes_of_one_each(tmp_path):
    """shoulder.dae's first mesh holds triangles of two materials: after the split every geometry has one
    primitive element, and trimesh reads the same triangles per material from both documents."""
    text = _ur5_mesh("shoulder.dae").read_text()
    split = one_material_per_mesh(text)
    path = tmp_path / "split.dae"
    path.write_text(split)
    counts = [len(re.findall(r"<(triangles|polylist|polygons)\b", g))
              for g in re.findall(r"<geometry\b.*?</geometry>", split, re.DOTALL)]
    assert counts and all(c == 1 for c in counts)
    assert len(counts) == 3  # 2 + 1 primitive elements in the original

    def by_material(file):
        scene = trimesh.load(file, force="scene")
        faces = {}
        for geometry in scene.geometry.values():
            key = getattr(geometry.visual.material, "name", None) or "?"
            faces.setdefault(key, []).append(np.sort(geometry.vertices[geometry.faces].reshape(-1, 9), axis=0))
        return {k: np.sort(np.vstack(v), axis=0) for k, v in faces.items()}

    before, after = by_material(_ur5_mesh("shoulder.dae")), by_material(path)
    assert sorted(before) == sorted(after)
    for key in before:
        np.testing.assert_array_equal(before[key], after[key])


def test_a_document_with_nothing_to_split_is_returned_as_it_is():
    text = _ur5_mesh("wrist3.dae", "ur10").read_text()  # one mesh of one material
    assert one_material_per_mesh(text) is text
    assert one_material_per_mesh("not xml <") == "not xml <"


# ---------------------------------------------------------------------------------------
# In the browser
# ---------------------------------------------------------------------------------------
#: Appended to the view's page: per visual node of the robot, whether every group of its mesh has a
#: drawable material, and its vertices' box in the robot node's frame, placed by three.js.
_BODIES = """<script>
(function () {
  viewer.scene.updateMatrixWorld(true);
  var robot = viewer.scene_tree.find(["meshcat", "robot"]).object;
  var inverse = robot.matrixWorld.clone().invert(), out = {};
  var visuals = viewer.scene_tree.find(["meshcat", "robot", "visuals"]).object;
  visuals.children.forEach(function (node) {
    var low = [Infinity, Infinity, Infinity], high = [-Infinity, -Infinity, -Infinity], drawable = true;
    var triangles = 0;
    node.traverse(function (obj) {
      if (!obj.isMesh) { return; }
      var materials = Array.isArray(obj.material) ? obj.material : [obj.material];
      var groups = obj.geometry.groups.length ? obj.geometry.groups : [{materialIndex: 0}];
      groups.forEach(function (g) {
        var m = materials[g.materialIndex];
        if (!m || Array.isArray(m) || !m.isMaterial) { drawable = false; }
      });
      var position = obj.geometry.attributes.position, V = obj.position.constructor;
      var matrix = inverse.clone().multiply(obj.matrixWorld);
      triangles += position.count / 3;
      for (var i = 0; i < position.count; i++) {
        var v = new V(position.getX(i), position.getY(i), position.getZ(i)).applyMatrix4(matrix);
        [v.x, v.y, v.z].forEach(function (c, k) { low[k] = Math.min(low[k], c); high[k] = Math.max(high[k], c); });
      }
    });
    out[node.name] = {drawable: drawable, low: low, high: high, triangles: triangles};
  });
  var pre = document.createElement("pre");
  pre.id = "tcr-bodies";
  pre.textContent = JSON.stringify(out);
  document.body.appendChild(pre);
})();
</script>"""


def _trimesh_box(urdf_mesh, placement):
    """(low, high) of the mesh file's vertices (trimesh, its node transforms applied) placed by ``placement``."""
    mesh = trimesh.load(urdf_mesh, force="mesh")
    points = mesh.vertices @ placement[:3, :3].T + placement[:3, 3]
    return points.min(axis=0), points.max(axis=0)


@pytest.mark.parametrize("name", ["ur5", "ur10", "panda", "kinova"])
def test_the_browser_draws_every_body_whole_where_yourdfpy_places_it(name, chromium, tmp_path):  # noqa: F811
    robot = _robot(name)
    urdf = _urdf(robot, meshes=False)
    q = _configurations(robot, 2)[1]
    scene = Scene(grid=False)
    scene.add_robot(robot, q, "robot")
    page = tmp_path / "view.html"
    page.write_text(scene.static_html().replace("</body>", _BODIES + "</body>"))
    dom = _dom(chromium, tmp_path, page)
    match = re.search(r'<pre id="tcr-bodies">(.*?)</pre>', dom, re.DOTALL)
    assert match, "the page's script did not run"
    import html

    bodies = json.loads(html.unescape(match.group(1)))
    expected = _visuals(urdf, q, list(robot.joint_names))
    share = example_robot_data_dir()
    assert set(bodies) == set(expected)
    for body, (placement, mesh) in expected.items():
        drawn = bodies[body]
        assert drawn["drawable"], f"{name}: {body} has a group three.js cannot draw"
        if mesh is None:
            continue
        file = share / mesh.filename[len("package://"):]
        low, high = _trimesh_box(str(file), placement)
        assert np.abs(np.array(drawn["low"]) - low).max() < 1e-6, (name, body)
        assert np.abs(np.array(drawn["high"]) - high).max() < 1e-6, (name, body)
