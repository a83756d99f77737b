"""Where a URDF's mesh names point: ``package://NAME/...`` in ROS package folders, relative
names beside the URDF, ``file://`` and absolute paths as written.

A ROS package is a folder holding a ``package.xml`` whose ``<name>`` names it. Packages are
looked for, in this order, in the folders given with ``--package-dir`` (:func:`package_dirs_given`),
in the entries of the ``ROS_PACKAGE_PATH`` environment variable, and in the robot's own folders
(the URDF's folder and the ones above it). Each of the first two may be a package folder
itself, a folder ``DIR`` with the package at ``DIR/NAME`` (with or without ``package.xml``,
as Pinocchio's ``package_dirs`` are read), or a folder with packages further below it, found
by their ``package.xml`` up to :data:`MAX_SEARCH_DEPTH` folders down, as ROS does.

Hand-written because neither Pinocchio nor yourdfpy finds a package by its manifest:
Pinocchio's ``package_dirs`` only try ``DIR/NAME`` and yourdfpy's ``filename_handler`` leaves
the search to its caller. Model layer; nothing here reads a mesh.
"""

from __future__ import annotations

import os
import re
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field
from pathlib import Path
from xml.etree import ElementTree

from ..exceptions import InputError
from ..input_files import SIZE_LIMITS, read_input_bytes
from .urdf import one_line

#: The file that makes a folder a ROS package.
PACKAGE_MANIFEST = "package.xml"
#: How many folders below a --package-dir or ROS_PACKAGE_PATH entry are searched for packages.
MAX_SEARCH_DEPTH = 5
#: At most this many folders are opened in one search (ROS_PACKAGE_PATH=/ must not crawl a disk).
MAX_SEARCH_FOLDERS = 20000
#: Files that tell ROS's tools to skip a folder and everything below it.
_IGNORE_MARKERS = ("CATKIN_IGNORE", "COLCON_IGNORE", "AMENT_IGNORE")
_MANIFEST_NAME = re.compile(rb"<name>\s*([^<\s]+)\s*</name>")

#: The folders given with --package-dir for the run (set by the command line, read by load_robot).
_GIVEN_DIRS: ContextVar[tuple[str, ...]] = ContextVar("package_dirs_given", default=())


@contextmanager
def package_dirs_given(dirs):
    """Within the block, :func:`tcr_accuracy.model.robot.load_robot` also looks for ROS packages
    in ``dirs`` (``--package-dir``), before ``ROS_PACKAGE_PATH``."""
    token = _GIVEN_DIRS.set(tuple(str(d) for d in dirs or ()))
    try:
        yield
    finally:
        _GIVEN_DIRS.reset(token)


def given_package_dirs() -> list[str]:
    """The folders of :func:`package_dirs_given` in force (empty outside it)."""
    return list(_GIVEN_DIRS.get())


def ros_package_path() -> list[str]:
    """The entries of ``ROS_PACKAGE_PATH`` (colon-separated; empty entries dropped)."""
    return [entry for entry in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep) if entry]


def package_name(folder: Path) -> str | None:
    """The ``<name>`` of ``folder/package.xml`` (its folder's name when the file says none), or
    None when the folder holds no ``package.xml``. Read with a pattern, not an XML parser: only
    the name is wanted and a manifest may declare entities."""
    manifest = folder / PACKAGE_MANIFEST
    if not manifest.is_file():
        return None
    try:
        head = read_input_bytes(manifest, "package manifest", limit=SIZE_LIMITS["urdf"])[:65536]
    except InputError:  # a pipe or device named package.xml, or unreadable: the folder's name
        return folder.name
    match = _MANIFEST_NAME.search(head)
    return match.group(1).decode("utf-8", "replace") if match else folder.name


def packages_below(folder: Path, wanted: set[str]) -> dict[str, Path]:
    """The packages named in ``wanted`` at or below ``folder`` (a package's own subfolders are
    not searched, nor hidden folders or those marked ``CATKIN_IGNORE``/``COLCON_IGNORE``/
    ``AMENT_IGNORE``), breadth first, at most :data:`MAX_SEARCH_DEPTH` folders down; the first
    found of a name wins. Links to folders are not followed (``--package-dir /`` would otherwise
    walk ``/proc/*/cwd`` and loops), and a folder that cannot be read is passed over."""
    found: dict[str, Path] = {}
    level, opened = [folder], 0
    for _ in range(MAX_SEARCH_DEPTH + 1):
        below = []
        for current in level:
            try:
                name = package_name(current)
                if name is not None:
                    if name in wanted:
                        found.setdefault(name, current)
                    continue
                opened += 1
                if opened > MAX_SEARCH_FOLDERS or any((current / m).exists() for m in _IGNORE_MARKERS):
                    continue
                entries = sorted(os.scandir(current), key=lambda e: e.name)
                below += [Path(e.path) for e in entries
                          if not e.name.startswith(".") and e.is_dir(follow_symlinks=False)]
            except OSError:  # no permission (/proc/1/cwd), gone meanwhile
                continue
        if wanted <= found.keys() or not below:
            break
        level = below
    return found


def find_packages(names, search_dirs, urdf_folder: Path | None) -> dict[str, Path]:
    """The folder of each package in ``names`` that can be found (the others are left out).

    Parameters
    ----------
    names : iterable of str
        Package names a URDF uses (``package://NAME/...``).
    search_dirs : list of str or Path
        ``--package-dir`` folders, then ``ROS_PACKAGE_PATH`` entries, in order: each a package,
        a folder with ``DIR/NAME``, or a folder with packages below it.
    urdf_folder : Path, optional
        The URDF's folder: a package it lies in (``package.xml`` in it or up to three folders
        above, or a folder of that name) is found last.
    """
    wanted = {n for n in names if n and n not in (".", "..")}
    found: dict[str, Path] = {}
    for folder in (Path(d) for d in search_dirs):
        missing = wanted - found.keys()
        if not missing:
            break
        if not folder.is_dir():
            continue
        own = package_name(folder) or folder.name  # the folder is the package, by manifest or name
        for name in sorted(missing):
            if own == name:
                found[name] = folder
            elif (folder / name).is_dir():
                found[name] = folder / name
        if wanted - found.keys():
            for name, place in packages_below(folder, wanted - found.keys()).items():
                found.setdefault(name, place)
    if urdf_folder is not None:
        for folder in [urdf_folder, *list(urdf_folder.parents)[:3]]:
            name = package_name(folder) or folder.name
            if name in wanted:
                found.setdefault(name, folder)
    return found


@dataclass(frozen=True)
class MeshPlace:
    """Where one ``<mesh filename=...>`` of a URDF points.

    Attributes
    ----------
    link : str
        The link whose ``<visual>`` or ``<collision>`` holds it.
    kind : {"visual", "collision"}
    name : str
        The file name as written in the URDF.
    candidates : list of Path
        Every place it could be read from, in the order they are tried.
    path : Path or None
        The first candidate that is a file; None: the mesh is missing.
    package : str or None
        The package a ``package://`` name points into.
    """

    link: str
    kind: str
    name: str
    candidates: list = field(default_factory=list)
    path: Path | None = None
    package: str | None = None


def package_of(name: str) -> str | None:
    """``NAME`` of ``package://NAME/...`` (None for another kind of file name)."""
    if not name.startswith("package://"):
        return None
    return name[len("package://"):].split("/", 1)[0]


def mesh_places(root: ElementTree.Element, kinds, urdf_folder: Path | None, search_dirs,
                packages: dict) -> list[MeshPlace]:
    """Where every mesh of the ``<visual>`` and/or ``<collision>`` elements (``kinds``) points.

    A ``package://NAME/rest`` name is ``packages[NAME]/rest`` for a package found, else
    ``DIR/NAME/rest`` for each of ``search_dirs``; a relative name is looked for in the URDF's
    folder, then in each of ``search_dirs``; ``file://`` and absolute names stand as written.
    Paths are normalised (``..`` folded) but not resolved: the caller checks where they lead.
    """
    searched = ([urdf_folder] if urdf_folder is not None else []) + [Path(d) for d in search_dirs]
    places = []
    for link in root.findall("link"):
        for kind in kinds:
            for element in link.findall(kind):
                for mesh in element.iter("mesh"):
                    name = mesh.get("filename") or ""
                    package = package_of(name)
                    if package is not None:
                        rest = name[len("package://") + len(package) + 1:]
                        folders = [Path(packages[package])] if package in packages else \
                            [Path(d) / package for d in search_dirs]
                        candidates = [f / rest for f in folders]
                    elif name.startswith("file://") or Path(name).is_absolute():
                        candidates = [Path(name.removeprefix("file://"))]
                    else:
                        candidates = [folder / name for folder in searched]
                    candidates = [Path(os.path.normpath(c)) for c in candidates]
                    path = next((c for c in candidates if c.is_file()), None)
                    places.append(MeshPlace(link.get("name") or "", kind, name, candidates, path, package))
    return places


def urdf_with_located_meshes(root: ElementTree.Element, kind: str, places: list[MeshPlace]) -> str:
    """The URDF's text with every ``<kind>`` mesh name replaced by the file it was found at
    (``places``, from :func:`mesh_places` on the same tree with ``kinds=(kind,)``) and every
    ``<kind>`` element whose mesh is missing left out, for Pinocchio's geometry parser, which
    stops at the first mesh it cannot find; ``root`` is not changed."""
    import copy

    root = copy.deepcopy(root)
    remaining = iter(places)
    for link in root.findall("link"):
        for element in link.findall(kind):
            keep = True
            for mesh in element.iter("mesh"):
                place = next(remaining)
                if place.path is None:
                    keep = False
                else:
                    mesh.set("filename", str(place.path))
            if not keep:
                link.remove(element)
    return ElementTree.tostring(root, encoding="unicode")


def missing_mesh_message(source: str, missing: list[MeshPlace], packages: dict) -> str:
    """One line saying which meshes are missing, what the run does without them, and how to
    provide them (``--package-dir`` or ``ROS_PACKAGE_PATH``)."""
    names = list(dict.fromkeys(p.name for p in missing))
    links = list(dict.fromkeys(p.link for p in missing))
    shown = ", ".join(repr(n) for n in names[:3]) + (f" and {len(names) - 3} more" if len(names) > 3 else "")
    unfound = sorted({p.package for p in missing if p.package is not None and p.package not in packages})
    found = sorted({p.package for p in missing if p.package in packages})
    if unfound:
        why = f"ROS package{_s(unfound)} {', '.join(repr(n) for n in unfound)} not found"
    elif found:
        why = f"not in package {', '.join(f'{n!r} ({packages[n]})' for n in found)}"
    else:
        why = "not beside the URDF"
    links_shown = ", ".join(links[:5]) + (" ..." if len(links) > 5 else "")
    return one_line(f"{source}: {len(names)} mesh file{_s(names)} missing ({shown}): {why}; give the package's "
                    "folder with package_dirs=DIR or in ROS_PACKAGE_PATH; 3D views draw "
                    f"link{_s(links)} {links_shown} as a skeleton and collision checks leave "
                    f"{'them' if len(links) > 1 else 'it'} out", 800)


def _s(items) -> str:
    """The plural ending for a count of ``items``."""
    return "s" if len(items) > 1 else ""
