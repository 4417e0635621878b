"""The top level of a BLF file: a stream of container events, resynchronisation, read-ahead inflation.

:class:`ContainerStream` walks the file's top-level objects and turns them into events in
file order: a :class:`Container` (its raw bytes), a :class:`Loose` object outside any
container, a :class:`Problem` found on the way (bad signature, impossible size,
truncation) or the final :class:`Damage` of a gzip-wrapped file. It never reports by
itself, so the reader can handle problems in order even while :func:`read_ahead` is
already inflating later containers on a worker thread (zlib releases the GIL, so
inflation overlaps with decoding on a second core).
"""

from __future__ import annotations

import collections
import struct
import zlib
from collections.abc import Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass

from app.ingest.readers import blf_layout as K
from app.ingest.readers._source import ByteStream, StreamDamage

OBJ_BASE = struct.Struct("<4sHHLL")
CONTAINER_HEADER = struct.Struct("<H6xL4x")
MAX_CONTAINER = 64 << 20  # containers are 128 kB in practice; larger sizes are corrupt
SCAN_BLOCK = 1 << 16
READ_AHEAD = 4  # containers inflated ahead of the decoder


@dataclass(slots=True)
class Problem:
    kind: str
    message: str
    offset: int
    truncated: bool = False


@dataclass(slots=True)
class Container:
    off: int  # file offset of the container object
    body: bytes  # everything after the 16-byte base header
    cut: bool  # the file ends inside this container
    inflated: Future[tuple[bytes, str | None]] | None = None


@dataclass(slots=True)
class Loose:
    off: int
    obj: bytes


@dataclass(slots=True)
class Damage:
    exc: StreamDamage


Event = Problem | Container | Loose | Damage


def inflate(payload: bytes, unc_size: int) -> tuple[bytes, str | None]:
    """zlib-inflate one container in pieces, keeping whatever precedes damage; cap the output size.

    Returns the bytes and an error description (None when the stream is complete and sound).
    """
    d = zlib.decompressobj()
    out: list[bytes] = []
    produced = 0
    try:
        for i in range(0, len(payload), SCAN_BLOCK * 4):
            piece = d.decompress(payload[i:i + SCAN_BLOCK * 4], MAX_CONTAINER - produced + 1)
            out.append(piece)
            produced += len(piece)
            if produced > MAX_CONTAINER or d.unconsumed_tail:
                return b"".join(out)[:MAX_CONTAINER], f"inflates beyond {MAX_CONTAINER} bytes"
            if d.eof:
                break
    except zlib.error as exc:
        return b"".join(out), f"corrupt zlib data ({exc})"
    if not d.eof:
        return b"".join(out), "zlib data ends before its end-of-stream marker"
    return b"".join(out), None


class ContainerStream:
    """Top-level objects of a BLF file as events (see the module docstring)."""

    def __init__(self, stream: ByteStream) -> None:
        self._stream = stream
        self._back = b""  # pushed-back bytes, read again before the stream
        self.off = 0  # file offset of the next byte ``_read`` returns

    def _read(self, n: int) -> bytes:
        if self._back:
            out = self._back[:n]
            self._back = self._back[n:]
            if len(out) < n:
                out += self._stream.read(n - len(out))
        else:
            out = self._stream.read(n)
        self.off += len(out)
        return out

    def _unread(self, data: bytes) -> None:
        self._back = data + self._back
        self.off -= len(data)

    def _scan(self, start_off: int, reason: str) -> Iterator[Event]:
        """Skip to the next ``LOBJ`` (pushed back); yields the problem describing the skipped region."""
        tail = b""
        while True:
            block = self._read(SCAN_BLOCK)
            if not block:
                break
            buf = tail + block
            j = buf.find(b"LOBJ")
            if j >= 0:
                found = self.off - len(buf) + j
                self._unread(buf[j:])
                yield Problem("bad_signature", f"{reason}; skipped {found - start_off} bytes to the next object "
                              "signature", start_off)
                return
            tail = buf[-3:]
        yield Problem("bad_signature", f"{reason}; no further object signature in the remaining "
                      f"{self.off - start_off} bytes", start_off, truncated=True)

    def events(self, header_size: int) -> Iterator[Event]:
        """Every top-level object after the ``header_size``-byte file header, in file order."""
        try:
            got = len(self._read(header_size))
            if got < header_size:
                yield Problem("truncated", f"the file ends inside its {header_size}-byte header", got, True)
            yield from self._objects()
        except StreamDamage as exc:
            yield Damage(exc)

    def _objects(self) -> Iterator[Event]:
        while True:
            off = self.off
            hdr = self._read(16)
            if not hdr:
                return
            if hdr[:4] != b"LOBJ":
                k = hdr.find(b"LOBJ", 1, 8)
                if 0 < k <= 3:  # padding after the previous object
                    self._unread(hdr[k:])
                    continue
                if len(hdr) < 16 and not hdr.strip(b"\0"):
                    return  # trailing padding
                self._unread(hdr[1:])
                yield from self._scan(off, f"no object signature at byte offset {off}")
                continue
            if len(hdr) < 16:
                yield Problem("truncated", f"file ends inside an object header ({len(hdr)} of 16 bytes)", off, True)
                return
            _sig, _hsize, _hver, size, otype = OBJ_BASE.unpack(hdr)
            limit = MAX_CONTAINER if otype == K.LOG_CONTAINER else K.MAX_OBJECT_SIZE
            if size < (32 if otype == K.LOG_CONTAINER else 16) or size > limit:
                self._unread(hdr[4:])
                yield from self._scan(off, f"object at byte offset {off} declares an impossible size {size} "
                                      f"(type {otype})")
                continue
            body = self._read(size - 16)
            cut = len(body) < size - 16
            if cut:
                yield Problem("truncated", f"file ends inside the object at byte offset {off}: it declares {size} "
                              f"bytes, {16 + len(body)} are present", off, True)
            if otype == K.LOG_CONTAINER:
                yield Container(off, body, cut)
            else:
                yield Loose(off, hdr + body)


def read_ahead(events: Iterator[Event]) -> Iterator[Event]:
    """The same events, with zlib containers already being inflated on a worker thread."""
    pending: collections.deque[Event] = collections.deque()
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="blf-inflate") as pool:
        for ev in events:
            if isinstance(ev, Container) and len(ev.body) >= CONTAINER_HEADER.size:
                method, unc_size = CONTAINER_HEADER.unpack_from(ev.body)
                if method == 2:
                    ev.inflated = pool.submit(inflate, ev.body[CONTAINER_HEADER.size:], unc_size)
            pending.append(ev)
            if len(pending) > READ_AHEAD:
                yield pending.popleft()
        while pending:
            yield pending.popleft()
