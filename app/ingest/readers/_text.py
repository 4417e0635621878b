"""Helpers shared by the text readers: exact decimal times, hex bytes, DLC tables, bounded line reading,
and :class:`LineFrameReader`, the reading loop of every format with one frame per line."""

from __future__ import annotations

import re
from collections.abc import Callable, Iterable, Iterator
from datetime import UTC, datetime, timedelta
from typing import Any

from app.ingest.frames import FrameChunk, LogMeta
from app.ingest.readers._base import BaseReader, ChunkBuilder
from app.ingest.readers._source import ByteStream, StreamDamage

# CAN FD DLC code -> payload length (codes above 15 read as 64, like python-can's ``dlc2len``)
DLC_TO_LEN = (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64)
LEN_TO_DLC = {n: i for i, n in enumerate(DLC_TO_LEN)}

MAX_TIME_NS = 2**62  # keeps differences of two times inside int64
BLOCK_BYTES = 1 << 20  # text is read in blocks of whole lines
MAX_LINE_BYTES = 1 << 16  # a longer "line" is garbage; it is skipped up to the next newline

_DECIMAL = re.compile(r"^(\d+)(?:\.(\d*))?$")


class BadLine(Exception):
    """One line that cannot be used: ``kind`` is the report kind, the message says why."""

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind
        self.message = message


def dlc2len(dlc: int) -> int:
    return DLC_TO_LEN[dlc] if 0 <= dlc <= 15 else 64


def decimal_to_ns(text: str, scale_exp: int = 9, *, what: str = "timestamp") -> int:
    """An unsigned decimal time as integer ns, exactly (no float rounding).

    ``scale_exp`` is the number of ns per unit as a power of ten: 9 for seconds, 6 for
    milliseconds, 3 for microseconds. Digits beyond 1 ns are truncated (logs print at most
    ns resolution); values above 2**62 ns (146 years) are out of range.
    """
    m = _DECIMAL.match(text)
    if m is None:
        if text.startswith("-"):
            raise BadLine("bad_timestamp", f"negative {what} {text!r}")
        raise BadLine("bad_timestamp", f"{what} {text!r} is not a decimal number")
    whole, frac = m.group(1), m.group(2) or ""
    frac = (frac + "0" * scale_exp)[:scale_exp]
    value = int(whole[-30:]) * 10**scale_exp + (int(frac) if frac else 0)
    if len(whole) > 30 or value > MAX_TIME_NS:
        raise BadLine("bad_timestamp", f"{what} {text[:40]!r} is out of range")
    return value


def hex_bytes(tokens: list[str], n: int, *, base: int = 16, what: str = "data byte") -> bytes:
    """The first ``n`` tokens as bytes; non-hex or short input raises :class:`BadLine`.

    The tokens present are checked before their count, so a line with a garbled byte names
    that byte (``non_hex``) rather than reporting it one byte short (``short_data``).
    """
    if base == 16 and len(tokens) >= n:
        try:  # the common case, in C: every token two hex digits
            fast = bytes.fromhex(" ".join(tokens[:n]))
        except ValueError:
            pass
        else:
            if len(fast) == n:
                return fast
    out = bytearray(n)
    for i in range(min(n, len(tokens))):
        tok = tokens[i]
        try:
            v = int(tok, base)
        except ValueError:
            raise BadLine("non_hex", f"{what} {i + 1} {tok!r} is not a {'hex' if base == 16 else 'decimal'} "
                          "number") from None
        if not 0 <= v <= 255 or tok[0] in "+-":
            raise BadLine("non_hex", f"{what} {i + 1} {tok!r} is not a byte value")
        out[i] = v
    if len(tokens) < n:
        raise BadLine("short_data", f"{len(tokens)} data bytes present, {n} expected from the DLC")
    return bytes(out)


def parse_int(tok: str, base: int, what: str) -> int:
    """A non-negative integer token; anything else raises :class:`BadLine` (kind ``non_hex``)."""
    if not tok or tok[0] in "+-" or "_" in tok:
        raise BadLine("non_hex", f"{what} {tok!r} is not a {'hex' if base == 16 else 'decimal'} number")
    try:
        return int(tok, base)
    except ValueError:
        raise BadLine("non_hex", f"{what} {tok!r} is not a {'hex' if base == 16 else 'decimal'} number") from None


def printable(line: str) -> bool:
    """False for lines with control characters other than tab: binary garbage."""
    return line.isprintable() or line.replace("\t", " ").isprintable()  # in C: tab-separated lines are common


class LineSource:
    """Whole lines from a :class:`ByteStream` with 1-based line numbers; long garbage lines are cut.

    ``on_long`` is called with the line number of every line longer than ``MAX_LINE_BYTES``
    (the line is then skipped); ``on_damage`` with stream damage (reading then ends).
    """

    def __init__(self, stream: ByteStream, on_long: Callable[[int], None],
                 on_damage: Callable[[StreamDamage], None]) -> None:
        self._stream = stream
        self._on_long = on_long
        self._on_damage = on_damage
        self.line_no = 0

    def blocks(self) -> Iterator[tuple[bytes, int]]:
        """Blocks of whole lines (``\\n``-terminated except possibly the last) with the first line's number."""
        carry = b""
        skipping = False  # inside an over-long line: drop bytes until its newline
        while True:
            try:
                data = self._stream.read(BLOCK_BYTES)
            except StreamDamage as exc:
                self._on_damage(exc)
                carry = b""  # the line cut by the damage is part of what the damage report covers
                data = b""
            if not data:
                if carry and not skipping:
                    first = self.line_no + 1
                    self.line_no += carry.count(b"\n") + 1
                    yield carry, first
                return
            if skipping:
                nl = data.find(b"\n")
                if nl < 0:
                    continue
                data = data[nl + 1:]
                skipping = False
            buf = carry + data if carry else data
            cut = buf.rfind(b"\n") + 1
            if cut == 0:
                if len(buf) > MAX_LINE_BYTES:
                    self.line_no += 1
                    self._on_long(self.line_no)
                    carry, skipping = b"", True
                else:
                    carry = buf
                continue
            block, carry = buf[:cut], buf[cut:]
            pending_long = len(carry) > MAX_LINE_BYTES  # the tail is an over-long line
            first = self.line_no + 1
            self.line_no += block.count(b"\n")
            yield block, first
            if pending_long:
                self.line_no += 1
                self._on_long(self.line_no)
                carry, skipping = b"", True

    def lines(self) -> Iterator[tuple[int, str]]:
        """Decoded lines (latin-1, so any byte decodes; CR/LF stripped) with their numbers."""
        for block, first in self.blocks():
            parts = block.split(b"\n")
            if block.endswith(b"\n"):
                parts.pop()
            for i, raw in enumerate(parts):
                yield first + i, raw.rstrip(b"\r").decode("latin-1")


EPOCH_2000_NS = 946_684_800 * 10**9


def epoch_origin(meta: LogMeta, t_ns: int) -> int:
    """Time origin of a text log: its first stamp, so ``t_ns`` counts from the log's start as for BLF.

    A first stamp after the year 2000 is taken as epoch time and sets ``meta.start_time`` (UTC,
    microseconds) with ``start_clock = "epoch_utc"``. Anything smaller is a device or relative clock:
    no absolute start is claimed, and the clock's reading at the first frame is kept as
    ``meta.extra["clock_at_start_s"]`` (a string, exact to the ns) so times as the logger printed them
    can be recovered.
    """
    if t_ns < EPOCH_2000_NS:
        whole, frac = divmod(t_ns, 10**9)
        meta.extra["clock_at_start_s"] = f"{whole}.{frac:09d}".rstrip("0").rstrip(".")
        return t_ns
    meta.start_time = datetime.fromtimestamp(t_ns // 10**9, tz=UTC) + timedelta(microseconds=(t_ns % 10**9) // 1000)
    meta.start_clock = "epoch_utc"
    return t_ns


def first_stamp(lines: Iterable[str], parse: Callable[[str], tuple[Any, ...] | None]) -> int | None:
    """The earliest time stamp (ns, the first field of a parsed frame) among the lines that parse as frames.

    The earliest rather than the first: logs of several buses interleave with small backwards
    steps, and the origin should not leave the frames just before it at negative times. Lines that
    are not frames (``None``) or are damaged (:class:`BadLine`) are passed over.
    """
    earliest: int | None = None
    for line in lines:
        try:
            frame = parse(line)
        except BadLine:
            continue
        if frame is not None and (earliest is None or int(frame[0]) < earliest):
            earliest = int(frame[0])
    return earliest


LineFrame = tuple[int, int, int, int, int, bytes]  # absolute t_ns, channel, arb_id, flags, dlc, payload


class LineFrameReader(BaseReader):
    """A text log with one frame per line (candump, SavvyCAN CSV, TCU): the shared reading loop.

    Subclasses turn a line into a :data:`LineFrame` in :meth:`_frame` (None for lines that
    carry no frame, :class:`BadLine` for damage, reported with the line number as a skipped
    ``unit``). The first frame's time is the origin (:meth:`_set_origin`): ``t_ns`` starts at 0; an
    epoch stamp becomes ``start_time``, a device clock's reading is kept in ``meta.extra``.
    """

    unit = "line"  # what a skipped line is called in the report ("row" for CSV)
    _t0: int | None = None

    def _frame(self, line: str) -> LineFrame | None:  # pragma: no cover - abstract
        raise NotImplementedError

    def _set_origin(self, t: int) -> None:
        self._t0 = epoch_origin(self.meta, t)

    def _named_channel(self, name: str) -> int:
        """The channel number of an interface named in the log (``can0``...), numbered in order of appearance and
        listed in ``meta.channels``."""
        names: dict[str, int] = self.__dict__.setdefault("_channel_numbers", {})
        ch = names.get(name)
        if ch is None:
            ch = names[name] = len(names)
            self.meta.channels[ch] = name
        return ch

    def _iter_chunks(self) -> Iterator[FrameChunk]:
        builder = ChunkBuilder(self.chunk_frames)
        lines = LineSource(self._stream, self._long_line, self.damage)
        for line_no, line in lines.lines():
            try:
                frame = self._frame(line)
            except BadLine as bad:
                self.problem(bad.kind, f"{self.unit} skipped: {bad.message}", line=line_no)
                continue
            if frame is None:
                continue
            t, channel, ident, fl, dlc, payload = frame
            if self._t0 is None:
                self._set_origin(t)
            builder.add(t - (self._t0 or 0), channel, ident, fl, dlc, payload)
            if builder.full:
                yield builder.take()
        if builder.n:
            yield builder.take()

    def _long_line(self, line_no: int) -> None:
        self.problem("bad_line", f"{self.unit} skipped: longer than 64 kB (binary data?)", line=line_no)
