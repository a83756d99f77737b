"""The calibration report's first page as blocks, rendered to HTML and Markdown.

:mod:`tcr_accuracy.view.calibration_report` says what the page holds as a list of blocks; this
module only lays them out. A block is a tuple whose first item names its kind:

- ``("h1", text)``, ``("h2", text)``: headings;
- ``("p", parts[, css class])``: a paragraph; ``parts`` is a string or a tuple of strings and
  :class:`Code` (a command line shown as code);
- ``("facts", rows)``: the identification table, rows of ``(label, value, label, value)``
  (a value is text or a list of lines);
- ``("table", columns, rows, note, css class)``: a table; a row ``("group", text)`` spans it;
- ``("verdict", status, text)``: the pass/fail line (status ``PASS``, ``FAIL`` or other words);
- ``("list", items)``: a bullet list, each item ``parts`` as for a paragraph;
- ``("links", [(label, href), ...])``: the files;
- ``("signatures", names)``: one column per signer, ``names`` ((role, name or ""), ...).

A list item or a table row may be :class:`Droppable`: :func:`fit_page` leaves such items out,
the last of the last list or table first, until the page's estimated height fits one A4 page, and
says under each list or table what it left out.

Names and paths in tables break after their separators, never mid-word
(:func:`tcr_accuracy.view.html_text.breakable_html`).
"""

from __future__ import annotations

import html
import math
from dataclasses import dataclass

from .html_text import breakable_html


@dataclass(frozen=True)
class Code:
    """A command line shown as code inside a text."""

    text: str


@dataclass(frozen=True)
class Droppable:
    """A list item or table row the first page may leave out for room; ``kind`` and ``name`` say
    what it was in the line that tells ("effect", "joint_offsets"; "check", "")."""

    parts: object
    kind: str
    name: str = ""


def _kept(items) -> list:
    """The items or rows of a list or table as shown (a Droppable one as its content)."""
    return [x.parts if isinstance(x, Droppable) else x for x in items]


def _parts(parts) -> tuple:
    if isinstance(parts, Droppable):
        parts = parts.parts
    return tuple(parts) if isinstance(parts, (list, tuple)) else (parts,)


def _text(parts) -> str:
    return "".join(p.text if isinstance(p, Code) else str(p) for p in _parts(parts))


# ---------------------------------------------------------------------------------------
# Fitting the page: an estimate of its height in lines of body text
# ---------------------------------------------------------------------------------------
#: Characters of body text per line on A4 at the print rules (8.5 pt on 186 mm; measured on
#: the printed pages: 115 to 125), and the lines of this estimate an A4 page holds: 75 lines of
#: 10.4 pt fit its 274 mm, and the estimate counts 4 to 6 % more than Chromium prints (margins
#: that collapse), measured on the printed first pages of a UR5 and of the tool-changer campaign.
CHARS_PER_LINE = 118
PAGE_LINES = 78


def _wrapped(text: str, chars: float) -> int:
    return max(1, math.ceil(len(text) / max(chars, 8)))


def estimated_lines(block) -> float:
    """How many lines of body text ``block`` takes on the printed first page (an estimate)."""
    kind = block[0]
    if kind == "h1":
        return 2.4
    if kind == "h2":
        return 2.0
    if kind == "p":
        return _wrapped(_text(block[1]), CHARS_PER_LINE) + 0.3
    if kind == "verdict":
        return _wrapped("Result: " + block[1] + ": " + _text(block[2]), CHARS_PER_LINE - 6) + 1.3
    if kind == "list":
        return sum(_wrapped(_text(item), CHARS_PER_LINE - 4) for item in block[1]) + 0.5
    if kind == "links":
        return _wrapped("Files: " + "; ".join(label for label, _ in block[1]), CHARS_PER_LINE) + 0.4
    if kind == "signatures":
        return 5.5
    if kind == "facts":  # value columns about 52 % and 28 % of the width; a row with one pair spans it
        lines = 0.0
        for row in block[1]:
            cells = [row[1], row[3]] if all(row[2::2]) else [row[1]]
            shares = (0.48, 0.22) if len(cells) == 2 else (0.85,)
            lines += 0.15 + max(sum(_wrapped(x, CHARS_PER_LINE * share) for x in (c if isinstance(c, list) else [c]))
                                for c, share in zip(cells, shares))
        return lines + 0.5
    if kind == "table":  # a row's text spread over the width, the first column wrapping first
        _, columns, rows, note, _ = block
        # the head wraps its longest name in an even share of the width beyond the first column's
        share = CHARS_PER_LINE * 0.6 / max(len(columns) - 1, 1)
        head = max([1.0] + [_wrapped(str(c), max(share, 8)) for c in columns[1:]])
        lines = 0.3 + head + (_wrapped(note, CHARS_PER_LINE * 1.15) * 0.9 if note else 0.0)
        for row in _kept(rows):
            if len(row) == 2 and row[0] == "group":  # a row spanning the table
                lines += 0.25 + _wrapped(str(row[1]), CHARS_PER_LINE)
                continue
            cells = [str(c) for c in row]
            rest = sum(len(c) + 3 for c in cells[1:])
            lines += 0.25 + max(_wrapped(cells[0], max(CHARS_PER_LINE - rest, 20)), 1)
        return lines
    return 1.0


def fit_page(blocks, lines: float = PAGE_LINES) -> list:
    """``blocks`` with :class:`Droppable` list items and table rows left out, the last of the last
    list or table first, until :func:`estimated_lines` of the whole is at most ``lines``; each list
    or table that lost some says what (they are in the technical detail)."""
    blocks = list(blocks)
    dropped: dict[int, list] = {}
    original = {i: b for i, b in enumerate(blocks)}
    while sum(estimated_lines(b) for b in blocks) > lines:
        where = next((i for i in reversed(range(len(blocks))) if blocks[i][0] in ("list", "table")
                      and any(isinstance(x, Droppable) for x in _items(blocks[i]))), None)
        if where is None:
            break
        items = [x for x in _items(blocks[where]) if not isinstance(x, _LeftOut)]
        last = max(k for k, x in enumerate(items) if isinstance(x, Droppable))
        dropped.setdefault(where, []).insert(0, items.pop(last))
        note = _LeftOut("Left out here for room, in the technical detail: " + _summary(dropped[where]) + ".")
        block = original[where]
        if block[0] == "list":
            blocks[where] = ("list", [*items, note])
        else:
            blocks[where] = ("table", block[1], items, (block[3] + " " if block[3] else "") + note, block[4])
    return blocks


def _items(block) -> list:
    return block[1] if block[0] == "list" else block[2]


def _summary(dropped) -> str:
    """"effects joint_offsets, drift; 7 checks": what was left out, by kind."""
    parts = []
    for kind in dict.fromkeys(x.kind for x in dropped):
        names = [x.name for x in dropped if x.kind == kind]
        parts.append(f"{kind}{'s' if len(names) > 1 else ''} {', '.join(names)}" if all(names) and len(names) <= 4
                     else f"{len(names)} {kind}{'s' if len(names) > 1 else ''}")
    return "; ".join(parts)


class _LeftOut(str):
    """The line that names what :func:`fit_page` left out of a list."""

    left_out = True


def _inline_html(parts) -> str:
    return "".join(f'<code class="command">{html.escape(p.text)}</code>' if isinstance(p, Code) else
                   breakable_html(str(p)) for p in _parts(parts))


def _inline_md(parts) -> str:
    from . import markdown_text as md

    return "".join(md.code(p.text) if isinstance(p, Code) else md.line(p) for p in _parts(parts))


def _cell(value) -> str:
    return "<br>".join(breakable_html(x) for x in value) if isinstance(value, list) else breakable_html(str(value))


def to_html(blocks) -> str:
    """The blocks as an HTML fragment (the inside of the first page's ``<section>``)."""
    esc = html.escape
    out = []
    for block in blocks:
        kind = block[0]
        if kind in ("h1", "h2"):
            out.append(f"<{kind}>{esc(block[1])}</{kind}>")
        elif kind == "p":
            cls = f' class="{block[2]}"' if len(block) > 2 else ""
            out.append(f"<p{cls}>{_inline_html(block[1])}</p>")
        elif kind == "facts":  # a row without its second pair spans the table
            rows = "".join("<tr>" + "".join(f"<th>{esc(row[i])}</th><td>{_cell(row[i + 1])}</td>"
                                            for i in range(0, len(row), 2) if row[i]) + "</tr>"
                           if all(row[2::2]) else
                           f'<tr><th>{esc(row[0])}</th><td class="wide" colspan="{len(row) - 1}">{_cell(row[1])}</td></tr>'
                           for row in block[1])
            out.append(f'<table class="facts"><tbody>{rows}</tbody></table>')
        elif kind == "table":
            _, columns, rows, note, cls = block
            head = "".join(f"<th>{breakable_html(c)}</th>" for c in columns)
            body = []
            for row in _kept(rows):
                if row[0] == "group":
                    body.append(f'<tr class="group"><td class="text" colspan="{len(columns)}"><b>'
                                f"{breakable_html(row[1])}</b></td></tr>")
                else:
                    body.append("<tr>" + "".join(f"<td>{_cell(x)}</td>" for x in row) + "</tr>")
            out.append(f'<table class="{cls}"><thead><tr>{head}</tr></thead><tbody>{"".join(body)}</tbody></table>')
            if note:
                out.append(f'<p class="note">{esc(note)}</p>')
        elif kind == "verdict":
            _, status, text = block
            out.append(f'<p class="verdict {esc(status.split()[0].lower())}"><b>Result: {esc(status)}</b>'
                       f"{': ' if text else ''}{_inline_html(text)}</p>")
        elif kind == "list":
            out.append("<ul>" + "".join(f"<li>{_inline_html(item)}</li>" for item in block[1]) + "</ul>")
        elif kind == "links":
            out.append('<p class="files">Files: ' + "; ".join(f'<a href="{esc(href)}">{breakable_html(label)}</a>'
                                                              for label, href in block[1]) + ".</p>")
        elif kind == "signatures":
            names = block[1]
            out.append('<table class="signatures"><thead><tr>' + "".join(
                f"<th>{esc(role)}</th>" for role, _ in names) + "</tr></thead><tbody><tr>" + "".join(
                f"<td>{esc(name) + '<br>' if name else ''}name, signature, date</td>" for _, name in names)
                + "</tr></tbody></table>")
    return "\n".join(out)


def to_markdown(blocks) -> str:
    """The same blocks as Markdown, every string made safe there (:mod:`tcr_accuracy.view.markdown_text`)."""
    from . import markdown_text as md

    def cell(value) -> str:
        return md.cell("; ".join(value) if isinstance(value, list) else value)

    out = []
    for block in blocks:
        kind = block[0]
        if kind == "h1":
            out += [f"# {md.line(block[1])}", ""]
        elif kind == "h2":
            out += [f"## {md.line(block[1])}", ""]
        elif kind == "p":
            out += [_inline_md(block[1]), ""]
        elif kind == "facts":
            out += [f"- **{md.line(row[i])}**: " + md.line("; ".join(row[i + 1]) if isinstance(row[i + 1], list)
                                                           else row[i + 1])
                    for row in block[1] for i in range(0, len(row), 2) if row[i]]
            out.append("")
        elif kind == "table":
            _, columns, rows, note, _ = block
            out += ["| " + " | ".join(map(md.cell, columns)) + " |", "|" + "|".join("---" for _ in columns) + "|"]
            for row in _kept(rows):
                cells = [f"**{md.cell(row[1])}**"] + [""] * (len(columns) - 1) if row[0] == "group" else \
                    [cell(c) for c in row]
                out.append("| " + " | ".join(cells) + " |")
            out += ["", md.text(note), ""] if note else [""]
        elif kind == "verdict":
            _, status, text = block
            out += [f"**Result: {md.line(status)}**" + (f": {_inline_md(text)}" if text else ""), ""]
        elif kind == "list":
            out += [f"- {_inline_md(item)}" for item in block[1]] + [""]
        elif kind == "links":
            out += ["Files: " + "; ".join(f"[{md.label(label)}]({md.href(href)})" for label, href in block[1]) + ".",
                    ""]
        elif kind == "signatures":
            names = block[1]
            out += ["| " + " | ".join(md.cell(role) for role, _ in names) + " |",
                    "|" + "|".join("---" for _ in names) + "|",
                    "| " + " | ".join((f"{md.cell(name)}: " if name else "") + "name, signature, date"
                                      for _, name in names) + " |", ""]
    return "\n".join(out)
