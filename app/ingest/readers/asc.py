"""Vector ASC: hex/dec base, absolute/relative timestamps, classic and FD frames, error and remote frames.

Lines handled (``<ts>`` is seconds since the measurement start, or since the previous
event when the header says ``timestamps relative``)::

    date Thu Apr 28 10:44:52.480 am 2022              absolute start (local time, ms)
    base hex  timestamps absolute                     number base, time mode
    Begin TriggerBlock ... / End TriggerBlock / // comment / internal events logged
    <ts> 1  18EBFF00x  Rx  d 8 01 02 03 04 05 06 07 08  [Length = ... trailer]
    <ts> 2  100  Tx  r [dlc]                          remote frame
    <ts> 1  ErrorFrame [details]                      error frame
    <ts> CANFD 1 Rx 1C4D80A7x [name] brs esi dlc len <len bytes> [trailer]
    <ts> CANFD 5 Tx ErrorFrame ...                    CAN FD error frame
    <ts> <anything else>                              other events (statistics, status, J1939TP, ...)

The common classic line goes through the vectorised scanner (:mod:`asc_scan`, numpy only);
all other lines through :meth:`ASCReader.parse_line`, which also diagnoses damaged lines.
Frame semantics follow python-can's ``ASCReader`` (channel = number - 1, DLC via
``dlc2len``, at most 8 bytes on classic frames), except that damaged lines are reported
and skipped instead of aborting or being silently shortened, that ``timestamps relative``
is honoured (python-can ignores it), and that a CANFD line with DLC 0 and no data is an
empty data frame (python-can makes every zero-length CANFD line a remote frame).
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from datetime import UTC, datetime
from typing import Any

import numpy as np

from app.ingest.frames import FrameChunk, FrameFlag
from app.ingest.readers._base import BaseReader, ChunkBuilder
from app.ingest.readers._text import BadLine, LineSource, decimal_to_ns, dlc2len, hex_bytes, parse_int, printable
from app.ingest.readers.asc_scan import scan_block
from app.ingest.readers.text_scan import Frame, block_lines, merge_rows
from app.log_formats import LogFormat

_TS = re.compile(r"^\d+\.\d+$")
_MONTHS = {"jan": 1, "feb": 2, "mar": 3, "mär": 3, "mrz": 3, "apr": 4, "may": 5, "mai": 5, "jun": 6, "jul": 7,
           "aug": 8, "sep": 9, "oct": 10, "okt": 10, "nov": 11, "dec": 12, "dez": 12}
_TIME = re.compile(r"^(\d{1,2}):(\d{2}):(\d{2})(?:\.(\d{1,6}))?$")
_I64_MAX = 2**63 - 1

EXT, FD, ERR, RTR, BRS, ESI, TX = (int(f) for f in (FrameFlag.EXTENDED, FrameFlag.FD, FrameFlag.ERROR,
                                                    FrameFlag.REMOTE, FrameFlag.BRS, FrameFlag.ESI, FrameFlag.TX))


# Text blocks of at least this many bytes go through the vectorised scanner (``asc_scan``);
# smaller ones are parsed line by line (the same result; tests switch between the two).
FAST_PATH_MIN_BYTES = 4096


def parse_asc_date(text: str) -> tuple[datetime, str] | None:
    """An ASC ``date`` header as (datetime, clock): naive local time, or UTC when it says GMT/UTC.

    Accepts Vector's ``Thu Apr 28 10:44:52.480 am 2022`` (German names too) and the
    RFC 1123 ``Thu, 09 Nov 2023 20:29:27 GMT`` some exporters write.
    """
    tokens = text.replace(",", " ").split()
    month = day = year = None
    hms: re.Match[str] | None = None
    pm: bool | None = None
    utc = False
    for tok in tokens:
        low = tok.lower()
        if month is None and low.isalpha() and low[:3] in _MONTHS:
            month = _MONTHS[low[:3]]
        elif (m := _TIME.match(tok)) is not None:
            hms = m
        elif low in ("am", "pm"):
            pm = low == "pm"
        elif low in ("gmt", "utc", "z"):
            utc = True
        elif tok.isdigit() and len(tok) == 4:
            year = int(tok)
        elif tok.isdigit() and len(tok) <= 2 and day is None:
            day = int(tok)
    if None in (month, day, year) or hms is None:
        return None
    hour, minute, second = int(hms.group(1)), int(hms.group(2)), int(hms.group(3))
    micro = int((hms.group(4) or "0").ljust(6, "0"))
    if pm is not None:
        if not 1 <= hour <= 12:
            return None
        hour = hour % 12 + (12 if pm else 0)
    try:
        dt = datetime(year, month, day, hour, minute, second, micro)  # type: ignore[arg-type]
    except ValueError:
        return None
    if utc:
        return dt.replace(tzinfo=UTC), "asc_date_header_utc"
    return dt, "asc_date_header_local"


EVENT_LINE = r"(?i)^\s*\d+\.\d+\s+(\d+\s+\w+x?\s+(Rx|Tx)\b|\d+\s+ErrorFrame|CANFD\s+\d+)"
FORMAT = LogFormat(name="asc", reader="ASCReader", label="Vector ASC", order=20, suffixes=(".asc",), lines=(
    r"(?i)^\s*date\s+\S+", r"(?i)^\s*base\s+(hex|dec)\b", r"(?i)^\s*(no\s+)?internal\s+events\s+logged",
    r"(?i)^\s*begin\s+triggerblock", EVENT_LINE))


class ASCReader(BaseReader):
    """Vector ASC reader (see the module docstring)."""

    fmt = FORMAT.name

    def _open(self) -> None:
        self.base = 16
        self.relative = False
        text = self._head.decode("latin-1")
        for line in text.splitlines()[:50]:
            s = line.strip()
            low = s.lower()
            if low.startswith("date ") and self.meta.start_time is None:
                parsed = parse_asc_date(s[5:])
                self.meta.extra["date_header"] = s[5:].strip()
                if parsed is not None:
                    self.meta.start_time, self.meta.start_clock = parsed
            elif low.startswith("base "):
                self._set_base(s)
            elif low.startswith("begin triggerblock"):
                self.meta.extra.setdefault("triggerblock", s[18:].strip())
                break
            elif s and s[0].isdigit():
                break

    def _set_base(self, s: str) -> None:
        tokens = s.lower().split()
        self.base = 10 if len(tokens) > 1 and tokens[1] == "dec" else 16
        if "timestamps" in tokens:
            i = tokens.index("timestamps")
            self.relative = i + 1 < len(tokens) and tokens[i + 1] == "relative"
        self.meta.extra["base"] = "dec" if self.base == 10 else "hex"
        self.meta.extra["timestamps"] = "relative" if self.relative else "absolute"

    # -- the slow path: one line, every rule ----------------------------------------------------
    def parse_line(self, line: str) -> tuple[int | None, Frame | None]:
        """Parse one line: ``(event time in ns or None, frame or None)``; damage raises :class:`BadLine`."""
        s = line.strip()
        if not s or s.startswith("//"):
            return None, None
        if not printable(s):
            raise BadLine("bad_line", "binary data (non-printable bytes) instead of an ASC line")
        tokens = s.split()
        head = tokens[0].lower()
        if head in ("date", "internal", "no", "end", "begin", "base"):
            if head == "base":
                self._set_base(s)
            elif head == "begin":
                self.meta.extra.setdefault("triggerblock", s[18:].strip())
            return None, None
        if not _TS.match(tokens[0]):
            if tokens[0].startswith("-") and _TS.match(tokens[0][1:]):
                raise BadLine("bad_timestamp", f"negative timestamp {tokens[0]}")
            raise BadLine("bad_line", f"not an ASC event line: {s[:60]!r}")
        ts = decimal_to_ns(tokens[0])
        if ts > _I64_MAX // 2:
            raise BadLine("bad_timestamp", f"timestamp {tokens[0]} is out of range")
        if len(tokens) < 3:
            return ts, None
        if tokens[1].upper() == "CANFD":
            return ts, self._fd_frame(tokens, ts)
        if tokens[1].isdigit():
            ch = self._channel(tokens[1])
            if tokens[2].lower() == "errorframe":
                return ts, (ts, ch, 0, ERR, 0, b"")
            if len(tokens) >= 4 and tokens[3] in ("Rx", "Tx"):
                return ts, self._classic_frame(tokens, ts, ch)
        return ts, None  # another event (statistics, chip status, J1939TP, start of measurement ...)

    @staticmethod
    def _channel(tok: str) -> int:
        ch = int(tok) - 1
        if not -1 <= ch <= 32766:
            raise BadLine("bad_line", f"channel {tok} out of range")
        return ch

    def _ident(self, tok: str) -> tuple[int, int]:
        ext = tok[-1:] in ("x", "X")
        ident = parse_int(tok[:-1] if ext else tok, self.base, "identifier")
        if ident > 0x1FFFFFFF:
            raise BadLine("bad_line", f"identifier {tok} exceeds 29 bits")
        return ident, EXT if ext else 0

    def _classic_frame(self, tokens: list[str], ts: int, ch: int) -> Frame:
        ident, fl = self._ident(tokens[2])
        if tokens[3] == "Tx":
            fl |= TX
        if len(tokens) > 4 and tokens[4][:1].lower() == "r":
            code = parse_int(tokens[5], self.base, "DLC") if len(tokens) > 5 and tokens[5].isdigit() else 0
            if code > 15:
                raise BadLine("bad_line", f"remote frame DLC {tokens[5]} out of range")
            return ts, ch, ident, fl | RTR, code, b""
        if len(tokens) < 6:
            raise BadLine("short_data", "data frame without a DLC")
        code = parse_int(tokens[5], self.base, "DLC")
        if code > 255:
            raise BadLine("bad_line", f"DLC {tokens[5]} out of range")
        length = dlc2len(code)
        payload = hex_bytes(tokens[6:], min(8, length), base=self.base)
        return ts, ch, ident, fl, length, payload

    def _fd_frame(self, tokens: list[str], ts: int) -> Frame:
        if len(tokens) < 5 or not tokens[2].isdigit():
            raise BadLine("bad_line", "CANFD line without channel and direction")
        ch = self._channel(tokens[2])
        fl = FD | (TX if tokens[3] == "Tx" else 0)
        if tokens[4].lower() == "errorframe":
            return ts, ch, 0, fl | ERR, 0, b""
        ident, ext = self._ident(tokens[4])
        fl |= ext
        rest = tokens[5:] if len(tokens) > 5 and tokens[5].isdigit() else tokens[6:]
        if len(rest) < 4:
            raise BadLine("short_data", "CANFD line without BRS, ESI, DLC and data length")
        brs, esi, dlc_tok, len_tok = rest[:4]
        if brs == "1":
            fl |= BRS
        if esi == "1":
            fl |= ESI
        code = parse_int(dlc_tok, self.base, "DLC")
        length = parse_int(len_tok, 10, "data length")
        if code > 15 or length > 64:
            raise BadLine("bad_line", f"CANFD DLC {dlc_tok} / data length {len_tok} out of range")
        if length == 0 and code != 0:  # no data for a non-zero DLC: a remote frame (python-can: any length 0)
            return ts, ch, ident, fl | RTR, code, b""
        payload = hex_bytes(rest[4:], length, base=self.base)
        if dlc2len(code) != length:
            self._mismatch += 1
        return ts, ch, ident, fl, length, payload

    # -- the loop -------------------------------------------------------------------------------
    def _iter_chunks(self) -> Iterator[FrameChunk]:
        builder = ChunkBuilder(self.chunk_frames)
        lines = LineSource(self._stream, self._long_line, self.damage)
        self._mismatch = 0
        self._t_acc = 0
        for block, first in lines.blocks():
            if len(block) < FAST_PATH_MIN_BYTES:
                yield from self._line_by_line(block, first, builder)
                continue
            pos, line_no = 0, first
            while pos < len(block):
                part = block if pos == 0 else block[pos:]
                used, rows = self._scan(part, line_no)
                yield from builder.extend(*rows)
                pos += used
                line_no += part.count(b"\n", 0, used)
        if self._mismatch:
            self.problem("dlc_mismatch", f"{self._mismatch} CANFD line(s) whose DLC does not match their data "
                         "length; the data length was used", count=self._mismatch)
        if builder.n:
            yield builder.take()

    def _line_by_line(self, block: bytes, first: int, builder: ChunkBuilder) -> Iterator[FrameChunk]:
        """Every line through :meth:`parse_line` (small blocks, and the reference the scanner is tested against)."""
        for i, raw in enumerate(block_lines(block)):
            got = self._slow(raw, first + i)
            if got is None:
                continue
            ts = got[0]
            if self.relative:
                self._t_acc += ts
                ts = self._t_acc
            if got[1] is not None:
                builder.add(ts, *got[1][1:])
                if builder.full:
                    yield builder.take()

    def _scan(self, block: bytes, first: int) -> tuple[int, tuple[Any, ...]]:
        """Frames of ``block`` in line order; returns the bytes used and the frame columns.

        Lines the scanner does not accept go through :meth:`parse_line` in order. A line that
        changes the number base or the time mode ends the pass there (the caller scans the rest).
        """
        scan = scan_block(block, self.base == 16)
        slow = np.flatnonzero(~scan.fast & ~scan.blank)
        mode = (self.base, self.relative)
        limit, used = len(scan.fast), len(block)
        events: list[tuple[int, int]] = []  # (line index, own time) of slow lines with a time
        frames: list[tuple[int, Frame]] = []
        for j in slow.tolist():
            raw = block[scan.starts[j]:scan.ends[j]]
            got = self._slow(raw, first + j)
            if got is not None:
                events.append((j, got[0]))
                if got[1] is not None:
                    frames.append((j, got[1]))
            if (self.base, self.relative) != mode:
                limit, used = j + 1, min(int(scan.ends[j]) + 1, len(block))
                break
        n_fast = int(np.count_nonzero(scan.fast[:limit]))
        cols = [scan.t_ns[:n_fast], scan.channel[:n_fast], scan.arb_id[:n_fast], scan.flags[:n_fast],
                scan.dlc[:n_fast]]
        data = scan.data[:n_fast]
        fast_line = np.flatnonzero(scan.fast[:limit])
        if mode[1]:  # relative: every event's time adds to the running time, in line order
            ev_line = np.concatenate([fast_line, np.array([e[0] for e in events], np.int64)])
            ev_t = np.concatenate([cols[0], np.array([e[1] for e in events], np.int64)])
            order = np.argsort(ev_line, kind="stable")
            absolute = np.empty_like(ev_t)
            absolute[order] = self._t_acc + np.cumsum(ev_t[order])
            if ev_t.size:
                self._t_acc = int(absolute[order[-1]])
            cols[0] = absolute[:n_fast]
            stamp = dict(zip((e[0] for e in events), absolute[n_fast:].tolist(), strict=True))
            frames = [(j, (stamp[j], *fr[1:])) for j, fr in frames]
        if frames:
            cols, data = merge_rows(fast_line, cols, data, frames)
        return used, (*cols, data)

    def _slow(self, raw: bytes, line_no: int) -> tuple[int, Frame | None] | None:
        """One line through the parser: (own time, frame or None), or None (no event, or damage reported)."""
        try:
            ts, frame = self.parse_line(raw.rstrip(b"\r").decode("latin-1"))
        except BadLine as bad:
            self.problem(bad.kind, f"line skipped: {bad.message}", line=line_no, frames_lost=None)
            return None
        if ts is None:
            return None
        return ts, frame

    def _long_line(self, line_no: int) -> None:
        self.problem("bad_line", "line skipped: longer than 64 kB (binary data?)", line=line_no)

