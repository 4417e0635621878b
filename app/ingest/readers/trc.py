"""PEAK-System TRC trace files, versions 1.0, 1.1, 1.2, 1.3, 2.0 and 2.1.

Columns per version (``;`` starts a comment; offsets are milliseconds since the start)::

    1.0   1)  17535  00000100  8  00 11 22 ...            number) offset id dlc data|RTR
    1.1   1)  17535.4  Tx  00000100  8  00 11 ...         ... type(Rx/Tx/Warng/Error) ...
    1.2   1)  17535.4  1  Tx  00000100  8  00 11 ...      ... bus type id dlc data
    1.3   1)  17535.400 1  Tx  00000100 -  8  00 11 ...   ... bus type id reserved dlc data
    2.x   columns named by ;$COLUMNS=N,O,T,B,I,d,R,L,D (l = length in 2.0)
          types DT, FD, FB (BRS), FE (ESI), BI (BRS+ESI), RR (remote), ER (error); ST/EC/EV skipped

``;$STARTTIME`` is days since 1899-12-30 in the recording PC's local time
(``start_clock = "trc_header_local"``; python-can reads it as UTC). Version 1.0 has only
a ``Start time:`` comment (``"trc_comment_local"``). Bus numbers are 1-based in the file
and stay so in our frames, as python-can's TRCReader keeps them (and PEAK tools show them);
files without a bus column are bus 1.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from datetime import datetime, timedelta
from typing import Any

import numpy as np

from app.errors import LogFormatError
from app.ingest.frames import FrameChunk, FrameFlag
from app.ingest.readers._base import BaseReader, ChunkBuilder
from app.ingest.readers._text import BadLine, LineSource, decimal_to_ns, dlc2len, hex_bytes, parse_int, printable
from app.ingest.readers.text_scan import Frame, block_lines, merge_rows
from app.ingest.readers.trc_scan import Layout, scan_block
from app.log_formats import LogFormat

EXT, FD, ERR, RTR, BRS, ESI, TX = (int(f) for f in (FrameFlag.EXTENDED, FrameFlag.FD, FrameFlag.ERROR,
                                                    FrameFlag.REMOTE, FrameFlag.BRS, FrameFlag.ESI, FrameFlag.TX))
_COMMENT_START = re.compile(r"Start time:\s*(\d{1,2})\.(\d{1,2})\.(\d{4})\s+(\d{1,2}):(\d{2}):(\d{2})(?:\.(\d{1,3}))?")
_V2_FRAME_TYPES = {"DT": 0, "FD": FD, "FB": FD | BRS, "FE": FD | ESI, "BI": FD | BRS | ESI, "RR": RTR}
_V2_EVENTS = {"ST", "EC", "EV", "ER"}

# Text blocks of at least this many bytes go through the vectorised scanner (``trc_scan``)
FAST_PATH_MIN_BYTES = 4096


def _bus(tok: str) -> int:
    """The 1-based bus number as written: the channel (python-can's TRCReader keeps it too)."""
    bus = parse_int(tok, 10, "bus")
    if not 1 <= bus <= 32767:
        raise BadLine("bad_line", f"bus number {tok} out of range")
    return bus


FORMAT = LogFormat(name="trc", reader="TRCReader", label="PEAK TRC", order=40, suffixes=(".trc",), lines=(
    r"^;\$(FILEVERSION|STARTTIME|COLUMNS)=", r"^\s*\d+\)\s+\d+(\.\d+)?\s+",
    r"^\s*\d+\s+\d+\.\d+\s+(DT|FD|FB|FE|BI|RR|ST|ER|EC|EV)\s"))


def _version_by_shape(line: str) -> str | None:
    """The 1.x version a frame line's columns show, for files without ``;$FILEVERSION`` (1.0 by default).

    1.0 has the identifier where 1.1 has the direction, and 1.2/1.3 a bus number before it; 1.3 a
    reserved ``-`` after the identifier. None where the line does not say.
    """
    tok = line.split()
    kinds = ("Rx", "Tx", "Warng", "Error")
    if len(tok) < 4 or not tok[0].endswith(")"):
        return None
    if tok[2] in kinds:
        return "1.1"
    if tok[3] in kinds and tok[2].isdigit():
        return "1.3" if len(tok) > 5 and tok[5] == "-" else "1.2"
    return None


class TRCReader(BaseReader):
    """PEAK TRC reader (see the module docstring)."""

    fmt = FORMAT.name

    def _open(self) -> None:
        self.version = "1.0"
        self.columns: dict[str, int] = {}
        declared, first_line = False, ""
        for line in self._head.decode("latin-1").splitlines()[:200]:
            s = line.strip()
            if not s.startswith(";"):
                if s:
                    first_line = s
                    break
                continue
            key, _, value = s[1:].partition("=")
            if key == "$FILEVERSION":
                self.version, declared = value.strip(), True
            elif key == "$STARTTIME":
                try:
                    days = float(value)
                    self.meta.start_time = datetime(1899, 12, 30) + timedelta(days=days)
                    self.meta.start_clock = "trc_header_local"
                except (ValueError, OverflowError):
                    self.problem("bad_header", f"unreadable $STARTTIME {value!r}", line=None)
            elif key == "$COLUMNS":
                self.columns = {c.strip(): i for i, c in enumerate(value.split(","))}
            elif self.meta.start_time is None and (m := _COMMENT_START.search(s)) is not None:
                d, mo, y, h, mi, sec, ms = m.groups()
                try:
                    self.meta.start_time = datetime(int(y), int(mo), int(d), int(h), int(mi), int(sec),
                                                    int((ms or "0").ljust(3, "0")) * 1000)
                    self.meta.start_clock = "trc_comment_local"
                except ValueError:
                    pass
        if not declared and (shaped := _version_by_shape(first_line)) is not None:
            self.version = shaped
            self.meta.extra["trc_version_from"] = "line shape (no $FILEVERSION)"
        self.meta.extra["trc_version"] = self.version
        if self.version not in ("1.0", "1.1", "1.2", "1.3", "2.0", "2.1"):
            self.problem("bad_header", f"unknown TRC version {self.version!r}; reading as 1.0")
            self.version = "1.0"
        if self.version.startswith("2"):
            missing = {"O", "T", "I", "D"} - set(self.columns)
            if missing or not ({"L", "l"} & set(self.columns)):
                raise LogFormatError(f"{self.name}: TRC {self.version} header lacks the $COLUMNS entries "
                                f"{sorted(missing) or 'L/l'}")

    # -- per version ------------------------------------------------------------------------------
    def parse_line(self, s: str) -> Frame | None:
        """One data line as a frame, or None for non-frame events; damage raises :class:`BadLine`."""
        if not printable(s):
            raise BadLine("bad_line", "binary data (non-printable bytes) instead of a TRC line")
        tok = s.split()
        if self.version.startswith("2"):
            return self._v2(tok)
        if not tok[0].endswith(")"):
            raise BadLine("bad_line", f"not a TRC {self.version} message line: {s[:60]!r}")
        if self.version == "1.0":
            if len(tok) < 4:
                raise BadLine("short_data", "fewer than 4 columns")
            t, ch, kind, rest = tok[1], 1, "Rx", tok[2:]
        elif self.version == "1.1":
            if len(tok) < 5:
                raise BadLine("short_data", "fewer than 5 columns")
            t, ch, kind, rest = tok[1], 1, tok[2], tok[3:]
        else:
            need = 6 if self.version == "1.2" else 7
            if len(tok) < need:
                raise BadLine("short_data", f"fewer than {need} columns")
            ch = _bus(tok[2])
            t, kind = tok[1], tok[3]
            rest = [tok[4], *tok[6:]] if self.version == "1.3" else tok[4:]
        t_ns = decimal_to_ns(t, 6, what="time offset")
        if kind == "Error":
            return t_ns, ch, 0, ERR, 0, b""
        if kind not in ("Rx", "Tx") or rest[0] == "FFFFFFFF":
            return None  # bus status ("Warng", bus-heavy info lines)
        id_tok, dlc_tok, data = rest[0], rest[1], rest[2:]
        ident = parse_int(id_tok, 16, "identifier")
        fl = (EXT if len(id_tok) > 4 else 0) | (TX if kind == "Tx" else 0)
        dlc = parse_int(dlc_tok, 10, "DLC")
        if dlc > 8:
            raise BadLine("bad_line", f"DLC {dlc} exceeds 8")
        if data[:1] == ["RTR"]:
            return t_ns, ch, ident, fl | RTR, dlc, b""
        return t_ns, ch, ident, fl, dlc, hex_bytes(data, dlc)

    def _v2(self, tok: list[str]) -> Frame | None:
        cols = self.columns
        n_fixed = len(cols) - 1  # the data column D is last and spans the rest of the line
        if len(tok) <= cols["T"]:
            raise BadLine("short_data", "line ends before the type column")
        kind = tok[cols["T"]]
        if kind in _V2_EVENTS:
            if kind == "ER":
                t_ns = decimal_to_ns(tok[cols["O"]], 6, what="time offset")
                ch = _bus(tok[cols["B"]]) if "B" in cols else 1
                return t_ns, ch, 0, ERR, 0, b""
            return None
        if kind not in _V2_FRAME_TYPES:
            raise BadLine("bad_line", f"unknown message type {kind!r}")
        if len(tok) < n_fixed:
            raise BadLine("short_data", f"{len(tok)} columns, {n_fixed} expected before the data")
        t_ns = decimal_to_ns(tok[cols["O"]], 6, what="time offset")
        ch = _bus(tok[cols["B"]]) if "B" in cols else 1
        id_tok = tok[cols["I"]]
        ident = parse_int(id_tok, 16, "identifier")
        fl = _V2_FRAME_TYPES[kind] | (EXT if len(id_tok) > 4 else 0)
        if "d" in cols and tok[cols["d"]] == "Tx":
            fl |= TX
        if "l" in cols:
            length = parse_int(tok[cols["l"]], 10, "data length")
        else:
            code = parse_int(tok[cols["L"]], 10, "DLC")
            length = dlc2len(code) if fl & FD else min(code, 8)
        if length > (64 if fl & FD else 8):
            raise BadLine("bad_line", f"data length {length} too long for a {'CAN FD' if fl & FD else 'CAN'} frame")
        if fl & RTR:
            return t_ns, ch, ident, fl, length, b""
        return t_ns, ch, ident, fl, length, hex_bytes(tok[cols["D"]:], length)

    def _iter_chunks(self) -> Iterator[FrameChunk]:
        builder = ChunkBuilder(self.chunk_frames)
        lines = LineSource(self._stream, self._long_line, self.damage)
        layout = Layout(self.version, self.columns)
        for block, first in lines.blocks():
            if len(block) < FAST_PATH_MIN_BYTES:
                yield from self._line_by_line(block, first, builder)
            else:
                yield from builder.extend(*self._scan(block, first, layout))
        if builder.n:
            yield builder.take()

    def _line_by_line(self, block: bytes, first: int, builder: ChunkBuilder) -> Iterator[FrameChunk]:
        """Every line through :meth:`parse_line` (small blocks, and the reference the scanner is tested against)."""
        for i, raw in enumerate(block_lines(block)):
            frame = self._slow(raw, first + i)
            if frame is not None:
                builder.add(*frame)
                if builder.full:
                    yield builder.take()

    def _scan(self, block: bytes, first: int, layout: Layout) -> tuple[Any, ...]:
        """Frames of ``block`` in line order: the scanner's, and the parser's for the lines it left."""
        tk, fast, cols, data = scan_block(block, layout)
        frames: list[tuple[int, Frame]] = []
        for j in np.flatnonzero(~fast & ~tk.blank).tolist():
            frame = self._slow(block[tk.starts[j]:tk.ends[j]], first + j)
            if frame is not None:
                frames.append((j, frame))
        if not frames:
            return (*cols, data)
        merged, data = merge_rows(np.flatnonzero(fast), list(cols), data, frames)
        return (*merged, data)

    def _slow(self, raw: bytes, line_no: int) -> Frame | None:
        """One line through the parser: its frame, or None (comments, events, damage reported)."""
        s = raw.rstrip(b"\r").decode("latin-1").strip()
        if not s or s.startswith(";"):
            return None
        try:
            return self.parse_line(s)
        except BadLine as bad:
            self.problem(bad.kind, f"line skipped: {bad.message}", line=line_no)
            return None

    def _long_line(self, line_no: int) -> None:
        self.problem("bad_line", "line skipped: longer than 64 kB (binary data?)", line=line_no)

