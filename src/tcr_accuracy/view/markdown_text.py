"""Text from results and the command line made safe inside Markdown.

A report's ``report.md`` holds strings that came from outside: JSON results (notes, labels,
file names), ``--title``, session labels, the command as typed. Many Markdown renderers pass raw
HTML through, so ``<script>`` in a note would run where the page is shown (``index.html``
escapes the same strings), and Markdown's own syntax is as live: ``![x](https://...)`` in a
result's file name is a remote image when rendered, ``[x](javascript:...)`` a link. Text is
shown as ``index.html`` shows it, as text: ``<``, ``>`` and ``&`` become entities, every
character that opens Markdown inline syntax is escaped with a backslash (CommonMark escapes any
ASCII punctuation so: ``[ ] ! * ` ~ |`` and the backslash, an ``_`` that is not inside a word), as is what a
renderer would turn into a link by itself (the ``:`` of ``https://``, the ``.`` of ``www.``, an
``@``) and a line start that opens a block (``#``, ``-``, ``+``, ``=``, ``1.``); link targets are
percent-encoded, and code is fenced by more backticks than it holds, so no string can close its
fence and leave code.
"""

from __future__ import annotations

import html
import re
from urllib.parse import quote


#: What opens Markdown inline syntax (links, images, emphasis, code, strikethrough, tables, escapes)
#: or an automatic link (GFM's ``https://``, ``www.``, ``a@b.c``), each escaped with a backslash.
_INLINE = re.compile(r"[\\`*\[\]!~|@]|(?<![0-9A-Za-z])_|_(?![0-9A-Za-z])|:(?=//)|(?<=[wW]{3})\.")
#: A line start that opens a block: a heading, a list item, a setext underline.
#: (CommonMark: a marker then a space or the line's end; a line of ``=`` or ``-`` alone)
_BLOCK_START = re.compile(r"^( {0,3})(?:(#{1,6}|[+-])(?=[ \t]|$)|(\d{1,9})([.)])(?=[ \t]|$)|([=-])(?=[=-]*[ \t]*$))",
                          re.MULTILINE)


def text(value) -> str:
    """Paragraph text shown as text (line breaks kept): no raw HTML, no Markdown syntax."""
    escaped = _INLINE.sub(lambda m: "\\" + m.group(0), html.escape(str(value), quote=False))
    return _BLOCK_START.sub(lambda m: m.group(1) + (m.group(3) + "\\" + m.group(4) if m.group(3) else
                                                    "\\" + (m.group(2) or m.group(5))), escaped)


def line(value) -> str:
    """One line of text (a heading, a list item): :func:`text` with line breaks as spaces."""
    return text(re.sub(r"\s+", " ", str(value)))


def cell(value) -> str:
    """A pipe-table cell (its ``|`` escaped, as everywhere)."""
    return line(value)


def label(value) -> str:
    """A link's or an image's text (its ``[`` and ``]`` escaped, as everywhere)."""
    return line(value)


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
