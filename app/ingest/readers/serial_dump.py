"""Serial-console CAN dumps: one frame per line as a microcontroller bridge prints it over a UART,
captured by a terminal program (the Porsche Taycan logs of dalathegreat/EV-CANlogs: PuTTY logs).

::

    =~=~=~=~=~=~=~=~=~=~=~= PuTTY log 2025.05.22 09:20:45 =~=~=~=~=~=~=~=~=~=~=~=
    (566.87) RX0 3BE [8] FD 0B 97 00 00 00 00 80
    (566.87) RX0 1BFFDA00 [8] E3 EA 31 2E 80 EA F5 05
    (566.90) TX1 A8 [3] BD ED DF

- ``(t)``: seconds of the bridge's clock (since it started), decimal: no absolute start
  (``start_clock = "unknown"``), ``t_ns`` counts from the first frame and
  ``meta.extra["clock_at_start_s"]`` keeps the bridge's clock there. A PuTTY header's time (when
  the capture was opened, local time of the PC) is kept as ``meta.extra["capture_opened"]``: it is
  not the time of the first frame, so it does not become ``start_time``.
- ``RXn`` / ``TXn``: received or transmitted on channel ``n`` (0-based as printed).
- The ID in hex without leading zeros: more than three digits is a 29-bit (extended) ID, as the
  bridge prints an 11-bit ID with at most three (``FD``, ``3BE``, ``1BFFDA00``).
- ``[n]``: the data length (0-8, or a CAN FD length up to 64), then the bytes in hex.

Captures start in the middle of whatever the bridge was printing (``00``, `` 00 10 00 00``) and
end in the middle of a line; those lines are reported and skipped like every damaged line.
"""

from __future__ import annotations

import re

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

EXT, FD, TX = int(FrameFlag.EXTENDED), int(FrameFlag.FD), int(FrameFlag.TX)

_LINE = re.compile(r"^\(([^)]*)\)\s+([RT])X(\d+)\s+(\S+)\s+\[(\d+)\]\s*(.*)$", re.I)
_HEX_ID = re.compile(r"^[0-9A-Fa-f]{1,8}$")
_PUTTY = re.compile(r"PuTTY log (\d{4})\.(\d\d)\.(\d\d) (\d\d:\d\d:\d\d)")


def parse_serial_line(line: str) -> tuple[int, int, int, int, int, bytes] | None:
    """One dump line as ``(t_ns, channel, id, flags, length, payload)`` (None for blank and capture header
    lines); damage raises :class:`BadLine`."""
    s = line.strip()
    if not s or s.startswith("=~="):
        return None
    if not printable(s):
        raise BadLine("bad_line", "binary data (non-printable bytes) instead of a dump line")
    m = _LINE.match(s)
    if m is None:
        if s.startswith("(") and ")" in s:
            raise BadLine("short_data", f"line ends after its time stamp (line cut?): {s[:60]!r}")
        raise BadLine("bad_line", f"not a '(t) RXn ID [len] bytes' line: {s[:60]!r}")
    t = decimal_to_ns(m.group(1))
    channel = int(m.group(3))
    if channel > 32767:
        raise BadLine("bad_line", f"channel {channel} out of range")
    id_str = m.group(4)
    if not _HEX_ID.match(id_str):
        raise BadLine("non_hex", f"identifier {id_str[:20]!r} is not 1-8 hex digits")
    ident = int(id_str, 16)
    if ident > 0x1FFFFFFF:
        raise BadLine("bad_line", f"identifier {id_str} is larger than 29 bits")
    length = int(m.group(5))
    if length > 64 or (length > 8 and length not in LEN_TO_DLC):
        raise BadLine("bad_line", f"length [{length}] is not a CAN or CAN FD length")
    data = m.group(6).split()
    if len(data) > length:
        raise BadLine("bad_line", f"{len(data)} data bytes, but the length says {length}")
    fl = (EXT if len(id_str) > 3 else 0) | (FD if length > 8 else 0) | (TX if m.group(2) in "Tt" else 0)
    return t, channel, ident, fl, length, hex_bytes(data, length)


FORMAT = LogFormat(name="serial_dump", reader="SerialDumpReader", label="serial RXn/TXn dump", order=90,
                   lines=(r"^\(\d+(\.\d+)?\)\s+[RT]X\d+\s+[0-9A-Fa-f]{1,8}\s+\[\d+\]",))


class SerialDumpReader(LineFrameReader):
    """Serial ``(t) RXn ID [len] bytes`` dump reader (see the module docstring)."""

    fmt = FORMAT.name

    def _open(self) -> None:
        head = self._head.decode("latin-1")
        self.meta.extra["time_base"] = "bridge clock (seconds)"
        if (m := _PUTTY.search(head[:400])) is not None:
            self.meta.extra["capture_opened"] = f"{m.group(1)}-{m.group(2)}-{m.group(3)}T{m.group(4)}"
        t = first_stamp(head.splitlines()[:1000], parse_serial_line)
        if t is not None:
            self._set_origin(t)

    def _frame(self, line: str) -> LineFrame | None:
        return parse_serial_line(line)
