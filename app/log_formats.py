"""The log formats lashscope reads: each reader module declares its own, this module collects them.

A reader module under :mod:`app.ingest.readers` says which format it reads with one module-level
statement::

    FORMAT = LogFormat(name="blf", reader="BLFReader", label="Vector BLF", order=10, suffixes=(".blf",),
                       magic=(b"LOGG",))

naming the format (the ``format`` of a stored log and of ``open_log(fmt=...)``), the reader class
in that module (imported only when a log of that format is opened), the words a user knows it by,
its place in every list (``order``: the sniffer prefers the earlier of two formats a text head fits
equally well), the suffixes that break a tie when the content fits several text formats, and how
the sniffer knows it: the magic bytes of a binary format, or the shapes of lines only that text
format has. :data:`LOG_FORMATS` is those declarations in ``order``. Help texts, the REST summary,
the dashboard's upload card and the "supported formats" part of an
:class:`~app.errors.UnsupportedFormatError` are all built from it, and so is the sniffer
(:mod:`app.ingest.readers.sniff`): a new reader is one module (with its ``FORMAT``) and its test.

This module sits outside ``app.ingest`` and imports nothing heavy: the command line builds its help
from it without loading numpy or cantools (``app.ingest``'s package import prepares cantools, the
readers import numpy). So the declarations are read from the readers' source, not imported: the
``FORMAT = LogFormat(...)`` statement of each ``app/ingest/readers/*.py`` is parsed on its own and
its arguments evaluated as literals (strings, bytes, numbers, tuples of them), a bare name standing
for a string constant assigned at the top of the same file (``lines=(HEADER, ROW)``). Anything else
-- a call, an expression, a missing or unknown argument, two formats with one name or one order --
raises :class:`FormatDeclarationError` naming the file, when this module is imported.
"""

from __future__ import annotations

import ast
from dataclasses import dataclass
from functools import cache
from pathlib import Path

READERS_DIR = Path(__file__).resolve().parent / "ingest" / "readers"


@dataclass(frozen=True)
class LogFormat:
    name: str  # key: LogMeta.format, open_log(fmt=...), the stored log's format
    reader: str  # the reader class in the declaring module
    label: str  # what a user calls it, in help texts and error messages
    suffixes: tuple[str, ...] = ()  # break ties between text formats whose lines both fit
    magic: tuple[bytes, ...] = ()  # the first bytes of every log of a binary format (the sniffer's test)
    lines: tuple[str, ...] = ()  # regular expressions (inline flags) of lines only this text format has: the
    # sniffer scores a text head by how many of its first lines match one of them
    order: int = 0  # place in every list and the sniffer's preference among equal scores (declared, unique)
    module: str = ""  # the declaring module under app.ingest.readers (set from its file name when collected)

    @property
    def reader_path(self) -> str:
        """``"module:Class"`` under :mod:`app.ingest.readers`."""
        return f"{self.module}:{self.reader}"


class FormatDeclarationError(Exception):
    """A reader module's ``FORMAT`` declaration cannot be read; the message names the file."""


_DECLARED = ("name", "reader", "label", "suffixes", "magic", "lines", "order")  # what a declaration may give
_REQUIRED = ("name", "reader", "label", "order")
_MAX_LINES = 40  # a declaration is a few lines
_LITERAL_NODES = (ast.Constant, ast.Tuple, ast.Name, ast.Load, ast.UnaryOp, ast.USub)  # what an argument may hold


def _assignment(source: str, name: str) -> int:
    """Where the top-level assignment of ``name`` starts (``NAME = ...`` or ``NAME: type = ...``), -1 if none
    (plain string search: this runs over every reader's source at import)."""
    text = "\n" + source
    at = text.find("\n" + name)  # at: the newline before the name in text, the name itself in source
    while at >= 0:
        after = text[at + 1 + len(name):at + 201 + len(name)].split("\n", 1)[0].lstrip()
        if after.startswith(":") or (after.startswith("=") and not after.startswith("==")):
            return at
        at = text.find("\n" + name, at + 1)
    return -1


def _statement(source: str, start: int, where: str) -> ast.stmt:
    """The top-level statement that starts at ``start``, parsed: the lines up to the next blank line when
    they parse (the common case, one parse), else the shortest run of its lines that is one whole
    statement (a call left open parses as none)."""
    blank = source.find("\n\n", start)
    try:
        body = ast.parse(source[start:blank if blank >= 0 else len(source)]).body
    except SyntaxError:
        body = []
    if body:
        return body[0]
    lines = source[start:].splitlines(keepends=True)
    error: SyntaxError | None = None
    for n in range(1, min(len(lines), _MAX_LINES) + 1):
        try:
            body = ast.parse("".join(lines[:n])).body
        except SyntaxError as exc:
            error = exc
            continue
        if body:
            return body[0]
    raise FormatDeclarationError(f"{where}: the statement at line {source.count(chr(10), 0, start) + 1} cannot be "
                                 f"parsed within {_MAX_LINES} lines: {error}")


def _string_constant(source: str, name: str, where: str) -> str:
    """The string a top-level ``NAME = "..."`` of the same file assigns."""
    at = _assignment(source, name)
    if at < 0:
        raise FormatDeclarationError(f"{where}: FORMAT refers to {name}, which is not a string constant "
                                     "assigned at the top of the file")
    node = _statement(source, at, where)
    value = getattr(node, "value", None)
    if not (isinstance(value, ast.Constant) and isinstance(value.value, str)):
        raise FormatDeclarationError(f"{where}: FORMAT refers to {name}, which is not a string literal")
    return value.value


class _Names(ast.NodeTransformer):
    def __init__(self, source: str, where: str) -> None:
        self.source, self.where = source, where

    def visit_Name(self, node: ast.Name) -> ast.Constant:
        return ast.copy_location(ast.Constant(_string_constant(self.source, node.id, self.where)), node)


def _check(where: str, key: str, value: object) -> None:
    def fail(what: str) -> FormatDeclarationError:
        return FormatDeclarationError(f"{where}: FORMAT {key}= must be {what}, not {value!r}")

    if key in ("name", "reader"):
        if not (isinstance(value, str) and value.isidentifier()):
            raise fail("an identifier string")
    elif key == "label":
        if not (isinstance(value, str) and value.strip()):
            raise fail("a non-empty string")
    elif key == "order":
        if not (isinstance(value, int) and not isinstance(value, bool)):
            raise fail("an integer")
    elif key == "magic":
        if not (isinstance(value, tuple) and all(isinstance(v, bytes) and v for v in value)):
            raise fail("a tuple of non-empty bytes")
    elif not (isinstance(value, tuple) and all(isinstance(v, str) and v for v in value)):  # suffixes, lines
        raise fail("a tuple of non-empty strings")
    if key == "suffixes" and not all(s.startswith(".") and s == s.lower() for s in value):  # type: ignore[union-attr]
        raise fail("a tuple of lower-case suffixes starting with '.'")


def read_declaration(path: Path) -> LogFormat | None:
    """The ``FORMAT`` a reader module's source declares (None when it declares none), read without
    importing the module; a malformed declaration raises :class:`FormatDeclarationError`."""
    try:
        data = path.read_bytes()
        if b"FORMAT" not in data:
            return None
        source = data.decode("utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise FormatDeclarationError(f"{path}: cannot be read for its FORMAT: {exc}") from None
    at = _assignment(source, "FORMAT")
    if at < 0:
        return None
    where = str(path)
    node = _statement(source, at, where)
    call = getattr(node, "value", None)
    if not (isinstance(node, ast.Assign | ast.AnnAssign) and isinstance(call, ast.Call)
            and isinstance(call.func, ast.Name) and call.func.id == "LogFormat"):
        raise FormatDeclarationError(f"{where}: FORMAT must be assigned LogFormat(...) with keyword arguments")
    if call.args:
        raise FormatDeclarationError(f"{where}: FORMAT = LogFormat(...) takes keyword arguments only")
    given: dict[str, object] = {}
    for kw in call.keywords:
        if kw.arg not in _DECLARED:
            raise FormatDeclarationError(f"{where}: FORMAT has no argument {kw.arg!r} (it takes "
                                         f"{', '.join(_DECLARED)})")
        try:
            if not all(isinstance(n, _LITERAL_NODES) for n in ast.walk(kw.value)):
                raise ValueError
            value = ast.literal_eval(_Names(source, where).visit(kw.value))
        except ValueError:
            raise FormatDeclarationError(f"{where}: FORMAT {kw.arg}= is not a literal (strings, bytes, numbers, "
                                         "tuples of them, or a string constant of the file): "
                                         f"{ast.unparse(kw.value)}") from None
        _check(where, kw.arg, value)
        given[kw.arg] = value
    missing = [k for k in _REQUIRED if k not in given]
    if missing:
        raise FormatDeclarationError(f"{where}: FORMAT lacks {', '.join(missing)}")
    return LogFormat(**given, module=path.stem)  # type: ignore[arg-type]


@cache
def discover_formats(directory: Path = READERS_DIR) -> tuple[LogFormat, ...]:
    """Every ``FORMAT`` declared by the modules in ``directory`` (``*.py``, not ``_private.py``), in
    ``order``; read once per process and directory."""
    found: list[LogFormat] = []
    for path in sorted(directory.glob("*.py")):
        if path.name.startswith("_"):
            continue
        f = read_declaration(path)
        if f is None:
            continue
        for other in found:
            for key in ("name", "order"):
                if getattr(other, key) == getattr(f, key):
                    raise FormatDeclarationError(f"{path}: FORMAT {key}={getattr(f, key)!r} is already declared by "
                                                 f"{directory / (other.module + '.py')}")
        found.append(f)
    return tuple(sorted(found, key=lambda f: f.order))


LOG_FORMATS: tuple[LogFormat, ...] = discover_formats()

BY_NAME: dict[str, LogFormat] = {f.name: f for f in LOG_FORMATS}
FORMAT_NAMES: tuple[str, ...] = tuple(f.name for f in LOG_FORMATS)
SNIFFED = tuple(n for n in FORMAT_NAMES if n != "described")  # "described" needs its description


def formats_sentence() -> str:
    """The formats in words, for help texts: ``Vector BLF, Vector ASC, ... or a text format described in
    a TOML file; gzip accepted``."""
    labels = [f.label for f in LOG_FORMATS]
    return f"{', '.join(labels[:-1])} or {labels[-1]}; gzip accepted"


def supported_list() -> str:
    """The format keys with their labels, for an error that says what is supported."""
    return ", ".join(f"{f.name} ({f.label})" for f in LOG_FORMATS)


SIDECAR_SUFFIX = ".format.toml"


def sidecar_of(log: Path) -> Path:
    """Where the format description of a text log lives beside it: ``drive.txt`` -> ``drive.txt.format.toml``
    (read by ``open_log`` when no format is given; the service stores an uploaded description so)."""
    return log.with_name(log.name + SIDECAR_SUFFIX)
