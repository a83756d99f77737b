#!/usr/bin/env python3
"""Rewrite the README's quoted outputs (``<!-- test: prints -->`` and ``<!-- test: output of ... -->``
blocks) with what the commands print now, for the blocks tests/test_readme.py finds out of date.

Runs every marked block as the README test does (its own machinery, imported from tests/), and for
each quoted block whose lines no longer appear: finds where its first line's words (the text before
the first figure) start in the new output and quotes as many lines from there. Look at the diff
before committing: the figures are the code's, the README's sentences around them are not.

usage: python scripts/update_readme_outputs.py [--dry-run]
"""

from __future__ import annotations

import re
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))

import test_readme as machinery  # noqa: E402  (the README test's own block reader and runner)


def _stem(line: str) -> str:
    """The words of a line before its first figure (what stays when figures change)."""
    match = re.search(r"[-+]?\d", line)
    return (line[:match.start()] if match else line).rstrip()


def _shape(line: str) -> str:
    """A line with every figure replaced by one mark (what stays when figures change)."""
    return re.sub(r"[-+]?\d[\d.,]*(?:e[-+]?\d+)?", "#", line)


def _replacement(expected: list[str], printed: list[str]) -> list[str] | None:
    if not expected:
        return None
    for start, line in enumerate(printed):  # the same line with other figures
        if _shape(line) == _shape(expected[0]):
            return printed[start:start + len(expected)]
    stem = _stem(expected[0])
    for start, line in enumerate(printed):  # else the same words before the first figure
        if stem.strip() and line.startswith(stem):
            return printed[start:start + len(expected)]
    return None


def main() -> int:
    dry = "--dry-run" in sys.argv
    readme = machinery.README.read_text(encoding="utf-8").splitlines()
    blocks = machinery.readme_blocks()
    quoted = [b for b in blocks if b.kind in ("prints", "output")]
    runs = {}
    with tempfile.TemporaryDirectory() as tmp:
        for b in blocks:
            if b.kind in ("runs", "output"):
                runs[b.line] = machinery._execute(b, Path(tmp) / f"line{b.line}")
    edits = []
    for b in quoted:
        run = runs[b.source or b.line]
        expected, printed = machinery._lines(b.text), machinery._lines(run.stdout)
        if machinery._contains_in_order(expected, printed):
            continue
        new = _replacement(expected, printed)
        if new is None:
            print(f"README.md:{b.line}: no line of the new output starts like {expected[0]!r}; edit it by hand")
            continue
        edits.append((b.line, len(expected), new))
        print(f"README.md:{b.line}: {len(expected)} lines re-quoted")
    for line, count, new in sorted(edits, reverse=True):  # the marker is at line; the text starts 2 lines below
        start = line + 1
        readme[start:start + count] = new
    if edits and not dry:
        machinery.README.write_text("\n".join(readme) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
