"""Opening a log source: a path or a caller's binary file object, gzip by magic, a peekable head.

Every reader consumes a :class:`ByteStream`: a forward-only byte stream that counts the
bytes it has handed out (so problems can be reported with a byte offset) and turns the
errors of a damaged gzip member into :class:`StreamDamage` instead of a foreign exception.

A gzip member inflates to at most :func:`inflate_cap` bytes, decided before any is read: the
smaller of ``LASHSCOPE_MAX_INFLATED_MB`` (:data:`MAX_INFLATED_BYTES` overrides it in code) and
:data:`MAX_INFLATE_RATIO` times the compressed size (at least :data:`MIN_INFLATED_BYTES`). CAN logs
compress 3-20x; a compression bomb (1000x) is refused with :class:`~app.errors.InflatedTooLargeError`
(413) after a bounded amount of work instead of keeping a reader busy for minutes.
"""

from __future__ import annotations

import contextlib
import gzip
import io
import os
import re
import stat
import sys
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import BinaryIO, Protocol, cast

from app.errors import InflatedTooLargeError, InputError, LogFormatError, LogNotFoundError, StorageError

GZIP_MAGIC = b"\x1f\x8b"
HEAD_BYTES = 65536  # enough for every format's header and a few hundred text lines
MAX_INFLATED_BYTES: int | None = None  # None: LASHSCOPE_MAX_INFLATED_MB from the settings
MAX_INFLATE_RATIO = 32  # inflated / compressed bytes of a gzipped log; CAN logs stay well below
MIN_INFLATED_BYTES = 32 * 2**20  # a small file may inflate this far whatever its ratio


def inflate_cap(compressed: int | None = None) -> tuple[int, str]:
    """Bytes a gzipped (or streamed, for MF4) log may inflate to, and the limit that sets it.

    ``compressed``: the stored size, None when unknown (a pipe): then only the configured cap."""
    if MAX_INFLATED_BYTES is not None:
        cap, why = MAX_INFLATED_BYTES, "LASHSCOPE_MAX_INFLATED_MB"
    else:
        cap, why = int(_max_inflated_mb() * 2**20), "LASHSCOPE_MAX_INFLATED_MB"
    if compressed is not None and max(MIN_INFLATED_BYTES, MAX_INFLATE_RATIO * compressed) < cap:
        cap, why = max(MIN_INFLATED_BYTES, MAX_INFLATE_RATIO * compressed), f"{MAX_INFLATE_RATIO}x its compressed size"
    return cap, why


def _max_inflated_mb() -> float:
    """``LASHSCOPE_MAX_INFLATED_MB`` as the settings read it.

    A command-line run that reads one log should not pay for loading the service's settings
    (a tenth of a second): where the settings are not loaded yet and the variable is unset or a
    plain positive decimal number, it is read here; anything else goes through the settings (and
    their error for a bad value). ``tests/ingest/test_inflate_cap.py`` holds both to the same answers.
    """
    if "app.settings" not in sys.modules:
        name = "lashscope_max_inflated_mb"  # the settings match environment names case-insensitively
        found = [v for k, v in os.environ.items() if k.lower() == name]
        if not found:
            return 4096.0  # the settings' default
        if len(found) == 1 and re.fullmatch(r"[0-9]{1,9}(\.[0-9]{1,9})?", found[0]) and float(found[0]) > 0:
            return float(found[0])
    from app.settings import get_settings  # lazy: pydantic settings cost 0.1 s (docstring)

    return get_settings().max_inflated_mb


def too_large(name: str, cap: int, why: str) -> InflatedTooLargeError:
    """The error for a log that inflates past ``cap`` bytes (``why``: the limit that set the cap)."""
    return InflatedTooLargeError(f"{name}: decompresses to more than the {cap / 2**20:g} MiB cap for compressed "
                                 f"logs ({why}); decompress it yourself or raise the cap")


class Readable(Protocol):
    def read(self, n: int = -1, /) -> bytes: ...

    def close(self) -> None: ...


class StreamDamage(Exception):
    """The decompressed stream ended early or is corrupt (gzip); ``truncated`` says which."""

    def __init__(self, message: str, *, truncated: bool) -> None:
        super().__init__(message)
        self.truncated = truncated


class _Prefixed:
    """Replays an already-read head, then continues with the wrapped stream (non-seekable input)."""

    def __init__(self, head: bytes, rest: Readable) -> None:
        self._head = head
        self._rest = rest

    def read(self, n: int = -1, /) -> bytes:
        if not self._head:
            return self._rest.read(n)
        if n < 0:
            out, self._head = self._head + self._rest.read(), b""
            return out
        out, self._head = self._head[:n], self._head[n:]
        return out

    def seekable(self) -> bool:
        return False

    def close(self) -> None:
        """The wrapped stream belongs to the caller."""


class ByteStream:
    """Forward-only reads with a running byte offset; gzip damage surfaces as :class:`StreamDamage`.

    Parameters
    ----------
    raw : BinaryIO
        The (possibly gzip-wrapped) stream positioned at the first byte of the log.
    name : str
        Display name used in every message (the file name, or ``"<stream>"``).
    compressed : bool
        True when ``raw`` is a gzip decompressor; offsets then count decompressed bytes.
    size : int, optional
        Bytes of the source (the file as stored, compressed or not) from the log's first byte.
    source_tell : callable, optional
        Bytes of a compressed source consumed so far (the decompressor reads ahead in blocks).
    """

    def __init__(self, raw: Readable, name: str, *, compressed: bool, closers: list[Readable],
                 size: int | None = None, source_tell: Callable[[], int] | None = None) -> None:
        self._cap = inflate_cap(size) if compressed else None
        self._raw = raw
        self.name = name
        self.compressed = compressed
        self.size = size
        self._source_tell = source_tell
        self.offset = 0
        self._closers = closers
        self._pending: StreamDamage | None = None
        self._dead = False
        self.on_read: Callable[[], None] | None = None  # called after every read; may raise to stop the reading
        # gzip: read1 hands out what one inflate step produced, so the bytes before damage are
        # returned first (a buffered read(n) would discard them together with the error)
        read1 = getattr(raw, "read1", None) if compressed else None
        self._read: Callable[[int], bytes] = read1 if callable(read1) else raw.read

    def read(self, n: int) -> bytes:
        """Up to ``n`` bytes; fewer only at the end of the stream or just before damage.

        Damage found after some bytes were read is raised by the *next* call, so the bytes
        before it are never lost; after that the stream reads as ended.
        """
        if self._pending is not None:
            damage, self._pending, self._dead = self._pending, None, True
            raise damage
        if n <= 0 or self._dead:
            return b""
        chunks: list[bytes] = []
        want = n
        while want > 0:
            try:
                data = self._read(want)
            except EOFError as exc:  # gzip: member ended before its end-of-stream marker
                damage = StreamDamage(f"compressed stream ends early after {self.offset} bytes ({exc})",
                                      truncated=True)
            except (gzip.BadGzipFile, zlib.error, OSError) as exc:
                damage = StreamDamage(f"compressed stream is corrupt after {self.offset} bytes ({exc})",
                                      truncated=False)
            else:
                if not data:
                    break
                chunks.append(data)
                self.offset += len(data)
                want -= len(data)
                if self._cap is not None and self.offset > self._cap[0]:
                    raise too_large(self.name, *self._cap)
                continue
            if chunks:
                self._pending = damage
                break
            self._dead = True
            raise damage
        if self.on_read is not None:
            self.on_read()
        return chunks[0] if len(chunks) == 1 else b"".join(chunks)

    def position(self) -> int | None:
        """Bytes of the source consumed so far (compressed bytes for gzip), None when unknown."""
        if not self.compressed:
            return self.offset
        if self._source_tell is None:
            return None
        try:
            pos = self._source_tell()
        except (OSError, ValueError):  # closed or not seekable after all
            return None
        return pos if self.size is None else min(pos, self.size)

    def close(self) -> None:
        for f in self._closers:
            with contextlib.suppress(OSError):  # a damaged gzip member can complain again on close
                f.close()
        self._closers = []


def describe(source: str | os.PathLike[str] | BinaryIO) -> str:
    """A short display name for messages."""
    if isinstance(source, str | os.PathLike):
        return Path(source).name
    name = getattr(source, "name", None)
    return Path(name).name if isinstance(name, str) else "<stream>"


def _peek(stream: BinaryIO, n: int) -> tuple[bytes, BinaryIO]:
    """Read the first ``n`` bytes and return them with a stream that still starts at byte 0."""
    head = stream.read(n)
    if not isinstance(head, bytes | bytearray):
        raise InputError("log source must be opened in binary mode ('rb')")
    head = bytes(head)
    try:
        if stream.seekable():
            stream.seek(-len(head), io.SEEK_CUR)
            return head, stream
    except (OSError, ValueError):
        pass
    return head, cast(BinaryIO, _Prefixed(head, stream))


def open_source(source: str | os.PathLike[str] | BinaryIO) -> tuple[ByteStream, bytes, Path | None]:
    """Open ``source`` and return the (decompressed) stream, its head bytes and the path if any.

    Raises
    ------
    LogFormatError
        Empty file, or a gzip member whose first bytes cannot be decompressed.
    LogNotFoundError
        No file at the path (code ``file_not_found``).
    StorageError
        The path cannot be opened otherwise (a directory, no permission).
    """
    name = describe(source)
    closers: list[Readable] = []
    path: Path | None = None
    if isinstance(source, str | os.PathLike):
        path = Path(source)
        try:
            raw: BinaryIO = open(path, "rb")  # noqa: SIM115 -- closed by ByteStream.close
        except FileNotFoundError as exc:
            raise LogNotFoundError(f"log file not found: {path}") from exc
        except IsADirectoryError as exc:
            raise StorageError(f"log path is a directory, not a file: {path}") from exc
        except OSError as exc:
            raise StorageError(f"cannot open log file {path}: {exc.strerror or exc}") from exc
        closers.append(raw)
    else:
        raw = source
    start, size = _extent(raw, path)
    try:
        head, raw = _peek(raw, HEAD_BYTES)
    except OSError as exc:
        ByteStream(raw, name, compressed=False, closers=closers).close()
        raise StorageError(f"cannot read log {name}: {exc}") from exc
    if not head:
        ByteStream(raw, name, compressed=False, closers=closers).close()
        raise LogFormatError(f"{name}: empty log")
    if head[:2] != GZIP_MAGIC:
        return ByteStream(raw, name, compressed=False, closers=closers, size=size), head, path
    gz_start = raw.tell() if raw.seekable() else 0
    gz = gzip.GzipFile(fileobj=raw, mode="rb")
    inner = ByteStream(gz, name, compressed=True, closers=[gz, *closers])
    try:
        inner_head = inner.read(HEAD_BYTES)
    except StreamDamage as exc:
        inner.close()
        raise LogFormatError(f"{name}: gzip data cannot be decompressed: {exc}") from exc
    if not inner_head:
        inner.close()
        raise LogFormatError(f"{name}: empty log (the gzip member decompresses to nothing)")
    if not raw.seekable():
        # Keep the decompressed head and continue decompressing from where the peek stopped.
        replay = _Prefixed(inner_head, gz)
        return ByteStream(replay, name, compressed=True, closers=[gz, *closers]), inner_head, path
    # Restart the decompressor so readers see decompressed byte 0 again.
    gz.close()  # does not close ``raw``: GzipFile only closes files it opened itself
    raw.seek(gz_start)
    gz = gzip.GzipFile(fileobj=raw, mode="rb")
    seekable_raw = raw
    base = start if start is not None else gz_start
    return ByteStream(gz, name, compressed=True, closers=[gz, *closers], size=size,
                      source_tell=lambda: seekable_raw.tell() - base), inner_head, path


def _extent(raw: BinaryIO, path: Path | None) -> tuple[int | None, int | None]:
    """Where the log starts in ``raw`` and how many bytes it has from there, when the source can tell."""
    try:
        start: int | None = raw.tell() if raw.seekable() else None
    except (OSError, ValueError):
        start = None
    total: int | None = None
    try:
        st = path.stat() if path is not None else os.fstat(raw.fileno())
        total = st.st_size if stat.S_ISREG(st.st_mode) else None  # a pipe or socket has no size
    except (AttributeError, OSError, ValueError, io.UnsupportedOperation):
        if start is not None:  # e.g. BytesIO: measure by seeking to the end and back
            try:
                total = raw.seek(0, io.SEEK_END)
                raw.seek(start)
            except (OSError, ValueError):
                total = None
    if total is None:
        return start, None
    return start, max(total - (start or 0), 0)
