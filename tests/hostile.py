"""Helpers of the hostile-input tests (``tests/test_hostile_*.py``, issues 12 and 22, and the
files that grew from them: input opener, output writer, result files, memory bounds, ROS packages).

Every bad input must end in ONE line on stderr naming the file, row, column or option at
fault, exit code 2, no traceback and no file left behind. The numbers in the test names
(``test_12_09_...``, ``test_22_01_...``) are the rows of those issues' tables. The files are
sorted by the component they attack; the decoys they aim at are made in ``tmp_path``.
"""

import base64
import re

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
    """err is one line, no traceback, holding every fragment."""
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert "Traceback" not in err
    for fragment in fragments:
        assert fragment in lines[0], err


#: A link's inertia: Pinocchio wants one on every moving link
INERTIAL = ('<inertial><mass value="1"/><inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" iyz="0"/>'
            '</inertial>')


def two_joint_urdf(*, j1_origin="0 0 0.5", j1_axis="0 0 1", j1_limit='lower="-1" upper="1"', j2_type="revolute",
                   extra="", l1_visual=""):
    """A two-joint arm base -j1-> l1 -j2-> l2; each argument replaces one piece of it."""
    return f"""<robot name="r">
  <link name="base"/>{extra}
  <link name="l1">{l1_visual}{INERTIAL}</link>
  <link name="l2">{INERTIAL}</link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="{j1_origin}"/>
    <axis xyz="{j1_axis}"/><limit {j1_limit} effort="1" velocity="1"/></joint>
  <joint name="j2" type="{j2_type}"><parent link="l1"/><child link="l2"/><origin xyz="0 0.5 0"/>
    <axis xyz="1 0 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
</robot>"""


def mimic_urdf(finger_multiplier: str | None = None) -> str:
    """[B]: a 3-link arm whose j3 follows j2 (``-1 x j2 + 0.1``), with, given a multiplier, a
    50 kg prismatic finger following j2 too."""
    links = "".join(f'<link name="l{i}">{INERTIAL}</link>' for i in range(4))
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


def embedded_blobs(html: str) -> bytes:
    """Everything a static view embeds, its base64 commands decoded and joined."""
    return b"".join(base64.b64decode(b) for b in re.findall(r'"([A-Za-z0-9+/=]{64,})"', html))


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


#: The tool-changer's joint columns in a measurement CSV
JOINTS = "j1_deg,j2_deg,j3_deg,j4_mm,j5_deg,j6_deg"


def m60_rows(m60, n):
    """The first n rows of m60 as (x, y, z, joints-as-CSV-text), positions and joints that agree."""
    import csv

    rows = list(csv.DictReader(m60.read_text().splitlines()))[:n]
    return [(r["x_mm"], r["y_mm"], r["z_mm"], ",".join(r[j] for j in JOINTS.split(","))) for r in rows]


def must_not_run(*args, **kwargs):
    """Stands in for the work a refusal must come before (monkeypatched over it)."""
    raise AssertionError("the work started before its outputs, inputs or memory were checked")
