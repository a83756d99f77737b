"""URDF text to Pinocchio: reading it safely, frames by name and type, reducing a tree to a chain.

Model layer, under :mod:`tcr_accuracy.model.robot`. URDF lets a link and a joint share a name and
Pinocchio's model reduction looks frames up by name alone, so both are handled here once.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path
from xml.etree import ElementTree

import numpy as np
import pinocchio as pin

from ..exceptions import InputError
from ..units import PRISMATIC, REVOLUTE


_ENTITY = re.compile(r"<!\s*(ENTITY|DOCTYPE)", re.IGNORECASE)
MAX_URDF_BYTES = 50 * 1024 * 1024


def read_urdf_text(path: Path) -> str:
    """Read a URDF file, refusing DTDs and entities (no entity expansion, ever)."""
    try:
        size = path.stat().st_size
    except OSError as exc:
        raise InputError(f"{path}: cannot read URDF ({exc.strerror})") from None
    if size > MAX_URDF_BYTES:
        raise InputError(f"{path}: URDF is {size} bytes, larger than the {MAX_URDF_BYTES} allowed")
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read URDF as UTF-8 text ({exc})") from None
    return text


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
        raise InputError(f"{source}: URDF does not parse as XML ({exc})") from None
    if root.tag != "robot":
        raise InputError(f"{source}: root element is <{root.tag}>, a URDF needs <robot>")
    return root


@dataclass(frozen=True)
class Mimic:
    """A URDF ``<mimic>`` rule: ``q = multiplier * q[joint] + offset`` [SI]."""

    joint: str
    multiplier: float = 1.0
    offset: float = 0.0


def mimic_rules(root: ElementTree.Element, source: str) -> dict:
    """URDF ``<mimic joint=... multiplier=... offset=...>`` rules by joint name."""
    rules = {}
    for joint in root.findall("joint"):
        mimic = joint.find("mimic")
        if mimic is None:
            continue
        try:
            rule = Mimic(mimic.get("joint", ""), float(mimic.get("multiplier", 1.0)), float(mimic.get("offset", 0.0)))
        except ValueError:
            raise InputError(f"{source}: joint {joint.get('name')}: <mimic> multiplier/offset is not a number") \
                from None
        if not (math.isfinite(rule.multiplier) and math.isfinite(rule.offset)) or not rule.joint:
            raise InputError(f"{source}: joint {joint.get('name')}: <mimic> needs a joint and finite numbers")
        rules[joint.get("name")] = rule
    return rules


_REVOLUTE_JOINT = re.compile(r"JointModel(R[XYZ]|RUB[XYZ]|RevoluteUnaligned|RevoluteUnboundedUnaligned)$")
_PRISMATIC_JOINT = re.compile(r"JointModel(P[XYZ]|PrismaticUnaligned)$")


def joint_kind(joint: pin.JointModel) -> str:
    short = joint.shortname()
    if _REVOLUTE_JOINT.match(short):
        return REVOLUTE
    if _PRISMATIC_JOINT.match(short):
        return PRISMATIC
    raise InputError(
        f"joint type {short} is not supported: tcr-accuracy handles serial chains of "
        "revolute, continuous and prismatic joints"
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
        raise InputError(f"--tool {name}: no such frame in {source} (frames: {', '.join(names)})")
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
        raise InputError(
            f"{source}: give the TCP frame with --tool (leaf links: {', '.join(leaves) or 'none'})"
        )
    return leaves[0]
