"""The files a mesh pulls in, confined like the mesh itself.

A COLLADA file names images (``<init_from>``), an OBJ names material libraries (``mtllib``)
and those name texture maps (``map_Kd``, ``bump``, ...). A viewer reads such files and embeds
them in its page, so each one must lie inside the folders the URDF may read from (its own
folder and the package folders), as its meshes must: otherwise a URDF could carry
``/etc/passwd`` into a report. Only the formats whose references are known here are drawn.

Model layer, beside :mod:`tcr_accuracy.model.urdf` (which confines the mesh files).
"""

from __future__ import annotations

import re
from pathlib import Path
from urllib.parse import unquote
from xml.etree import ElementTree

from ..exceptions import InputError
from ..input_files import SIZE_LIMITS, read_input_bytes
from .urdf import one_line

#: Mesh formats a view draws, each with the references it can make (read by ``mesh_references``).
DRAWN_FORMATS = (".dae", ".obj", ".stl")

_DTD = re.compile(rb"<!\s*(ENTITY|DOCTYPE)", re.IGNORECASE)
_SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]*:")
#: Material-library statements that name a file besides ``map_*`` (options come before the name).
_MTL_FILE_KEYS = ("bump", "disp", "decal", "refl", "norm")
_MAP_OPTIONS = {"-blendu", "-blendv", "-bm", "-boost", "-cc", "-clamp", "-imfchan", "-mm", "-o", "-s", "-t",
                "-texres", "-type"}


def inside(path: Path, roots: list[Path]) -> bool:
    """Whether ``path`` (resolved, symlinks followed) lies in one of the resolved ``roots``."""
    path = path.resolve()
    return any(path == r or r in path.parents for r in roots)


def mesh_references(mesh: Path, source: str) -> list[tuple[str, Path]]:
    """Every file ``mesh`` names, as (name as written, path it resolves to).

    A COLLADA file's ``<init_from>`` names (images), an OBJ's ``mtllib`` names and, for
    each of those that is a file, its texture maps. A name resolves against the mesh's folder;
    ``file://`` is dropped and percent escapes are decoded, as a browser would.

    Raises
    ------
    InputError
        A COLLADA file that does not parse or declares a DTD (``source`` names the URDF).
    """
    suffix = mesh.suffix.lower()
    if suffix == ".dae":
        return [(name, _resolve(name, mesh.parent)) for name in _dae_image_names(mesh, source)]
    if suffix == ".obj":
        found = []
        for name in _statements(mesh, ("mtllib", "call", "maplib"), source):
            library = _resolve(name, mesh.parent)
            found.append((name, library))
            if library.suffix.lower() == ".mtl" and library.is_file():
                found += [(n, _resolve(n, library.parent))
                          for n in _statements(library, _MTL_FILE_KEYS, source, maps=True)]
        return found
    return []


def check_mesh_references(mesh: Path, roots: list, source: str, mesh_name: str) -> list[tuple[str, Path]]:
    """The files ``mesh`` references, each checked to lie inside ``roots``.

    Raises
    ------
    InputError
        A mesh format no view can draw (its references are unknown), a referenced file
        outside the roots, or a name that is a URL; one line naming the URDF (``source``),
        the mesh and the file.
    """
    roots = [Path(r).resolve() for r in roots]
    if mesh.suffix.lower() not in DRAWN_FORMATS:
        raise InputError(f"{source}: mesh {one_line(mesh_name, 120)!r}: format {one_line(mesh.suffix, 20)!r} "
                         f"is not drawn (only {', '.join(DRAWN_FORMATS)}, whose referenced files can be checked)")
    references = mesh_references(mesh, source)
    for name, path in references:
        if _SCHEME.match(name) and not name.lower().startswith("file:"):
            raise InputError(f"{source}: mesh {one_line(mesh_name, 120)!r} references {one_line(name, 120)!r}, "
                             "a URL; only files beside the URDF are read")
        if not inside(path, roots):
            folders = ", ".join(str(r) for r in roots) or "none: this URDF has no folder"
            raise InputError(f"{source}: mesh {one_line(mesh_name, 120)!r} references {one_line(name, 120)!r}, "
                             f"which lies outside the URDF's folder and package folders "
                             f"({one_line(folders, 200)}); refused")
    return references


def _resolve(name: str, folder: Path) -> Path:
    name = unquote(name)
    if name.lower().startswith("file://"):
        name = name[len("file://"):]
    elif name.lower().startswith("file:"):
        name = name[len("file:"):]
    return (folder / name) if not Path(name).is_absolute() else Path(name)


def _dae_image_names(mesh: Path, source: str) -> list[str]:
    """The text of every ``<init_from>`` (COLLADA 1.4) and ``<init_from><ref>`` (1.5) in the file."""
    try:
        data = read_input_bytes(mesh, "mesh", limit=SIZE_LIMITS["mesh"])
    except InputError as exc:
        raise InputError(f"{source}: mesh {exc}") from None
    if _DTD.search(data):
        raise InputError(f"{source}: mesh {mesh} declares a DTD or entity; entity expansion is refused")
    try:
        root = ElementTree.fromstring(data)
    except ElementTree.ParseError as exc:
        raise InputError(f"{source}: mesh {mesh} does not parse as COLLADA XML ({one_line(exc)})") from None
    names = []
    for element in root.iter():
        if element.tag.rpartition("}")[2] in ("init_from", "ref") and (element.text or "").strip():
            names.append(element.text.strip())
    return names


def _statements(path: Path, keys: tuple[str, ...], source: str, maps: bool = False) -> list[str]:
    """The file names on the lines of an OBJ or MTL file that start with one of ``keys`` (and,
    with ``maps``, with ``map_``): the rest of the line as one name, and each word in it that
    is not a map option or a number, so that no name slips through however it is written."""
    names = []
    try:
        lines = read_input_bytes(path, "mesh file", limit=SIZE_LIMITS["mesh"]).splitlines()
    except InputError as exc:
        raise InputError(f"{source}: mesh file {exc}") from None
    for raw in lines:
        key, *rest = raw.decode("latin-1").strip().split(None, 1) or [""]
        key, rest = key.lower(), " ".join(rest)
        if not rest.strip() or not (key in keys or (maps and key.startswith("map_"))):
            continue
        names.append(rest.strip())
        names += [w for w in rest.split() if w.lower() not in _MAP_OPTIONS and not _is_number(w)]
    return names


def _is_number(word: str) -> bool:
    try:
        float(word)
    except ValueError:
        return False
    return True
