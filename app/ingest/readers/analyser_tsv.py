"""Tab-separated exports of a common USB-CAN analyser's PC software (the Nissan Leaf logs of
dalathegreat/EV-CANlogs are in this form).

::

    ParserFlags<TAB>Ch<TAB>Counter<TAB>T/R<TAB>Time<TAB>Flags<TAB>CAN ID<TAB>Len<TAB>Data<TAB>Parser Name<TAB>default
    1<TAB>0<TAB>1<TAB>RX<TAB>48659511<TAB><TAB>0x000001db<TAB>8<TAB>0xee c0 c3 ea 00 f7 61 9b <TAB>Default Parser<TAB>

One frame per row. Columns are found by their header names (``Ch``, ``T/R``, ``Time``,
``Flags``, ``CAN ID``, ``Len``, ``Data``), so exports with fewer or more trailing columns (some
lack ``Parser Name``) read the same; a file without the header uses the layout above.

- ``Time`` is milliseconds of the analyser's clock (the Leaf's 10 ms messages are 10 apart), an
  integer or a decimal: no absolute start (``start_clock = "unknown"``), ``t_ns`` counts from the
  first frame and ``meta.extra["clock_at_start_s"]`` keeps the analyser's clock there.
- ``CAN ID`` is always written as ``0x`` and eight hex digits, so its width says nothing about
  the frame format: an ID above 0x7FF is extended, and so is any frame whose ``Flags`` mention
  ``ext`` (``EXT``, ``Extended``, ``X``); ``Flags`` mentioning ``rtr``/``remote`` mark a remote frame.
- ``Data`` is the bytes in hex separated by spaces, the first with a ``0x`` prefix.
- ``Ch`` is the 0-based channel as written; ``T/R`` ``TX`` marks a transmitted frame.
"""

from __future__ import annotations

import re

from app.errors import LogFormatError
from app.ingest.frames import FrameFlag
from app.ingest.readers._text import (
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

EXT, RTR, TX = int(FrameFlag.EXTENDED), int(FrameFlag.REMOTE), int(FrameFlag.TX)

HEADER_LINE = r"(?i)^\ufeff?ParserFlags\tCh\tCounter\tT/R\tTime\t"
ROW = r"(?i)^\d+\t\d+\t\d+\t(RX|TX)\t\d+(\.\d+)?\t[^\t]*\t(0x)?[0-9A-Fa-f]{1,8}\t\d+\t"
FORMAT = LogFormat(name="analyser_tsv", reader="AnalyserTsvReader", label="USB-CAN analyser tab export", order=80,
                   lines=(HEADER_LINE, ROW))

HEADER = re.compile(HEADER_LINE)  # the export's header line, as the sniffer knows it

_DEFAULT_COLUMNS = {"ch": 1, "t/r": 3, "time": 4, "flags": 5, "can id": 6, "len": 7, "data": 8}
_FLAG_EXT = re.compile(r"ext|\bx\b", re.I)
_FLAG_RTR = re.compile(r"rtr|remote", re.I)


class AnalyserTsvReader(LineFrameReader):
    """USB-CAN analyser tab export reader (see the module docstring)."""

    fmt = FORMAT.name
    unit = "row"

    def _open(self) -> None:
        self._cols = dict(_DEFAULT_COLUMNS)
        first = self._head.decode("latin-1").split("\n", 1)[0].rstrip("\r").lstrip("\ufeff")
        if HEADER.match(first):
            names = [c.strip().lower() for c in first.split("\t")]
            missing = [n for n in ("time", "can id", "len", "data") if n not in names]
            if missing:
                raise LogFormatError(f"{self.name}: analyser export header lacks the column(s) "
                                     f"{', '.join(missing)}: {first[:80]!r}")
            self._cols = {n: names.index(n) for n in _DEFAULT_COLUMNS if n in names}
            self.meta.extra["header"] = first
        self.meta.extra["time_base"] = "analyser clock (milliseconds)"
        t = first_stamp(self._head.decode("latin-1").splitlines()[:1000], self.parse_row)
        if t is not None:
            self._set_origin(t)

    def parse_row(self, line: str) -> LineFrame | None:
        """One row as ``(analyser t_ns, channel, id, flags, len, payload)``; damage raises :class:`BadLine`."""
        s = line.rstrip("\r\n")
        if not s.strip() or HEADER.match(s):
            return None
        if not printable(s):
            raise BadLine("bad_line", "binary data (non-printable bytes) instead of an analyser row")
        f = s.split("\t")
        c = self._cols
        if len(f) <= c["data"]:
            raise BadLine("short_data", f"{len(f)} tab-separated fields, at least {c['data'] + 1} expected")
        t = decimal_to_ns(f[c["time"]].strip(), 6)
        id_tok = f[c["can id"]].strip()
        ident = parse_int(id_tok[2:] if id_tok[:2].lower() == "0x" else id_tok, 16, "CAN ID")
        if ident > 0x1FFFFFFF:
            raise BadLine("bad_line", f"CAN ID {id_tok} is larger than 29 bits")
        flags_text = f[c["flags"]] if "flags" in c else ""
        fl = EXT if ident > 0x7FF or _FLAG_EXT.search(flags_text) else 0
        if "t/r" in c and f[c["t/r"]].strip().upper() == "TX":
            fl |= TX
        channel = parse_int(f[c["ch"]].strip(), 10, "channel") if "ch" in c else 0
        if channel > 32767:
            raise BadLine("bad_line", f"channel {channel} out of range")
        length = parse_int(f[c["len"]].strip(), 10, "Len")
        if length > 8:
            raise BadLine("bad_line", f"Len {length}: a CAN frame has at most 8 data bytes")
        if _FLAG_RTR.search(flags_text):
            return t, channel, ident, fl | RTR, length, b""
        data = f[c["data"]].split()
        if data and data[0][:2].lower() == "0x":
            data[0] = data[0][2:]
        if len(data) > length:
            raise BadLine("bad_line", f"{len(data)} data bytes, but Len says {length}")
        return t, channel, ident, fl, length, hex_bytes(data, length)

    def _frame(self, line: str) -> LineFrame | None:
        return self.parse_row(line)
