"""Text in the report's HTML tables: escaped, and long names that break at their separators.

A parameter name (``geometry.shoulder_lift_joint.dy``) or a path in a narrow cell should wrap
after a dot, an underscore or a slash, never mid-word ("shoulder_pan_join/t.a1"): the browser
breaks a line only where the text allows it, so each long word gets a ``<wbr>`` after each of its
separators and nowhere else.
"""

from __future__ import annotations

import html
import re


#: A word longer than this [characters] (a path, a parameter name) may break in a table cell, so
#: that the table fits the page: after its separators (:data:`SEPARATORS`), and anywhere only in
#: a stretch between separators that is itself this long; shorter words and numbers stay whole.
LONG_WORD = 24

#: Where a long word may break: after these characters ("geometry.shoulder_lift_joint.dy",
#: "/data/ur5/grid.csv"), so that a name wraps at its separators and never mid-word.
SEPARATORS = "._/\\:,"


def breakable_html(text: str) -> str:
    """``text`` as escaped HTML in which each long word (> :data:`LONG_WORD` characters) may
    break after its separators (``<wbr>``); a stretch between separators that is itself longer
    than LONG_WORD (a hash, a long run of digits) may break anywhere (``span.long``, see the report's CSS)."""
    out = []
    for part in re.split(r"(\s+)", str(text)):
        if len(part) <= LONG_WORD or part.isspace():
            out.append(html.escape(part))
            continue
        pieces = re.split(f"(?<=[{re.escape(SEPARATORS)}])", part)
        out.append("<wbr>".join(f'<span class="long">{html.escape(p)}</span>' if len(p) > LONG_WORD
                                else html.escape(p) for p in pieces if p))
    return "".join(out)
