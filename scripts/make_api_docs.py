#!/usr/bin/env python3
"""Write docs/api.md, the reference of the names ``import tcr_accuracy`` exports, from their
numpydoc docstrings.

    python scripts/make_api_docs.py            # writes docs/api.md
    python scripts/make_api_docs.py --check    # exit 1 if docs/api.md is not current

tests/test_api_docs.py runs the check, so the page always says what the code does. Only the
standard library's ``inspect`` reads the docstrings: the numpydoc sections (Parameters,
Returns, Attributes, Examples, ...) are turned into Markdown by :func:`render_docstring`,
hand-written because numpydoc and Sphinx render to reStructuredText/HTML, not to one
Markdown page, and would be heavy dependencies for that.
"""

from __future__ import annotations

import argparse
import inspect
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "api.md"

#: numpydoc section titles, in the order numpydoc lists them
SECTIONS = ("Parameters", "Attributes", "Returns", "Yields", "Raises", "Warns", "See Also", "Notes",
            "References", "Examples", "Methods")

#: the layer each exported module belongs to, in the order the page lists them
LAYER_TITLES = {"model": "Robot, error model, kinematics", "io": "Measurements", "effects": "Effects",
                "frames": "Measurement frames", "analysis": "Monte Carlo and simulation", "diagnosis": "Diagnosis",
                "prediction": "Prediction and compensation", "asbuilt": "As-built model and export",
                "iso9283": "ISO 9283", "results": "Result files", "view": "Reports and viewer",
                "cli": "Files written (the command line's one writer)", "exceptions": "Errors"}




def split_sections(doc: str) -> tuple[str, dict[str, str]]:
    """A docstring's summary text and its numpydoc sections (title -> body, dedented).

    Parameters
    ----------
    doc : str
        A cleaned docstring (:func:`inspect.cleandoc`).

    Returns
    -------
    tuple of (str, dict)
        The text before the first section, and every section's body by title.
    """
    lines = doc.splitlines()
    head, sections, current = [], {}, None
    i = 0
    while i < len(lines):
        line = lines[i]
        title = line.strip()
        if (title in SECTIONS and i + 1 < len(lines) and set(lines[i + 1].strip()) == {"-"}
                and len(lines[i + 1].strip()) == len(title)):
            current = title
            sections[current] = []
            i += 2
            continue
        (head if current is None else sections[current]).append(line)
        i += 1
    return "\n".join(head).strip(), {k: "\n".join(v).strip("\n") for k, v in sections.items()}


def documented_names(section: str) -> list[str]:
    """The names a Parameters/Attributes section documents ("a, b : float" documents a and b).

    Parameters
    ----------
    section : str
        The section's body.

    Returns
    -------
    list of str
        Names in order, ``*`` and ``**`` stripped.
    """
    names = []
    for line in section.splitlines():
        if not line or line[0].isspace():
            continue
        match = re.match(r"^\s*([*\w]+(?:\s*,\s*[*\w]+)*)\s*(?::|$)", line)
        if match:
            names += [n.strip().lstrip("*") for n in match.group(1).split(",")]
    return names


def _render_items(body: str) -> list[str]:
    """"name : type" lines as bullets, their indented descriptions joined after them."""
    out = []
    for line in body.splitlines():
        if not line.strip():
            continue
        if not line[0].isspace():
            name, _, kind = line.partition(" : ")
            out.append(f"- **{name.strip()}**" + (f" : *{kind.strip()}*" if kind else ""))
        else:
            out[-1] = (out[-1] + (" —" if out[-1].endswith("*") or out[-1].endswith("**") else "")
                       + " " + line.strip()) if out else line.strip()
    return out


def render_docstring(doc: str, level: int = 4) -> list[str]:
    """A numpydoc docstring as Markdown lines.

    Parameters
    ----------
    doc : str
        The cleaned docstring.
    level : int, default=4
        Heading level of the sections.

    Returns
    -------
    list of str
        Markdown lines.
    """
    summary, sections = split_sections(doc)
    out = [summary, ""] if summary else []
    for title, body in sections.items():
        out += [f"{'#' * level} {title}", ""]
        if title in ("Parameters", "Attributes", "Returns", "Yields", "Raises", "Warns"):
            out += _render_items(body)
        elif title == "Examples":
            out += ["```python", *(line for line in body.splitlines()), "```"]
        else:
            out.append(body)
        out.append("")
    return out


class _Written(str):
    """An annotation as the source writes it (``from __future__ import annotations`` keeps
    them as strings, which inspect would print quoted)."""

    def __repr__(self) -> str:
        return str(self)


def _signature(name: str, obj) -> str:
    try:
        sig = inspect.signature(obj)
    except (TypeError, ValueError):
        return name

    def plain(annotation):
        return _Written(annotation) if isinstance(annotation, str) else annotation

    sig = sig.replace(parameters=[p.replace(annotation=plain(p.annotation)) for p in sig.parameters.values()],
                      return_annotation=plain(sig.return_annotation))
    return f"{name}{sig}"


def _public_methods(cls) -> list[tuple[str, object]]:
    """Methods and properties the package defines on a class (not those of object, dataclasses
    or scikit-learn's BaseEstimator), in source order."""
    out = []
    for klass in cls.__mro__:
        if not klass.__module__.startswith("tcr_accuracy"):
            continue
        for attr, value in vars(klass).items():
            if attr.startswith("_") or attr in dict(out) or not (callable(value) or isinstance(value, property)):
                continue
            out.append((attr, value))
    return out


def render_api() -> str:
    """The Markdown of docs/api.md.

    Returns
    -------
    str
        The page, ending in a newline.
    """
    import tcr_accuracy

    lines = ["# Python API reference", "",
             "Generated from the docstrings by `python scripts/make_api_docs.py`; do not edit by hand "
             "(tests/test_api_docs.py fails when this page and the code disagree).", "",
             "Every name below is importable from the package root (`import tcr_accuracy as tcr`). "
             "SI units throughout (m, rad, kg, N); randomness through `random_state` (an int, a "
             "`numpy.random.Generator` or None).", ""]
    by_layer: dict[str, list[str]] = {}
    for name, module in tcr_accuracy._EXPORTS.items():
        by_layer.setdefault(module.split(".")[0], []).append(name)
    lines += ["## Contents", ""]
    for layer, names in by_layer.items():
        lines.append(f"- {LAYER_TITLES[layer]}: " + ", ".join(f"[`{n}`](#{n.lower()})" for n in names))
    lines.append("")
    for layer, names in by_layer.items():
        lines += [f"## {LAYER_TITLES[layer]}", ""]
        for name in names:
            obj = getattr(tcr_accuracy, name)
            kind = "class" if inspect.isclass(obj) else "function"
            lines += [f"### {name}", "", f"*{kind}* `tcr_accuracy.{tcr_accuracy._EXPORTS[name]}.{name}`", "",
                      "```python", _signature(name, obj), "```", ""]
            lines += render_docstring(docstring(name, obj))
            if inspect.isclass(obj):
                methods = _public_methods(obj)
                if methods:
                    lines += ["#### Methods and properties", ""]
                    for attr, value in methods:
                        target = value.fget if isinstance(value, property) else value
                        doc = (inspect.getdoc(target) or "").split("\n\n")[0].replace("\n", " ")
                        shown = attr if isinstance(value, property) else _signature(attr, target)
                        lines.append(f"- `{shown}`" + (f": {doc}" if doc else ""))
                    lines.append("")
    text = "\n".join(lines)
    text = re.sub(r"\n{3,}", "\n\n", text)
    return text.rstrip("\n") + "\n"


def docstring(name: str, obj) -> str:
    """``obj``'s cleaned docstring.

    Parameters
    ----------
    name : str
        Its public name.
    obj : object

    Returns
    -------
    str
    """
    return inspect.getdoc(obj) or ""


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="exit 1 if docs/api.md is not current")
    args = parser.parse_args(argv)
    text = render_api()
    if args.check:
        current = OUT.read_text() if OUT.exists() else ""
        if current != text:
            print(f"{OUT} is not current: run python scripts/make_api_docs.py", file=sys.stderr)
            return 1
        return 0
    OUT.write_text(text)
    print(f"wrote {OUT} ({len(text.splitlines())} lines)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
