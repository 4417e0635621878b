"""SocketCAN ``candump -L`` logs (also python-can's ``CanutilsLogWriter``).

Line shapes::

    (1436509052.249713) vcan0 123#11223344          classic, 3 hex digits = 11-bit ID
    (1436509052.249713) vcan0 1F334455#1122         8 hex digits = 29-bit ID
    (1436509052.249713) can1 123##1112233           CAN FD: '##', a flags nibble (1 BRS, 2 ESI), data
    (1436509052.249713) can0 123#R  /  123#R5       remote frame (optional DLC)
    (1436509052.249713) can0 20000080#0000000000000000   error frame: CAN_ERR_FLAG in the ID
    (...) ... T / R                                 optional direction suffix (python-can)

Channels are numbered by first appearance; ``meta.channels`` maps them back to names.
Timestamps are epoch seconds (``gettimeofday``): ``start_time`` is the first frame's time,
``start_clock = "epoch_utc"`` and ``t_ns`` counts from it. Logs whose first timestamp is
before 2000 are taken as already relative (``start_clock = "unknown"``, times as logged).
Error frames keep the error class bits as ``arb_id`` and the 8 detail bytes as data
(python-can drops both).
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
    printable,
)
from app.log_formats import LogFormat

_LINE = re.compile(r"^\(([^)]*)\)\s+(\S+)\s+(\S+)(?:\s+([RrTt]))?$")
_HEX = re.compile(r"^[0-9A-Fa-f]*$")
CAN_ERR_FLAG = 0x20000000

EXT, FD, ERR, RTR, BRS, ESI, TX = (int(f) for f in (FrameFlag.EXTENDED, FrameFlag.FD, FrameFlag.ERROR,
                                                    FrameFlag.REMOTE, FrameFlag.BRS, FrameFlag.ESI, FrameFlag.TX))

Frame = tuple[int, str, int, int, int, bytes]  # absolute t_ns, interface, arb_id, flags, dlc, payload


def parse_candump_line(s: str) -> Frame | None:
    """One ``candump -L`` line as a frame (None for blank lines); damage raises :class:`BadLine`."""
    s = s.strip()
    if not s:
        return None
    if not printable(s):
        raise BadLine("bad_line", "binary data (non-printable bytes) instead of a candump line")
    m = _LINE.match(s)
    if m is None:
        raise BadLine("bad_line", f"not a candump -L line: {s[:60]!r}")
    t = decimal_to_ns(m.group(1))
    iface, frame, direction = m.group(2), m.group(3), m.group(4)
    id_str, sep, rest = frame.partition("#")
    if not sep or not id_str or len(id_str) > 8 or not _HEX.match(id_str):
        raise BadLine("non_hex", f"identifier {id_str!r} is not 1-8 hex digits")
    ident = int(id_str, 16)
    fl = TX if direction in ("T", "t") else 0
    if rest.startswith("#"):
        if len(rest) < 2 or not _HEX.match(rest[1]):
            raise BadLine("non_hex", f"CAN FD flags {rest[1:2]!r} are not a hex digit")
        fd_flags = int(rest[1], 16)
        fl |= FD | (BRS if fd_flags & 1 else 0) | (ESI if fd_flags & 2 else 0)
        hex_data = rest[2:]
    elif rest[:1] in ("R", "r"):
        dlc_str = rest[1:]
        if dlc_str and not (dlc_str.isdigit() and int(dlc_str) <= 8):
            raise BadLine("bad_line", f"remote frame DLC {dlc_str!r} is not 0-8")
        dlc = int(dlc_str) if dlc_str else 0
        return t, iface, ident & 0x1FFFFFFF, fl | RTR | (EXT if len(id_str) > 3 else 0), dlc, b""
    else:
        hex_data, _, raw_dlc = rest.partition("_")  # "_X": the raw DLC of an 8-byte frame (len8_dlc)
        if raw_dlc and not (len(raw_dlc) == 1 and _HEX.match(raw_dlc)):
            raise BadLine("non_hex", f"raw DLC suffix {raw_dlc!r} is not one hex digit")
    hex_data = hex_data.replace(".", "")
    if len(hex_data) % 2 or not _HEX.match(hex_data):
        raise BadLine("non_hex", f"data {hex_data[:40]!r} is not whole hex bytes")
    payload = bytes.fromhex(hex_data)
    limit = 64 if fl & FD else 8
    if len(payload) > limit or (fl & FD and len(payload) not in LEN_TO_DLC):
        raise BadLine("bad_line", f"{len(payload)} data bytes is not a valid {'CAN FD' if fl & FD else 'CAN'} length")
    if ident & CAN_ERR_FLAG and not fl & FD:
        return t, iface, ident & 0x1FFFFFFF, fl | ERR, len(payload), payload
    return t, iface, ident & 0x1FFFFFFF, fl | (EXT if len(id_str) > 3 else 0), len(payload), payload


FORMAT = LogFormat(name="candump", reader="CandumpReader", label="candump -L", order=30, suffixes=(".log",),
                   lines=(r"^\s*\(\d+(\.\d+)?\)\s+\S+\s+[0-9A-Fa-f]{3,8}#",))


class CandumpReader(LineFrameReader):
    """``candump -L`` reader (see the module docstring)."""

    fmt = FORMAT.name

    def _open(self) -> None:
        t = first_stamp(self._head.decode("latin-1").splitlines()[:1000], parse_candump_line)
        if t is not None:
            self._set_origin(t)

    def _frame(self, line: str) -> LineFrame | None:
        frame = parse_candump_line(line)
        if frame is None:
            return None
        t, iface, ident, fl, dlc, payload = frame
        return t, self._named_channel(iface), ident, fl, dlc, payload
