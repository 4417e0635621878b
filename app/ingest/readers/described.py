"""Text logs described by the user: a small TOML file says how a line holds a frame, so a logger
lashscope has no reader for is read without code.

A description either gives a regular expression with named groups or column positions::

    name = "bench logger"                        # shown in reports (optional)
    regex = '^(?P<time>\\d+\\.\\d+);(?P<id>[0-9A-F]+);(?P<dlc>\\d);(?P<data>[0-9A-F ]*)$'
    # or, instead of regex:
    # separator = ";"                            # one character, "\\t", or "whitespace"
    # columns = { time = 0, id = 1, dlc = 2, data = 3 }
    # data_to_end = true                         # the data bytes are column `data` and every column after it
    time_unit = "s"                              # s, ms, us or ns
    time_encoding = "decimal"                    # decimal or hex
    id_encoding = "hex"                          # hex or decimal (a 0x prefix is accepted either way)
    data_encoding = "hex_bytes"                  # hex_bytes ("01 02 03"), hex_string ("010203"), decimal_bytes
    skip_lines = 1                               # header lines before the first frame
    comment = "#"                                # lines starting with this are not frames (optional)
    extended = "auto"                            # auto (ID > 0x7FF), digits (more than 3 ID digits),
                                                 # always, never, or field (the `ext` field)
    extended_values = ["x", "ext", "true", "1"]  # what the `ext` field holds for an extended frame
    tx_values = ["tx", "t"]                      # what the `dir` field holds for a transmitted frame
    channel_base = 0                             # subtract from the `channel` field (1 for 1-based)

Fields (regex groups or columns): ``time``, ``id`` and ``data`` are required; ``dlc`` (else the
number of data bytes), ``channel`` (else 0), ``ext`` and ``dir`` are optional. Times are read
exactly (integer ns, no float rounding) and count from the first frame, as for every text log.

A description with a mistake raises :class:`~app.errors.FormatFileError` (code ``format_file``)
naming the file and the field, when it is loaded, before any log is read.

Where descriptions come from: ``open_log(source, layout=...)`` forces one; a file beside the
log named ``<log file name>.format.toml`` is used for that log (the service keeps an uploaded
description so, next to the stored log); descriptions registered with :func:`register_format_file` or
listed in ``LASHSCOPE_FORMAT_FILES`` (files or folders of ``*.toml``, separated by the OS path
separator) also take part in recognising a log by its content: a description whose lines match
at least half of a log's first lines wins over the built-in formats.
"""

from __future__ import annotations

import os
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from app.errors import FormatFileError
from app.ingest.frames import FrameFlag
from app.ingest.readers._source import ByteStream
from app.ingest.readers._text import (
    LEN_TO_DLC,
    BadLine,
    LineFrame,
    LineFrameReader,
    decimal_to_ns,
    first_stamp,
    hex_bytes,
    parse_int,
    printable,
)
from app.log_formats import LogFormat

EXT, FD, TX = int(FrameFlag.EXTENDED), int(FrameFlag.FD), int(FrameFlag.TX)

TIME_UNITS = {"s": 9, "ms": 6, "us": 3, "ns": 0}
FIELDS = ("time", "id", "data", "dlc", "channel", "ext", "dir")
REQUIRED = ("time", "id", "data")
_KEYS = {"name", "regex", "separator", "columns", "data_to_end", "time_unit", "time_encoding", "id_encoding",
         "data_encoding", "skip_lines", "comment", "extended", "extended_values", "tx_values", "channel_base"}
_CHOICES = {
    "time_encoding": ("decimal", "hex"),
    "id_encoding": ("hex", "decimal"),
    "data_encoding": ("hex_bytes", "hex_string", "decimal_bytes"),
    "extended": ("auto", "digits", "always", "never", "field"),
}
ENV = "LASHSCOPE_FORMAT_FILES"
MAX_DESCRIPTION_BYTES = 64 * 1024


@dataclass(frozen=True)
class TextLayout:
    """A validated format description (see the module docstring for the fields)."""

    name: str
    source: str  # where it came from (file name), for messages
    regex: re.Pattern[str] | None
    separator: str | None  # None: whitespace (with columns)
    columns: dict[str, int]
    data_to_end: bool
    time_exp: int  # ns per time unit as a power of ten
    time_hex: bool
    id_base: int
    data_encoding: str
    skip_lines: int
    comment: str | None
    extended: str
    extended_values: frozenset[str]
    tx_values: frozenset[str]
    channel_base: int

    def fields(self, line: str) -> dict[str, str] | None:
        """The named fields of one line, or None when the line does not have the described shape."""
        if self.regex is not None:
            m = self.regex.match(line)
            return None if m is None else {k: v for k, v in m.groupdict().items() if v is not None}
        parts = line.split() if self.separator is None else line.split(self.separator)
        need = max((i for k, i in self.columns.items() if not (self.data_to_end and k == "data")), default=0)
        if len(parts) <= need:
            return None
        out = {k: parts[i] for k, i in self.columns.items() if i < len(parts)}
        if self.data_to_end:
            out["data"] = " ".join(p.strip() for p in parts[self.columns["data"]:])
        return out

    def matches(self, line: str) -> bool:
        """True when ``line`` has the shape of a frame line (for recognising a log by content)."""
        try:
            return self.parse(line) is not None
        except BadLine:
            return False

    def parse(self, line: str) -> LineFrame | None:
        """One line as ``(t_ns, channel, id, flags, dlc, payload)``; None for blank and comment lines."""
        s = line.rstrip("\r\n")
        if not s or s.isspace() or (self.comment and s.lstrip().startswith(self.comment)):
            return None
        if not printable(s):
            raise BadLine("bad_line", "binary data (non-printable bytes) instead of a log line")
        f = self.fields(s)
        if f is None:
            raise BadLine("bad_line", f"line does not have the shape {self.name!r} describes: {s[:60]!r}")
        if "time" not in f or "id" not in f or "data" not in f:
            missing = [k for k in REQUIRED if k not in f]
            raise BadLine("bad_line", f"no {', '.join(missing)} field in {s[:60]!r}")
        t_tok = f["time"].strip()
        if self.time_hex:
            t = parse_int(t_tok[2:] if t_tok[:2].lower() == "0x" else t_tok, 16, "time stamp") * 10**self.time_exp
        else:
            t = decimal_to_ns(t_tok, self.time_exp)
        id_tok = f["id"].strip()
        digits = id_tok[2:] if id_tok[:2].lower() == "0x" else id_tok
        ident = parse_int(digits, self.id_base, "identifier")
        if ident > 0x1FFFFFFF:
            raise BadLine("bad_line", f"identifier {id_tok} is larger than 29 bits")
        data = self._data(f["data"].strip())
        dlc_tok = f.get("dlc", "").strip()
        dlc = parse_int(dlc_tok, 10, "DLC") if dlc_tok else len(data)
        if dlc > 64 or (dlc > 8 and dlc not in LEN_TO_DLC):
            raise BadLine("bad_line", f"length {dlc} is not a CAN or CAN FD length")
        if len(data) > dlc:
            raise BadLine("bad_line", f"{len(data)} data bytes, but the length says {dlc}")
        if isinstance(data, bytes) and len(data) == dlc:
            payload = data
        else:
            payload = hex_bytes(data if isinstance(data, list) else [f"{b:02x}" for b in data], dlc,
                                base=10 if self.data_encoding == "decimal_bytes" else 16)
        channel = 0
        ch_tok = f.get("channel", "").strip()
        if ch_tok:
            channel = parse_int(ch_tok, 10, "channel") - self.channel_base
            if not 0 <= channel <= 32767:
                raise BadLine("bad_line", f"channel {ch_tok} out of range")
        fl = FD if dlc > 8 else 0
        if self._extended(ident, digits, f.get("ext", "")):
            fl |= EXT
        elif ident > 0x7FF:
            raise BadLine("bad_line", f"identifier {id_tok} is larger than 11 bits in a standard frame")
        if "dir" in f and f["dir"].strip().lower() in self.tx_values:
            fl |= TX
        return t, channel, ident, fl, dlc, payload

    def _data(self, text: str) -> list[str] | bytes:
        """The data field as bytes (hex_string that converts whole, in C) or as tokens to check one by one."""
        if self.data_encoding == "hex_string":
            compact = "".join(text.split())
            if compact[:2].lower() == "0x":
                compact = compact[2:]
            if len(compact) % 2:
                raise BadLine("short_data", f"data {compact[:40]!r} has an odd number of hex digits (line cut?)")
            try:
                return bytes.fromhex(compact)
            except ValueError:
                return [compact[i:i + 2] for i in range(0, len(compact), 2)]
        tokens = text.replace(",", " ").split()
        if tokens and tokens[0][:2].lower() == "0x" and self.data_encoding == "hex_bytes":
            tokens = [t[2:] if t[:2].lower() == "0x" else t for t in tokens]
        return tokens

    def _extended(self, ident: int, digits: str, ext_field: str) -> bool:
        rule = self.extended
        if rule == "always":
            return True
        if rule == "never":
            return False
        if rule == "digits":
            return len(digits) > 3
        if rule == "field":
            return ext_field.strip().lower() in self.extended_values
        return ident > 0x7FF


def _fail(source: str, field: str, why: str) -> FormatFileError:
    return FormatFileError(f"{source}: {field}: {why}")


def _get(data: dict[str, Any], source: str, key: str, kind: type | tuple[type, ...], default: Any) -> Any:
    value = data.get(key, default)
    if value is not default and (not isinstance(value, kind) or (isinstance(value, bool) and kind is int)):
        names = " or ".join(k.__name__ for k in (kind if isinstance(kind, tuple) else (kind,)))
        raise _fail(source, key, f"expected {names}, got {value!r}")
    return value


def parse_layout(text: str, source: str = "format description") -> TextLayout:
    """A :class:`TextLayout` from the TOML text of a description; FormatFileError names the field at fault."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise FormatFileError(f"{source}: not valid TOML: {exc}") from None
    except RecursionError:
        raise FormatFileError(f"{source}: not valid TOML: tables or arrays nested too deeply") from None
    unknown = sorted(set(data) - _KEYS)
    if unknown:
        raise _fail(source, unknown[0], f"unknown field; the fields are {', '.join(sorted(_KEYS))}")
    name = _get(data, source, "name", str, Path(source).stem)
    regex_text = _get(data, source, "regex", str, None)
    columns_in = _get(data, source, "columns", dict, None)
    if (regex_text is None) == (columns_in is None):
        raise _fail(source, "regex", "give either regex (named groups) or columns (field = position), not "
                    + ("both" if regex_text is not None else "neither"))
    regex: re.Pattern[str] | None = None
    columns: dict[str, int] = {}
    if regex_text is not None:
        try:
            regex = re.compile(regex_text)
        except re.error as exc:
            raise _fail(source, "regex", f"not a valid regular expression: {exc}") from None
        groups = set(regex.groupindex)
        missing = [g for g in REQUIRED if g not in groups]
        if missing:
            raise _fail(source, "regex", f"needs the named group(s) {', '.join(f'(?P<{g}>...)' for g in missing)}")
        extra = sorted(groups - set(FIELDS))
        if extra:
            raise _fail(source, "regex", f"unknown group {extra[0]!r}; groups are {', '.join(FIELDS)}")
    else:
        for key, pos in columns_in.items():
            if key not in FIELDS:
                raise _fail(source, f"columns.{key}", f"unknown field; fields are {', '.join(FIELDS)}")
            if not isinstance(pos, int) or isinstance(pos, bool) or not 0 <= pos < 1000:
                raise _fail(source, f"columns.{key}", f"expected a column position 0-999, got {pos!r}")
            columns[key] = pos
        missing = [g for g in REQUIRED if g not in columns]
        if missing:
            raise _fail(source, "columns", f"needs a position for {', '.join(missing)}")
    separator = _get(data, source, "separator", str, None)
    if regex is not None and separator is not None:
        raise _fail(source, "separator", "only with columns (a regex says where the fields are)")
    if separator is not None:
        if separator == "whitespace":
            separator = None
        elif separator == "\\t":
            separator = "\t"
        elif len(separator) != 1:
            raise _fail(source, "separator", f"one character, \"\\t\" or \"whitespace\", got {separator!r}")
    data_to_end = _get(data, source, "data_to_end", bool, False)
    if data_to_end and regex is not None:
        raise _fail(source, "data_to_end", "only with columns")
    unit = _get(data, source, "time_unit", str, "s")
    if unit not in TIME_UNITS:
        raise _fail(source, "time_unit", f"{unit!r}: choose from {', '.join(TIME_UNITS)}")
    choice = {}
    for key, options in _CHOICES.items():
        value = _get(data, source, key, str, options[0])
        if value not in options:
            raise _fail(source, key, f"{value!r}: choose from {', '.join(options)}")
        choice[key] = value
    if choice["extended"] == "field" and not ("ext" in columns or (regex is not None and "ext" in regex.groupindex)):
        raise _fail(source, "extended", "'field' needs an ext field (a regex group or a column)")
    skip = _get(data, source, "skip_lines", int, 0)
    if not 0 <= skip <= 10000:
        raise _fail(source, "skip_lines", f"expected 0-10000, got {skip}")
    comment = _get(data, source, "comment", str, None)
    if comment == "":
        raise _fail(source, "comment", "must not be empty (every line would be a comment)")
    ext_values = _strings(data, source, "extended_values", ["x", "ext", "extended", "true", "1", "e"])
    tx_values = _strings(data, source, "tx_values", ["tx", "t", "transmit"])
    base = _get(data, source, "channel_base", int, 0)
    if base not in (0, 1):
        raise _fail(source, "channel_base", f"0 or 1, got {base}")
    return TextLayout(name=name, source=source, regex=regex, separator=separator, columns=columns,
                      data_to_end=data_to_end, time_exp=TIME_UNITS[unit], time_hex=choice["time_encoding"] == "hex",
                      id_base=16 if choice["id_encoding"] == "hex" else 10, data_encoding=choice["data_encoding"],
                      skip_lines=skip, comment=comment, extended=choice["extended"],
                      extended_values=ext_values, tx_values=tx_values, channel_base=base)


def _strings(data: dict[str, Any], source: str, key: str, default: list[str]) -> frozenset[str]:
    value = _get(data, source, key, list, default)
    if not all(isinstance(v, str) for v in value):
        raise _fail(source, key, f"expected a list of strings, got {value!r}")
    return frozenset(v.strip().lower() for v in value)


def load_layout(path: str | os.PathLike[str]) -> TextLayout:
    """Read and validate a description file; FormatFileError for a missing, unreadable or wrong one."""
    p = Path(path)
    try:
        with p.open("rb") as fh:
            raw = fh.read(MAX_DESCRIPTION_BYTES + 1)
    except OSError as exc:
        raise FormatFileError(f"{p}: cannot read the format description ({exc.strerror or exc})") from None
    if len(raw) > MAX_DESCRIPTION_BYTES:
        raise FormatFileError(f"{p.name}: a format description is at most 64 kB")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise FormatFileError(f"{p.name}: not UTF-8 text") from None
    return parse_layout(text, p.name)


_registered: list[TextLayout] = []


def register_format_file(path: str | os.PathLike[str]) -> TextLayout:
    """Validate a description and let it take part in recognising logs in this process (first wins)."""
    layout = load_layout(path)
    _registered.insert(0, layout)
    return layout


def user_layouts() -> list[TextLayout]:
    """The registered descriptions, then those of ``LASHSCOPE_FORMAT_FILES`` (files, or folders of ``*.toml``).

    A listed file that is wrong raises FormatFileError: a misconfigured format is said, not ignored.
    """
    found = list(_registered)
    for entry in filter(None, os.environ.get(ENV, "").split(os.pathsep)):
        p = Path(entry)
        files = sorted(p.glob("*.toml")) if p.is_dir() else [p]
        found.extend(_cached(f) for f in files)
    return found


_cache: dict[Path, tuple[float, TextLayout]] = {}


def _cached(path: Path) -> TextLayout:
    try:
        mtime = path.stat().st_mtime
    except OSError:
        mtime = -1.0
    hit = _cache.get(path)
    if hit is not None and hit[0] == mtime:
        return hit[1]
    layout = load_layout(path)
    _cache[path] = (mtime, layout)
    return layout


FORMAT = LogFormat(name="described", reader="DescribedReader", label="a text format described in a TOML file",
                   order=1000)  # last: the help texts end with it ("... or a text format described in a TOML file")


class DescribedReader(LineFrameReader):
    """Reads a text log with a :class:`TextLayout` (see the module docstring)."""

    fmt = FORMAT.name

    def __init__(self, stream: ByteStream, head: bytes, *, layout: TextLayout, **kwargs: Any) -> None:
        self.layout = layout
        self._skip = layout.skip_lines
        super().__init__(stream, head, **kwargs)

    def _open(self) -> None:
        self.meta.extra["description"] = self.layout.name
        lines = self._head.decode("latin-1").splitlines()[self.layout.skip_lines:1000]
        t = first_stamp(lines, self.layout.parse)
        if t is not None:
            self._set_origin(t)

    def _frame(self, line: str) -> LineFrame | None:
        if self._skip:
            self._skip -= 1
            return None
        return self.layout.parse(line)
