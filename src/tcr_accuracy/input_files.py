"""Reading a user's file: the one opener every command and every reader goes through.

A file a user names (a measurement CSV, a result JSON, a URDF, a YAML or TOML settings file,
a mesh) is read by :func:`read_input_bytes` and the helpers built on it:

* only a regular file is read: a named pipe, a device (``/dev/zero``), a socket or a folder
  is one :class:`~tcr_accuracy.exceptions.InputError` line, never a hang. The path is looked
  at before it is opened (a device is never opened), opened without blocking (a pipe with no
  writer opens at once) and looked at again on the open descriptor, so the file checked is
  the file read;
* each kind of file has a size bound (:data:`SIZE_LIMITS`), checked on the open file and again
  while reading (a file that grows while it is read, a ``/proc`` file that says it is empty);
  inside :func:`memory_budget` (the command line's ``--max-memory-gb``), a file whose reading
  would need more memory than the budget (:data:`MEMORY_PER_BYTE` per byte) is refused first;
* text is UTF-8 (a byte-order mark is dropped); a byte that is not is one line naming the line;
* JSON (:func:`parse_json`) and YAML or TOML (:func:`parse_settings`) are parsed with their
  nesting bounded (:data:`MAX_NESTING`, never a ``RecursionError``), without YAML aliases
  (a few hundred bytes can stand for 10^9 values), without a key given twice in one table or
  object, and without JSON's ``NaN`` and ``Infinity``;
* every file read is recorded, by device and inode, for the run that reads it
  (:func:`recording_inputs`): the command line's output writer refuses to write over any of
  them, however the two paths are spelt.

Base layer: no import from the rest of the package but :mod:`tcr_accuracy.exceptions`.
"""

from __future__ import annotations

import json
import math
import os
import re
import stat
import unicodedata
from contextlib import contextmanager
from contextvars import ContextVar
from pathlib import Path

from .exceptions import InputError

MB = 1 << 20

#: The largest file [bytes] read of each kind. A measurement table of a million rows is about
#: 200 MB; a diagnosis JSON of 100,000 poses about 30 MB; the settings, scenario and as-built
#: YAML files the tool writes are a few kB (PyYAML reads about 1 MB/s, so a bound of 4 MB
#: keeps a hostile file to seconds); a URDF of 1000 joints is about 1 MB; a mesh rarely
#: passes 100 MB.
SIZE_LIMITS = {"table": 2048 * MB, "json": 256 * MB, "settings": 4 * MB, "urdf": 50 * MB, "mesh": 512 * MB}

#: Memory [bytes] reading one byte of a file takes, parsed (text, cells or objects, numbers): the
#: figure the command line's CSV estimate uses too. A reader whose parser takes more says how much
#: (``memory_per_byte``): a URDF's XML trees about 30, a YAML file's nodes about 350 (measured on
#: lists of empty tables: 330), a TOML file's about 100; a JSON text's objects are counted
#: (:func:`json_memory`).
MEMORY_PER_BYTE = 12.0
MEMORY_PER_BYTE_OF = {"urdf": 30.0, "yaml": 350.0, "toml": 100.0}

#: The deepest nesting of objects, lists or tables a JSON, YAML or TOML file may have (the
#: tool's own files use at most 6; real settings files 3 or 4).
MAX_NESTING = 20


# ---------------------------------------------------------------------------------------
# The files a run has read
# ---------------------------------------------------------------------------------------
_inputs: ContextVar[list | None] = ContextVar("tcr_accuracy_inputs", default=None)
_budget: ContextVar[tuple[float, str] | None] = ContextVar("tcr_accuracy_read_budget", default=None)


@contextmanager
def memory_budget(n_bytes: float, hint: str):
    """Inside the block, refuse a file whose reading would need more than ``n_bytes`` of memory
    (:data:`MEMORY_PER_BYTE` per byte); ``hint``: what the refusal says to do instead."""
    token = _budget.set((float(n_bytes), hint))
    try:
        yield
    finally:
        _budget.reset(token)


@contextmanager
def recording_inputs():
    """Record every file read inside the block; yields the list of ``(path, st_dev, st_ino)``
    it fills (the command line holds its outputs against it)."""
    record: list = []
    token = _inputs.set(record)
    try:
        yield record
    finally:
        _inputs.reset(token)


def record_input(path, st: os.stat_result) -> None:
    """Note that ``path`` (whose ``os.stat`` is ``st``) is an input of the current run, if one
    records (:func:`recording_inputs`). For readers that cannot go through
    :func:`read_input_bytes` (a library opening the file itself)."""
    record = _inputs.get()
    if record is not None:
        record.append((str(path), st.st_dev, st.st_ino))


# ---------------------------------------------------------------------------------------
# Bytes and text
# ---------------------------------------------------------------------------------------
def _kind_of(mode: int) -> str | None:
    """What a file that is not a regular one is, in words (None for a regular file)."""
    if stat.S_ISREG(mode):
        return None
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISFIFO(mode):
        return "a named pipe"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "a special file"


def _refuse_kind(path, what: str, kind: str) -> InputError:
    return InputError(f"{path}: is {kind}; the {what} must be a regular file")


def check_input_file(path, what: str) -> os.stat_result:
    """The ``os.stat`` of ``path`` if it is an existing regular file, else one InputError line
    (missing, a folder, a pipe, a device). Opens nothing."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise InputError(f"{path}: no such {what}") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read the {what} ({exc.strerror or exc})") from None
    kind = _kind_of(st.st_mode)
    if kind:
        raise _refuse_kind(path, what, kind)
    return st


def read_input_bytes(path, what: str, *, limit: int, memory_per_byte: float = MEMORY_PER_BYTE) -> bytes:
    """The bytes of the regular file ``path`` (see the module docstring), recorded as an input.

    Parameters
    ----------
    path : str or Path
    what : str
        What the file is, for messages ("measurement file", "diagnosis JSON").
    limit : int
        The largest size accepted [bytes] (one of :data:`SIZE_LIMITS`).
    memory_per_byte : float
        Memory [bytes] the file's reader takes per byte (held to :func:`memory_budget`).

    Raises
    ------
    InputError
        Missing, not a regular file, larger than ``limit``, or unreadable.
    """
    fd, st = open_input(path, what, limit=limit, memory_per_byte=memory_per_byte)
    try:
        chunks, size = [], 0
        while True:
            chunk = os.read(fd, min(8 * MB, limit + 1 - size))
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
            if size > limit:
                _check_size(path, what, size, limit, memory_per_byte)
    except OSError as exc:
        raise InputError(f"{path}: cannot read the {what} ({exc.strerror or exc})") from None
    finally:
        os.close(fd)
    record_input(path, st)
    return b"".join(chunks)


def open_input(path, what: str, *, limit: int, memory_per_byte: float = MEMORY_PER_BYTE) -> tuple[int, os.stat_result]:
    """(file descriptor, its ``os.fstat``) of the regular file ``path``, opened for reading
    without blocking and checked on the open descriptor (see :func:`read_input_bytes`); the
    caller closes it. For a reader that streams the file instead of reading it whole."""
    before = check_input_file(path, what)
    _check_size(path, what, before.st_size, limit, memory_per_byte)
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(path, flags)
    except OSError as exc:
        raise InputError(f"{path}: cannot read the {what} ({exc.strerror or exc})") from None
    try:
        st = os.fstat(fd)
        kind = _kind_of(st.st_mode)
        if kind:  # replaced between the look and the open
            raise _refuse_kind(path, what, kind)
        _check_size(path, what, st.st_size, limit, memory_per_byte)
    except BaseException:
        os.close(fd)
        raise
    return fd, st


def _check_size(path, what: str, size: int, limit: int, memory_per_byte: float = MEMORY_PER_BYTE) -> None:
    if size > limit:
        raise InputError(f"{path}: the {what} is larger than the {_size(limit)} this kind of file may have "
                         f"({_size(size)}{' or more' if size == limit + 1 else ''})")
    check_parse_memory(path, f"the {what} ({_size(size)})", size * memory_per_byte)


def check_parse_memory(source, what: str, need: float) -> None:
    """Inside :func:`memory_budget`, one InputError line when reading ``what`` of ``source`` needs
    ``need`` bytes of memory, more than the budget (outside it, nothing)."""
    budget = _budget.get()
    if budget is not None and need > budget[0]:
        raise InputError(f"{source}: reading {what} needs about {need / 1e9:.3g} GB of memory, more than "
                         f"the {budget[0] / 1e9:.3g} GB allowed; {budget[1]}")


def json_memory(text: str) -> float:
    """Memory [bytes] parsing the JSON ``text`` takes, estimated from what it holds (measured with
    tracemalloc on ``json.loads``: an object about 200 bytes, a list 64, each item 40, beside
    twice the text): 12 bytes per byte for a result's numbers, 25 for a file of ``{},`` only."""
    return 2.0 * len(text) + 200.0 * text.count("{") + 64.0 * text.count("[") + 40.0 * text.count(",")


def _size(n: int) -> str:
    return f"{n / MB:.4g} MB" if n >= MB else f"{n} bytes"


def decode_text(data: bytes, source, what: str) -> str:
    """UTF-8 bytes to text (a byte-order mark dropped); a byte that is not UTF-8 is one
    InputError line naming the line it is on."""
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data[:exc.start].count(b"\n") + 1
        raise InputError(f"{source}: line {line}: byte 0x{data[exc.start]:02x} is not UTF-8 text; the {what} "
                         "must be text saved as UTF-8") from None


def read_input_text(path, what: str, *, limit: int, memory_per_byte: float = MEMORY_PER_BYTE) -> str:
    """The UTF-8 text of the regular file ``path`` (:func:`read_input_bytes`, :func:`decode_text`)."""
    return decode_text(read_input_bytes(path, what, limit=limit, memory_per_byte=memory_per_byte), path, what)


# ---------------------------------------------------------------------------------------
# JSON
# ---------------------------------------------------------------------------------------
def _nesting(data) -> int:
    """The deepest nesting of dicts and lists in ``data`` (walked without recursion)."""
    deepest, stack = 0, [(data, 1)]
    while stack:
        node, depth = stack.pop()
        if isinstance(node, dict):
            node = node.values()
        elif not isinstance(node, list):
            continue
        deepest = max(deepest, depth)
        if depth <= MAX_NESTING:
            stack.extend((child, depth + 1) for child in node)
    return deepest


def _too_deep(source) -> InputError:
    return InputError(f"{source}: objects or lists nested more than {MAX_NESTING} deep")


#: The most digits an integer of a file may have: beyond 309, no float holds it (a YAML or TOML
#: integer of 400 digits ended as "OverflowError: int too large to convert to float", one of more
#: than 4300, Python's bound on converting text to int, as a ValueError or a traceback).
MAX_INTEGER_DIGITS = 309


class _HugeInteger(str):
    """An integer's text too long for a number (a parser's hook returns it in place of the int,
    so that :func:`_huge_integer_at` can name its key)."""


def _integer(text: str):
    """``text`` (an integer's digits, with a sign, TOML's ``_``) as an int, or a :class:`_HugeInteger`
    when it has more than :data:`MAX_INTEGER_DIGITS` digits or lies beyond the largest float."""
    digits = sum(c.isdigit() for c in text)
    if digits > MAX_INTEGER_DIGITS:
        return _HugeInteger(text)
    value = int(text)
    return _HugeInteger(text) if abs(value) > 1.7976931348623157e308 else value


def _huge_integer_at(data, top: str) -> tuple[str, _HugeInteger] | None:
    """(key path, text) of the first integer of ``data`` too large for a number, or None; the path
    starts with ``top`` (``$`` for JSON, empty for a settings file) and names keys and list items."""
    stack = [(data, top)]
    while stack:
        node, path = stack.pop()
        if isinstance(node, _HugeInteger) or (isinstance(node, int) and not isinstance(node, bool)
                                              and node.bit_length() > 1024):
            return path, node
        if isinstance(node, dict):
            stack.extend((v, f"{path}.{k}" if path else str(k)) for k, v in reversed(list(node.items())))
        elif isinstance(node, list):
            stack.extend((v, f"{path}[{i}]") for i, v in reversed(list(enumerate(node))))
    return None


def _refuse_huge_integer(source, data, top: str = "") -> None:
    found = _huge_integer_at(data, top)
    if found is not None:
        path, value = found
        digits = sum(c.isdigit() for c in str(value))
        raise InputError(f"{source}: {path or 'the value'}: an integer of {digits} digits is beyond the range of a "
                         f"number (about 1.8e308); write a number of sane size")


def parse_json(text: str, source, hint: str = "") -> object:
    """JSON text to Python, nested at most :data:`MAX_NESTING` deep, without ``NaN`` or
    ``Infinity`` (nor a number such as ``1e400`` that would read as one) and without a key given
    twice in one object; anything else is one
    InputError line naming ``source`` (and ``hint``: what to give instead)."""
    hint = f"; {hint}" if hint else ""

    def constant(name):
        raise InputError(f"{source}: {name} is not a number JSON allows; write a finite number or null")

    def finite(text):
        value = float(text)
        if not math.isfinite(value):
            raise InputError(f"{source}: {_short(text, 40)} is beyond the range of a number (about 1.8e308)")
        return value

    def unique(pairs):
        out = {}
        for key, value in pairs:
            if key in out:
                raise InputError(f"{source}: key {_short(key)!r} is given twice in one object")
            out[key] = value
        return out

    check_parse_memory(source, f"its JSON ({text.count('{') + text.count('[')} objects and lists)", json_memory(text))
    try:
        data = json.loads(text, parse_constant=constant, parse_float=finite, parse_int=_integer,
                          object_pairs_hook=unique)
    except InputError:
        raise
    except json.JSONDecodeError as exc:
        raise InputError(f"{source}: not JSON (line {exc.lineno}, column {exc.colno}: {exc.msg}){hint}") from None
    except RecursionError:
        raise _too_deep(source) from None
    if _nesting(data) > MAX_NESTING:
        raise _too_deep(source)
    _refuse_huge_integer(source, data, "$")
    return data


def read_json_file(path, what: str, *, hint: str = "", limit: int = SIZE_LIMITS["json"]) -> object:
    """The JSON document of the regular file ``path`` (:func:`read_input_text`, :func:`parse_json`)."""
    return parse_json(read_input_text(path, what, limit=limit), path, hint)


# ---------------------------------------------------------------------------------------
# YAML and TOML settings
# ---------------------------------------------------------------------------------------
def parse_settings(text: str, source, kind: str = "yaml") -> object:
    """TOML or YAML text to Python, nested at most :data:`MAX_NESTING` deep, YAML without
    aliases and no key given twice in one table; anything else is one InputError line naming
    ``source`` (and its line where the parser says it)."""
    check_parse_memory(source, f"its {kind.upper()} ({len(text)} characters)",
                       len(text) * MEMORY_PER_BYTE_OF["toml" if kind == "toml" else "yaml"])
    try:
        if kind == "toml":
            try:
                import tomllib
            except ModuleNotFoundError:  # Python 3.10: the same parser as the tomli package
                import tomli as tomllib

            try:
                data = tomllib.loads(text)
            except tomllib.TOMLDecodeError as exc:
                raise InputError(f"{source}: not valid TOML: {_short(exc)}") from None
            except ValueError:  # an integer of more than 4300 digits: tomllib's int() refuses it
                raise _huge_toml_integer(text, source) from None
        else:
            import yaml

            try:
                data = yaml.load(text, Loader=_strict_yaml_loader(source))  # noqa: S506 - a SafeLoader
            except yaml.YAMLError as exc:
                raise InputError(f"{source}: not valid YAML: {_short(exc)}") from None
    except RecursionError:
        raise InputError(f"{source}: tables or lists nested too deeply (at most {MAX_NESTING} levels)") from None
    if _nesting(data) > MAX_NESTING:
        raise InputError(f"{source}: tables or lists nested too deeply (at most {MAX_NESTING} levels)")
    _refuse_huge_integer(source, data)
    return data


def _huge_toml_integer(text: str, source) -> InputError:
    """The refusal of a TOML text holding an integer tomllib cannot convert: its line, the table
    above it and the key on it named (tomllib's ValueError says none of them)."""
    table = ""
    for number, line in enumerate(text.splitlines(), start=1):
        header = re.match(r"\s*\[\[?\s*([^\]]+?)\s*\]", line)
        if header:
            table = header.group(1)
        run = re.search(r"[0-9_]{%d,}" % (MAX_INTEGER_DIGITS + 1), line)
        if run:
            key = re.match(r"\s*([^=\[]+?)\s*=", line)
            path = ".".join(p for p in (table, key.group(1).strip('"\' ') if key else "") if p)
            return InputError(f"{source}: line {number}: {path or 'a value'}: an integer of "
                              f"{sum(c.isdigit() for c in run.group(0))} digits is beyond the range of a number "
                              "(about 1.8e308); write a number of sane size")
    return InputError(f"{source}: not valid TOML: an integer of more than 4300 digits")


def read_settings_file(path, what: str, kind: str | None = None, *, limit: int = SIZE_LIMITS["settings"]) -> object:
    """The YAML (or, with ``kind='toml'`` or a ``.toml`` name, TOML) document of the regular file ``path``."""
    kind = kind or ("toml" if Path(path).suffix.lower() == ".toml" else "yaml")
    return parse_settings(read_input_text(path, what, limit=limit), path, kind)


#: YAML 1.2's core schema for plain scalars: decimal numbers, true/false; PyYAML's 1.1 shortcuts
#: that turn text into numbers (``yes``, ``on``, ``0x10``, ``1:30``, ``010``, dates) stay text.
_BOOL = re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$")
_INT = re.compile(r"^[-+]?(?:0|[1-9][0-9]*)$")
_FLOAT = re.compile(r"^(?:[-+]?(?:[0-9]+\.[0-9]*|\.[0-9]+|[0-9]+)(?:[eE][-+]?[0-9]+)?|[-+]?\.(?:inf|Inf|INF)"
                    r"|\.(?:nan|NaN|NAN))$")
_CORE_TAGS = ("tag:yaml.org,2002:bool", "tag:yaml.org,2002:int", "tag:yaml.org,2002:float",
              "tag:yaml.org,2002:timestamp")


def _core_schema(loader_class) -> None:
    """Give ``loader_class`` (a SafeLoader subclass) YAML 1.2's core scalars (:data:`_BOOL`,
    :data:`_INT`, :data:`_FLOAT`) in place of YAML 1.1's."""
    import yaml

    loader_class.yaml_implicit_resolvers = {
        first: [(tag, regexp) for tag, regexp in resolvers if tag not in _CORE_TAGS]
        for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()}
    loader_class.add_implicit_resolver("tag:yaml.org,2002:bool", _BOOL, list("tTfF"))
    loader_class.add_implicit_resolver("tag:yaml.org,2002:int", _INT, list("-+0123456789"))
    loader_class.add_implicit_resolver("tag:yaml.org,2002:float", _FLOAT, list("-+0123456789."))

    def checked(pattern, build):  # an explicit tag (!!int 0x10) still holds to the core form
        def construct(loader, node):
            text = loader.construct_scalar(node)
            if not pattern.match(text):
                raise yaml.constructor.ConstructorError(None, None, f"{text!r} is not a plain decimal or true/false",
                                                        node.start_mark)
            return build(text)
        return construct

    loader_class.add_constructor("tag:yaml.org,2002:int", checked(_INT, _integer))
    loader_class.add_constructor("tag:yaml.org,2002:float", checked(
        _FLOAT, lambda t: float(t.lower().replace(".inf", "inf").replace(".nan", "nan"))))
    loader_class.add_constructor("tag:yaml.org,2002:bool", checked(_BOOL, lambda t: t.lower() == "true"))


def _strict_yaml_loader(source):
    """PyYAML's SafeLoader with YAML 1.2's core scalars (:func:`_core_schema`), refusing aliases
    and repeated keys, and nesting beyond :data:`MAX_NESTING`, in one line naming the line.

    An alias (``*name``) lets a 500-byte file stand for 10^9 nodes (nine levels of ten
    copies each): no walk over the result could end. A key given twice in one mapping would
    silently keep the last value. Block nesting (by indentation) has no bracket to count
    beforehand: the composer counts it.
    """
    import yaml

    class StrictLoader(yaml.SafeLoader):
        depth = 0

        def compose_node(self, parent, index):
            if self.check_event(yaml.AliasEvent):
                event = self.peek_event()
                raise InputError(f"{source}: line {event.start_mark.line + 1}: YAML aliases "
                                 f"(*{_short(event.anchor, 40)}) are refused; write the values out")
            self.depth += 1
            if self.depth > MAX_NESTING:
                line = self.peek_event().start_mark.line + 1
                raise InputError(f"{source}: line {line}: tables or lists nested too deeply "
                                 f"(at most {MAX_NESTING} levels)")
            try:
                return super().compose_node(parent, index)
            finally:
                self.depth -= 1

        def construct_mapping(self, node, deep=False):
            if isinstance(node, yaml.MappingNode):
                self.flatten_mapping(node)
                seen = set()
                for key_node, _ in node.value:
                    key = self.construct_object(key_node, deep=True)
                    try:
                        repeated = key in seen
                    except TypeError:  # an unhashable key: SafeLoader names it
                        break
                    if repeated:
                        raise InputError(f"{source}: line {key_node.start_mark.line + 1}: key "
                                         f"{_short(key, 60)!r} is given twice in one table")
                    seen.add(key)
            return super().construct_mapping(node, deep)

    _core_schema(StrictLoader)
    return StrictLoader


def _short(value, limit: int = 300) -> str:
    """``value`` as one line of at most ``limit`` characters."""
    text = " ".join(str(value).split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


#: Characters that reorder the text shown around them (a name could be made to read otherwise).
BIDI_CONTROLS = frozenset("\u202a\u202b\u202c\u202d\u202e\u2066\u2067\u2068\u2069")


def control_character(text: str, allowed: str = "") -> str | None:
    """The first character of ``text`` that a page or a table should not print as it is (a
    control character, a surrogate, a private or unassigned code point, a bidirectional
    override), other than those in ``allowed``; None when there is none."""
    return next((c for c in text if c not in allowed and (unicodedata.category(c) in ("Cc", "Cs", "Co", "Cn")
                                                           or c in BIDI_CONTROLS)), None)


def csv_cells(line: str, source, row: int, delimiter: str = ",") -> list[str]:
    """The cells of one line of delimited text (the csv module's quoting rules).

    Raises
    ------
    InputError
        Naming ``source`` and ``row`` where the csv module refuses the line (a cell over its
        field limit of 131072 characters ended as "unexpected error: Error" before).
    """
    import csv

    try:
        return next(csv.reader([line], delimiter=delimiter), [])
    except csv.Error as exc:
        raise InputError(f"{source}: row {row}: not delimited text the reader takes ({exc})") from None
