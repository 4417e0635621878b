"""SocketCAN ``candump`` screen output with time stamps (``candump -t a can0 > drive.txt``), the layout
candump prints without ``-L``: one frame per line, the fields in aligned columns.

Line shapes::

     (1436509052.249713)  can0  123   [3]  11 22 33             -t a: epoch seconds; classic, 3 digits: 11-bit ID
     (1436509052.249713)  can0  1F334455   [2]  11 22          8 hex digits: 29-bit ID
     (1436509052.249713)  can1  123  [12]  00 11 22 ...         CAN FD: the length in two digits ([08] too)
     (1436509052.249713)  can0  123   [2]  remote request      remote frame
     (1436509052.249713)  can0  20000080   [8]  00 00 00 00 00 00 00 00   ERRORFRAME   CAN_ERR_FLAG in the ID
     (000.001204)  can0  123   [3]  11 22 33                     -t z: seconds since candump started
     (2015-07-09 19:57:32.249713)  can0  123   [3]  11 22 33     -t A: local date and time
     (1436509052.249713)  can0  RX B -  123  [08]  ...          -x: direction, then BRS/ESI of an FD frame
     (1436509052.249713)  can0  123   [3]  11 22 33   '."3'    -a: the bytes as ASCII (ignored)

Channels are numbered by first appearance; ``meta.channels`` maps them back to the interface names.
``-t a`` stamps are epoch seconds (``gettimeofday``): ``start_time`` is the first frame's time (UTC,
``start_clock = "epoch_utc"``) and ``t_ns`` counts from it; ``-t z`` stamps (before 2000) are
taken as relative (``start_clock = "unknown"``, the first stamp in ``extra["clock_at_start_s"]``);
``-t A`` stamps are the PC's local wall time (``start_clock = "candump_date_local"``, a naive
``start_time``; a clock change while logging shows as a jump). ``-t d`` prints the gap to the
previous frame, which cannot be told from ``-t z`` stamps: such a log reads with wrong times; without
``-t`` there is no time at all and every line is reported as skipped. The
lines ``-e`` adds under an error frame (indented with a tab) are passed over. Error frames keep the
error class bits as ``arb_id`` and the detail bytes as data, as for ``candump -L``.
"""

from __future__ import annotations

import re
from datetime import datetime, timedelta

from app.ingest.frames import FrameFlag
from app.ingest.readers._text import (
    LEN_TO_DLC,
    BadLine,
    LineFrame,
    LineFrameReader,
    decimal_to_ns,
    first_stamp,
    hex_bytes,
    printable,
)
from app.log_formats import LogFormat

LINE = (r"^\s*\((\d+\.\d+|\d{4}-\d\d-\d\d \d\d:\d\d:\d\d\.\d+)\)\s+(?![RT]X\d+\s)\S+\s+"
        r"((RX|TX)\s+[B-]\s+[E-]\s+)?([0-9A-Fa-f]{3}|[0-9A-Fa-f]{8})\s+\[\d\d?\]")
FORMAT = LogFormat(name="candump_screen", reader="CandumpScreenReader", label="candump screen output (-t a/z/A)",
                   order=100, lines=(LINE,))

EXT, FD, ERR, RTR, BRS, ESI, TX = (int(f) for f in (FrameFlag.EXTENDED, FrameFlag.FD, FrameFlag.ERROR,
                                                    FrameFlag.REMOTE, FrameFlag.BRS, FrameFlag.ESI, FrameFlag.TX))
CAN_ERR_FLAG = 0x20000000

_LINE = re.compile(r"^\(([^)]*)\)\s+(\S+)\s+(?:(RX|TX)\s+([B-])\s+([E-])\s+)?(\S+)\s+\[(\d+)\]\s*(.*)$")
_DATE = re.compile(r"^(\d{4}-\d\d-\d\d \d\d:\d\d:\d\d)\.(\d{1,9})$")
_HEX_ID = re.compile(r"^(?:[0-9A-Fa-f]{3}|[0-9A-Fa-f]{8})$")
_EPOCH = datetime(1970, 1, 1)

Frame = tuple[int, str, int, int, int, bytes, bool]  # t_ns, interface, arb_id, flags, dlc, payload, dated stamp


def _stamp(text: str) -> tuple[int, bool]:
    """A time stamp as ns: epoch or relative seconds, or (dated) the local wall time counted from 1970-01-01."""
    m = _DATE.match(text)
    if m is None:
        return decimal_to_ns(text), False
    try:
        wall = datetime.strptime(m.group(1), "%Y-%m-%d %H:%M:%S")
    except ValueError:
        raise BadLine("bad_timestamp", f"time stamp {text!r} is not a date and time") from None
    if wall < _EPOCH:
        raise BadLine("bad_timestamp", f"time stamp {text!r} is before 1970")
    whole = (wall - _EPOCH) // timedelta(seconds=1)
    return whole * 10**9 + int((m.group(2) + "00000000")[:9]), True


def parse_screen_line(line: str) -> Frame | None:
    """One line of candump's screen output as a frame (None for blank lines and ``-e`` explanations);
    damage raises :class:`BadLine`."""
    if line.startswith("\t") or not line.strip():
        return None
    s = line.strip()
    if not printable(s):
        raise BadLine("bad_line", "binary data (non-printable bytes) instead of a candump line")
    m = _LINE.match(s)
    if m is None:
        if not s.startswith("("):
            raise BadLine("bad_line", f"no time stamp (candump without -t a, -t z or -t A?): {s[:60]!r}")
        raise BadLine("bad_line", f"not a '(time) interface ID [length] bytes' line: {s[:60]!r}")
    t, dated = _stamp(m.group(1))
    iface, direction, brs, esi, id_str, len_str, rest = m.group(2, 3, 4, 5, 6, 7, 8)
    if not _HEX_ID.match(id_str):
        raise BadLine("non_hex", f"identifier {id_str[:20]!r} is not 3 or 8 hex digits")
    ident = int(id_str, 16)
    length = int(len_str)
    fd = len(len_str) == 2  # candump prints an FD length in two digits, a classic one in one
    if (length > 8 and not fd) or length > 64 or (fd and length not in LEN_TO_DLC):
        raise BadLine("bad_line", f"length [{len_str}] is not a {'CAN FD' if fd else 'CAN'} length")
    fl = (TX if direction == "TX" else 0) | (EXT if len(id_str) == 8 else 0)
    if fd:
        fl |= FD | (BRS if brs == "B" else 0) | (ESI if esi == "E" else 0)
    if rest == "remote request":
        return t, iface, ident & 0x1FFFFFFF, fl | RTR, length, b"", dated
    tokens = rest.split()
    extra = tokens[length:]
    if extra and extra[0] != "ERRORFRAME" and not extra[0].startswith("'"):
        raise BadLine("bad_line", f"{len(tokens)} data bytes, but the length says {length}")
    payload = hex_bytes(tokens, length)
    if ident & CAN_ERR_FLAG and len(id_str) == 8:
        return t, iface, ident & 0x1FFFFFFF, (fl & ~EXT) | ERR, length, payload, dated
    return t, iface, ident, fl, length, payload, dated


class CandumpScreenReader(LineFrameReader):
    """``candump -t a|z|A`` screen output reader (see the module docstring)."""

    fmt = FORMAT.name

    def _open(self) -> None:
        self._dated: bool | None = None
        lines = self._head.decode("latin-1").splitlines()[:1000]
        for line in lines:  # the first frame says which stamps the log has
            try:
                frame = parse_screen_line(line)
            except BadLine:
                continue
            if frame is not None:
                self._dated = frame[6]
                break
        t = first_stamp(lines, self._parse)
        if t is not None:
            self._set_origin(t)

    def _parse(self, line: str) -> Frame | None:
        frame = parse_screen_line(line)
        if frame is not None and self._dated is not None and frame[6] != self._dated:
            raise BadLine("bad_timestamp", "time stamp form changes (dated and numbered stamps in one log)")
        return frame

    def _set_origin(self, t: int) -> None:
        if not self._dated:
            super()._set_origin(t)
            return
        self._t0 = t
        self.meta.start_time = _EPOCH + timedelta(microseconds=t // 1000)
        self.meta.start_clock = "candump_date_local"

    def _frame(self, line: str) -> LineFrame | None:
        frame = self._parse(line)
        if frame is None:
            return None
        t, iface, ident, fl, dlc, payload, _ = frame
        return t, self._named_channel(iface), ident, fl, dlc, payload
