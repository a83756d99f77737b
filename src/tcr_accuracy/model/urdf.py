"""URDF text to Pinocchio: reading it safely, frames by name and type, reducing a tree to a chain.

Model layer, under :mod:`tcr_accuracy.model.robot`. URDF lets a link and a joint share a name and
Pinocchio's model reduction looks frames up by name alone, so both are handled here once.
"""

from __future__ import annotations

import math
import re
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from xml.etree import ElementTree

import numpy as np
import pinocchio as pin

from ..exceptions import InputError
from ..input_files import MEMORY_PER_BYTE_OF, SIZE_LIMITS, read_input_text
from ..units import PRISMATIC, REVOLUTE, parse_number


_ENTITY = re.compile(r"<!\s*(ENTITY|DOCTYPE)", re.IGNORECASE)
MAX_URDF_BYTES = SIZE_LIMITS["urdf"]


def read_urdf_text(path: Path) -> str:
    """Read a URDF file, refusing DTDs and entities (no entity expansion, ever)."""
    return read_input_text(path, "URDF", limit=MAX_URDF_BYTES, memory_per_byte=MEMORY_PER_BYTE_OF["urdf"])


def parse_urdf_xml(text: str, source: str) -> ElementTree.Element:
    """Parse URDF text into an element tree, with one clear line on failure."""
    match = _ENTITY.search(text)
    if match:
        line = text.count("\n", 0, match.start()) + 1
        raise InputError(
            f"{source}: line {line}: URDF declares a DTD or entity (<!{match.group(1)}); "
            "entity expansion is refused"
        )
    try:
        root = ElementTree.fromstring(text)
    except ElementTree.ParseError as exc:
        raise InputError(f"{source}: URDF does not parse as XML ({one_line(exc)})") from None
    if root.tag != "robot":
        raise InputError(f"{source}: root element is <{one_line(root.tag)}>, a URDF needs <robot>")
    return root


@contextmanager
def quiet_native_stderr():
    """Hold what native code (urdfdom, through Pinocchio) writes to file descriptor 2 inside the
    block; yields a function returning the first line written (empty if none), for a message.

    Python's own ``sys.stderr`` is untouched; when fd 2 cannot be redirected, nothing is held.
    """
    import os
    import tempfile

    try:
        saved = os.dup(2)
    except OSError:
        yield lambda: ""
        return
    with tempfile.TemporaryFile() as held:
        def first_line() -> str:
            held.seek(0)
            for line in held.read(4096).decode("utf-8", "replace").splitlines():
                if line.strip():
                    return line.strip().removeprefix("Error:").strip()
            return ""

        try:
            os.dup2(held.fileno(), 2)
            yield first_line
        finally:
            os.dup2(saved, 2)
            os.close(saved)


def listed(names, limit: int = 300) -> str:
    """Names joined with commas for a message, cut at ``limit`` characters with how many there are."""
    text = one_line(", ".join(names), limit)
    return text if not text.endswith("...") else f"{text} ({len(names)} in all)"


def one_line(text, limit: int = 200) -> str:
    """A message part on one line of at most ``limit`` characters (a parser's message, a name from a file)."""
    text = " ".join(str(text).split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


#: The URDF joint types; tcr-accuracy moves the TCP with the first three (``fixed`` joints fold
#: into their links; ``floating`` and ``planar`` joints may only sit outside the TCP chain).
URDF_JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar")

#: The largest length a URDF may give [m] (an origin, a joint limit): beyond it a value is a typo.
MAX_URDF_LENGTH = 1e4
#: The largest angle [rad] (an origin's rpy, a revolute limit) and mass-property value a URDF may give.
MAX_URDF_ANGLE = 1e4
MAX_URDF_MASS = 1e9
#: The largest ratio a ``<mimic>`` rule may give between two joints.
MAX_MIMIC_MULTIPLIER = 1e3
#: The most joints a URDF may have, and the most a chain from the base to the TCP may have:
#: the error model grows with the chain and its Jacobians with its square.
MAX_URDF_JOINTS = 1000
MAX_CHAIN_JOINTS = 100


def check_urdf(root: ElementTree.Element, source: str) -> None:
    """Refuse, in one line naming the link or joint, what Pinocchio's URDF parser would take
    silently, answer with several lines of its own, or turn into a crash later.

    Links need unique names; joints a name, a known type, an existing parent and child and at
    most one parent per link (a tree); every number (origins, axes, limits, masses, inertias)
    is a plain finite decimal in a sane range (a ``<mimic>`` rule's too); an axis is not of zero
    length and a limit's lower bound is not above its upper one.
    """
    links: set = set()
    for k, link in enumerate(root.findall("link")):
        name = link.get("name")
        if not name:
            raise InputError(f"{source}: link #{k + 1} (<link> element {k + 1}) has no name")
        if name in links:
            raise InputError(f"{source}: link {one_line(name)} is defined twice")
        links.add(name)
        for inertial in link.findall("inertial"):
            _check_origin(inertial, f"{source}: link {one_line(name)}: <inertial>")
            mass = inertial.find("mass")
            if mass is not None:
                _number(mass, "value", f"{source}: link {one_line(name)}: <mass>", 0.0, MAX_URDF_MASS)
            inertia = inertial.find("inertia")
            if inertia is not None:
                for key in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"):
                    _number(inertia, key, f"{source}: link {one_line(name)}: <inertia>", -MAX_URDF_MASS,
                            MAX_URDF_MASS, default=0.0)
        for kind in ("visual", "collision"):
            for element in link.findall(kind):
                _check_origin(element, f"{source}: link {one_line(name)}: <{kind}>")
    if not links:
        raise InputError(f"{source}: the URDF has no <link>")
    joints: set = set()
    parent_of: dict = {}
    if len(root.findall("joint")) > MAX_URDF_JOINTS:
        raise InputError(f"{source}: {len(root.findall('joint'))} joints, more than the {MAX_URDF_JOINTS} "
                         "tcr-accuracy reads")
    for k, joint in enumerate(root.findall("joint")):
        name = joint.get("name")
        if not name:
            raise InputError(f"{source}: joint #{k + 1} (<joint> element {k + 1}) has no name")
        where = f"{source}: joint {one_line(name)}"
        if name in joints:
            raise InputError(f"{where}: defined twice")
        joints.add(name)
        kind = joint.get("type")
        if kind not in URDF_JOINT_TYPES:
            raise InputError(f"{where}: type {one_line(kind)!r} is not a URDF joint type "
                             f"({', '.join(URDF_JOINT_TYPES)})")
        ends = {}
        for end in ("parent", "child"):
            element = joint.find(end)
            ends[end] = None if element is None else element.get("link")
            if not ends[end]:
                raise InputError(f"{where}: no <{end} link=...>")
            if ends[end] not in links:
                raise InputError(f"{where}: {end} link {one_line(ends[end])} is not defined")
        child = ends["child"]
        if child in parent_of:
            raise InputError(f"{where}: link {one_line(child)} already has a parent joint "
                             f"({one_line(parent_of[child][1])}); a URDF is a tree")
        parent_of[child] = (ends["parent"], name)
        _check_origin(joint, where)
        if kind in ("revolute", "continuous", "prismatic", "planar"):
            axis = joint.find("axis")
            if axis is not None:
                xyz = _vector(axis, "xyz", f"{where}: <axis>", 1.0, "1 0 0")
                if math.sqrt(sum(v * v for v in xyz)) < 1e-9:
                    raise InputError(f"{where}: <axis xyz=...> has zero length: the joint would not move")
        limit = joint.find("limit")
        if limit is not None and kind in ("revolute", "prismatic"):
            bound = MAX_URDF_ANGLE if kind == "revolute" else MAX_URDF_LENGTH
            lower = _number(limit, "lower", f"{where}: <limit>", -bound, bound, default=0.0)
            upper = _number(limit, "upper", f"{where}: <limit>", -bound, bound, default=0.0)
            for key in ("effort", "velocity"):
                _number(limit, key, f"{where}: <limit>", 0.0, math.inf, default=0.0)
            if lower > upper:
                raise InputError(f"{where}: <limit> lower {lower:g} is above upper {upper:g}")
    for link in links:  # every chain of parents ends at a root: no loop
        seen = {link}
        while link in parent_of:
            link = parent_of[link][0]
            if link in seen:
                raise InputError(f"{source}: joints form a loop through link {one_line(link)}; a URDF is a tree")
            seen.add(link)
    roots = [link for link in links if link not in parent_of]
    if len(roots) != 1:
        raise InputError(f"{source}: {len(roots)} root links ({one_line(', '.join(sorted(roots)))}); "
                         "a URDF is one tree with one root")
    mimic_rules(root, source)  # their numbers too, before Pinocchio reads them


def check_mesh_paths(places, source: str, roots: list) -> None:
    """Refuse a mesh that could be read from outside ``roots`` (the URDF's folder and the package
    folders), in one line naming the link, so that no view or report reads and embeds
    ``../../secret/x.obj``.

    ``places`` are :class:`tcr_accuracy.model.ros_packages.MeshPlace` records: the file each mesh
    was found at, the one file Pinocchio is then given, must lie inside one of the roots
    (symlinks followed); a mesh found nowhere is read from nowhere.
    """
    roots = [Path(r).resolve() for r in roots]

    def inside(path: Path) -> bool:
        return any(path == r or r in path.parents for r in roots)

    for place in places:
        if place.path is not None and not inside(place.path.resolve()):
            folders = ", ".join(str(r) for r in roots) or "none: this URDF has no folder"
            raise InputError(f"{source}: link {one_line(place.link)}: mesh {one_line(place.name, 120)!r} lies "
                             f"outside the URDF's folder and package folders ({one_line(folders, 200)}); "
                             "refused")


def _number(element, key: str, where: str, low: float, high: float, default: float | None = None) -> float:
    text = element.get(key)
    if text is None:
        if default is None:
            raise InputError(f"{where}: no {key}=...")
        return default
    try:
        value = parse_number(text)
    except ValueError:
        raise InputError(f"{where}: {key}={one_line(text, 40)!r} is not a finite number") from None
    if not low <= value <= high:
        raise InputError(f"{where}: {key}={one_line(text, 40)} is outside [{low:g}, {high:g}]")
    return value


def _vector(element, key: str, where: str, bound: float, default: str) -> list:
    text = element.get(key, default)
    parts = text.split()
    if len(parts) != 3:
        raise InputError(f"{where}: {key}={one_line(text, 60)!r} needs three numbers")
    values = []
    for part in parts:
        try:
            value = parse_number(part)
        except ValueError:
            raise InputError(f"{where}: {key}={one_line(text, 60)!r}: {one_line(part, 40)!r} is not a finite "
                             "number") from None
        if abs(value) > bound:
            raise InputError(f"{where}: {key}={one_line(text, 60)!r}: {one_line(part, 40)} is beyond "
                             f"+-{bound:g}")
        values.append(value)
    return values


def _check_origin(element, where: str) -> None:
    origin = element.find("origin")
    if origin is not None:
        _vector(origin, "xyz", f"{where} <origin>", MAX_URDF_LENGTH, "0 0 0")
        _vector(origin, "rpy", f"{where} <origin>", MAX_URDF_ANGLE, "0 0 0")


@dataclass(frozen=True)
class Mimic:
    """A URDF ``<mimic>`` rule: ``q = multiplier * q[joint] + offset`` [SI]."""

    joint: str
    multiplier: float = 1.0
    offset: float = 0.0


def mimic_rules(root: ElementTree.Element, source: str) -> dict:
    """URDF ``<mimic joint=... multiplier=... offset=...>`` rules by joint name; the multiplier
    within +-:data:`MAX_MIMIC_MULTIPLIER`, the offset within the URDF's bound on lengths and
    angles (a ``1e308`` multiplier made gravity torques infinite). A rule must name another joint
    of the URDF, one that follows no rule itself: a joint mimicking itself, a loop of rules or a
    chain of them has no joint value to start from (as ROS, which follows one rule, reads it)."""
    rules = {}
    names = {joint.get("name") for joint in root.findall("joint")}
    for joint in root.findall("joint"):
        mimic = joint.find("mimic")
        if mimic is None:
            continue
        where = f"{source}: joint {one_line(joint.get('name'))}: <mimic>"
        if not mimic.get("joint"):
            raise InputError(f"{where} names no joint (joint=...)")
        multiplier = _number(mimic, "multiplier", where, -MAX_MIMIC_MULTIPLIER, MAX_MIMIC_MULTIPLIER, 1.0)
        offset = _number(mimic, "offset", where, -MAX_URDF_LENGTH, MAX_URDF_LENGTH, 0.0)
        if mimic.get("joint") == joint.get("name"):
            raise InputError(f"{where} names the joint itself; a joint follows another joint")
        if mimic.get("joint") not in names:
            raise InputError(f"{where} names {one_line(mimic.get('joint'))!r}, no joint of this URDF")
        rules[joint.get("name")] = Mimic(mimic.get("joint"), multiplier, offset)
    for name, rule in rules.items():
        if rule.joint in rules:
            kind = "a loop of <mimic> rules" if rules[rule.joint].joint == name or _loops(rules, name) else \
                "a chain of <mimic> rules"
            raise InputError(f"{source}: joint {one_line(name)}: <mimic> names {one_line(rule.joint)}, which follows "
                             f"{one_line(rules[rule.joint].joint)} itself ({kind}); name the joint that drives both")
    return rules


def _loops(rules: dict, start: str) -> bool:
    """Whether following the rules from ``start`` comes back to it."""
    seen, here = set(), start
    while here in rules and here not in seen:
        seen.add(here)
        here = rules[here].joint
    return here == start


_REVOLUTE_JOINT = re.compile(r"JointModel(R[XYZ]|RUB[XYZ]|RevoluteUnaligned|RevoluteUnboundedUnaligned)$")
_PRISMATIC_JOINT = re.compile(r"JointModel(P[XYZ]|PrismaticUnaligned)$")


def joint_kind(joint: pin.JointModel, where: str | None = None) -> str:
    """``revolute`` or ``prismatic`` for a 1-DoF Pinocchio joint; InputError (starting with
    ``where``, e.g. ``robot.urdf: joint j2``) for any other kind (planar, floating, ...)."""
    short = joint.shortname()
    if _REVOLUTE_JOINT.match(short):
        return REVOLUTE
    if _PRISMATIC_JOINT.match(short):
        return PRISMATIC
    raise InputError(
        f"{where + ': ' if where else ''}joint type {short} is not supported: "
        "tcr-accuracy handles serial chains of revolute, continuous and prismatic joints"
    )


#: Which frame a name means when a link, a joint or a fixed joint share it: links first.
_FRAME_PREFERENCE = (pin.FrameType.BODY, pin.FrameType.OP_FRAME, pin.FrameType.FIXED_JOINT,
                     pin.FrameType.JOINT, pin.FrameType.SENSOR)


def find_frame(model: pin.Model, name: str, source: str = "the model") -> int:
    """Index of frame ``name`` in ``model.frames``: a link's frame if there is one, else an
    operational frame, a fixed joint's or a joint's (URDF lets a link and a joint share a name).

    Raises
    ------
    InputError
        No frame has that name; the message lists the frames there are.
    """
    matches = [i for i, f in enumerate(model.frames) if f.name == name]
    if not matches:
        names = sorted({f.name for f in model.frames if f.name != "universe"})
        raise InputError(f"tool={one_line(name, 80)}: no such frame in {source} (frames: {listed(names)})",
                         parameter="tool", value=name)
    return min(matches, key=lambda i: _FRAME_PREFERENCE.index(model.frames[i].type)
               if model.frames[i].type in _FRAME_PREFERENCE else len(_FRAME_PREFERENCE))


def reduce_model(full: pin.Model, locked: list[int], geometry: pin.GeometryModel | None = None,
                 q_locked: np.ndarray | None = None):
    """``pin.buildReducedModel`` that also works when frames share a name.

    Pinocchio looks frames up by name inside the reduction and stops when a link and a
    joint share one (legal URDF). Each duplicate is renamed for the call and restored in
    the result, so frame names stay those of the URDF.

    Returns the reduced model, or (model, geometry) when ``geometry`` is given.
    """
    q_locked = pin.neutral(full) if q_locked is None else q_locked
    counts: dict = {}
    for f in full.frames:
        counts[f.name] = counts.get(f.name, 0) + 1
    work = full
    renamed: dict = {}
    if any(c > 1 for c in counts.values()):
        work = pin.Model(full)
        for i, f in enumerate(work.frames):
            if counts[f.name] > 1 and f.type != pin.FrameType.JOINT:
                renamed[f"{f.name}\x00{i}"] = f.name
                frame = work.frames[i]
                frame.name = f"{f.name}\x00{i}"
                work.frames[i] = frame
    if geometry is None:
        reduced = pin.buildReducedModel(work, locked, q_locked)
    else:
        reduced, geometry = pin.buildReducedModel(work, geometry, locked, q_locked)
    for i, f in enumerate(reduced.frames):
        if f.name in renamed:
            frame = reduced.frames[i]
            frame.name = renamed[f.name]
            reduced.frames[i] = frame
    return reduced if geometry is None else (reduced, geometry)


def single_leaf_link(root: ElementTree.Element, source: str) -> str:
    links = [link.get("name") for link in root.findall("link")]
    parents = {joint.find("parent").get("link") for joint in root.findall("joint")
               if joint.find("parent") is not None}
    leaves = [link for link in links if link not in parents]
    if len(leaves) != 1:
        raise InputError(f"{source}: give the TCP frame with tool= (leaf links: {listed(leaves) or 'none'})",
                         parameter="tool")
    return leaves[0]
