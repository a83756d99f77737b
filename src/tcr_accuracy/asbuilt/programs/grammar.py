"""Lark's parser for each language's grammar, its faults as one line, and the pieces the parsers share.

The grammars (one per language module) describe each language's block structure (routines, IF,
loops) and its statements as sequences of atoms (names, numbers, strings, operators and the
bracketed groups that hold literals: ``p[...]``, ``[...]``, ``{...}``, ``(...)``); the motion targets,
declarations and tool data are read off that tree. Lark's LALR parser keeps every token's place, so
a target's numbers are replaced where they stand and every other character stays as written.
(Hand-written because no parser of URScript, KRL or RAPID is published for Python; lark is the
grammar engine.)
"""

from __future__ import annotations

from functools import lru_cache

from ...exceptions import InputError
from .targets import NumberText

#: Tokens of a number and of a sign before it.
SIGNS = ("-", "+")


@lru_cache(maxsize=None)
def lark_parser(grammar: str):
    """An LALR parser of ``grammar`` (built once), every rule and token placed in the text."""
    from lark import Lark

    return Lark(grammar, parser="lalr", propagate_positions=True, maybe_placeholders=False)


def parse(grammar: str, text: str, source: str, language: str):
    """The tree of ``text``; InputError 'FILE:LINE:COLUMN: ... does not parse as LANGUAGE (...)' otherwise."""
    from lark.exceptions import UnexpectedCharacters, UnexpectedEOF, UnexpectedInput, UnexpectedToken

    try:
        return lark_parser(grammar).parse(text)
    except UnexpectedCharacters as exc:
        found = text[exc.pos_in_stream:exc.pos_in_stream + 1] if exc.pos_in_stream is not None else "?"
        raise InputError(f"{source}:{exc.line}:{exc.column}: does not parse as {language} (unexpected character "
                         f"{found!r})") from None
    except UnexpectedEOF:
        line = text.count("\n") + 1
        raise InputError(f"{source}:{line}:1: does not parse as {language} (the file ends inside a block, a bracket "
                         "or a statement: an end of block, a closing bracket or a ';' is missing)") from None
    except UnexpectedToken as exc:
        token = exc.token
        if token.type == "$END":
            raise InputError(f"{source}:{text.count(chr(10)) + 1}:1: does not parse as {language} (the file ends inside "
                             "a block, a bracket or a statement: an end of block, a closing bracket or a ';' is "
                             "missing)") from None
        shown = repr(str(token).strip() or token.type)
        raise InputError(f"{source}:{token.line}:{token.column}: does not parse as {language} (unexpected "
                         f"{shown[:60]})") from None
    except UnexpectedInput as exc:  # pragma: no cover - the two above are lark's kinds for LALR
        raise InputError(f"{source}:{getattr(exc, 'line', '?')}:{getattr(exc, 'column', '?')}: does not parse as "
                         f"{language}") from None


def is_token(node, kind: str | None = None, value: str | None = None, *, fold: bool = False) -> bool:
    """Whether ``node`` is a token (of type ``kind``, of text ``value``; ``fold``: any letter case)."""
    from lark import Token

    if not isinstance(node, Token):
        return False
    if kind is not None and node.type != kind:
        return False
    if value is not None:
        return str(node).lower() == value.lower() if fold else str(node) == value
    return True


def is_tree(node, rule: str) -> bool:
    from lark import Tree

    return isinstance(node, Tree) and node.data == rule


def elements(children, separator: str = ",") -> list[list]:
    """The atoms of a bracketed group split at its top-level separators (commas)."""
    out, current = [], []
    for child in children:
        if is_token(child, value=separator):
            out.append(current)
            current = []
        else:
            current.append(child)
    out.append(current)
    return [] if out == [[]] else out


def number_of(element) -> NumberText | None:
    """The number an element is (``[sign] NUMBER``), where it sits, or None when it is anything else."""
    if len(element) == 1 and is_token(element[0], "NUMBER"):
        token = element[0]
        return NumberText(token.start_pos, token.end_pos, float(str(token)), str(token))
    if len(element) == 2 and is_token(element[0]) and str(element[0]) in SIGNS and is_token(element[1], "NUMBER"):
        sign, token = element
        value = float(str(token)) * (-1.0 if str(sign) == "-" else 1.0)
        return NumberText(sign.start_pos, token.end_pos, value, f"{sign}{token}")
    return None


def numbers_of(group_children) -> list[NumberText] | None:
    """Every element of a group as a number, or None when one is not a number."""
    out = []
    for element in elements(group_children):
        number = number_of(element)
        if number is None:
            return None
        out.append(number)
    return out


def start_of(node) -> int:
    """The character offset where a token or a tree starts."""
    return node.start_pos if is_token(node) else node.meta.start_pos


def end_of(node) -> int:
    return node.end_pos if is_token(node) else node.meta.end_pos


def text_of(text: str, nodes) -> str:
    """The program's own text of a run of atoms (one line, shortened)."""
    if not nodes:
        return ""
    shown = " ".join(text[start_of(nodes[0]):end_of(nodes[-1])].split())
    return shown if len(shown) <= 80 else shown[:77] + "..."
