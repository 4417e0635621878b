"""Hex-stamped SD-card text logs, as the UWaterloo Formula Electric telemetry unit (TCU) writes them.

One frame per line, fixed width, no header, no separators::

    000000EAx08041001000070CF08D11D00
    ^^^^^^^^ ^^^^^^^^^^^^^^^^^^^^^^^^
    time     'x', 29-bit ID (8 hex digits), then the data bytes (2 hex digits each, 0..8 bytes)

The time stamp is milliseconds of the logger's own clock (since power-up), in hex: there
is no absolute start (``start_clock = "unknown"``) and ``t_ns`` is that clock in ns, so
1 ms is the resolution of every period measured from such a log. The ID field is always
eight digits and is a 29-bit (extended) identifier; the team's DBC defines its messages
with the extended bit. A line cut by a power loss (the last line of a file, typically) is
reported and skipped, like every damaged line.
"""

from __future__ import annotations

import re

from app.ingest.frames import FrameFlag
from app.ingest.readers._text import BadLine, LineFrame, LineFrameReader, first_stamp, printable
from app.log_formats import LogFormat

EXT = int(FrameFlag.EXTENDED)
_LINE = re.compile(r"^([0-9A-Fa-f]{1,12})x([0-9A-Fa-f]{8})([0-9A-Fa-f]*)$")

Frame = tuple[int, int, int, bytes]  # device t_ns, arb_id, flags, payload


def parse_tcu_line(line: str) -> Frame | None:
    """One log line as ``(t_ns, id, flags, payload)`` (None for a blank line); damage raises :class:`BadLine`."""
    s = line.strip()
    if not s:
        return None
    if not printable(s):
        raise BadLine("bad_line", "binary data (non-printable bytes) instead of a log line")
    m = _LINE.match(s)
    if m is None:
        if "x" not in s[:13]:
            raise BadLine("bad_line", f"no 'x' after the time stamp: {s[:40]!r}")
        stamp, _, rest = s.partition("x")
        if not re.fullmatch(r"[0-9A-Fa-f]{1,12}", stamp):
            raise BadLine("bad_timestamp", f"time stamp {stamp[:20]!r} is not 1-12 hex digits")
        if len(rest) < 8:
            raise BadLine("bad_line", f"identifier {rest!r} is shorter than 8 hex digits (line cut?)")
        raise BadLine("non_hex", f"identifier or data {rest[:40]!r} is not hex")
    t_ms, ident, data = int(m.group(1), 16), int(m.group(2), 16), m.group(3)
    if ident > 0x1FFFFFFF:
        raise BadLine("bad_line", f"identifier {m.group(2)} is larger than 29 bits")
    if len(data) % 2:
        raise BadLine("short_data", f"data {data!r} has an odd number of hex digits (line cut?)")
    if len(data) > 16:
        raise BadLine("bad_line", f"{len(data) // 2} data bytes; a CAN frame has at most 8")
    return t_ms * 1_000_000, ident, EXT, bytes.fromhex(data)


FORMAT = LogFormat(name="tcu", reader="TcuReader", label="TCU SD-card text", order=70,
                   lines=(r"^[0-9A-Fa-f]{8}x[0-9A-Fa-f]{8}(?:[0-9A-Fa-f]{2}){0,8}\s*$",))


class TcuReader(LineFrameReader):
    """TCU hex-stamped text reader (see the module docstring)."""

    fmt = FORMAT.name

    def _open(self) -> None:
        self.meta.extra["time_base"] = "logger clock (milliseconds since power-up)"
        t = first_stamp(self._head.decode("latin-1").splitlines()[:1000], parse_tcu_line)
        if t is not None:
            self._set_origin(t)

    def _frame(self, line: str) -> LineFrame | None:
        frame = parse_tcu_line(line)
        if frame is None:
            return None
        t, ident, fl, payload = frame
        return t, 0, ident, fl, len(payload), payload
