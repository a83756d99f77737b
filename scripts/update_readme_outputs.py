#!/usr/bin/env python3
"""Rewrite the quoted outputs (``<!-- test: prints -->`` and ``<!-- test: output of ... -->`` blocks) of
README.md and every docs/*.md page with what the commands print now, for the blocks
tests/test_readme.py finds out of date.

Runs every marked block of every page as the README test does (its own machinery, imported from
tests/; two at a time), and for each quoted block whose lines no longer appear: finds where its first line's words (the text before
the first figure) start in the new output and quotes as many lines from there. Look at the diff
before committing: the figures are the code's, the README's sentences around them are not.

usage: python scripts/update_readme_outputs.py [--dry-run] [PAGE.md ...]   (default: every page)
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
    args = [a for a in sys.argv[1:] if a != "--dry-run"]
    dry = "--dry-run" in sys.argv
    pages = [Path(a).resolve() for a in args] if args else machinery.PAGES
    blocks = [b for page in pages for b in machinery.readme_blocks(page)]
    with tempfile.TemporaryDirectory() as tmp:
        runs = machinery.run_blocks(blocks, Path(tmp))
    for b in blocks:  # a block that fails is the page's to mend, not a quote to re-take
        if b.key in runs and runs[b.key].returncode != 0:
            print(f"{b.where}: the block exits {runs[b.key].returncode}: {runs[b.key].stderr.strip()[-300:]}")
    edits: dict[Path, list] = {}
    for b in blocks:
        if b.kind not in ("prints", "output"):
            continue
        run = runs[b.source_key]
        expected, printed = machinery._lines(b.text), machinery._lines(run.stdout)
        if machinery._contains_in_order(expected, printed):
            continue
        new = _replacement(expected, printed)
        if new is None:
            print(f"{b.where}: no line of the new output starts like {expected[0]!r}; edit it by hand")
            continue
        edits.setdefault(b.page, []).append((b.line, len(expected), new))
        print(f"{b.where}: {len(expected)} lines re-quoted")
    for page, page_edits in edits.items():
        text = page.read_text(encoding="utf-8").splitlines()
        for line, count, new in sorted(page_edits, reverse=True):  # the marker is at line; the text 2 lines below
            start = line + 1
            text[start:start + count] = new
        if not dry:
            page.write_text("\n".join(text) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
