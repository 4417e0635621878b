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
PIECE = 512  # input bytes per call when re-inflating a damaged zlib stream


@dataclass(slots=True)
class Problem:
    kind: str
    message: str
    offset: int
    truncated: bool = False
    frames_lost: int | None = None  # None: the reader estimates from ``bytes_lost``
    bytes_lost: int | None = None  # file bytes skipped because of this problem


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
    """zlib-inflate one container, keeping whatever inflates before damage; cap the output size.

    Returns the bytes and an error description (None when the stream is complete and sound).
    A sound stream inflates in one call; a damaged one is inflated again in pieces
    (:func:`inflate_prefix`) so the output up to the byte where zlib detects the damage is kept.
    A stream whose only fault is its Adler-32 checksum inflated completely to bytes that are
    wrong somewhere unknown: nothing of it is kept.
    """
    d = zlib.decompressobj()
    try:
        out = d.decompress(payload, MAX_CONTAINER + 1)
    except zlib.error as exc:
        if "incorrect data check" in str(exc):
            return b"", f"corrupt zlib data ({exc}: the container inflates but its checksum fails)"
        return inflate_prefix(payload), f"corrupt zlib data ({exc})"
    if len(out) > MAX_CONTAINER or d.unconsumed_tail:
        return out[:MAX_CONTAINER], f"inflates beyond {MAX_CONTAINER} bytes"
    if not d.eof:
        return out, "zlib data ends before its end-of-stream marker"
    return out, None


def inflate_prefix(payload: bytes) -> bytes:
    """The output of a damaged zlib stream up to the input byte where inflation fails.

    Fed in pieces of :data:`PIECE` bytes; the piece that fails is fed again byte by byte from
    a copy of the state before it, so nothing inflated before the failing byte is lost.
    """
    d = zlib.decompressobj()
    out: list[bytes] = []
    for i in range(0, len(payload), PIECE):
        before = d.copy()
        try:
            out.append(d.decompress(payload[i:i + PIECE]))
        except zlib.error:
            d = before
            for k in range(i, min(i + PIECE, len(payload))):
                try:
                    out.append(d.decompress(payload[k:k + 1]))
                except zlib.error:
                    break
            break
        if d.eof:
            break
    return b"".join(out)


class ContainerStream:
    """Top-level objects of a BLF file as events (see the module docstring)."""

    def __init__(self, stream: ByteStream) -> None:
        self._stream = stream
        self._back = b""  # pushed-back bytes, read again (from ``_back_at`` on) before the stream
        self._back_at = 0
        self.off = 0  # file offset of the next byte ``_read`` returns

    def _read(self, n: int) -> bytes:
        if self._back_at < len(self._back):  # offset, not slicing: a large push-back is not copied per read
            out = self._back[self._back_at:self._back_at + n]
            self._back_at += len(out)
            if len(out) < n:
                out += self._stream.read(n - len(out))
        else:
            out = self._stream.read(n)
        self.off += len(out)
        return out

    def _unread(self, data: bytes) -> None:
        rest = self._back[self._back_at:]
        self._back, self._back_at = (data + rest if rest else data), 0
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
                              "signature", start_off, bytes_lost=found - start_off)
                return
            tail = buf[-3:]
        yield Problem("bad_signature", f"{reason}; no further object signature in the remaining "
                      f"{self.off - start_off} bytes", start_off, truncated=True, bytes_lost=self.off - start_off)

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
                pad = len(hdr) - len(hdr.lstrip(b"\0"))
                if 0 < pad <= 3:  # padding, then an object whose signature is damaged
                    self._unread(hdr[pad:])
                    continue
                if len(hdr) == 16 and is_container_header(b"LOBJ" + hdr[4:]):
                    # only the signature is damaged: the header is a container's, read it as one
                    yield Problem("bad_signature", f"no object signature at byte offset {off} ({hdr[:4]!r}) but a "
                                  "sound container header; read as a container", off, frames_lost=0, bytes_lost=0)
                    hdr = b"LOBJ" + hdr[4:]
                else:
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
            if otype == K.LOG_CONTAINER:
                fixed = self._true_extent(off, size, body, cut)
                if fixed is not None:
                    body, problem = fixed
                    cut = False
                    yield problem
            if cut:
                yield Problem("truncated", f"file ends inside the object at byte offset {off}: it declares {size} "
                              f"bytes, {16 + len(body)} are present", off, True)
            if otype == K.LOG_CONTAINER:
                yield Container(off, body, cut)
            else:
                yield Loose(off, hdr + body)

    def _true_extent(self, off: int, size: int, body: bytes, cut: bool) -> tuple[bytes, Problem] | None:
        """The body of a container whose size field is wrong, cut at the next container header.

        A sound container ends where the next object's signature (after 0-3 padding bytes) or
        the file's end begins. When it does not, its size field is damaged (over- or
        under-declared, by any amount): the container really ends at the next sound container
        header after its own, which is searched first inside the declared body, then in the
        bytes after it. Returns None when the declared size is right, or when no such header
        exists (then the declared size is all there is to go on).
        """
        peek = self._read(24)
        self._unread(peek)
        k = peek.find(b"LOBJ", 0, 8)
        if not cut and (not peek.strip(b"\0") or 0 <= k <= 3 or any(
                not peek[:p].strip(b"\0") and is_container_header(b"LOBJ" + peek[p + 4:p + 20]) for p in range(4))):
            return None  # the next object, the file's end, or the next container with a damaged signature
        j = find_container_header(body, CONTAINER_HEADER.size)
        if j < 0 and not cut:
            blocks: list[bytes] = []
            seen, tail = len(body), body[-15:]  # a header may straddle the block boundary
            while len(blocks) * SCAN_BLOCK < MAX_CONTAINER:
                block = self._read(SCAN_BLOCK)
                if not block:
                    break
                blocks.append(block)
                k = find_container_header(tail + block, 0)
                if k >= 0:
                    j = seen - len(tail) + k
                    break
                seen, tail = seen + len(block), (tail + block)[-15:]
            if j < 0:
                self._unread(b"".join(blocks))
                return None
            body = body + b"".join(blocks)
        elif j < 0:
            return None
        self._unread(body[j:])
        true_size = 16 + j
        return body[:j], Problem("bad_object_size", f"log container at byte offset {off} declares {size} bytes but "
                                 f"the next container header follows after {true_size}; the size was corrected",
                                 off, frames_lost=0, bytes_lost=0)


def is_container_header(b: bytes) -> bool:
    """True when the 16+ bytes ``b`` are a plausible LOG_CONTAINER header (signature, sizes, method)."""
    if len(b) < 16 or b[:4] != b"LOBJ":
        return False
    _sig, hsize, hver, size, otype = OBJ_BASE.unpack_from(b)
    if hsize != 16 or hver != 1 or otype != K.LOG_CONTAINER or not 32 <= size <= MAX_CONTAINER:
        return False
    return len(b) < 18 or int.from_bytes(b[16:18], "little") in (0, 2)


def find_container_header(buf: bytes, start: int) -> int:
    """Position of the first plausible container header in ``buf[start:]``, or -1."""
    j = buf.find(b"LOBJ", start)
    while j >= 0:
        if is_container_header(buf[j:j + 18]):
            return j
        j = buf.find(b"LOBJ", j + 1)
    return -1


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
