"""Text from results and the command line made safe inside Markdown.

A report's ``report.md`` holds strings that came from outside: JSON results (notes, labels,
file names), ``--title``, session labels, the command as typed. Many Markdown renderers pass raw
HTML through, so ``<script>`` in a note would run where the page is shown (``index.html``
escapes the same strings). Here: ``<``, ``>`` and ``&`` become entities in text, table cells
also escape ``|``, link labels ``[`` and ``]``, link targets are percent-encoded, and code is
fenced by more backticks than it holds, so no string can close its fence and leave code.
"""

from __future__ import annotations

import html
import re
from urllib.parse import quote


def text(value) -> str:
    """Paragraph text: raw HTML shown as text (line breaks kept)."""
    return html.escape(str(value), quote=False)


def line(value) -> str:
    """One line of text (a heading, a list item): :func:`text` with line breaks as spaces."""
    return re.sub(r"\s+", " ", text(value))


def cell(value) -> str:
    """A pipe-table cell."""
    return line(value).replace("|", "\\|")


def label(value) -> str:
    """A link's or an image's text."""
    return line(value).replace("[", "\\[").replace("]", "\\]")


def href(value) -> str:
    """A link target (a relative file path): percent-encoded, so that no ``)`` or space ends it early."""
    return quote(str(value), safe="/._-~")


def _fence_for(value: str, least: int) -> str:
    longest = max((len(run) for run in re.findall(r"`+", value)), default=0)
    return "`" * max(least, longest + 1)


def fenced(value) -> list[str]:
    """A fenced code block (its lines shown as they are), as Markdown lines."""
    value = str(value)
    fence = _fence_for(value, 3)
    return [fence, value, fence]


def code(value) -> str:
    """Inline code (shown as it is)."""
    value = re.sub(r"\s+", " ", str(value))
    fence = _fence_for(value, 1)
    pad = " " if value.startswith("`") or value.endswith("`") else ""  # CommonMark strips one each side
    return f"{fence}{pad}{value}{pad}{fence}"
