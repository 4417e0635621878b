"""Vector BLF: a strict, salvaging, streaming reader (our own; python-can's hangs and truncates silently).

File layout::

    file header (usually 144 bytes)   "LOGG", u32 header size, app/version bytes,
                                      u64 file size, u64 uncompressed size, u32 object count,
                                      u32 objects read, SYSTEMTIME start, SYSTEMTIME stop
    LOG_CONTAINER objects             "LOBJ" base header (16 bytes), u16 compression
                                      (0 none, 2 zlib), 6 reserved, u32 uncompressed size,
                                      4 reserved, then the (compressed) bytes of inner objects
    ...                               inner objects may straddle container boundaries

Containers are read one at a time (:mod:`blf_containers`; memory is bounded by a few
containers plus one chunk), inflated with zlib on a worker thread and decoded whole by
numpy (:mod:`blf_vector`). A container that is not a clean chain of objects is walked
object by object by the compiled kernel in :mod:`blf_kernel`, which diagnoses what is
wrong. Damage is reported with the file offset of the enclosing container; reading
resumes at the next signature. The start time is the header's SYSTEMTIME, which Vector
tools write in local time (python-can reads it as UTC, its issue 1992):
``start_clock = "blf_header_local"``.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from datetime import datetime
from typing import Any

import numpy as np

from app.errors import LogFormatError, TruncatedLogError
from app.ingest.frames import FrameChunk, ReadIssue
from app.ingest.readers import blf_layout as K
from app.ingest.readers._base import BaseReader, ChunkBuilder
from app.ingest.readers._source import inflate_cap, too_large
from app.ingest.readers.blf_containers import (
    CONTAINER_HEADER,
    Container,
    ContainerStream,
    Loose,
    Problem,
    inflate,
    read_ahead,
)
from app.ingest.readers.blf_vector import decode_run
from app.log_formats import LogFormat

FILE_HEADER = struct.Struct("<4sLBBBBBBBBQQLL8H8H")

# Non-CAN objects skipped without an issue (they carry no frames); other types get an
# "unknown_object" entry. DATA_LOST_* mean the logger itself dropped data: reported.
KNOWN_OTHER = {
    3: "CAN_OVERLOAD", 4: "CAN_STATISTIC", 5: "APP_TRIGGER", 10: "LOG_CONTAINER", 31: "CAN_DRIVER_ERROR",
    44: "CAN_DRIVER_SYNC", 65: "APP_TEXT", 72: "SYS_VARIABLE", 74: "CAN_DRIVER_ERROR_EXT", 92: "EVENT_COMMENT",
    96: "GLOBAL_MARKER", 115: "RESTORE_POINT_CONTAINER", 127: "WATER_MARK_EVENT", 128: "TRIGGER_CONDITION",
}
DATA_LOST = {125: "DATA_LOST_BEGIN", 126: "DATA_LOST_END"}


def _walk_objects() -> Any:
    """The compiled fallback walker, imported on first need (numba has a fixed start-up cost)."""
    from app.ingest.readers.blf_kernel import walk_objects  # lazy: numba start-up

    return walk_objects


def _starts_frame(c: bytes) -> bool:
    """True when ``c`` begins (after up to 3 padding bytes) with the header of a CAN object."""
    j = c.find(b"LOBJ", 0, 7)
    return 0 <= j <= 3 and len(c) >= j + 16 and struct.unpack_from("<L", c, j + 12)[0] in K.FRAME_TYPES


def _sound_header(buf: bytes, j: int) -> bool:
    """True when a complete, plausible inner object base header starts at ``j`` (-1: none)."""
    if j < 0 or j + 16 > len(buf):
        return False
    hsize, hver, size, _otype = struct.unpack_from("<HHLL", buf, j + 4)
    return (hver, hsize) in ((1, 32), (2, 40)) and hsize <= size <= K.MAX_OBJECT_SIZE


def systemtime(fields: tuple[int, ...]) -> datetime | None:
    """Windows SYSTEMTIME (year, month, weekday, day, h, min, s, ms) as a naive datetime, or None."""
    year, month, _dow, day, hour, minute, second, ms = fields
    try:
        return datetime(year, month, day, hour, minute, second, ms * 1000)
    except ValueError:
        return None


FORMAT = LogFormat(name="blf", reader="BLFReader", label="Vector BLF", order=10, suffixes=(".blf",),
                   magic=(b"LOGG",))


class BLFReader(BaseReader):
    """Vector BLF reader; see the module docstring for the layout and policies."""

    fmt = FORMAT.name

    def _open(self) -> None:
        head = self._head
        if head[:4] != b"LOGG":
            raise LogFormatError(f"{self.name}: not a BLF file (signature {head[:4]!r}, expected b'LOGG')")
        if len(head) < FILE_HEADER.size:
            declared = int.from_bytes(head[4:8], "little") if len(head) >= 8 else 144
            size = declared if FILE_HEADER.size <= declared <= 4096 else 144
            raise TruncatedLogError(f"{self.name}: the file ends inside its {size}-byte header after "
                                    f"{len(head)} bytes")
        h = FILE_HEADER.unpack_from(head)
        self._header_size = int(h[1])
        if not FILE_HEADER.size <= self._header_size <= 4096:
            self.problem("bad_header", f"file header size {self._header_size} is implausible; assuming 144",
                         offset=4)
            self._header_size = 144
        start, stop = systemtime(h[14:22]), systemtime(h[22:30])
        self.meta.start_time = start
        self.meta.start_clock = "blf_header_local" if start else "unknown"
        self._declared_size = 0 if self._stream.compressed else int(h[10])
        self.meta.extra.update({
            "application_id": str(h[2]), "application_version": f"{h[3]}.{h[4]}.{h[5]}",
            "header_object_count": str(h[12]),
        })
        if stop is not None:
            self.meta.extra["stop_time_local"] = stop.isoformat()

    # -- outer loop ------------------------------------------------------------------------------
    def _iter_chunks(self) -> Iterator[FrameChunk]:
        self._carry = b""
        self._carry_src = (0, 0)  # (container offset, byte inside it) where the carry starts
        self._resync_inner = False
        self._truncation_reported = False
        self._type_counts = np.zeros(256, np.int64)
        self._inner_resync: ReadIssue | None = None
        self._inflated = 0  # container bytes walked (after inflation)
        self._inflate_cap = inflate_cap(self.size)  # zlib containers: the same cap as a gzipped log's
        self._estimates: list[tuple[ReadIssue, bool]] = []  # (issue, counted in inflated bytes)
        builder = ChunkBuilder(self.chunk_frames)
        top = ContainerStream(self._stream)
        for ev in read_ahead(top.events(self._header_size)):
            if isinstance(ev, Container):
                yield from self._container(ev, builder)
            elif isinstance(ev, Loose):
                yield from self._loose_object(ev.off, ev.obj, builder)
            elif isinstance(ev, Problem):
                issue = self.problem(ev.kind, ev.message, offset=ev.offset, truncated=ev.truncated,
                                     frames_lost=ev.frames_lost, bytes_lost=ev.bytes_lost)
                if ev.frames_lost is None and ev.bytes_lost:
                    self._estimates.append((issue, False))
                if ev.bytes_lost:  # bytes were skipped: an object straddling them cannot be completed
                    self._drop_carry(ev.offset)
                self._truncation_reported |= ev.truncated
            else:
                self.damage(ev.exc)
                self._truncation_reported = True
        yield from self._finish(builder)
        if builder.n:
            yield builder.take()
        if not self._truncation_reported and top.off < self._declared_size:
            self.problem("truncated", f"the file ends after {top.off} bytes but its header declares "
                         f"{self._declared_size}", offset=top.off, truncated=True)
        self._summarise_objects()
        self._estimate_losses(max(1, top.off - self._header_size))

    def _container(self, ev: Container, builder: ChunkBuilder) -> Iterator[FrameChunk]:
        off, body, cut = ev.off, ev.body, ev.cut
        if len(body) < CONTAINER_HEADER.size:
            return  # truncation already reported
        method, unc_size = CONTAINER_HEADER.unpack_from(body)
        payload = body[CONTAINER_HEADER.size:]
        broken = cut
        if method == 0:
            data = payload
        elif method == 2:
            data, error = ev.inflated.result() if ev.inflated is not None else inflate(payload, unc_size)
            broken = broken or error is not None
            if error is not None and not cut:
                data = self._verified_prefix(data)
                lost = max(0, unc_size - len(data))
                issue = self.problem("corrupt_zlib", f"log container at byte offset {off}: {error}; the objects "
                                     f"in the first {len(data)} of {unc_size} bytes are kept, reading resumes at "
                                     "the next container", offset=off, bytes_lost=lost)
                self._estimates.append((issue, True))
        else:
            issue = self.problem("unknown_compression", f"log container at byte offset {off} uses compression "
                                 f"method {method} (known: 0 none, 2 zlib); container skipped", offset=off,
                                 bytes_lost=16 + len(body))
            self._estimates.append((issue, False))
            self._drop_carry(off)
            return
        if method == 0 and not cut and len(data) > unc_size:
            data = data[:unc_size]  # a corrected container size leaves the padding in the body
        self._inflated += len(data)
        if self._inflated > self._inflate_cap[0]:
            raise too_large(self.name, *self._inflate_cap)
        yield from self._walk(data, off, builder)
        if broken:
            self._drop_carry(off)

    def _verified_prefix(self, data: bytes) -> bytes:
        """The part of a damaged container's bytes whose objects chain to a following sound header.

        zlib detects damage some bytes after it begins, and what it inflated in between is
        garbage that may still look like objects (a back-reference copies old ones). Only
        objects followed by the next object's sound header where their size says are kept, and
        the last of them is dropped too: garbage just before the detected damage can still chain
        to a header that zlib happened to inflate right.
        """
        buf = self._carry + data
        pos = buf.find(b"LOBJ") if self._resync_inner else 0
        if pos < 0:
            return b""
        last = pos
        while True:
            j = buf.find(b"LOBJ", pos, pos + 8)
            if j < 0 or j - pos > 3 or not _sound_header(buf, j):
                break
            nxt = j + struct.unpack_from("<L", buf, j + 8)[0]
            k = buf.find(b"LOBJ", nxt, nxt + 8)
            if k < 0 or k - nxt > 3 or not _sound_header(buf, k):
                break
            last, pos = pos, nxt
        keep = last - len(self._carry)
        return data[:max(0, keep)]

    def _drop_carry(self, off: int) -> None:
        """After a damaged container the bytes that straddle into the next one are meaningless."""
        if self._carry.strip(b"\0") and _starts_frame(self._carry):
            self.problem("truncated", f"an object straddling into the damaged container at byte offset {off} "
                             "is lost", offset=off, frames_lost=1)
        self._carry = b""
        self._resync_inner = True

    def _loose_object(self, off: int, obj: bytes, builder: ChunkBuilder) -> Iterator[FrameChunk]:
        """An object outside any container (older writers): walk it on its own."""
        saved, saved_src, saved_resync = self._carry, self._carry_src, self._resync_inner
        self._carry, self._resync_inner = b"", False
        yield from self._walk(obj, off, builder)
        self._carry, self._carry_src, self._resync_inner = saved, saved_src, saved_resync

    # -- inner walk ------------------------------------------------------------------------------
    def _where(self, pos: int, carry_len: int, off: int) -> tuple[int, str]:
        if pos >= carry_len:
            return off, f"byte {pos - carry_len} of the container at byte offset {off}"
        coff, inner = self._carry_src
        return coff, f"byte {inner + pos} of the container at byte offset {coff}"

    def _walk(self, data: bytes, off: int, builder: ChunkBuilder) -> Iterator[FrameChunk]:
        carry = self._carry
        buf = carry + data if carry else data
        arr = np.frombuffer(buf, np.uint8)
        end = len(buf)
        pos = 0
        if self._resync_inner:
            j = buf.find(b"LOBJ")
            if j < 0:
                self._set_carry(buf, max(0, end - 3), len(carry), off)
                return
            pos, self._resync_inner = j, False
        decoded = decode_run(buf, pos)
        if decoded is not None:
            self._type_counts += decoded.type_counts
            yield from builder.extend(decoded.t_ns, decoded.channel, decoded.arb_id, decoded.flags, decoded.dlc,
                                      decoded.data)
            self._set_carry(buf, decoded.end, len(carry), off)
            return
        walk = _walk_objects()
        builder.widen()
        while True:
            st, pos, n, detail = walk(arr, pos, end, builder.t_ns, builder.channel, builder.arb_id,
                                                builder.flags, builder.dlc, builder.data, builder.n, builder.cap,
                                                self._type_counts)
            if n > builder.n:
                self._inner_resync = None  # decoded something: a later problem is a new region
            builder.n = n
            if st == K.ST_FULL:
                yield builder.take()
                continue
            if st == K.ST_END:
                self._set_carry(buf, pos, len(carry), off)
                return
            coff, where = self._where(pos, len(carry), off)
            if st in (K.ST_BAD_TS, K.ST_BAD_FRAME):
                what = "a timestamp beyond int64 ns" if st == K.ST_BAD_TS else "impossible content (> 64 data bytes)"
                self.problem("bad_frame", f"CAN object at {where} has {what}; object skipped", offset=coff,
                             frames_lost=1)
                pos += detail
                continue
            if st == K.ST_BAD_SIG:
                reason, start = f"no object signature at {where}", pos + 1
            elif st == K.ST_BAD_HEADER:
                reason, start = f"object at {where} has an unknown header (version {detail})", pos + 4
            else:
                reason, start = f"object at {where} declares an impossible size {detail}", pos + 4
            j = buf.find(b"LOBJ", start)
            if self._inner_resync is None:
                kind = "bad_signature" if st == K.ST_BAD_SIG else "bad_object_size"
                self._inner_resync = self.problem(kind, f"{reason}; skipped to the next object signature",
                                                  offset=coff, bytes_lost=0)
                self._estimates.append((self._inner_resync, True))
            skipped = (j if j >= 0 else max(pos, end - 3)) - pos
            self._inner_resync.bytes_lost = (self._inner_resync.bytes_lost or 0) + skipped
            if j < 0:
                self._set_carry(buf, max(pos, end - 3), len(carry), off)
                return
            pos = j

    def _set_carry(self, buf: bytes, pos: int, carry_len: int, off: int) -> None:
        if pos >= carry_len:
            self._carry_src = (off, pos - carry_len)
        else:
            coff, inner = self._carry_src
            self._carry_src = (coff, inner + pos)
        self._carry = buf[pos:]

    def _finish(self, builder: ChunkBuilder) -> Iterator[FrameChunk]:
        """At the end of the file: an incomplete last object is reported, and the objects after it salvaged."""
        rest = self._carry
        self._carry = b""
        if not rest.strip(b"\0"):
            return
        coff, inner = self._carry_src
        if not self._truncation_reported:
            self.problem("truncated", f"the file ends inside the object at byte {inner} of the container at byte "
                         f"offset {coff}", offset=coff, frames_lost=1 if _starts_frame(rest) else 0,
                         truncated=True)
        arr = np.frombuffer(rest, np.uint8)
        pos, resume = 0, False
        while True:
            builder.widen()
            if not resume:  # skip past the incomplete (or bad) object at ``pos``
                j = rest.find(b"LOBJ", pos + 4)
                if j < 0:
                    return
                pos = j
            st, pos, n, detail = _walk_objects()(arr, pos, len(rest), builder.t_ns, builder.channel, builder.arb_id,
                                                builder.flags, builder.dlc, builder.data, builder.n, builder.cap,
                                                self._type_counts)
            builder.n = n
            resume = st == K.ST_FULL
            if resume:
                yield builder.take()
            elif st in (K.ST_BAD_TS, K.ST_BAD_FRAME):
                pos += detail - 4

    def _estimate_losses(self, file_bytes: int) -> None:
        """Frames lost in regions known only by their size: bytes x the frames per byte read elsewhere."""
        frames = self.report.frames
        for issue, inflated in self._estimates:
            total = self._inflated if inflated else file_bytes
            if issue.frames_lost is None and issue.bytes_lost and frames and total:
                issue.frames_lost = max(1, round(issue.bytes_lost * frames / total))

    def _summarise_objects(self) -> None:
        counts = self._type_counts
        skipped = []
        for found in np.flatnonzero(counts):
            t, c = int(found), int(counts[found])
            if t in KNOWN_OTHER:
                skipped.append(f"{KNOWN_OTHER[t]}({t}) x{c}")
            elif t in DATA_LOST:
                self.problem("data_lost", f"the logger recorded {c} {DATA_LOST[t]} event(s): it dropped data "
                             "while recording", count=c)
            else:
                label = f"type {t}" if t < 255 else "types >= 255"
                self.problem("unknown_object", f"skipped {c} object(s) of {label} (not CAN)", count=c)
        if skipped:
            self.meta.extra["skipped_objects"] = ", ".join(skipped)
